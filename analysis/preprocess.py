"""Rest baseline, smoothed activation, the pressure signal and the contact score of a run.

Baseline (rest impedance per finger and taxel) and its uncertainty, in this order:

- ``tare``: the run's ``tare`` event (``detail.start``/``detail.end``, s), the protocol's rest
  stretch before anything moves — the normal case of a recorded run; uncertainty 0;
- ``stored``: ``biotac/baseline`` — an import's calibration file or its estimate across the
  files of one import, or a recorded run's session calibration; uncertainty: the stored
  ``biotac/baseline_uncertainty`` if there is one, else ``contact.stored_uncertainty_counts``
  (the drift of a sensor since its calibration that is not common to all its electrodes);
- ``record``: the ``baseline.fallback_window_s`` stretch in which the finger is least pressed
  (the lowest mean PDC if recorded, else the lowest summed electrode impedance: impedance
  rises under pressure) — never simply the first samples (a record that starts in contact
  would take the contact as its zero). A record that never leaves contact has no rest
  stretch at all, and nothing in the record can say so: the summary states the assumption.

Each finger's samples outside 1..4094 counts (``RunData.valid``) are bridged by linear
interpolation in time; a finger with fewer than half its samples usable is not analysed
(``unusable``, with the reason) and never holds the other fingers back.

Smoothing: a running median of ``contact.despike_frames`` frames (real BioTacs glitch on one
electrode for a frame or two, by up to ~150 counts: see the resting recording in
``tests/data``), then Kalman + RTS (:meth:`tactile.pipeline.TactileModel.smooth`).

Pressure signal per finger, (T,) above rest: the PDC minus its rest level (counts) when the
record has PDC, else the proxy :func:`tactile.signals.pdc_proxy` (sum of the smoothed
activations, kΩ). ``pressure.signal`` forces either.

Contact score per finger, (T,): :func:`tactile.contact.contact_score` of the smoothed
impedance, in units of the record's own noise (the spread of the raw ln Z about the smoothed
one, per taxel) and the baseline's uncertainty.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.ndimage import median_filter

from tactile import contact as tcontact
from tactile import signals

from .load import COUNT_RANGE, RunData
from .segments import smooth

MIN_USABLE_FRACTION = 0.5


@dataclass
class Baseline:
    """The rest state the activation is measured from.

    Attributes:
        kind: ``tare``, ``stored`` or ``record`` (see the module doc).
        impedance: (F, 24) rest impedance, kΩ.
        uncertainty: (F, 24) uncertainty of ln Z_rest (dimensionless).
        description: one sentence for the summary (where the numbers come from, how sure).
        rest: per finger, the [start, stop) frames of the rest stretch used for the pressure's
            rest level and noise (the tare, or the quietest stretch).
    """

    kind: str
    impedance: np.ndarray
    uncertainty: np.ndarray
    description: str
    rest: list[tuple[int, int]]


@dataclass
class PreparedRun:
    """Smoothed activation, pressure and contact score of every finger.

    Attributes:
        raw_activation: (T, F, 24) unsmoothed activation, kΩ.
        activation: (T, F, 24) despiked, Kalman+RTS smoothed activation, kΩ.
        pressure: (T, F) pressure above rest (``pressure_units``).
        proxy: (T, F) sum of smoothed activations, kΩ (always computed).
        pressure_units: "count" (PDC) or "kohm" (proxy).
        pressure_name: "pdc" or "proxy".
        baseline: the :class:`Baseline`.
        rest_noise: (F,) std of the pressure during the rest stretch.
        noise: (F, 24) the record's white-noise level of ln Z per taxel.
        score: (T, F) contact score (noise units) of the smoothed activation.
        fine_score: (T, F) the same of the despiked activation lightly smoothed
            (Savitzky–Golay over ``segmentation.smooth_s``), for the contacts' edges.
        usable: finger → True if analysed; ``unusable``: finger → reason it is not.
        repaired: finger → samples bridged by interpolation.
    """

    raw_activation: np.ndarray
    activation: np.ndarray
    pressure: np.ndarray
    proxy: np.ndarray
    pressure_units: str
    pressure_name: str
    baseline: Baseline
    rest_noise: np.ndarray
    noise: np.ndarray
    score: np.ndarray
    fine_score: np.ndarray
    unusable: dict = field(default_factory=dict)
    repaired: dict = field(default_factory=dict)

    @property
    def baseline_source(self) -> str:
        return self.baseline.description

    @property
    def rest(self) -> list[tuple[int, int]]:
        return self.baseline.rest


def tare_window(run: RunData) -> tuple[int, int] | None:
    """Frame indices [start, stop) of the run's tare stretch, or ``None`` without a usable one."""
    for _, _, detail in run.events.of_kind("tare"):
        try:
            t0, t1 = float(detail["start"]), float(detail["end"])
        except (KeyError, TypeError, ValueError):
            continue
        i0, i1 = np.searchsorted(run.time, [t0, t1])
        if i1 - i0 >= 5:
            return int(i0), int(i1)
    return None


def quietest_window(level, n: int) -> tuple[int, int]:
    """[start, start+n) with the lowest mean of ``level`` (T,), ties to the earliest."""
    level = np.asarray(level, float)
    n = max(1, min(int(n), len(level)))
    means = np.convolve(level, np.ones(n) / n, "valid")
    start = int(np.argmin(means))
    return start, start + n


def repair(counts: np.ndarray, valid: np.ndarray, fingers) -> tuple[np.ndarray, dict, dict]:
    """Impedance (T, F, 24) kΩ with each finger's invalid samples bridged linearly in time.

    Returns ``(impedance, unusable, repaired)``: fingers with fewer than
    :data:`MIN_USABLE_FRACTION` usable samples are left as they are (counts clipped into
    :data:`.load.COUNT_RANGE`, so every impedance is finite) and named in ``unusable`` with
    the reason."""
    T = counts.shape[0]
    safe = np.clip(counts, *COUNT_RANGE)
    imp = signals.counts_to_impedance(safe)
    unusable, repaired = {}, {}
    idx = np.arange(T)
    for k, f in enumerate(fingers):
        ok = valid[:, k]
        if ok.all():
            continue
        if ok.sum() < max(2, MIN_USABLE_FRACTION * T):
            c = counts[:, k]
            if np.all(c <= 0):
                why = "every electrode reads 0 in every frame (disconnected, or a channel shorted)"
            elif np.all(c >= 4095):
                why = "every electrode reads 4095 (saturated: an impedance of 0 kΩ) in every frame"
            else:
                stuck = np.flatnonzero(np.all((c < 1) | (c > 4094), axis=0))
                why = (f"taxel(s) {', '.join(str(i + 1) for i in stuck)} outside 1..4094 counts throughout"
                       if stuck.size else f"only {int(ok.sum())} of {T} frames have all 24 electrodes within "
                                          f"1..4094 counts")
            unusable[f] = why
            continue
        for j in range(imp.shape[2]):
            imp[~ok, k, j] = np.interp(idx[~ok], idx[ok], imp[ok, k, j])
        repaired[f] = int((~ok).sum())
    return imp, unusable, repaired


def choose_baseline(run: RunData, imp: np.ndarray, cfg) -> Baseline:
    """The rest impedance, its uncertainty and where it comes from (module doc)."""
    F = len(run.fingers)
    n_fb = int(round(cfg.baseline_fallback_window_s * run.rate_hz))
    window = tare_window(run)
    if window is not None:
        base = imp[window[0]:window[1]].mean(axis=0)
        return Baseline("tare", base, np.zeros((F, 24)), "tare: the protocol's rest stretch before the contact",
                        [window] * F)
    level = run.pdc if run.pdc is not None else imp.sum(axis=2)
    rest = [quietest_window(level[:, k], n_fb) for k in range(F)]
    if run.baseline_counts is not None:
        counts = np.clip(run.baseline_counts, *COUNT_RANGE)
        method = (run.attrs.get("baseline") or {}).get("method", "stored")
        if run.baseline_uncertainty is not None:
            sigma, how = run.baseline_uncertainty, "its stored uncertainty"
        else:
            sigma, how = cfg.contact.stored_uncertainty_counts, \
                f"an assumed {cfg.contact.stored_uncertainty_counts:g} counts per electrode"
        unc = tcontact.counts_uncertainty_to_log(counts, sigma)
        return Baseline("stored", signals.counts_to_impedance(counts), np.broadcast_to(unc, (F, 24)).copy(),
                        f"no tare event: the stored baseline biotac/baseline ({method}), uncertain by {how}", rest)
    base = np.stack([imp[a:b, k].mean(axis=0) for k, (a, b) in enumerate(rest)])
    what = "PDC" if run.pdc is not None else "summed electrode impedance"
    return Baseline("record", base, np.zeros((F, 24)),
                    f"no tare event and no stored baseline: the {cfg.baseline_fallback_window_s:g} s stretch of "
                    f"lowest {what} per finger, assumed at rest (a record that never leaves contact has no rest "
                    f"stretch: import with baseline=estimate or a calibration file)", rest)


def despike(impedance: np.ndarray, frames: int) -> np.ndarray:
    """Running median of ``frames`` (odd) frames along time; ``frames`` ≤ 1 returns the input."""
    if frames <= 1 or len(impedance) < frames:
        return impedance
    return median_filter(impedance, size=(frames | 1,) + (1,) * (impedance.ndim - 1), mode="nearest")


def prepare(run: RunData, cfg, model) -> PreparedRun:
    """Baseline → activation → despike + Kalman/RTS → pressure and contact score, all fingers."""
    valid = run.valid if run.valid is not None else np.ones(run.electrodes.shape[:2], bool)
    imp, unusable, repaired = repair(run.electrodes, valid, run.fingers)
    baseline = choose_baseline(run, imp, cfg)
    raw = signals.activation(imp, baseline.impedance)
    clean = despike(raw, cfg.contact.despike_frames)
    act = model.smooth(clean)
    proxy = signals.pdc_proxy(act)                                   # (T, F)
    use_pdc = run.pdc is not None and cfg.pressure_signal in ("auto", "pdc")
    description = baseline.description
    if cfg.pressure_signal == "pdc" and run.pdc is None:
        description += "; pressure.signal=pdc but the record has no PDC: proxy used"
    baseline.description = description
    if use_pdc:
        p0 = np.array([run.pdc[a:b, k].mean() for k, (a, b) in enumerate(baseline.rest)])
        pressure = run.pdc - p0
        units, name = "count", "pdc"
    else:
        pressure, units, name = proxy.copy(), "kohm", "proxy"
    rest_noise = np.array([max(float(np.std(pressure[a:b, k])), 1e-6) for k, (a, b) in enumerate(baseline.rest)])
    smooth_imp = np.maximum(baseline.impedance + act, 1e-6)
    noise = tcontact.residual_noise(np.log(imp), np.log(smooth_imp), floor=1e-6)             # (F, 24)
    change = tcontact.relative_change(smooth_imp, baseline.impedance)
    score = tcontact.contact_score(change, noise, baseline.uncertainty)
    light = np.maximum(baseline.impedance + smooth(clean, run.rate_hz, cfg.segmentation.smooth_s), 1e-6)
    fine = tcontact.contact_score(tcontact.relative_change(light, baseline.impedance), noise, baseline.uncertainty)
    for f in unusable:
        score[:, run.fingers.index(f)] = fine[:, run.fingers.index(f)] = 0.0
    return PreparedRun(raw_activation=raw, activation=act, pressure=pressure, proxy=proxy, pressure_units=units,
                    pressure_name=name, baseline=baseline, rest_noise=rest_noise, noise=noise, score=score,
                    fine_score=fine,
                    unusable=unusable, repaired=repaired)

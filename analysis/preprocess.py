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

A record longer than ``memory.chunk_frames`` frames is prepared a stretch at a time
(:mod:`analysis.chunking`: each stretch with the frames around it that the smoothers reach, so
the values are those of the whole record); only the (T, F) signals below are kept whole, as
float32, and the (T, F, 24) activations are computed again for the windows that ask for them.
The record's noise level (below) is measured on at most ``memory.noise_sample_frames`` frames,
evenly spread (every frame of a shorter record).

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

import numba
import numpy as np

from tactile_flow.tactile import contact as tcontact
from tactile_flow.tactile import signals

from .chunking import ImpedanceReader, LazyActivation, smoother_reach, stretches
from .electrodes import COUNT_RANGE, READ_FRAMES
from .load import RunData
from .segments import savgol_frames, smooth

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
class Envelope:
    """The activation of a record in ``bins`` stretches of time, for pictures of any length.

    Attributes:
        edges: (bins + 1,) frame indices of the stretches' boundaries.
        raw_min, raw_max, act_min, act_max: (bins, F, 24) the lowest and highest raw and smoothed
            activation (kΩ) within each stretch.
        peak: (F, 24) the largest |smoothed activation| of each taxel over the record, kΩ.
    """

    edges: np.ndarray
    raw_min: np.ndarray
    raw_max: np.ndarray
    act_min: np.ndarray
    act_max: np.ndarray
    peak: np.ndarray

    @classmethod
    def empty(cls, T: int, F: int, bins: int = 2000) -> Envelope:
        edges = np.unique(np.linspace(0, T, min(bins, T) + 1).astype(np.int64))
        n = len(edges) - 1
        return cls(edges, *(np.full((n, F, 24), v) for v in (np.inf, -np.inf, np.inf, -np.inf)), np.zeros((F, 24)))

    def add(self, a: int, raw: np.ndarray, act: np.ndarray) -> None:
        """Fold in frames [a, a + len(raw)) (each (n, F, 24))."""
        b = a + len(raw)
        first = int(np.searchsorted(self.edges, a, "right")) - 1
        last = int(np.searchsorted(self.edges, b - 1, "right")) - 1
        starts = np.maximum(self.edges[first:last + 1], a) - a
        for lo, hi, x in ((self.raw_min, self.raw_max, raw), (self.act_min, self.act_max, act)):
            m = x.shape[1] * x.shape[2]
            _fold_extremes(np.ascontiguousarray(x).reshape(len(x), m), starts,
                           lo[first:last + 1].reshape(-1, m), hi[first:last + 1].reshape(-1, m))
        np.maximum(self.peak, np.abs(act).max(axis=0), out=self.peak)


@numba.njit(cache=True, nogil=True)
def _fold_extremes(x, starts, lo, hi):  # pragma: no cover - compiled
    """``lo[s] = minimum(lo[s], x[starts[s]:starts[s + 1]].min(axis=0))`` and ``hi`` likewise
    with the maximum (NaN propagates, as with ``np.minimum``); the last stretch runs to the end
    of ``x`` (n, M). ``lo``, ``hi`` (len(starts), M), updated in place. One pass over ``x``:
    ``np.minimum.reduceat`` along the frames took ~4× longer."""
    n, m = x.shape
    for s in range(len(starts)):
        stop = starts[s + 1] if s + 1 < len(starts) else n
        for t in range(starts[s], stop):
            for j in range(m):
                v = x[t, j]
                if v < lo[s, j] or v != v:
                    lo[s, j] = v
                if v > hi[s, j] or v != v:
                    hi[s, j] = v


@dataclass
class PreparedRun:
    """Smoothed activation, pressure and contact score of every finger.

    Attributes:
        raw_activation: (T, F, 24) unsmoothed activation, kΩ.
        activation: (T, F, 24) despiked, Kalman+RTS smoothed activation, kΩ. Both are arrays,
            or for a record of more than ``memory.chunk_frames`` frames
            :class:`analysis.chunking.LazyActivation`: index them by windows (``[a:b, k]``).
        pressure: (T, F) pressure above rest (``pressure_units``).
        proxy: (T, F) sum of smoothed activations, kΩ (always computed).
        causal_proxy: (T, F) sum of the forward-only Kalman-filtered raw activation, kΩ: what
            an online estimate knows at each frame (dates a slip the smoother would blur), or
            ``None`` when not asked for.
        pressure_units: "count" (PDC) or "kohm" (proxy).
        pressure_name: "pdc" or "proxy".
        baseline: the :class:`Baseline`.
        rest_noise: (F,) std of the pressure during the rest stretch.
        noise: (F, 24) the record's white-noise level of ln Z per taxel.
        score: (T, F) contact score (noise units) of the smoothed activation.
        fine_score: (T, F) the same of the despiked activation lightly smoothed
            (Savitzky–Golay over ``segmentation.smooth_s``), for the contacts' edges.
        envelope: the :class:`Envelope` of the activations, for figures.
        preparation: how the record was prepared (for provenance): ``stretches``,
            ``chunk_frames``, ``noise_sample_every`` (frames).
        usable: finger → True if analysed; ``unusable``: finger → reason it is not.
        repaired: finger → samples bridged by interpolation.

    The (T, F) signals are float64, or float32 for a record prepared in stretches.
    """

    raw_activation: np.ndarray | LazyActivation
    activation: np.ndarray | LazyActivation
    pressure: np.ndarray
    proxy: np.ndarray
    causal_proxy: np.ndarray | None
    pressure_units: str
    pressure_name: str
    baseline: Baseline
    rest_noise: np.ndarray
    noise: np.ndarray
    score: np.ndarray
    fine_score: np.ndarray
    envelope: Envelope
    preparation: dict = field(default_factory=dict)
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


def unusable_fingers(electrodes, valid: np.ndarray, fingers) -> tuple[dict, dict]:
    """``(unusable, repaired)``: the fingers with fewer than :data:`MIN_USABLE_FRACTION` usable
    samples (finger → why), and the others' count of samples to bridge (finger → frames).

    ``electrodes``: (T, F, 24) counts (array or stored); ``valid``: (T, F) bool."""
    T = len(valid)
    unusable, repaired = {}, {}
    for k, f in enumerate(fingers):
        ok = int(valid[:, k].sum())
        if ok == T:
            continue
        if ok < max(2, MIN_USABLE_FRACTION * T):
            unusable[f] = _why_unusable(electrodes, k, ok, T)
        else:
            repaired[f] = T - ok
    return unusable, repaired


def _why_unusable(electrodes, k: int, ok: int, T: int) -> str:
    zero, saturated, stuck = True, True, np.ones(24, bool)
    for a in range(0, T, READ_FRAMES):
        c = electrodes[a:a + READ_FRAMES, k]
        zero &= bool(np.all(c <= 0))
        saturated &= bool(np.all(c >= 4095))
        stuck &= np.all((c < 1) | (c > 4094), axis=0)
    if zero:
        return "every electrode reads 0 in every frame (disconnected, or a channel shorted)"
    if saturated:
        return "every electrode reads 4095 (saturated: an impedance of 0 kΩ) in every frame"
    if stuck.any():
        return f"taxel(s) {', '.join(str(i + 1) for i in np.flatnonzero(stuck))} outside 1..4094 counts throughout"
    return f"only {ok} of {T} frames have all 24 electrodes within 1..4094 counts"


def choose_baseline(run: RunData, read: ImpedanceReader, cfg) -> Baseline:
    """The rest impedance, its uncertainty and where it comes from (module doc); ``read(a, b)``
    gives the (repaired) impedance of frames [a, b)."""
    F = len(run.fingers)
    n_fb = int(round(cfg.baseline_fallback_window_s * run.rate_hz))
    window = tare_window(run)
    if window is not None:
        base = read(*window).mean(axis=0)
        return Baseline("tare", base, np.zeros((F, 24)), "tare: the protocol's rest stretch before the contact",
                        [window] * F)
    if run.pdc is not None:
        level = run.pdc
    else:
        level = np.concatenate([read(a, min(a + READ_FRAMES, read.T)).sum(axis=2)
                                for a in range(0, read.T, READ_FRAMES)])
    rest = [quietest_window(level[:, k], n_fb) for k in range(F)]
    del level
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
    base = np.stack([read(a, b, k).mean(axis=0) for k, (a, b) in enumerate(rest)])
    what = "PDC" if run.pdc is not None else "summed electrode impedance"
    return Baseline("record", base, np.zeros((F, 24)),
                    f"no tare event and no stored baseline: the {cfg.baseline_fallback_window_s:g} s stretch of "
                    f"lowest {what} per finger, assumed at rest (a record that never leaves contact has no rest "
                    f"stretch: import with baseline=estimate or a calibration file)", rest)


def despike(impedance: np.ndarray, frames: int) -> np.ndarray:
    """Running median of ``frames`` (odd) frames along time; ``frames`` ≤ 1 returns the input."""
    if frames <= 1 or len(impedance) < frames:
        return impedance
    return signals.running_median(impedance, frames)


def smoothed(imp: np.ndarray, rest: np.ndarray, cfg, model) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(raw, despiked, smoothed)`` activation (kΩ) of impedance ``imp`` (T, ..., 24) above ``rest``."""
    raw = signals.activation(imp, rest)
    clean = despike(raw, cfg.contact.despike_frames)
    return raw, clean, model.smooth(clean)


def prepare(run: RunData, cfg, model, causal_proxy: bool = True) -> PreparedRun:
    """Baseline → activation → despike + Kalman/RTS → pressure and contact score, all fingers,
    in one piece or a stretch at a time (module doc); ``causal_proxy=False`` leaves out the
    causal proxy (only a pour's slip dating reads it)."""
    T, F = len(run.time), len(run.fingers)
    rate = run.rate_hz
    valid = run.valid if run.valid is not None else np.ones((T, F), bool)
    unusable, repaired = unusable_fingers(run.electrodes, valid, run.fingers)
    read = ImpedanceReader(run.electrodes, valid, [k for k, f in enumerate(run.fingers) if f not in unusable])
    baseline = choose_baseline(run, read, cfg)
    if cfg.pressure_signal == "pdc" and run.pdc is None:
        baseline.description += "; pressure.signal=pdc but the record has no PDC: proxy used"
    tc = model.config
    reach = smoother_reach(tc.kalman_r, tc.kalman_q, cfg.contact.despike_frames,
                           savgol_frames(rate, cfg.segmentation.smooth_s))
    parts = stretches(T, cfg.memory.chunk_frames, reach)
    whole = len(parts) == 1
    dtype = np.float64 if whole else np.float32
    base, unc = baseline.impedance, baseline.uncertainty
    progress = _progress(cfg, T, len(parts))

    # pass 1: the proxies, the residuals the noise is measured on, the envelope
    proxy = np.empty((T, F), dtype)
    causal = np.empty((T, F), dtype) if causal_proxy else None
    stride = -(-T // cfg.memory.noise_sample_frames)
    residual = np.empty((len(range(0, T, stride)), F, 24))         # ln Z − ln Z_smoothed, sampled frames
    envelope, kept = Envelope.empty(T, F), None
    for (a, b), (a0, b0) in parts:
        imp = read(a0, b0)
        raw, clean, act = smoothed(imp, base, cfg, model)
        core = slice(a - a0, b - a0)
        proxy[a:b] = signals.pdc_proxy(act[core])
        if causal is not None:
            causal[a:b] = signals.kalman_filter(raw, R=tc.kalman_r, Q=tc.kalman_q)[core].sum(axis=-1)
        rows = np.arange(a + (-a) % stride, b, stride)
        residual[rows // stride] = np.log(imp[rows - a0]) - np.log(np.maximum(base + act[rows - a0], 1e-6))
        envelope.add(a, raw[core], act[core])
        kept = (raw, clean, act) if whole else None
        progress.update(b - a)
    noise = tcontact.noise_from_residuals(residual, floor=1e-6, overwrite=True)          # (F, 24)
    del residual

    # pass 2: the contact scores, which need the noise
    score, fine = np.empty((T, F), dtype), np.empty((T, F), dtype)
    for (a, b), (a0, b0) in parts:
        raw, clean, act = kept if whole else smoothed(read(a0, b0), base, cfg, model)
        core = slice(a - a0, b - a0)
        change = tcontact.relative_change(np.maximum(base + act[core], 1e-6), base)
        score[a:b] = tcontact.contact_score(change, noise, unc)
        light = np.maximum(base + smooth(clean, rate, cfg.segmentation.smooth_s)[core], 1e-6)
        fine[a:b] = tcontact.contact_score(tcontact.relative_change(light, base), noise, unc)
        progress.update(b - a)
    progress.close()
    for f in unusable:
        score[:, run.fingers.index(f)] = fine[:, run.fingers.index(f)] = 0.0

    if run.pdc is not None and cfg.pressure_signal in ("auto", "pdc"):
        p0 = np.array([run.pdc[a:b, k].mean(dtype=np.float64) for k, (a, b) in enumerate(baseline.rest)])
        pressure, units, name = np.empty((T, F), dtype), "count", "pdc"
        for k in range(F):
            pressure[:, k] = run.pdc[:, k] - p0[k]
    else:
        pressure, units, name = proxy.copy(), "kohm", "proxy"
    rest_noise = np.array([max(float(np.std(pressure[a:b, k])), 1e-6) for k, (a, b) in enumerate(baseline.rest)])
    if whole:
        raw_activation, activation = kept[0], kept[2]
    else:
        def rest_of(k):
            return base if k is None else base[k]
        raw_activation = LazyActivation(lambda a0, b0, k: signals.activation(read(a0, b0, k), rest_of(k)),
                                        (T, F, 24), 0, cfg.memory.chunk_frames)
        activation = LazyActivation(lambda a0, b0, k: smoothed(read(a0, b0, k), rest_of(k), cfg, model)[2],
                                    (T, F, 24), reach, cfg.memory.chunk_frames)
    return PreparedRun(raw_activation=raw_activation, activation=activation, pressure=pressure, proxy=proxy,
                       causal_proxy=causal, pressure_units=units, pressure_name=name, baseline=baseline,
                       rest_noise=rest_noise, noise=noise, score=score, fine_score=fine, envelope=envelope,
                       preparation={"stretches": len(parts), "chunk_frames": cfg.memory.chunk_frames,
                                    "noise_sample_every": stride},
                       unusable=unusable, repaired=repaired)


def _progress(cfg, T: int, stretches_: int):
    """A progress bar over both passes of a record prepared in stretches (none for one piece)."""
    from tactile_flow.cliapp.progress import progress_bar
    return progress_bar(total=2 * T, unit="frame", desc="preprocessing", leave=False, dynamic_ncols=True,
                disable=not cfg.progress or stretches_ == 1)

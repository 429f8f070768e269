"""Rest baseline, smoothed activation and the pressure signal of a run.

Baseline (rest impedance per finger and taxel):

- the run's ``tare`` event (``detail.start``/``detail.end``, s): the protocol's rest stretch
  before anything moves; this is the normal case;
- records without a tare but with a stored baseline (an import's calibration file or its
  estimate across files, ``biotac/baseline``): that baseline;
- otherwise: the ``baseline.fallback_window_s`` stretch
  in which the finger is least pressed — the lowest mean PDC if recorded, else the lowest
  summed electrode impedance (impedance rises under pressure) — never simply the first samples
  (a record that starts in contact would take the contact as its zero).

Pressure signal per finger, (T,) above rest: the PDC minus its rest level (counts) when the
record has PDC, else the proxy :func:`tactile.signals.pdc_proxy` (sum of the smoothed
activations, kΩ). ``pressure.signal`` forces either.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tactile import signals

from .load import RunData


@dataclass
class Prepared:
    """Smoothed activation and pressure of every finger.

    Attributes:
        raw_activation: (T, F, 24) unsmoothed activation, kΩ.
        activation: (T, F, 24) Kalman+RTS smoothed activation, kΩ.
        pressure: (T, F) pressure above rest (``pressure_units``).
        proxy: (T, F) sum of smoothed activations, kΩ (always computed).
        pressure_units: "count" (PDC) or "kohm" (proxy).
        pressure_name: "pdc" or "proxy".
        baseline_source: "tare" or a sentence describing the fallback.
        rest: (start, stop) frame indices of the rest stretch per finger.
        rest_noise: (F,) std of the pressure during rest.
    """

    raw_activation: np.ndarray
    activation: np.ndarray
    pressure: np.ndarray
    proxy: np.ndarray
    pressure_units: str
    pressure_name: str
    baseline_source: str
    rest: list[tuple[int, int]]
    rest_noise: np.ndarray


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


def prepare(run: RunData, cfg, model) -> Prepared:
    """Baseline → activation → Kalman+RTS smoothing → pressure, for all fingers."""
    imp = signals.counts_to_impedance(run.electrodes)              # (T, F, 24) kΩ
    window = tare_window(run)
    n_fb = int(round(cfg.baseline_fallback_window_s * run.rate_hz))
    rest = []
    for k in range(len(run.fingers)):
        if window is not None:
            rest.append(window)
        elif run.pdc is not None:
            rest.append(quietest_window(run.pdc[:, k], n_fb))
        else:
            rest.append(quietest_window(imp[:, k].sum(axis=1), n_fb))
    if window is not None:
        source = "tare"
    elif run.baseline_counts is not None:
        method = (run.attrs.get("baseline") or {}).get("method", "stored")
        source = f"no tare event: the stored baseline biotac/baseline ({method})"
    else:
        source = (f"no tare event: the {cfg.baseline_fallback_window_s:g} s stretch of lowest "
                  + ("PDC" if run.pdc is not None else "summed electrode impedance") + " per finger")
    if window is None and run.baseline_counts is not None:
        base = signals.counts_to_impedance(run.baseline_counts)                          # (F, 24)
    else:
        base = np.stack([imp[a:b, k].mean(axis=0) for k, (a, b) in enumerate(rest)])     # (F, 24)
    raw = signals.activation(imp, base)
    act = model.smooth(raw)
    proxy = signals.pdc_proxy(act)                                   # (T, F)
    use_pdc = run.pdc is not None and cfg.pressure_signal in ("auto", "pdc")
    if cfg.pressure_signal == "pdc" and run.pdc is None:
        source += "; pressure.signal=pdc but the record has no PDC: proxy used"
    if use_pdc:
        p0 = np.array([run.pdc[a:b, k].mean() for k, (a, b) in enumerate(rest)])
        pressure = run.pdc - p0
        units, name = "count", "pdc"
    else:
        pressure, units, name = proxy.copy(), "kohm", "proxy"
    noise = np.array([max(float(np.std(pressure[a:b, k])), 1e-6) for k, (a, b) in enumerate(rest)])
    return Prepared(raw_activation=raw, activation=act, pressure=pressure, proxy=proxy, pressure_units=units,
                    pressure_name=name, baseline_source=source, rest=rest, rest_noise=noise)

"""Per-stream clock model: map a device's timestamps onto the host clock.

Every sample carries the device's own timestamp ``d`` (s, device clock) and the host
time of receipt ``h`` (s, host monotonic clock). The model is

    h = offset + (1 + drift) · d + latency,        latency ≥ 0,

so the samples delivered with the least latency lie on a line, the *lower envelope* of
``h`` against ``d``. We take the minimum of ``h − d`` in each window of ``window_s``
(device seconds), fit a straight line through those minima with outlier rejection, and
read the time of a sample as that line at its device time. The time base therefore
includes the stream's minimum transport latency (unobservable from timestamps alone);
``min_latency_s``, when known from the hardware, is subtracted.

The computation is pure functions on arrays (:func:`window_minima`, :func:`fit_envelope`,
:func:`sequence_gaps`); :class:`OnlineClockModel` only accumulates the per-window minima
so a stream can be mapped as it arrives and refitted on all of it at the end. Memory is
one point per window (an hour at 1 s windows: 3600 points).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ClockFit:
    """``host = intercept + slope · (device − device_ref)``, all in s.

    ``offset_s`` and ``drift`` are the same line in the form ``host = offset + (1+drift)·device``;
    ``n_windows`` minima were fitted (``n_used`` kept after outlier rejection).
    """

    device_ref: float
    intercept: float
    slope: float
    n_windows: int
    n_used: int

    @property
    def drift(self) -> float:
        """Relative rate error of the device clock (dimensionless; ×1e6 for ppm)."""
        return self.slope - 1.0

    @property
    def offset_s(self) -> float:
        return self.intercept - self.slope * self.device_ref

    def __call__(self, device_time) -> np.ndarray:
        """Host time (s) of samples stamped ``device_time`` (s, any shape)."""
        return self.intercept + self.slope * (np.asarray(device_time, float) - self.device_ref)


def window_minima(device_time, host_time, window_s: float = 1.0, origin: float = 0.0):
    """Lowest ``host − device`` in each window of ``window_s`` device seconds.

    Args:
        device_time, host_time: (N,) s.
        window_s: window length (device s); windows are ``[origin + k·window_s, ...)``.
    Returns:
        ``(keys, d, h)``: (W,) int window indices and the (W,) device/host times of the
        sample with the least ``h − d`` in each non-empty window, sorted by key.
    """
    d = np.asarray(device_time, float)
    h = np.asarray(host_time, float)
    if d.size == 0:
        return np.zeros(0, np.int64), np.zeros(0), np.zeros(0)
    keys = np.floor((d - origin) / window_s).astype(np.int64)
    r = h - d
    order = np.lexsort((r, keys))          # by window, then by residual
    k = keys[order]
    first = np.r_[True, k[1:] != k[:-1]]
    idx = order[first]
    return keys[idx], d[idx], h[idx]


def robust_line(x, y, k: float = 4.0, n_iter: int = 3, min_scale: float = 1e-5):
    """Least-squares line ``y = a + b·x`` refitted without points beyond ``k`` robust σ.

    ``min_scale`` (units of y) keeps quantisation-level scatter from rejecting good points.
    Returns ``(a, b, keep)`` with ``keep`` the (N,) mask of points used. Needs N ≥ 2.
    """
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    keep = np.ones(x.size, bool)
    a = b = 0.0
    for _ in range(n_iter):
        b, a = np.polyfit(x[keep], y[keep], 1)
        res = y - (a + b * x)
        scale = max(1.4826 * float(np.median(np.abs(res[keep] - np.median(res[keep])))), min_scale)
        new = np.abs(res) <= k * scale
        if new.sum() < 2 or np.array_equal(new, keep):
            break
        keep = new
    return float(a), float(b), keep


def fit_envelope(min_device, min_host, min_drift_span_s: float = 10.0,
                 min_latency_s: float = 0.0) -> ClockFit:
    """Fit the lower envelope through per-window minima (see :func:`window_minima`).

    Args:
        min_device, min_host: (W,) s, one point per window.
        min_drift_span_s: below this span of device time the drift is not identifiable
            (a few ppm of ms-level scatter) and is fixed to 0: offset only.
        min_latency_s: known minimum latency (s) subtracted from the envelope.
    Raises ValueError for W = 0.
    """
    d = np.asarray(min_device, float)
    h = np.asarray(min_host, float)
    if d.size == 0:
        raise ValueError("clock model: no samples to fit")
    ref = float(d[0])
    x = d - ref
    y = h - d                                # offset + drift·d (+ latency): small numbers
    if d.size >= 3 and x.max() - x.min() >= min_drift_span_s:
        a, b, keep = robust_line(x, y)
        slope = 1.0 + b
    else:
        a, keep, slope = float(np.median(y)), np.ones(d.size, bool), 1.0
    # a is the envelope's value of h − d at d = ref, so host = ref + a + slope·(d − ref)
    return ClockFit(ref, ref + a - min_latency_s, slope, int(d.size), int(keep.sum()))


def latency_stats(fit: ClockFit, device_time, host_time) -> dict[str, float]:
    """Residual latency ``host − fit(device)`` (ms): min, median, p95, max (NaN if empty)."""
    r = (np.asarray(host_time, float) - fit(device_time)) * 1e3
    if r.size == 0:
        return {k: math.nan for k in ("min_ms", "median_ms", "p95_ms", "max_ms")}
    return {"min_ms": float(r.min()), "median_ms": float(np.median(r)),
            "p95_ms": float(np.percentile(r, 95)), "max_ms": float(r.max())}


def sequence_gaps(seq, previous: int | None = None) -> list[tuple[int, int, int]]:
    """Jumps in a sequence number that should increase by one per sample.

    Args:
        seq: (N,) int sequence numbers in arrival order.
        previous: the last number seen before ``seq`` (None: no history).
    Returns:
        ``[(index, last_before, missing), ...]``: ``seq[index]`` follows ``last_before``
        with ``missing`` numbers lost. A repeat or a step back is reported with
        ``missing ≤ 0`` (a device restart or a duplicated message), never silently dropped.
    """
    s = np.asarray(seq, np.int64)
    if s.size == 0:
        return []
    prev = np.r_[s[0] - 1 if previous is None else previous, s[:-1]]
    jump = s - prev - 1
    return [(int(i), int(prev[i]), int(jump[i])) for i in np.flatnonzero(jump != 0)]


class OnlineClockModel:
    """Accumulate per-window minima of one stream and fit them on demand.

    ``update(d, h)`` with each batch, ``map(d)`` maps device times with the current fit
    (refitted when a window has closed), ``final()`` refits on everything. Before the first
    window closes the current batch's own minimum gives the offset, so mapping never waits.
    """

    def __init__(self, window_s: float = 1.0, min_drift_span_s: float = 10.0,
                 min_latency_s: float = 0.0):
        self.window_s = window_s
        self.min_drift_span_s = min_drift_span_s
        self.min_latency_s = min_latency_s
        self._origin: float | None = None
        self._minima: dict[int, tuple[float, float]] = {}   # window -> (d, h) of least h − d
        self._fit: ClockFit | None = None
        self._dirty = False

    @property
    def n_windows(self) -> int:
        return len(self._minima)

    def update(self, device_time, host_time) -> None:
        """Add a batch of (N,) device and host times (s)."""
        d = np.asarray(device_time, float)
        h = np.asarray(host_time, float)
        if d.size == 0:
            return
        if self._origin is None:
            self._origin = float(d[0])
        keys, dm, hm = window_minima(d, h, self.window_s, self._origin)
        for k, di, hi in zip(keys.tolist(), dm.tolist(), hm.tolist()):
            old = self._minima.get(k)
            if old is None or hi - di < old[1] - old[0]:
                self._minima[k] = (di, hi)
        self._dirty = True

    def _points(self):
        pts = np.array([self._minima[k] for k in sorted(self._minima)], float).reshape(-1, 2)
        return pts[:, 0], pts[:, 1]

    def current(self) -> ClockFit | None:
        """The fit on every window so far (None before any sample)."""
        if self._dirty and self._minima:
            d, h = self._points()
            self._fit = fit_envelope(d, h, self.min_drift_span_s, self.min_latency_s)
            self._dirty = False
        return self._fit

    def map(self, device_time) -> np.ndarray:
        """Host time (s) of ``device_time`` (s) under the current fit."""
        fit = self.current()
        if fit is None:
            raise ValueError("clock model: map() before any update()")
        return fit(device_time)

    def final(self) -> ClockFit | None:
        """Refit on every window (the same data as :meth:`current`, all of the run)."""
        self._dirty = True
        return self.current()

"""Long records in pieces: stretches of frames with the overlap the smoothers need, the
repaired impedance of any stretch, and the activation computed on demand.

The preprocessing (:mod:`analysis.preprocess`) smooths along time: a running median, a Kalman
filter and an RTS smoother, a Savitzky–Golay filter. Each output frame depends on its
neighbours, but only on near ones: the Kalman filter forgets its start, and the RTS smoother its
end, by the factor ``ρ`` per frame (the steady-state gains, :func:`smoother_reach`). A stretch
``[a, b)`` computed from the frames ``[a − reach, b + reach)`` therefore gives the values the
whole record would, to below the last bit of a float64 (``ρ^reach < 1e-20``), so a record
analysed in pieces gives the results of the record analysed whole (tested both ways).
"""

from __future__ import annotations

import math

import numpy as np

from tactile_flow.tactile import signals

from .electrodes import COUNT_RANGE

FORGET = 1e-20
"""How much of a stretch's edge the smoothers may remember at the stretch's first kept frame."""


def smoother_reach(R: float, Q: float, despike_frames: int, savgol_frames: int) -> int:
    """Frames on each side of a stretch that make its smoothed values those of the whole record.

    The random-walk Kalman filter's steady-state variance is ``P = (−Q + √(Q² + 4QR)) / 2``;
    the filter keeps ``1 − K = R / (P + Q + R)`` of its state per frame, the RTS smoother
    ``C = P / (P + Q)``: both reach back ``log(FORGET) / log(max(1 − K, C))`` frames. The running
    median and the Savitzky–Golay window add half their width.
    """
    P = (-Q + math.sqrt(Q * Q + 4 * Q * R)) / 2
    rho = max(R / (P + Q + R), P / (P + Q))
    kalman = math.ceil(math.log(FORGET) / math.log(rho)) if rho > 0 else 1
    return kalman + despike_frames // 2 + savgol_frames // 2 + 1


def stretches(T: int, frames: int, reach: int, a: int = 0, b: int | None = None):
    """``[((s, e), (s0, e0)), …]``: consecutive stretches ``[s, e)`` of at most ``max(frames,
    4·reach)`` frames covering ``[a, b)`` (default the whole T-frame record), each with the frames
    ``[s0, e0)`` to compute it from (its reach either side, clipped to the record). A record of
    at most ``frames`` frames is one stretch with nothing around it."""
    b = T if b is None else b
    step = max(frames, 4 * reach)
    return [((s, min(s + step, b)), (max(0, s - reach), min(T, min(s + step, b) + reach)))
            for s in range(a, b, step)]


class ImpedanceReader:
    """The electrode impedance (kΩ) of any stretch of frames, each usable finger's invalid
    samples bridged linearly in time between its nearest valid samples (wherever they lie,
    so a stretch gets the values the whole record would).

    ``electrodes``: (T, F, N) counts (an array or :class:`.electrodes.StoredElectrodes`);
    ``valid``: (T, F) bool; ``bridged``: the fingers (indices) whose invalid samples are
    bridged (the usable ones); the others are only clipped into the usable counts (1..4094).
    ``sensor``: the :class:`tactile.sensor.SensorModel` whose counts these are (its usable
    range and its counts → impedance); the BioTacs' when ``None``.
    """

    def __init__(self, electrodes, valid: np.ndarray, bridged, sensor=None):
        self.electrodes, self.valid = electrodes, valid
        self.T, self.F = valid.shape
        self._range = COUNT_RANGE if sensor is None else sensor.valid_counts
        self._impedance = signals.counts_to_impedance if sensor is None else sensor.impedance
        self._ok = {k: np.flatnonzero(valid[:, k]) for k in bridged if not valid[:, k].all()}

    def __call__(self, a: int, b: int, k: int | None = None) -> np.ndarray:
        """(b−a, F, N) impedance of frames [a, b), or (b−a, N) of finger ``k`` only."""
        counts = self.electrodes[a:b] if k is None else self.electrodes[a:b, k]
        imp = self._impedance(np.clip(counts, *self._range))
        for j, ok in self._ok.items():
            if k is not None and j != k:
                continue
            column = imp if k is not None else imp[:, j]
            self._bridge(column, j, ok, a, b)
        return imp

    def _bridge(self, imp: np.ndarray, j: int, ok: np.ndarray, a: int, b: int) -> None:
        """Bridge finger ``j``'s invalid frames in ``imp`` (b−a, 24), in place."""
        bad = ~self.valid[a:b, j]
        if not bad.any():
            return
        lo, hi = np.searchsorted(ok, [a, b])
        xp = ok[max(lo - 1, 0):hi + 1]                 # valid frames inside, and the nearest either side
        outside = [i for i in (xp[0], xp[-1]) if not a <= i < b]
        fp = np.empty((len(xp), imp.shape[1]))
        inside = (xp >= a) & (xp < b)
        fp[inside] = imp[xp[inside] - a]
        for i in outside:
            fp[xp == i] = self._impedance(np.clip(self.electrodes[i, j], *self._range))
        x = np.flatnonzero(bad) + a
        for t in range(imp.shape[1]):
            imp[bad, t] = np.interp(x, xp, fp[:, t])


class LazyActivation:
    """(T, F, 24) activation (kΩ) computed for the frames asked for, never held whole.

    ``compute(a0, b0, k)`` returns the activation of frames [a0, b0) (of finger ``k``, or of
    every finger for ``None``); ``reach``: the frames it needs on each side (:func:`smoother_reach`);
    ``frames``: the longest stretch computed at once. ``act[a:b, k]``, ``act[a:b]`` and
    ``act[rows, k]`` (rows: an integer array) return arrays; ``act[:, k]`` of a whole long record
    is as large as it sounds, so the analysis asks for windows.
    """

    def __init__(self, compute, shape: tuple[int, int, int], reach: int, frames: int):
        self._compute, self.shape, self.reach, self.frames = compute, shape, reach, frames
        self.ndim = 3

    def __len__(self) -> int:
        return self.shape[0]

    def __getitem__(self, key):
        key = key if isinstance(key, tuple) else (key,)
        rows, k, taxels = (key + (slice(None), slice(None)))[:3]
        if isinstance(k, slice):
            if k != slice(None):
                raise TypeError("LazyActivation: index fingers with one integer (or all of them)")
            k = None
        one = isinstance(rows, (int, np.integer))
        if one:
            rows = slice(int(rows), int(rows) + 1)
        if isinstance(rows, slice):
            a, b, step = rows.indices(len(self))
            out = self.window(a, max(a, b), k)[::step]
        else:
            idx = np.asarray(rows)
            lo, hi = (int(idx.min()), int(idx.max()) + 1) if idx.size else (0, 0)
            out = self.window(lo, hi, k)[idx - lo]
        out = out[..., taxels]
        return out[0] if one else out

    def finger(self, k: int) -> FingerActivation:
        """Finger ``k``'s (T, 24) activation, computed for the frames asked for."""
        return FingerActivation(self, k)

    def window(self, a: int, b: int, k: int | None = None) -> np.ndarray:
        """Frames [a, b) (of finger ``k``), computed a stretch of at most ``frames`` at a time."""
        if b <= a:
            return np.zeros((0,) + (self.shape[1:] if k is None else self.shape[2:]))
        parts = []
        for (s, e), (s0, e0) in stretches(self.shape[0], self.frames, self.reach, a, b):
            parts.append(self._compute(s0, e0, k)[s - s0:e - s0])
        return np.concatenate(parts) if len(parts) > 1 else parts[0]



class FingerActivation:
    """One finger's (T, 24) activation of a :class:`LazyActivation`: ``[a:b]`` → (b−a, 24)."""

    def __init__(self, activation: LazyActivation, k: int):
        self._activation, self._k = activation, k
        self.shape = (activation.shape[0], activation.shape[2])

    def __len__(self) -> int:
        return self.shape[0]

    def __getitem__(self, rows):
        return self._activation[rows, self._k]


def finger_activation(activation, k: int):
    """Finger ``k``'s (T, 24) activation: a view of an array, or a :class:`FingerActivation`."""
    return activation[:, k] if isinstance(activation, np.ndarray) else activation.finger(k)


def centre_of_pressure(activation, k: int, a: int, b: int, taxels, frames: int = 20_000) -> np.ndarray:
    """(b−a, 3) centre of pressure (mm, NaN where nothing is pressed) of finger ``k`` over frames
    [a, b), ``frames`` at a time (:func:`tactile.aggregate.centre_of_pressure`)."""
    from tactile_flow.tactile.aggregate import centre_of_pressure as cop
    parts = [cop(activation[s:min(s + frames, b), k], taxels)[0] for s in range(a, b, frames)]
    return np.concatenate(parts) if parts else np.zeros((0, 3))

"""Savitzky–Golay smoothing and peak finding on sampled signals, as ``scipy.signal`` does them.

The program does not import ``scipy.signal``: SciPy 1.17 parses its docstrings and loads
``scipy.stats`` when it is imported (~0.7 s on one core), for two functions.
These give SciPy's results: :func:`find_peaks` the same indices on every (NaN-free) input,
:func:`savgol_filter` the same arithmetic (the coefficients and edge fits by LAPACK's least
squares, the interior in the order of ``scipy.ndimage.convolve1d``), bit for bit where both use
the same LAPACK. ``tests/test_small_math.py`` compares them with SciPy's. (No SciPy module is
imported at all: ``scipy.ndimage`` alone cost a start ~0.2 s on one core.)

>>> find_peaks(np.array([0., 2., 0., 1., 0., 3., 3., 0.]), prominence=1.5).tolist()
[1, 5]
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

__all__ = ["find_peaks", "savgol_filter"]


# ----------------------------------------------------------------------------- Savitzky–Golay

def savgol_filter(x, window: int, polyorder: int = 2) -> np.ndarray:
    """Savitzky–Golay filter of ``x`` (T, ...) along its first axis (time), as
    ``scipy.signal.savgol_filter(x, window, polyorder, axis=0)`` (mode ``"interp"``).

    Each sample is the value at the window's centre of the degree-``polyorder`` polynomial
    fitted (least squares) to the ``window`` (odd) samples around it; within ``window // 2``
    of either end, the polynomial fitted to the first (last) ``window`` samples, evaluated there.
    Returns a new float array of the shape of ``x``.
    """
    x = np.asarray(x, float)
    if window % 2 == 0 or window <= polyorder:
        raise ValueError(f"the Savitzky–Golay window must be odd and longer than the polynomial's order "
                         f"{polyorder}, got {window}")
    if x.ndim == 0 or len(x) < window:
        raise ValueError(f"the Savitzky–Golay window ({window} samples) is longer than the signal "
                         f"({x.shape[0] if x.ndim else 0})")
    half, n = window // 2, len(x)
    y = np.empty_like(x)
    y[half:n - half] = _centred_sums(x, _savgol_coefficients(window, polyorder)[::-1])
    y[:half] = _polyfit_eval(x[:window], polyorder, 0, half)
    y[n - half:] = _polyfit_eval(x[n - window:], polyorder, window - half, window)
    return y


def _centred_sums(x, w) -> np.ndarray:
    """Σ_k w[half + k]·x[i + k] for every i with the whole window inside ``x`` (T, ...), summed in
    the order of ``scipy.ndimage.correlate1d``, so the interior is the same to the bit: weights
    symmetric (or antisymmetric) to within machine epsilon pair the samples around the centre,
    outermost first; any others are summed left to right after the last."""
    half, n = len(w) // 2, len(x)
    eps = np.finfo(float).eps

    def at(k):
        return x[half + k:n - half + k]
    pairs = range(-half, 0)
    if all(abs(w[half - j] - w[half + j]) <= eps for j in pairs):
        y = at(0) * w[half]
        for j in pairs:
            y += (at(j) + at(-j)) * w[half + j]
    elif all(abs(w[half - j] + w[half + j]) <= eps for j in pairs):
        y = at(0) * w[half]
        for j in pairs:
            y += (at(j) - at(-j)) * w[half + j]
    else:
        y = at(half) * w[2 * half]
        for k in range(-half, half):
            y += at(k) * w[half + k]
    return y


def _lstsq(a, b, rcond: float) -> np.ndarray:
    return np.linalg.lstsq(a, b, rcond=rcond)[0]


@lru_cache(maxsize=32)
def _savgol_coefficients(window: int, polyorder: int) -> np.ndarray:
    """(window,) convolution weights giving the fitted polynomial's value at the centre."""
    half = window // 2
    t = np.arange(-half, window - half, dtype=float)[::-1]            # reversed: for a convolution
    A = t ** np.arange(polyorder + 1, dtype=float).reshape(-1, 1)     # (polyorder + 1, window)
    e0 = np.zeros(polyorder + 1)
    e0[0] = 1.0
    c = _lstsq(A, e0, np.finfo(float).eps * max(A.shape))
    c.flags.writeable = False
    return c


def _polyfit_eval(edge, polyorder: int, start: int, stop: int) -> np.ndarray:
    """Fit a polynomial to each channel of ``edge`` (window, ...) against 0, 1, … (least
    squares on column-scaled powers, as ``numpy.polyfit``) and evaluate it at start … stop − 1."""
    t = np.arange(len(edge), dtype=float)
    lhs = t[:, None] ** np.arange(polyorder, -1, -1, dtype=float)[None, :]
    scale = np.sqrt(np.sum(lhs * lhs, axis=0))
    lhs /= scale
    c = _lstsq(lhs, edge.reshape(len(edge), -1), len(t) * np.finfo(float).eps)
    c = (c.T / scale).T                                              # (polyorder + 1, channels)
    at = np.arange(start, stop, dtype=float).reshape(-1, 1)
    y = np.zeros_like(at)
    for cj in c:                                                     # Horner
        y = y * at + cj
    return y.reshape((stop - start, *edge.shape[1:]))


# ----------------------------------------------------------------------------- peaks

def find_peaks(x, *, prominence: float | None = None, distance: float | None = None) -> np.ndarray:
    """Indices of the peaks of ``x`` (T,), as ``scipy.signal.find_peaks(x, prominence=…,
    distance=…)[0]``.

    A peak is a sample (or the middle of a flat run, rounded down) higher than both
    neighbours; the ends never are. Then, as SciPy orders them: ``distance`` (samples, ≥ 1)
    keeps, from the highest peak down, those at least ``ceil(distance)`` from every peak kept
    before; ``prominence`` (signal units) keeps those standing at least that far above the
    higher of the lowest points between them and the nearest higher sample on either side (or
    the signal's end). Returns an int array, ascending.
    """
    x = np.ascontiguousarray(x, dtype=float)
    if x.ndim != 1:
        raise ValueError(f"find_peaks takes a 1-D signal, got shape {x.shape}")
    if distance is not None and distance < 1:
        raise ValueError(f"find_peaks: distance must be at least 1 sample, got {distance}")
    peaks = _local_maxima(x)
    if distance is not None and len(peaks) > 1:
        peaks = peaks[_far_enough(peaks, x[peaks], math.ceil(distance))]
    if prominence is not None and len(peaks):
        peaks = peaks[prominence <= _prominences(x, peaks)]
    return peaks


def _local_maxima(x) -> np.ndarray:
    """Samples (the middle of flat runs, rounded down) higher than both neighbours."""
    n = len(x)
    if n < 3:
        return np.zeros(0, np.intp)
    change = np.flatnonzero(x[1:] != x[:-1]) + 1
    first = np.r_[0, change]                                # runs of equal values: [first, last]
    last = np.r_[change - 1, n - 1]
    inner = (first > 0) & (last < n - 1)
    first, last = first[inner], last[inner]
    top = (x[first - 1] < x[first]) & (x[last + 1] < x[last])
    return (first[top] + last[top]) // 2


def _far_enough(peaks, heights, distance: int) -> np.ndarray:
    """Keep-mask: from the highest peak down (ties in ``np.argsort``'s order, as SciPy), each
    kept peak removes the others closer than ``distance``. Only peaks with a neighbour that
    close take part in the (sequential) pass."""
    keep = np.ones(len(peaks), bool)
    crowded = np.diff(peaks) < distance
    crowded = np.r_[crowded, False] | np.r_[False, crowded]
    if not crowded.any():
        return keep
    order = np.argsort(heights)
    order = order[crowded[order]][::-1].tolist()
    lo = np.searchsorted(peaks, peaks - distance, side="right").tolist()   # first within reach
    hi = np.searchsorted(peaks, peaks + distance, side="left").tolist()    # first out of reach
    for j in order:
        if keep[j]:
            keep[lo[j]:j] = False
            keep[j + 1:hi[j]] = False
    return keep


def _prominences(x, peaks) -> np.ndarray:
    """x[peak] − max(left minimum, right minimum), each minimum taken from the peak to the
    nearest higher sample on that side (exclusive) or to the end (SciPy's ``wlen=None``)."""
    m, v = len(peaks), x[peaks]
    both, twice = np.r_[peaks, peaks], np.r_[v, v]
    bound = _Pyramid(x, np.maximum, -np.inf).nearest_above(both, twice, np.repeat([-1, 1], m))
    lows = _Pyramid(x, np.minimum, np.inf).reduce(np.r_[bound[:m] + 1, peaks], np.r_[peaks + 1, bound[m:]])
    return v - np.maximum(lows[:m], lows[m:])


class _Pyramid:
    """Pairwise reductions of a 1-D array, level by level (level 0: the array; each level but
    the top padded to an even length with ``pad``): O(n) memory, O(log n) queries answered
    for many positions at once."""

    def __init__(self, x, op, pad: float):
        self.op, self.pad = op, pad
        a = np.asarray(x, float)
        self.n, self.levels = len(a), []
        while len(a) > 1:
            if len(a) % 2:
                a = np.r_[a, pad]
            self.levels.append(a)
            a = op(a[0::2], a[1::2])
        self.levels.append(a)

    def reduce(self, lo, hi) -> np.ndarray:
        """op over x[lo:hi] for each pair of bounds (``pad`` where empty)."""
        out = np.full(len(lo), self.pad)
        lo, hi = np.array(lo, np.intp), np.array(hi, np.intp)
        for a in self.levels:
            take = (lo & 1).astype(bool) & (lo < hi)
            out = np.where(take, self.op(out, a.take(lo, mode="clip")), out)
            lo += take
            take = (hi & 1).astype(bool) & (lo < hi)
            hi -= take
            out = np.where(take, self.op(out, a.take(hi, mode="clip")), out)
            lo >>= 1
            hi >>= 1
        return out

    def nearest_above(self, at, value, step) -> np.ndarray:
        """For each position ``at``, the nearest index on its side ``step`` (−1 left, +1 right)
        whose sample exceeds ``value`` (a max pyramid), or −1 (left) / n (right) if none.

        Going up from ``at``, the siblings on that side cover the neighbouring blocks, nearest
        first; the first block holding a larger value is then descended, nearer child first."""
        node, step = np.array(at, np.intp), np.asarray(step, np.intp)
        near = (step < 0).astype(np.intp)     # left: odd nodes have a sibling there, the right child is nearer
        found = np.full(len(node), -1, np.intp)
        level = np.full(len(node), -1, np.intp)
        for k, a in enumerate(self.levels[:-1]):
            hit = (level < 0) & ((node & 1) == near) & (a.take(node + step, mode="clip") > value)
            found = np.where(hit, node + step, found)
            level = np.where(hit, k, level)
            node >>= 1
        for k in range(len(self.levels) - 2, 0, -1):
            child = 2 * found + near
            nearer = self.levels[k - 1].take(child, mode="clip") > value
            found = np.where(level >= k, np.where(nearer, child, child + 1 - 2 * near), found)
        return np.where(level >= 0, found, np.where(step < 0, -1, self.n))

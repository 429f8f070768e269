"""Regions of interest from a pressure signal: contacts, peaks and troughs, feature bumps.

Pure functions on 1-D arrays sampled at ``rate_hz``; indices are frame indices, intervals
are half-open ``[start, stop)``. Durations are given in seconds and converted here, so the
parameters keep their meaning at any frame rate.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .signal1d import find_peaks, savgol_filter


def savgol_frames(rate_hz: float, window_s: float) -> int:
    """Frames in the Savitzky–Golay window of :func:`smooth` (``window_s`` s, odd, ≥ 5)."""
    return max(int(round(window_s * rate_hz)) | 1, 5)


def smooth(signal, rate_hz: float, window_s: float) -> np.ndarray:
    """Savitzky–Golay (quadratic) smoothing along the first axis (time) over ``window_s``
    seconds (:func:`savgol_frames` samples)."""
    x = np.asarray(signal, float)
    n = savgol_frames(rate_hz, window_s)
    if len(x) < n:
        return x.copy()
    return savgol_filter(x, n, 2)


def contact_intervals(pressure, threshold: float, rate_hz: float, min_s: float = 0.1,
                      merge_gap_s: float = 0.05) -> list[tuple[int, int]]:
    """Intervals where ``pressure`` (T,) exceeds ``threshold``.

    Intervals separated by less than ``merge_gap_s`` are merged; intervals shorter than
    ``min_s`` are dropped. Returns [(start, stop), ...] frame indices, sorted.
    """
    p = np.asarray(pressure, float)
    above = p > threshold
    if not above.any():
        return []
    edges = np.diff(np.r_[0, above.astype(np.int8), 0])
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    gap = int(round(merge_gap_s * rate_hz))
    merged: list[list[int]] = []
    for a, b in zip(starts, stops):
        if merged and a - merged[-1][1] <= gap:
            merged[-1][1] = int(b)
        else:
            merged.append([int(a), int(b)])
    n_min = max(1, int(round(min_s * rate_hz)))
    return [(a, b) for a, b in merged if b - a >= n_min]


@dataclass(frozen=True)
class Extrema:
    """Peaks and troughs of a mean-shifted signal (frame indices) and the prominence used."""

    peaks: np.ndarray
    troughs: np.ndarray
    prominence: float


def extrema(signal, rate_hz: float, prominence: float, distance_s: float) -> Extrema:
    """Peaks and troughs of ``signal − mean(signal)`` (:func:`analysis.signal1d.find_peaks`,
    as ``scipy.signal.find_peaks``).

    ``prominence``: in the signal's units; ``distance_s``: minimum distance between two
    peaks (or two troughs), seconds.
    """
    x = np.asarray(signal, float)
    shifted = x - x.mean() if len(x) else x
    dist = max(1, int(round(distance_s * rate_hz)))
    peaks = find_peaks(shifted, prominence=prominence, distance=dist)
    troughs = find_peaks(-shifted, prominence=prominence, distance=dist)
    return Extrema(peaks.astype(int), troughs.astype(int), float(prominence))


@dataclass(frozen=True)
class Bump:
    """One pressure bump (a feature under the finger) inside a contact.

    ``start``/``stop``: the bump's extent (contact ends or the troughs between bumps);
    ``plateau``: [i0, i1) where the pressure is above ``level`` × the bump's height;
    ``peak``: index of the maximum; ``height``: pressure at the peak (signal units).
    """

    start: int
    stop: int
    peak: int
    plateau: tuple[int, int]
    height: float


def _crossing(p, i, level, step) -> float:
    """Fractional index where ``p`` crosses ``level`` walking from ``i`` by ``step`` (±1)."""
    j = i
    n = len(p)
    while 0 <= j + step < n and p[j + step] >= level:
        j += step
    k = j + step
    if not 0 <= k < n:
        return float(j)
    # linear interpolation between j (≥ level) and k (< level)
    frac = (p[j] - level) / (p[j] - p[k]) if p[j] != p[k] else 0.0
    return j + step * frac


def bumps(pressure, contact: tuple[int, int], peaks, level: float = 0.5) -> list[Bump]:
    """Split a contact [start, stop) at the minima between its ``peaks`` and find each plateau.

    Each bump's plateau is the stretch around its peak where the pressure stays above
    ``level`` × (peak − the bump's lowest edge value). Fractional plateau edges are
    rounded to frames for the segments; :func:`plateau_duration` keeps the fraction.
    """
    p = np.asarray(pressure, float)
    a, b = contact
    pk = sorted(int(k) for k in peaks if a <= k < b)
    if not pk:
        if b - a < 1:
            return []
        pk = [a + int(np.argmax(p[a:b]))]
    cuts = [a] + [pk[i] + int(np.argmin(p[pk[i]:pk[i + 1] + 1])) for i in range(len(pk) - 1)] + [b]
    out = []
    for i, k in enumerate(pk):
        s, e = cuts[i], cuts[i + 1]
        floor = min(p[s], p[e - 1], 0.0) if e > s else 0.0
        height = p[k] - floor
        lev = floor + level * height
        lo, hi = _crossing(p, k, lev, -1), _crossing(p, k, lev, +1)
        i0 = max(s, int(np.ceil(lo)))
        i1 = min(e, int(np.floor(hi)) + 1)
        out.append(Bump(start=s, stop=e, peak=k, plateau=(i0, max(i1, i0 + 1)), height=float(p[k])))
    return out


def replateau(signal, pressure, bump: Bump, level: float = 0.5, frames: float | None = None) -> Bump:
    """The bump's plateau centred where ``pressure``'s plateau is centred, as long as
    ``signal``'s plateau lasts (both (T,); fractional edges, rounded to frames), or ``frames``
    long when given.

    Used with the PDC as ``pressure`` (the whole-fingertip pressure, symmetric about the pad's
    lowest point: where the feature is) and the pad electrodes' sum as ``signal`` (a sharper
    footprint: how long the feature is under the pad), or the electrodes' own plateaus'
    duration as ``frames`` (the feature's width, read as the width estimate reads it)."""
    def edges(x):
        x = np.asarray(x, float)
        k = bump.start + int(np.argmax(x[bump.start:bump.stop]))
        floor = min(x[bump.start], x[bump.stop - 1], 0.0)
        lev = floor + level * (x[k] - floor)
        return _crossing(x, k, lev, -1), _crossing(x, k, lev, +1)
    lo_p, hi_p = edges(pressure)
    if frames is None:
        lo_s, hi_s = edges(signal)
        frames = hi_s - lo_s
    c, half = (lo_p + hi_p) / 2.0, frames / 2.0
    i0 = max(bump.start, int(round(c - half)))
    i1 = min(bump.stop, int(round(c + half)))
    return Bump(bump.start, bump.stop, bump.peak, (i0, max(i1, i0 + 1)), bump.height)


def plateau_duration(pressure, bump: Bump, rate_hz: float, level: float = 0.5) -> tuple[float, float, float]:
    """Interpolated plateau (t_start, t_end, duration) in seconds relative to frame 0."""
    p = np.asarray(pressure, float)
    floor = min(p[bump.start], p[bump.stop - 1], 0.0)
    lev = floor + level * (p[bump.peak] - floor)
    lo, hi = _crossing(p, bump.peak, lev, -1), _crossing(p, bump.peak, lev, +1)
    return lo / rate_hz, hi / rate_hz, (hi - lo) / rate_hz


def first_drop(signal, start: int, fraction: float, window: int, noise_k: float = 8.0,
               largest: bool = False) -> int | None:
    """Onset of the first sudden fall of ``signal`` (T,) at or after ``start``: the frame of its
    steepest descent over the fall — the frames from which it falls within ``window`` frames by
    more than max(``fraction`` × its range after ``start``, ``noise_k`` × its noise), and a
    window on (a non-causal smoother leads a step by a gentle decline that may pass the
    threshold first). The noise is
    the robust std (MAD) of the signal about its running median over ``window`` frames, so
    slow trends do not count and coloured (smoothed) noise is not underestimated. ``None`` if
    it never falls so fast. ``largest``: the deepest such fall instead of the first.
    """
    x = np.asarray(signal, float)[start:]
    n = len(x)
    window = max(2, int(window))
    if n < window + 3:
        return None
    noise = robust_noise(x, window)
    thr = max(fraction * float(np.ptp(x)), noise_k * noise)
    if thr <= 0:
        return None
    # fall(i) = x[i] − min(x[i+1 .. i+window])
    from numpy.lib.stride_tricks import sliding_window_view
    ahead = sliding_window_view(np.r_[x[1:], np.full(window, np.inf)], window).min(axis=1)[:n]
    fall = x - ahead
    hit = np.flatnonzero(fall > thr)
    if not hit.size:
        return None
    i = int(hit[np.argmax(fall[hit])]) if largest else int(hit[0])
    if largest:
        i = max(0, i - window)
        j = min(n - 1, i + 2 * window)
    else:
        # the fall's own extent: every frame from which it still falls so fast, and a window
        # on (a smoothed fall may pass the threshold well ahead of its steepest step)
        e = i
        while e + 1 < n and fall[e + 1] > thr:
            e += 1
        j = min(n - 1, e + window)
    steep = i + int(np.argmin(np.diff(x[i:j + 1])))
    return start + steep + 1


def shared_first_drop(signals, start: int, stop: int, window: int, noise_k: float = 8.0) -> int | None:
    """Onset of the first sudden fall that most of ``signals`` (each (T,): the fingers holding one
    object) share, between frames ``start`` and ``stop``: the first frame where the median over
    the signals of each one's fall within ``window`` frames, in units of its own noise
    (:func:`robust_noise`), stands out of that median fall's own spread over the stretch (above
    its median by ``noise_k`` × its robust std); dated at the steepest step of the signals' sum
    (each in units of its noise) over the fall and a window on, as :func:`first_drop`.

    Why shared: an object that gives slips under every finger at once, while one finger's
    pressure may fluctuate well beyond its median noise on its own (a looser, noisier contact).
    Only ratios to each signal's noise are read: neither its scale nor its slow trend (which a
    fraction of the range would follow) decides. ``None`` if they never fall so together.
    """
    from numpy.lib.stride_tricks import sliding_window_view
    window = max(2, int(window))
    n = stop - start
    if n < window + 3 or not len(signals):
        return None
    z = []
    for sig in signals:
        x = np.asarray(sig, float)[start:stop]
        noise = robust_noise(x, window)
        if not noise > 0:
            continue
        x = x / noise
        ahead = sliding_window_view(np.r_[x[1:], np.full(window, np.inf)], window).min(axis=1)[:n]
        z.append((x, x - ahead))
    if not z:
        return None
    fall = np.median([f for _, f in z], axis=0)
    # a window's fall of coloured noise with a slow trend runs to several times the noise: the
    # threshold is read on the falls themselves, their median plus noise_k times their spread
    typical = float(np.median(fall))
    thr = typical + noise_k * 1.4826 * float(np.median(np.abs(fall - typical)))
    hit = np.flatnonzero(fall > thr)
    if not hit.size:
        return None
    i = e = int(hit[0])
    while e + 1 < n and fall[e + 1] > thr:
        e += 1
    j = min(n - 1, e + window)
    total = np.sum([x for x, _ in z], axis=0)
    return start + i + int(np.argmin(np.diff(total[i:j + 1]))) + 1


def robust_noise(signal, window: int) -> float:
    """Robust std (MAD × 1.4826) of ``signal`` (T,) about its running median over ``window``
    frames: the noise without the slow trends (and without underestimating smoothed,
    coloured noise)."""
    from scipy.ndimage import median_filter
    x = np.asarray(signal, float)
    r = x - median_filter(x, size=max(2, int(window)) | 1, mode="nearest")
    return 1.4826 * float(np.median(np.abs(r - np.median(r))))


def largest_change(signal, start: int, stop: int, window: int, noise_k: float = 6.0) -> tuple[int, float] | None:
    """The steepest frame of the largest sudden change of ``signal`` (T,) in ``[start, stop)``:
    the window of ``window`` frames over which it changes most (either way) must change by
    more than ``noise_k`` × the noise of such changes (the robust std, MAD × 1.4826, of the
    changes over every window there: a smoothed, wandering signal's noise is measured as
    what the test reads); within it, the frame of the steepest step that way. Returns
    (frame, sign of the change: +1 rise, −1 fall), or ``None`` when nothing there stands out
    of the noise. Scale-free: only ratios to the signal's own changes decide."""
    x = np.asarray(signal, float)[start:stop]
    window = max(2, int(window))
    if len(x) < 2 * window + 3:
        return None
    change = x[window:] - x[:-window]
    noise = 1.4826 * float(np.median(np.abs(change - np.median(change))))
    i = int(np.argmax(np.abs(change)))
    if not abs(change[i]) > noise_k * noise:
        return None
    sign = 1.0 if change[i] > 0 else -1.0
    steep = i + int(np.argmax(sign * np.diff(x[i:i + window + 1])))
    return start + steep, sign


def knee(t, y, lo: int, hi: int) -> int:
    """Frame of the knee of ``y`` (T,) over ``[lo, hi]``: the break of the best continuous
    two-line fit (least squares over every break frame), i.e. where a level or slow drift
    turns into a rise or fall. Independent of the signal's scale and offset; ``hi`` is meant
    to be the steepest frame of the change, so the second line is its leading flank."""
    t = np.asarray(t, float)[lo:hi + 1]
    y = np.asarray(y, float)[lo:hi + 1]
    n = len(y)
    if n < 5:
        return lo
    tt = t - t[0]
    best, best_k = np.inf, 0
    for k in range(1, n - 2):
        # y ≈ c + s1·(t − t_k) + (s2 − s1)·max(0, t − t_k)
        A = np.column_stack([np.ones(n), tt - tt[k], np.maximum(0.0, tt - tt[k])])
        coef, *_ = np.linalg.lstsq(A, y, rcond=None)
        sse = float(np.sum((A @ coef - y) ** 2))
        if sse < best:
            best, best_k = sse, k
    return lo + best_k


def edge_crossing(signal, edge: int, lo: int, before: int, after_level: float, level: float) -> int:
    """Where a fall of ``signal`` (T,) whose steepest frame is ``edge`` passes ``level`` of its
    own depth: from its level just before (the median over ``before`` frames ending
    ``before // 2`` frames ahead of ``edge``, not before ``lo``) down to ``after_level``. The
    first frame at or after which the signal stays below that level, up to ``edge``."""
    x = np.asarray(signal, float)
    a = max(lo, edge - before - before // 2)
    b = max(a + 1, edge - before // 2)
    pre = float(np.median(x[a:b]))
    lev = after_level + level * (pre - after_level)
    above = np.flatnonzero(x[lo:edge + 1] >= lev)
    return lo + int(above[-1]) + 1 if above.size else lo

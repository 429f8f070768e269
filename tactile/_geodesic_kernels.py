"""The compiled (numba) kernels of the accurate geodesic (:mod:`tactile.geodesic`): relaxed,
subdivided and Richardson-extrapolated discrete geodesics. Private; loaded on first use.
"""

# numba's on-disk cache is checked against this file's size and time and names the module it was
# compiled in: this file changed when the package moved under tactile_flow (0.2), so a cache from
# before the move is not loaded.

from __future__ import annotations

import numba
import numpy as np

_N_START = 4        # segments of the starting paths
_START_OMEGA = 1.17  # ~ optimal SOR factor 2 / (1 + sin(pi / n)) for n = 4 ...
_N0 = 8              # ... and n = 8 segments, the coarsest level of the extrapolation
_N0_OMEGA = 1.45
_COARSE_SWEEPS = 200  # cap; near-conjugate pairs converge slowly but their length is flat
_COARSE_TOL = 1e-8    # node movement per sweep, relative to the largest semi-axis
_LEVELS = 4           # 8, 16, 32, 64 segments
_FINE_SWEEPS = 3
_NMAX = _N0 * 2 ** (_LEVELS - 1)
_SAME_PATH = 1e-3     # relaxed start paths closer than this (relative) are one geodesic

_jit = numba.njit(cache=True, error_model="numpy")


@_jit
def _proj1(ax, p, out):
    """Closest point on the ellipsoid to p (3,), written to out (3,); see project_to_ellipsoid."""
    a2x, a2y, a2z = ax[0] ** 2, ax[1] ** 2, ax[2] ** 2
    apx, apy, apz = ax[0] * p[0], ax[1] * p[1], ax[2] * p[2]
    f0 = (p[0] / ax[0]) ** 2 + (p[1] / ax[1]) ** 2 + (p[2] / ax[2]) ** 2 - 1.0
    t = max(ax[0] * abs(p[0]) - a2x, ax[1] * abs(p[1]) - a2y, ax[2] * abs(p[2]) - a2z)
    if f0 > 0:
        t = max(t, 0.0)
    else:
        qx, qy, qz = apx / a2x, apy / a2y, apz / a2z
        t = max(t, f0 / (2.0 * (qx * qx / a2x + qy * qy / a2y + qz * qz / a2z)))
    t_floor = -min(a2x, a2y, a2z) * (1.0 - 1e-12)
    t = max(t, t_floor)
    scale = max(a2x, a2y, a2z)
    for _ in range(100):
        rx, ry, rz = 1.0 / (a2x + t), 1.0 / (a2y + t), 1.0 / (a2z + t)
        qx, qy, qz = apx * rx, apy * ry, apz * rz
        qx, qy, qz = qx * qx, qy * qy, qz * qz
        step = (qx + qy + qz - 1.0) / (2.0 * (qx * rx + qy * ry + qz * rz))
        t = max(t + step, t_floor)
        # Quadratic convergence: after a step this small the error in t is ~1e-18 scale.
        if abs(step) <= 1e-9 * (scale + abs(t)):
            break
    out[0] = p[0] * a2x / (a2x + t)
    out[1] = p[1] * a2y / (a2y + t)
    out[2] = p[2] * a2z / (a2z + t)


@_jit
def _relax(ax, X, n, sweeps, omega, tol, mid, y):
    """Gauss-Seidel (omega = 1) or SOR sweeps on the interior nodes of the polyline X[:n+1].

    Each node moves to the normal projection of (an over-relaxed step towards) the
    midpoint of its neighbours; stops early once no node moves more than tol (mm).
    """
    for _ in range(sweeps):
        moved = 0.0
        for k in range(1, n):
            for i in range(3):
                mid[i] = X[k, i] + omega * (0.5 * (X[k - 1, i] + X[k + 1, i]) - X[k, i])
            # With omega != 1 the fixed point is unchanged: there mid - X[k] is normal.
            _proj1(ax, mid, y)
            for i in range(3):
                moved = max(moved, abs(y[i] - X[k, i]))
                X[k, i] = y[i]
        if moved <= tol:
            break


@_jit
def _subdivide(ax, X, Y, n, mid, y):
    """Double the polyline X[:n+1] in place (Y scratch): new nodes are projected midpoints."""
    for k in range(n + 1):
        for i in range(3):
            Y[2 * k, i] = X[k, i]
    for k in range(n):
        for i in range(3):
            mid[i] = 0.5 * (X[k, i] + X[k + 1, i])
        _proj1(ax, mid, y)
        for i in range(3):
            Y[2 * k + 1, i] = y[i]
    for k in range(2 * n + 1):
        for i in range(3):
            X[k, i] = Y[k, i]
    return 2 * n


@_jit
def _polyline_length(X, n):
    total = 0.0
    for k in range(n):
        total += np.sqrt((X[k + 1, 0] - X[k, 0]) ** 2 + (X[k + 1, 1] - X[k, 1]) ** 2
                         + (X[k + 1, 2] - X[k, 2]) ** 2)
    return total


@_jit
def _coarse(ax, X, Y, mid, y):
    """Relax a start path X[:_N_START+1] and bring it to the converged _N0-segment level."""
    tol = _COARSE_TOL * max(ax[0], ax[1], ax[2])
    _relax(ax, X, _N_START, _COARSE_SWEEPS, _START_OMEGA, tol, mid, y)
    n = _N_START
    while n < _N0:
        n = _subdivide(ax, X, Y, n, mid, y)
    _relax(ax, X, _N0, _COARSE_SWEEPS, _N0_OMEGA, tol, mid, y)


@_jit
def _refine_levels(ax, X, Y, lengths, mid, y):
    """Richardson-extrapolated length of the relaxed _N0-segment polyline X, refined
    through all levels (X holds the finest path on exit; lengths: (_LEVELS,) scratch)."""
    n = _N0
    lengths[0] = _polyline_length(X, n)
    for level in range(1, _LEVELS):
        n = _subdivide(ax, X, Y, n, mid, y)
        _relax(ax, X, n, _FINE_SWEEPS, 1.0, 0.0, mid, y)
        lengths[level] = _polyline_length(X, n)
    # Discrete-geodesic length = L + C/n^2 + D/n^4 + ...: extrapolate twice.
    r1_prev = (4.0 * lengths[_LEVELS - 2] - lengths[_LEVELS - 3]) / 3.0
    r1_last = (4.0 * lengths[_LEVELS - 1] - lengths[_LEVELS - 2]) / 3.0
    return (16.0 * r1_last - r1_prev) / 15.0


@_jit
def _start_paths(ax, a, b, XA, XB):
    """Start polylines (_N_START segments): the paper's (theta, phi) path, and the chord
    in unit-sphere coordinates bent towards the pole (z < 0)."""
    ua = np.empty(3)
    ub = np.empty(3)
    for i in range(3):
        ua[i] = a[i] / ax[i]
        ub[i] = b[i] / ax[i]
    ta = np.arctan2(np.hypot(ua[0], ua[1]), ua[2])
    tb = np.arctan2(np.hypot(ub[0], ub[1]), ub[2])
    fa = np.arctan2(ua[1], ua[0])
    fb = np.arctan2(ub[1], ub[0])
    dphi = np.pi - np.mod(np.pi - (fb - fa), 2.0 * np.pi)
    # The bend grows from 0 (coincident) to 1 (antipodal in unit-sphere coordinates).
    bend = 1.0 - 0.5 * np.sqrt((ua[0] + ub[0]) ** 2 + (ua[1] + ub[1]) ** 2
                               + (ua[2] + ub[2]) ** 2)
    for k in range(1, _N_START):
        s = k / _N_START
        th = ta + s * (tb - ta)
        ph = fa + s * dphi
        XA[k, 0] = ax[0] * np.sin(th) * np.cos(ph)
        XA[k, 1] = ax[1] * np.sin(th) * np.sin(ph)
        XA[k, 2] = ax[2] * np.cos(th)
        vx = (1 - s) * ua[0] + s * ub[0]
        vy = (1 - s) * ua[1] + s * ub[1]
        vz = (1 - s) * ua[2] + s * ub[2] - 4.0 * s * (1 - s) * bend
        norm = np.sqrt(vx * vx + vy * vy + vz * vz)
        if norm == 0.0:  # only possible for degenerate upper-half configurations
            vx, vy, vz, norm = 0.0, 0.0, -1.0, 1.0
        XB[k, 0] = ax[0] * vx / norm
        XB[k, 1] = ax[1] * vy / norm
        XB[k, 2] = ax[2] * vz / norm
    for i in range(3):  # endpoints exactly as given
        XA[0, i] = a[i]
        XA[_N_START, i] = b[i]
        XB[0, i] = a[i]
        XB[_N_START, i] = b[i]


@_jit
def _geodesic_pair(ax, a, b, XA, XB, Y, lengths, mid, y, path_out):
    """Accurate geodesic distance between surface points a, b (3,); path in path_out."""
    chord = np.sqrt((a[0] - b[0]) ** 2 + (a[1] - b[1]) ** 2 + (a[2] - b[2]) ** 2)
    if chord == 0.0:
        for k in range(_NMAX + 1):
            for i in range(3):
                path_out[k, i] = a[i]
        return 0.0
    _start_paths(ax, a, b, XA, XB)
    _coarse(ax, XA, Y, mid, y)
    _coarse(ax, XB, Y, mid, y)
    apart = 0.0
    for k in range(_N0 + 1):
        for i in range(3):
            apart = max(apart, abs(XA[k, i] - XB[k, i]))
    same = apart <= _SAME_PATH * _polyline_length(XA, _N0)
    best = _refine_levels(ax, XA, Y, lengths, mid, y)
    _copy_path(XA, path_out)
    if not same:  # the two starts found different geodesics: keep the shorter
        other = _refine_levels(ax, XB, Y, lengths, mid, y)
        if other < best:
            best = other
            _copy_path(XB, path_out)
    return best


@_jit
def _copy_path(src, dst):
    """dst[:, :] = src, element by element: an array assignment would compile numba's
    shape-mismatch error reporting (~8 s of a first run) for two arrays that always match."""
    for k in range(src.shape[0]):
        for i in range(3):
            dst[k, i] = src[k, i]


@_jit
def _accurate_distances(ax, pa, pb, keep_paths):
    m, n = pa.shape[0], pb.shape[0]
    out = np.empty((m, n))
    paths = np.empty((m if keep_paths else 0, n if keep_paths else 0, _NMAX + 1, 3))
    XA = np.empty((_NMAX + 1, 3))
    XB = np.empty((_NMAX + 1, 3))
    Y = np.empty((_NMAX + 1, 3))
    path = np.empty((_NMAX + 1, 3))
    lengths = np.empty(_LEVELS)
    mid, y = np.empty(3), np.empty(3)
    for i in range(m):
        for j in range(n):
            out[i, j] = _geodesic_pair(ax, pa[i], pb[j], XA, XB, Y, lengths, mid, y, path)
            if keep_paths:
                _copy_path(path, paths[i, j])
    return out, paths

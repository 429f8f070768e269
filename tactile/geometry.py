"""Taxel positions, the half-ellipsoid fitted to them, and geodesic distances on it.

Computational tactile flow models the BioTac SP fingertip as a half-ellipsoid through the
24 taxels and interpolates taxel values over that surface with a kernel of the *geodesic*
distance between a surface point and each taxel. This module holds the geometry: it loads
the taxel positions, fits the ellipsoid, maps between points and surface parameters, and
computes (and caches) geodesic distances.

Frames and units
----------------
Lengths are in mm. The sensor frame has x along the finger's long axis, y lateral, z normal
to the pad, contact side z < 0. All functions taking ``axes`` work on an *origin-centred*,
axis-aligned ellipsoid with semi-axes ``axes = (a, b, c)`` along (x, y, z); subtract
:attr:`EllipsoidFit.centre` from sensor-frame points first (:func:`taxel_angles` does so).

Parameterisation
----------------
::

    x = a sin(theta) cos(phi),   y = b sin(theta) sin(phi),   z = c cos(theta),
    theta in [0, pi],  phi in (-pi, pi].

The contact-side half (z <= 0) is theta in [pi/2, pi]; the pad's pole (0, 0, -c) is
theta = pi (where phi is undefined and reported as 0). These are the ellipsoid's
"reduced" (parametric) angles, not geographic latitude/longitude.

Geodesic distances
------------------
``method="paper"`` reproduces the method's approximation: the path that is a straight line
in (theta, phi) (phi difference wrapped to (-pi, pi], i.e. the shorter way round), sampled
at ``n_steps`` equal steps, its length the sum of the chords between consecutive samples.
Away from the pole this is within about 1 % of the true geodesic for short pairs; near the
pole it runs around the parallel instead of across the pole and is tens of percent too long.

``method="accurate"`` (default) computes the shortest geodesic as the limit of discrete
geodesics: polylines with nodes on the surface that are stationary for the polyline's
energy, i.e. every interior node is the closest-point (surface-normal) projection of the
midpoint of its neighbours. Why this scheme: it needs nothing but closest-point
projection (exact, cheap Newton on the Lagrange multiplier); it has no coordinate
singularity at the pole; a Gauss-Seidel update minimises the energy over the moved node
(the surface point closest to the midpoint minimises |x - x_prev|^2 + |x - x_next|^2), so
relaxation descends to a locally shortest path rather than any geodesic; and the length
error of a converged discrete geodesic is a clean series in 1/n^2 that extrapolates
away. Projection is along the surface normal, not radial scaling, which would bias the
curve on a triaxial ellipsoid. Steps, per pair:

1. two starting polylines of 4 segments: the paper's (theta, phi) path, and the chord in
   the ellipsoid's unit-sphere coordinates bent towards the pad's pole;
2. relax each by successive over-relaxation, subdivide (new nodes = projected midpoints)
   to 8 segments, relax again until no node moves more than 1e-8 x the largest semi-axis
   (the coarse level carries the slow, global modes);
3. subdivide to 16, 32, 64 segments with 3 Gauss-Seidel sweeps each (the inherited nodes
   are already accurate to O(h^2); only the new nodes' high-frequency error needs
   smoothing), and Richardson-extrapolate the lengths of the 8..64 levels twice (1/n^2,
   1/n^4);
4. if the two starts relaxed to different geodesics, refine both and keep the shorter.

The second start matters for near-opposite points on or near the equator: there the
paper's path lies on the equator, itself a longer geodesic that relaxation cannot leave
by symmetry. For points in the lower half the shortest path on the full ellipsoid stays in
the closed lower half (reflection symmetry in z), so the full ellipsoid is used.

Accuracy, measured on the ellipsoid fitted to the taxels: principal-section arcs (exact by
quadrature) within 2e-8 relative; 300 random lower-half pairs over 0.5 mm apart against
geodesic-ODE shooting: median 7e-9, worst 3e-6 relative, never shorter than the geodesic by
more than 1e-13; over 24 000 pairs the worst is ~1e-5, for ~28 mm near-opposite pairs close
to the equator (near-conjugate points, where the length is flat in the path's position
and relaxation converges slowly). Speed: 24 x 4000 pairs in ~7 s on one core, after a
one-off numba compilation of ~10 s (cached on disk by numba). Memory: a few
(65, 3) buffers, pairs are looped over.

The results are cached on disk by :func:`cached_geodesic_distances`; change
:data:`ALGORITHM_VERSION` whenever a change alters the numbers.
"""

from __future__ import annotations

import hashlib
import importlib.resources
import io
import json
import os
import tempfile
import warnings
from dataclasses import dataclass
from pathlib import Path

import numba
import numpy as np
from scipy.optimize import least_squares

from ._checks import finite_array, positive

#: Part of every cache key; bump when a change alters computed distances.
ALGORITHM_VERSION = "geodesic-1"

GEODESIC_METHODS = ("accurate", "paper")
KERNEL_FORMS = ("paper", "squared")

#: Relative tolerance |sqrt(sum((p/axes)^2)) - 1| for a point to count as on the surface.
SURFACE_TOL = 1e-6

_TAXEL_FILE = "biotac_sp_taxels.csv"


# --------------------------------------------------------------------------- taxels

def load_taxels() -> np.ndarray:
    """BioTac SP taxel positions, shape (24, 3), mm, sensor frame, rows in taxel order 1..24.

    Source: Garcia-Garcia et al. 2019, "TactileGCN: A Graph Convolutional Network for
    Predicting Grasp Stability with Tactile Sensors" (repository 3dperceptionlab/tactile-gcn,
    converted from inches and remapped to this frame; see ``tactile/data/README.md``).
    """
    text = importlib.resources.files("tactile").joinpath("data", _TAXEL_FILE).read_text()
    table = np.genfromtxt(io.StringIO(text), delimiter=",", names=True, dtype=None,
                          encoding="utf-8")
    order = np.argsort(table["taxel"])
    if not np.array_equal(table["taxel"][order], np.arange(1, 25)):
        raise ValueError(f"{_TAXEL_FILE}: expected taxels 1..24, got {table['taxel']}")
    xyz = np.column_stack([table["x_mm"], table["y_mm"], table["z_mm"]]).astype(np.float64)
    return xyz[order]


# --------------------------------------------------------------------------- validation

def _check_axes(axes) -> np.ndarray:
    ax = finite_array("axes", axes, ndim=1, last=3)
    if np.any(ax <= 0):
        raise ValueError(f"axes: expected three semi-axes > 0 (mm), got {ax.tolist()}")
    return ax


def _check_points(name: str, points) -> np.ndarray:
    return finite_array(name, points, last=3)


def _check_on_surface(name: str, axes: np.ndarray, points) -> np.ndarray:
    """``points`` as an (n, 3) array after checking they lie on the ellipsoid ``axes``."""
    p = finite_array(name, points, ndim=(1, 2), last=3).reshape(-1, 3)
    off = np.abs(np.sqrt(np.sum((p / axes) ** 2, axis=-1)) - 1.0)
    if np.any(off > SURFACE_TOL):
        k = int(np.argmax(off))
        raise ValueError(f"{name}: expected points on the ellipsoid with semi-axes "
                         f"{axes.tolist()} mm (relative tolerance {SURFACE_TOL:g}); "
                         f"{int(np.count_nonzero(off > SURFACE_TOL))} point(s) off it, "
                         f"worst #{k} {p[k].tolist()} off by {off[k]:.3g}")
    return p


# --------------------------------------------------------------------------- ellipsoid maps

def ellipsoid_points(axes, theta, phi) -> np.ndarray:
    """Surface points (..., 3) in mm for parameters ``theta``, ``phi`` (rad, broadcast)."""
    ax = _check_axes(axes)
    th = finite_array("theta", theta)
    ph = finite_array("phi", phi)
    th, ph = np.broadcast_arrays(th, ph)
    s = np.sin(th)
    return np.stack([ax[0] * s * np.cos(ph), ax[1] * s * np.sin(ph), ax[2] * np.cos(th)],
                    axis=-1)


def ellipsoid_normals(axes, points) -> np.ndarray:
    """Unit outward normals (..., 3) at surface ``points`` (..., 3).

    For a point off the surface this is the normal of the scaled copy of the ellipsoid
    through it (the direction of the gradient of ``sum((p/axes)^2)``).
    """
    ax = _check_axes(axes)
    p = _check_points("points", points)
    g = p / ax**2
    norm = np.linalg.norm(g, axis=-1, keepdims=True)
    if np.any(norm == 0):
        raise ValueError("points: expected points away from the ellipsoid's centre, "
                         "where the normal is undefined")
    return g / norm


def ellipsoid_angles(axes, points) -> tuple[np.ndarray, np.ndarray]:
    """Parameters ``(theta, phi)`` (rad, each of shape ...) of surface ``points`` (..., 3).

    theta in [0, pi], phi in (-pi, pi]. For a point off the surface these are the
    parameters of its scaled-radial image ``p / |p/axes|``, not of its closest point; use
    :func:`project_to_ellipsoid` first when that matters.
    """
    ax = _check_axes(axes)
    u = _check_points("points", points) / ax
    rho = np.hypot(u[..., 0], u[..., 1])
    if np.any((rho == 0) & (u[..., 2] == 0)):
        raise ValueError("points: expected points away from the ellipsoid's centre, "
                         "where the angles are undefined")
    theta = np.arctan2(rho, u[..., 2])  # accurate near the poles, unlike arccos
    phi = np.arctan2(u[..., 1], u[..., 0])
    phi = np.where(phi <= -np.pi, np.pi, phi)
    return theta, phi


def project_to_ellipsoid(axes, points) -> np.ndarray:
    """Closest points (..., 3) on the ellipsoid to ``points`` (..., 3), mm.

    The foot point is ``x_i = p_i a_i^2 / (a_i^2 + t)`` with the Lagrange multiplier t the
    root of ``F(t) = sum (a_i p_i / (a_i^2 + t))^2 - 1``, which is convex and decreasing
    on t > -min(a_i^2). Newton started at a lower bound of the root therefore converges
    monotonically. For points deep inside, near the ellipsoid's medial disc, the closest
    point may not be unique; one of them is returned.
    """
    ax = _check_axes(axes)
    p = _check_points("points", points)
    return _project_np(ax, p)


def _project_np(ax: np.ndarray, p: np.ndarray) -> np.ndarray:
    a2 = ax**2
    ap = ax * p
    t_floor = -a2.min() * (1.0 - 1e-12)
    # Two lower bounds of the root: the root of any single term, and 0 for points outside.
    t = np.max(ax * np.abs(p) - a2, axis=-1)
    outside = np.sum((p / ax) ** 2, axis=-1) > 1.0
    t = np.where(outside, np.maximum(t, 0.0), t)
    # For points inside, one Newton step from t = 0 also lands below the root (convexity),
    # and is much closer for points near the surface.
    q2 = (ap / a2) ** 2
    t0 = (q2.sum(-1) - 1.0) / (2.0 * np.sum(q2 / a2, axis=-1))
    t = np.where(outside, t, np.maximum(t, t0))
    t = np.maximum(t, t_floor)
    scale = a2.max()
    for _ in range(100):
        d = a2 + t[..., None]
        q2 = (ap / d) ** 2
        step = (q2.sum(-1) - 1.0) / (2.0 * np.sum(q2 / d, axis=-1))
        t = np.maximum(t + step, t_floor)
        if np.all(np.abs(step) <= 1e-15 * (scale + np.abs(t))):
            break
    return p * a2 / (a2 + t[..., None])


# --------------------------------------------------------------------------- fit

@dataclass(frozen=True, eq=False)
class EllipsoidFit:
    """Axis-aligned ellipsoid fitted to points.

    centre: (3,) mm, sensor frame. axes: (3,) mm, semi-axes along x, y, z.
    rms: root-mean-square orthogonal distance of the points to the surface, mm.
    The arrays are stored as read-only float64 copies. (``eq=False``: field-wise ``==``
    on arrays has no single truth value; compare ``centre``/``axes`` explicitly.)
    """

    centre: np.ndarray
    axes: np.ndarray
    rms: float

    def __post_init__(self):
        for name in ("centre", "axes"):
            arr = np.array(getattr(self, name), dtype=np.float64)
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "rms", float(self.rms))


def _signed_distance_and_jacobian(params: np.ndarray, pts: np.ndarray):
    centre, ax = params[:3], params[3:]
    q = pts - centre
    foot = _project_np(ax, q)
    g = foot / ax**2
    gnorm = np.linalg.norm(g, axis=-1)
    n = g / gnorm[:, None]
    dist = np.sum((q - foot) * n, axis=-1)
    # First-order change of the distance is minus the surface's normal velocity at the
    # foot point: -n for the centre; (x_j^2 / a_j^3) / |x / a^2| for semi-axis a_j.
    jac = np.empty((len(pts), 6))
    jac[:, :3] = -n
    jac[:, 3:] = -(foot**2 / ax**3) / gnorm[:, None]
    return dist, jac


def _initial_guess(pts: np.ndarray) -> np.ndarray:
    # Algebraic fit A x^2 + B y^2 + C z^2 + D x + E y + F z = 1 (exact for exact points).
    design = np.column_stack([pts**2, pts])
    coef, *_ = np.linalg.lstsq(design, np.ones(len(pts)), rcond=None)
    quad, lin = coef[:3], coef[3:]
    if np.all(quad > 0):
        centre = -lin / (2 * quad)
        k = 1.0 + np.sum(lin**2 / (4 * quad))
        if k > 0:
            return np.concatenate([centre, np.sqrt(k / quad)])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    half = np.maximum((hi - lo) / 2, 1e-3 * np.max(hi - lo))
    return np.concatenate([(lo + hi) / 2, half])


def fit_ellipsoid(points) -> EllipsoidFit:
    """Least-squares axis-aligned ellipsoid (centre + 3 semi-axes) through ``points`` (N>=6, 3) mm.

    Minimises the sum of squared *orthogonal* distances (exact closest-point distances,
    analytic Jacobian) with ``scipy.optimize.least_squares``, started from the algebraic
    fit of ``A x^2 + B y^2 + C z^2 + D x + E y + F z = 1``. Recovers centre and semi-axes
    of exact synthetic points, also when they cover only one half of the ellipsoid.

    On the 24 BioTac SP taxels (:func:`load_taxels`): centre (-0.076, 0.000, -0.842) mm,
    semi-axes (12.022, 7.828, 6.955) mm, rms 0.087 mm. The taxels lie only on the contact
    side, so centre-z and c trade off (correlation 0.997, 1-sigma ~0.5 mm on centre-z):
    forcing centre-z = 0 gives axes (12.36, 8.07, 7.86) and rms 0.093 mm. The fit is used
    unconstrained and unregularised: the optimum is interior and unique, all taxels lie
    below its equator, and over the taxel-covered region (z <= -2.5 mm) the two surfaces
    differ by at most 0.06 mm, less than the rms; they differ by up to 0.26 mm only
    near the equator, where there are no taxels to say which is right.
    """
    pts = finite_array("points", points, ndim=2, last=3)
    if len(pts) < 6:
        raise ValueError(f"points: expected at least 6 points to fit 6 parameters, "
                         f"got {len(pts)}")
    x0 = _initial_guess(pts)
    span = float(np.max(np.ptp(pts, axis=0)))
    if span == 0:
        raise ValueError("points: expected points that are not all identical")
    lower = np.r_[np.full(3, -np.inf), np.full(3, 1e-9 * span)]
    x0[3:] = np.maximum(x0[3:], 2e-9 * span)
    result = least_squares(lambda p: _signed_distance_and_jacobian(p, pts)[0], x0,
                           jac=lambda p: _signed_distance_and_jacobian(p, pts)[1],
                           bounds=(lower, np.inf), x_scale="jac",
                           xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=1000)
    dist, _ = _signed_distance_and_jacobian(result.x, pts)
    return EllipsoidFit(centre=result.x[:3], axes=result.x[3:],
                        rms=float(np.sqrt(np.mean(dist**2))))


def taxel_angles(fit: EllipsoidFit, points) -> tuple[np.ndarray, np.ndarray]:
    """Parameters ``(theta, phi)`` (rad) of the closest points on ``fit`` to sensor-frame
    ``points`` (..., 3) mm."""
    p = finite_array("points", points, last=3)
    foot = _project_np(np.asarray(fit.axes, dtype=np.float64), p - fit.centre)
    return ellipsoid_angles(fit.axes, foot)


# --------------------------------------------------------------------------- paper geodesic

def _wrap_angle(d: np.ndarray) -> np.ndarray:
    """Angle difference wrapped to (-pi, pi]."""
    return np.pi - np.mod(np.pi - d, 2 * np.pi)


def _paper_distances(ax: np.ndarray, pa: np.ndarray, pb: np.ndarray, n_steps: int) -> np.ndarray:
    ta, fa = ellipsoid_angles(ax, pa)
    tb, fb = ellipsoid_angles(ax, pb)
    dtheta = tb[None, :] - ta[:, None]
    dphi = _wrap_angle(fb[None, :] - fa[:, None])
    total = np.zeros(dtheta.shape)
    prev = np.broadcast_to(pa[:, None, :], dtheta.shape + (3,))
    for k in range(1, n_steps + 1):
        s = k / n_steps
        th = ta[:, None] + s * dtheta
        ph = fa[:, None] + s * dphi
        sin_th = np.sin(th)
        cur = np.stack([ax[0] * sin_th * np.cos(ph), ax[1] * sin_th * np.sin(ph),
                        ax[2] * np.cos(th)], axis=-1)
        total += np.linalg.norm(cur - prev, axis=-1)
        prev = cur
    return total


# --------------------------------------------------------------------------- accurate geodesic

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
    path_out[:, :] = XA
    if not same:  # the two starts found different geodesics: keep the shorter
        other = _refine_levels(ax, XB, Y, lengths, mid, y)
        if other < best:
            best = other
            path_out[:, :] = XB
    return best


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
                paths[i, j] = path
    return out, paths


def geodesic_distances(axes, points_a, points_b, method: str = "accurate", *,
                       n_steps: int = 100) -> np.ndarray:
    """Geodesic distances (len(a), len(b)) in mm between points on an ellipsoid.

    axes: (3,) semi-axes (mm) along x, y, z of the origin-centred ellipsoid.
    points_a, points_b: (n, 3) or (3,) points on its surface (relative tolerance
    :data:`SURFACE_TOL`). method: ``"accurate"`` (shortest geodesic, ~1e-9 relative
    typical) or ``"paper"`` (the method's (theta, phi)-straight path, ``n_steps`` chords;
    ``n_steps`` is ignored by ``"accurate"``). See the module docstring for both.
    """
    ax = _check_axes(axes)
    if method not in GEODESIC_METHODS:
        raise ValueError(f"method: expected one of {GEODESIC_METHODS}, got {method!r}")
    pa = _check_on_surface("points_a", ax, points_a)
    pb = _check_on_surface("points_b", ax, points_b)
    if method == "paper":
        if isinstance(n_steps, bool) or int(n_steps) != n_steps or n_steps < 1:
            raise ValueError(f"n_steps: expected an integer >= 1, got {n_steps!r}")
        return _paper_distances(ax, pa, pb, int(n_steps))
    dist, _ = _accurate_distances(ax, np.ascontiguousarray(pa), np.ascontiguousarray(pb),
                                  False)
    return dist


def geodesic_path(axes, point_a, point_b) -> np.ndarray:
    """The accurate method's shortest-geodesic polyline (65, 3) mm from ``point_a`` to
    ``point_b`` (each (3,), on the ellipsoid ``axes``): a discrete geodesic with 64 equal
    segments (its length is within ~(h/R)^2/24 of the geodesic's, h the segment length
    and R the radius of curvature; :func:`geodesic_distances` extrapolates this away)."""
    ax = _check_axes(axes)
    pa = _check_on_surface("point_a", ax, point_a)
    pb = _check_on_surface("point_b", ax, point_b)
    if len(pa) != 1 or len(pb) != 1:
        raise ValueError("point_a, point_b: expected one point (3,) each")
    _, paths = _accurate_distances(ax, np.ascontiguousarray(pa), np.ascontiguousarray(pb),
                                   True)
    return paths[0, 0]


# --------------------------------------------------------------------------- cache

def default_cache_dir() -> Path:
    """$TACTILE_CACHE_DIR, else $XDG_CACHE_HOME/tactile-flow, else ~/.cache/tactile-flow."""
    if os.environ.get("TACTILE_CACHE_DIR"):
        return Path(os.environ["TACTILE_CACHE_DIR"])
    if os.environ.get("XDG_CACHE_HOME"):
        return Path(os.environ["XDG_CACHE_HOME"]) / "tactile-flow"
    return Path.home() / ".cache" / "tactile-flow"


def _cache_key(ax: np.ndarray, pa: np.ndarray, pb: np.ndarray, method: str, kw: dict) -> str:
    h = hashlib.sha256()
    h.update(ALGORITHM_VERSION.encode())
    h.update(method.encode())
    h.update(json.dumps(kw, sort_keys=True, default=repr).encode())
    for arr in (ax, pa, pb):
        arr = np.ascontiguousarray(arr, dtype="<f8")
        h.update(repr(arr.shape).encode())
        h.update(arr.tobytes())
    return h.hexdigest()


def _checksum(arr: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(arr, dtype="<f8").tobytes()).hexdigest()


def _read_cache(path: Path, shape: tuple[int, int]) -> np.ndarray:
    # Open the file ourselves: np.load leaks its handle when the zip is unreadable.
    with open(path, "rb") as fh, np.load(fh, allow_pickle=False) as data:
        dist = np.array(data["distances"], dtype="<f8")
        stored = str(data["checksum"])
    if dist.shape != shape:
        raise ValueError(f"shape {dist.shape}, expected {shape}")
    if _checksum(dist) != stored:
        raise ValueError("checksum mismatch")
    return dist.astype(np.float64)


def _write_cache(path: Path, dist: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name + ".", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            np.savez(fh, distances=dist, checksum=np.array(_checksum(dist)))
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def cached_geodesic_distances(axes, points_a, points_b, method: str = "accurate",
                              cache_dir=None, **kw) -> np.ndarray:
    """:func:`geodesic_distances`, computed once and cached on disk.

    The .npz file in ``cache_dir`` (default :func:`default_cache_dir`) is named by a
    SHA-256 of the axes, the points' bytes, ``method``, ``kw`` and
    :data:`ALGORITHM_VERSION`, and stores the array with a checksum of its bytes. A file
    that cannot be read, has the wrong shape or fails the checksum is reported with a
    warning and rebuilt. Writes are atomic (temporary file + ``os.replace``).
    """
    ax = _check_axes(axes)
    if method not in GEODESIC_METHODS:
        raise ValueError(f"method: expected one of {GEODESIC_METHODS}, got {method!r}")
    pa = _check_on_surface("points_a", ax, points_a)
    pb = _check_on_surface("points_b", ax, points_b)
    directory = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    path = directory / f"geodesic-{_cache_key(ax, pa, pb, method, kw)}.npz"
    shape = (len(pa), len(pb))
    if path.exists():
        try:
            return _read_cache(path, shape)
        except Exception as exc:  # any damage: report and rebuild
            warnings.warn(f"geodesic cache file {path} is unusable ({exc!r}); recomputing",
                          RuntimeWarning, stacklevel=2)
    dist = geodesic_distances(ax, pa, pb, method, **kw)
    try:
        _write_cache(path, dist)
    except OSError as exc:  # an unwritable cache must not cost the result
        warnings.warn(f"could not write geodesic cache file {path} ({exc!r})",
                      RuntimeWarning, stacklevel=2)
    return dist


# --------------------------------------------------------------------------- kernel

def kernel_weights(distances, sigma, form: str = "paper", normalise: bool = True) -> np.ndarray:
    """Kernel weights of geodesic ``distances`` (..., n_taxels) mm, same shape.

    form ``"paper"``: ``exp(-d / (2 sigma^2))``, exactly as the method writes it (d in mm,
    sigma in mm, so the exponent is not dimensionless; kept for fidelity).
    form ``"squared"``: the Gaussian ``exp(-d^2 / (2 sigma^2))``.
    normalise: Nadaraya-Watson weights, each row (last axis) summing to 1; computed with
    the row's largest exponent subtracted, so rows far from every taxel do not underflow.
    """
    d = finite_array("distances", distances, ndim=(1, 2))
    if d.shape[-1] == 0:
        raise ValueError(f"distances: expected at least one column, got shape {d.shape}")
    if np.any(d < 0):
        raise ValueError("distances: expected distances >= 0 (mm)")
    s = positive("sigma", sigma)
    if form not in KERNEL_FORMS:
        raise ValueError(f"form: expected one of {KERNEL_FORMS}, got {form!r}")
    exponent = -(d if form == "paper" else d * d) / (2.0 * s * s)
    if not normalise:
        return np.exp(exponent)
    w = np.exp(exponent - exponent.max(axis=-1, keepdims=True))
    return w / w.sum(axis=-1, keepdims=True)

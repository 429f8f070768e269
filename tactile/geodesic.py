"""Geodesic distances on the fitted ellipsoid (see :mod:`tactile.ellipsoid` for the frame and
the parameterisation).

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
one-off numba compilation of ~9 s (cached on disk by numba). Memory: a few
(65, 3) buffers, pairs are looped over.

The results are cached on disk by :func:`tactile.disk_cache.cached_geodesic_distances`; change
:data:`ALGORITHM_VERSION` whenever a change alters the numbers.
"""

from __future__ import annotations

import numpy as np

from ._lazy import lazy_import
from .ellipsoid import _check_axes, _check_on_surface, ellipsoid_angles

__all__ = ["ALGORITHM_VERSION", "GEODESIC_METHODS", "geodesic_distances", "geodesic_path"]

_kernels = lazy_import("tactile_flow.tactile._geodesic_kernels")   # numba: compiled on first use

#: Part of every cache key; bump when a change alters computed distances.
ALGORITHM_VERSION = "geodesic-1"

GEODESIC_METHODS = ("accurate", "paper")


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


def geodesic_distances(axes, points_a, points_b, *, method: str = "accurate",
                       n_steps: int = 100) -> np.ndarray:
    """Geodesic distances (len(a), len(b)) in mm between points on an ellipsoid.

    axes: (3,) semi-axes (mm) along x, y, z of the origin-centred ellipsoid.
    points_a, points_b: (n, 3) or (3,) points on its surface (relative tolerance
    :data:`SURFACE_TOL`). method: ``"accurate"`` (shortest geodesic, ~1e-9 relative
    typical) or ``"paper"`` (the method's (theta, phi)-straight path, ``n_steps`` chords;
    ``n_steps`` is ignored by ``"accurate"``). See the module docstring for both.

    >>> import numpy as np
    >>> axes = np.array([12.0, 7.8, 7.0])
    >>> pole, rim = [0.0, 0.0, -7.0], [12.0, 0.0, 0.0]      # a quarter of the x-z ellipse
    >>> float(geodesic_distances(axes, pole, rim).round(3)[0, 0])
    15.182
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
    dist, _ = _kernels._accurate_distances(ax, np.ascontiguousarray(pa), np.ascontiguousarray(pb),
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
    _, paths = _kernels._accurate_distances(ax, np.ascontiguousarray(pa), np.ascontiguousarray(pb),
                                   True)
    return paths[0, 0]

"""The half-ellipsoid fitted to the taxels: surface maps, closest points, the fit.

Computational tactile flow models the BioTac SP fingertip as a half-ellipsoid through the
24 taxels and interpolates taxel values over that surface with a kernel of the *geodesic*
distance between a surface point and each taxel. This module fits the ellipsoid and maps between
points and surface parameters (geodesic distances: :mod:`tactile.geodesic`).

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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._checks import finite_array

__all__ = ["EllipsoidFit", "SURFACE_TOL", "ellipsoid_angles", "ellipsoid_normals", "ellipsoid_points", "fit_ellipsoid",
           "fit_ellipsoid_with_normals", "project_to_ellipsoid", "taxel_angles"]

#: Relative tolerance |sqrt(sum((p/axes)^2)) - 1| for a point to count as on the surface.
SURFACE_TOL = 1e-6


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
    from scipy.optimize import least_squares      # SciPy loads on the first fit, not on import
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


def fit_ellipsoid_with_normals(points, normals, weight: float = 3.0) -> EllipsoidFit:
    """Axis-aligned ellipsoid through ``points`` (N>=6, 3) mm whose outward normals at them
    match ``normals`` (N, 3), unit: least squares of the orthogonal distances (mm) and of
    ``weight`` × the difference of the unit normals (per mm of distance).

    For taxels that cover only a band of the surface (the classic BioTac's 19 electrodes lie
    between z = −5.1 and −1.1 mm) the positions alone leave the height of the centre free —
    the position-only fit puts it 6.7 mm *above* every electrode, with a rim far from any —
    while the published normals (the side electrodes face almost sideways) pin the equator
    down. ``rms`` is that of the distances alone. Started from the point nearest to every
    normal's line (where the normals point away from).
    """
    from scipy.optimize import least_squares
    pts = finite_array("points", points, ndim=2, last=3)
    nrm = finite_array("normals", normals, ndim=2, last=3)
    if len(pts) < 6 or len(nrm) != len(pts):
        raise ValueError(f"points, normals: expected at least 6 points and one normal each, got {len(pts)} "
                         f"and {len(nrm)}")
    nrm = nrm / np.linalg.norm(nrm, axis=1, keepdims=True)
    w = float(weight)
    proj = np.eye(3)[None] - nrm[:, :, None] * nrm[:, None, :]            # (N, 3, 3) across each normal
    centre0 = np.linalg.lstsq(proj.sum(0), np.einsum("nij,nj->i", proj, pts), rcond=None)[0]
    span = float(np.max(np.ptp(pts, axis=0)))
    x0 = np.r_[centre0, np.maximum(np.ptp(pts, axis=0) / 2 + 1.0, 1e-3 * span)]

    def residuals(p):
        centre, ax = p[:3], p[3:]
        q = pts - centre
        foot = _project_np(ax, q)
        g = foot / ax**2
        n = g / np.linalg.norm(g, axis=1, keepdims=True)
        return np.r_[np.sum((q - foot) * n, axis=1), w * (n - nrm).ravel()]

    result = least_squares(residuals, x0, bounds=(np.r_[np.full(3, -np.inf), np.full(3, 1e-9 * span)], np.inf),
                           x_scale="jac", xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=2000)
    dist = residuals(result.x)[:len(pts)]
    return EllipsoidFit(centre=result.x[:3], axes=result.x[3:], rms=float(np.sqrt(np.mean(dist**2))))


def taxel_angles(fit: EllipsoidFit, points) -> tuple[np.ndarray, np.ndarray]:
    """Parameters ``(theta, phi)`` (rad) of the closest points on ``fit`` to sensor-frame
    ``points`` (..., 3) mm."""
    p = finite_array("points", points, last=3)
    foot = _project_np(np.asarray(fit.axes, dtype=np.float64), p - fit.centre)
    return ellipsoid_angles(fit.axes, foot)

"""The sensor's surface mesh, kernel interpolation of taxel values, and the *tactile surface*.

A sensor model (:mod:`tactile.sensor`) names its surface: a half-ellipsoid (the BioTacs) or a
flat rectangle (a taxel pad). The fitted half-ellipsoid (see :mod:`tactile.ellipsoid`) is sampled on rings of constant θ
between the rim (θ = π/2, z = centre) and the pad's pole (θ = π). Each ring carries a
number of vertices proportional to its circumference, so vertices are spaced about
``spacing`` mm apart everywhere, including near the pole where a plain (θ, φ) grid would
crowd thousands of vertices into a few square millimetres.

Taxel values are carried to every vertex by Nadaraya–Watson kernel interpolation with a
kernel of the geodesic distance (weights precomputed once, one matrix product per record),
and the *tactile surface* is the mesh displaced along its outward normals by
``scale × value`` (mm).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ._checks import finite_array, positive
from .ellipsoid import ellipsoid_normals, ellipsoid_points, project_to_ellipsoid
from .disk_cache import cached_geodesic_distances, geodesic_cache_file

__all__ = ["KERNEL_FORMS", "SurfaceMesh", "build_mesh", "build_plane_mesh", "interpolate", "interpolation_weights",
           "kernel_weights", "mesh_of", "tactile_surface", "weights_on_disk"]

KERNEL_FORMS = ("paper", "squared")


@dataclass(frozen=True)
class SurfaceMesh:
    """Triangle mesh of the sensor's surface, in the sensor frame: the contact-side half of the
    fitted ellipsoid (``kind`` ``ellipsoid``) or a flat rectangle facing −z (``plane``).

    Attributes:
        points: (M, 3) vertex positions, mm, sensor frame (ellipsoid centre added).
        normals: (M, 3) unit outward normals.
        theta, phi: (M,) ellipsoid parameters of each vertex (rad), see :mod:`tactile.ellipsoid`
            (zeros on a plane).
        triangles: (F, 3) int32 vertex indices, counter-clockwise seen from outside.
        centre: (3,) ellipsoid centre (plane: the rectangle's centre), mm.  axes: (3,) semi-axes
            along x, y, z, mm (plane: half its size along x and y, and 0).
    """

    points: np.ndarray
    normals: np.ndarray
    theta: np.ndarray
    phi: np.ndarray
    triangles: np.ndarray
    centre: np.ndarray
    axes: np.ndarray
    kind: str = "ellipsoid"

    @property
    def n_vertices(self) -> int:
        return len(self.points)

    @cached_property
    def local_points(self) -> np.ndarray:
        """(M, 3) vertices relative to the ellipsoid centre (the frame of the geodesics), mm."""
        return self.points - self.centre


def build_mesh(centre, axes, spacing: float = 0.6) -> SurfaceMesh:
    """Mesh the contact-side half-ellipsoid (z ≤ centre z) with vertices ~``spacing`` mm apart.

    Args:
        centre: (3,) ellipsoid centre in the sensor frame, mm.
        axes: (3,) semi-axes (a, b, c) along x, y, z, mm.
        spacing: target distance between neighbouring vertices, mm (> 0).

    Returns:
        A :class:`SurfaceMesh`: rings of constant θ from the rim (θ = π/2) to the pole
        (θ = π, a single vertex), each ring with ~circumference/spacing vertices.
    """
    centre = finite_array("centre", centre, ndim=1, last=3)
    axes = finite_array("axes", axes, ndim=1, last=3)
    if np.any(axes <= 0):
        raise ValueError(f"axes: expected three semi-axes > 0 mm, got {axes.tolist()}")
    spacing = positive("spacing", spacing)
    a, b, c = axes
    # Meridian arc length from rim to pole, to choose the number of rings.
    t = np.linspace(np.pi / 2, np.pi, 257)
    meridian = np.sum(np.hypot(np.diff(max(a, b) * np.sin(t)), np.diff(c * np.cos(t))))
    n_rings = max(3, int(np.ceil(meridian / spacing)))
    thetas = np.linspace(np.pi / 2, np.pi, n_rings + 1)[:-1]      # pole added separately

    # Ramanujan's perimeter of each ring's ellipse (semi-axes a sinθ, b sinθ).
    def ring_count(th: float) -> int:
        p, q = a * np.sin(th), b * np.sin(th)
        h = ((p - q) / (p + q)) ** 2
        perimeter = np.pi * (p + q) * (1 + 3 * h / (10 + np.sqrt(4 - 3 * h)))
        return max(6, int(np.ceil(perimeter / spacing)))

    counts = [ring_count(th) for th in thetas]
    theta = np.concatenate([np.full(n, th) for th, n in zip(thetas, counts)] + [[np.pi]])
    phi = np.concatenate([np.linspace(-np.pi, np.pi, n, endpoint=False) for n in counts] + [[0.0]])
    starts = np.concatenate([[0], np.cumsum(counts)])
    pole = starts[-1]

    tris = []
    for r in range(len(counts)):
        i0, n0 = starts[r], counts[r]
        if r + 1 < len(counts):
            i1, n1 = starts[r + 1], counts[r + 1]
            tris.extend(_stitch_rings(i0, n0, i1, n1))
        else:
            tris.extend([(i0 + k, i0 + (k + 1) % n0, pole) for k in range(n0)])
    triangles = np.asarray(tris, dtype=np.int32)

    local = ellipsoid_points(axes, theta, phi)
    normals = ellipsoid_normals(axes, local)
    triangles = _orient_outward(local + centre, normals, triangles)
    return SurfaceMesh(points=local + centre, normals=normals, theta=theta, phi=phi,
                       triangles=triangles, centre=centre, axes=axes)


def build_plane_mesh(centre, size, spacing: float = 0.6) -> SurfaceMesh:
    """Mesh a flat rectangle facing −z (the contact side) with vertices ~``spacing`` mm apart.

    Args:
        centre: (3,) the rectangle's centre in the sensor frame, mm.
        size: (2,) its extent along x and y, mm.
        spacing: target distance between neighbouring vertices, mm (> 0).
    """
    centre = finite_array("centre", centre, ndim=1, last=3)
    size = finite_array("size", size, ndim=1, last=2)
    if np.any(size <= 0):
        raise ValueError(f"size: expected two lengths > 0 mm, got {size.tolist()}")
    spacing = positive("spacing", spacing)
    nx, ny = (max(2, int(np.ceil(s / spacing)) + 1) for s in size)
    x = np.linspace(-size[0] / 2, size[0] / 2, nx)
    y = np.linspace(-size[1] / 2, size[1] / 2, ny)
    gx, gy = np.meshgrid(x, y, indexing="ij")                        # vertex (i, j) at index i·ny + j
    local = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=-1)
    i, j = np.meshgrid(np.arange(nx - 1), np.arange(ny - 1), indexing="ij")
    a = (i * ny + j).ravel()
    b, c, d = a + ny, a + ny + 1, a + 1
    triangles = np.concatenate([np.stack([a, b, c], -1), np.stack([a, c, d], -1)]).astype(np.int32)
    normals = np.tile([0.0, 0.0, -1.0], (len(local), 1))
    triangles = _orient_outward(local + centre, normals, triangles)
    zeros = np.zeros(len(local))
    return SurfaceMesh(points=local + centre, normals=normals, theta=zeros, phi=zeros.copy(), triangles=triangles,
                       centre=centre, axes=np.r_[size / 2, 0.0], kind="plane")


def mesh_of(shape, spacing: float) -> SurfaceMesh:
    """The mesh of a sensor model's surface (a :class:`tactile.sensor.SurfaceShape`)."""
    if shape.kind == "plane":
        return build_plane_mesh(shape.centre, shape.extent, spacing)
    return build_mesh(shape.centre, shape.extent, spacing)


def _stitch_rings(i0: int, n0: int, i1: int, n1: int) -> list[tuple[int, int, int]]:
    """Triangulate the band between two closed rings by advancing along both in φ."""
    out = []
    j0 = j1 = 0
    while j0 < n0 or j1 < n1:
        a0, a1 = i0 + j0 % n0, i1 + j1 % n1
        # Advance on the ring whose next vertex has the smaller φ fraction.
        if j1 >= n1 or (j0 < n0 and (j0 + 1) / n0 <= (j1 + 1) / n1):
            out.append((a0, i0 + (j0 + 1) % n0, a1))
            j0 += 1
        else:
            out.append((a0, i1 + (j1 + 1) % n1, a1))
            j1 += 1
    return out


def _orient_outward(points, normals, triangles):
    """Flip triangles so that their vertex order is counter-clockwise seen from outside."""
    p0, p1, p2 = (points[triangles[:, k]] for k in range(3))
    face_n = np.cross(p1 - p0, p2 - p0)
    inward = np.einsum("ij,ij->i", face_n, normals[triangles].mean(axis=1)) < 0
    triangles = triangles.copy()
    triangles[inward] = triangles[inward][:, ::-1]
    return triangles


def interpolation_weights(mesh: SurfaceMesh, taxels, sigma: float = 2.0,
                          kernel: str = "paper", geodesic: str = "accurate",
                          cache_dir=None) -> np.ndarray:
    """Nadaraya–Watson weights carrying taxel values to the mesh vertices.

    Args:
        mesh: the surface mesh.
        taxels: (N, 3) taxel positions, mm, sensor frame; projected onto the fitted ellipsoid
            (on a plane: onto the plane, where the geodesic distance is the straight one).
        sigma: kernel width σ, mm (> 0).
        kernel: ``"paper"`` for exp(−d/(2σ²)) as the method writes it, ``"squared"`` for
            exp(−d²/(2σ²)).
        geodesic: ``"accurate"`` (default) or ``"paper"``, see
            :func:`tactile.geodesic.geodesic_distances`. Distances are cached on disk.

    Returns:
        (M, N) weights, rows summing to 1: ``values = activation @ weights.T``.
    """
    if mesh.kind == "plane":
        t = finite_array("taxels", taxels, ndim=2, last=3)
        d = np.linalg.norm(mesh.points[:, None, :2] - t[None, :, :2], axis=-1)
        return kernel_weights(d, sigma, form=kernel)
    d = cached_geodesic_distances(mesh.axes, mesh.local_points, _on_surface(mesh, taxels), method=geodesic,
                                  cache_dir=cache_dir)
    return kernel_weights(d, sigma, form=kernel)


def weights_on_disk(mesh: SurfaceMesh, taxels, geodesic: str = "accurate", cache_dir=None) -> bool:
    """Whether :func:`interpolation_weights` finds its geodesic distances on disk (a plane needs none)."""
    if mesh.kind == "plane":
        return True
    return geodesic_cache_file(mesh.axes, mesh.local_points, _on_surface(mesh, taxels), method=geodesic,
                               cache_dir=cache_dir).exists()


def _on_surface(mesh: SurfaceMesh, taxels) -> np.ndarray:
    """(N, 3) taxel positions (mm, sensor frame) projected onto the mesh's ellipsoid, centred."""
    return project_to_ellipsoid(mesh.axes, finite_array("taxels", taxels, ndim=2, last=3) - mesh.centre)


def interpolate(activation, weights) -> np.ndarray:
    """Taxel values (..., N) → vertex values (..., M) by one matrix product with ``weights``."""
    activation = finite_array("activation", activation, last=weights.shape[1])
    return activation @ weights.T


def tactile_surface(mesh: SurfaceMesh, values, scale: float) -> np.ndarray:
    """Displace the mesh along its outward normals by ``scale × values``.

    Args:
        mesh: the surface mesh (M vertices).
        values: (..., M) interpolated activation at each vertex (e.g. kΩ).
        scale: displacement per unit value, mm per unit (may be 0).

    Returns:
        (..., M, 3) displaced vertex positions, mm, sensor frame.
    """
    values = finite_array("values", values, last=mesh.n_vertices)
    return mesh.points + float(scale) * values[..., None] * mesh.normals


def kernel_weights(distances, sigma, *, form: str = "paper", normalise: bool = True) -> np.ndarray:
    """Kernel weights of geodesic ``distances`` (..., n_taxels) mm, same shape.

    form ``"paper"``: ``exp(-d / (2 sigma^2))``, exactly as the method writes it (d in mm,
    sigma in mm, so the exponent is not dimensionless; kept for fidelity).
    form ``"squared"``: the Gaussian ``exp(-d^2 / (2 sigma^2))``.
    normalise: Nadaraya-Watson weights, each row (last axis) summing to 1; computed with
    the row's largest exponent subtracted, so rows far from every taxel do not underflow.

    >>> kernel_weights([[0.0, 2.0]], 1.0).round(3).tolist()     # the nearer taxel weighs e times more
    [[0.731, 0.269]]
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

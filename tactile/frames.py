"""Tactile frames: orthographic, z-buffered projections of the tactile surface onto camera planes.

A :class:`View` names a camera: the direction it looks along, the image's up vector, and
which half of the sensor it sees. Image axes follow from those: ``rows`` = −up (made
orthogonal to ``look``), ``cols`` = rows × look, so that cols × rows = look and a positive
curl in the image is a counter-clockwise rotation about ``look``.

Default views (sensor frame: x long axis, y lateral, z normal to the pad, contact z < 0):

========  =============  ==========  ===================  ====================
view      looks along    sees        columns increase     rows increase
========  =============  ==========  ===================  ====================
bottom    +z (from below) whole pad   +x                   +y
left      +y             y < 0 half   +x                   −z
right     −y             y > 0 half   −x                   −z
========  =============  ==========  ===================  ====================

Rendering rasterises every triangle of the displaced mesh with a depth test (z-buffer), so
where the displaced surface folds over itself the point nearest the camera wins, exactly as
projecting a 3D surface does. Pixel value = the activation at the visible point,
interpolated linearly inside the triangle. Off-surface pixels are 0 and the view's
``mask`` marks the footprint of the undisplaced sensor.

Default frame size 32 × 32: the bottom footprint (≈ 2a × 2b ≈ 25 × 16 mm) then spans
≈ 0.8 mm per pixel, so a pressure blob under one or two taxels (σ of a few mm) is 8–15 px
across. Farnebäck's polynomial expansion (5–7 px neighbourhood) and its 15 px window with a
3-level pyramid track such blobs over the few pixels per frame a sweep moves them; blobs of
many tens of pixels (64 × 64 and up) flatten into regions of near-constant brightness where
dense flow has nothing to lock on to and costs 3–4× more per frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numba
import numpy as np

from ._checks import finite_array, positive
from .surface import SurfaceMesh

MIN_FRAME_PIXELS = 8


@dataclass(frozen=True)
class View:
    """A camera on the sensor. Vectors in the sensor frame; need not be unit length.

    ``half``: ``"facing"`` keeps only the half of the sensor on the camera's side of the
    plane through the ellipsoid centre normal to ``look``; ``"all"`` keeps the whole mesh.
    """

    name: str
    look: tuple[float, float, float]
    up: tuple[float, float, float]
    half: str = "facing"


DEFAULT_VIEWS: dict[str, View] = {
    "bottom": View("bottom", look=(0.0, 0.0, 1.0), up=(0.0, -1.0, 0.0), half="all"),
    "left": View("left", look=(0.0, 1.0, 0.0), up=(0.0, 0.0, 1.0)),
    "right": View("right", look=(0.0, -1.0, 0.0), up=(0.0, 0.0, 1.0)),
}


@dataclass(frozen=True)
class FramePlan:
    """Everything needed to render one view, precomputed once per geometry.

    Attributes:
        view: the :class:`View`.
        cols, rows, look: (3,) unit image axes in the sensor frame.
        origin: (2,) position (mm) on the (cols, rows) plane of the centre of pixel (0, 0).
        mm_per_px: pixel size (square pixels), mm.
        shape: (H, W).
        vertices: (K,) indices of the mesh vertices this view uses.
        triangles: (F, 3) triangles re-indexed into ``vertices``.
        mask: (H, W) bool, the footprint of the undisplaced sensor half seen by this view.
    """

    view: View
    cols: np.ndarray
    rows: np.ndarray
    look: np.ndarray
    origin: np.ndarray
    mm_per_px: float
    shape: tuple[int, int]
    vertices: np.ndarray
    triangles: np.ndarray
    mask: np.ndarray = field(repr=False)

    def image_to_sensor(self, vectors) -> np.ndarray:
        """Image-plane vectors (..., 2) as (cols, rows) components → sensor-frame (..., 3)."""
        vectors = np.asarray(vectors, dtype=np.float64)
        return vectors[..., :1] * self.cols + vectors[..., 1:2] * self.rows


def view_axes(view: View) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(cols, rows, look) unit vectors of a view; ValueError if ``up`` is parallel to ``look``."""
    look = finite_array(f"views.{view.name}.look", view.look, ndim=1, last=3)
    up = finite_array(f"views.{view.name}.up", view.up, ndim=1, last=3)
    if np.linalg.norm(look) == 0:
        raise ValueError(f"views.{view.name}.look: expected a non-zero direction")
    look = look / np.linalg.norm(look)
    rows = -(up - (up @ look) * look)
    if np.linalg.norm(rows) < 1e-9 * max(np.linalg.norm(up), 1e-300):
        raise ValueError(f"views.{view.name}.up: expected a vector not parallel to look {view.look}")
    rows /= np.linalg.norm(rows)
    return np.cross(rows, look), rows, look


def make_plan(mesh: SurfaceMesh, view: View, size=(32, 32), margin: float = 1.5,
              mm_per_px: float | None = None) -> FramePlan:
    """Precompute the projection of ``mesh`` for ``view``.

    Args:
        mesh: the sensor surface mesh.
        view: the camera.
        size: (H, W) frame size in pixels, each ≥ 8.
        margin: room (mm) left around the footprint for the surface's outward displacement.
        mm_per_px: pixel size; ``None`` fits footprint + margin into ``size``. If given and
            the footprint does not fit, ``ValueError``.
    """
    if view.half not in ("facing", "all"):
        raise ValueError(f"views.{view.name}.half: expected 'facing' or 'all', got {view.half!r}")
    h, w = (int(s) for s in size)
    if min(h, w) < MIN_FRAME_PIXELS:
        raise ValueError(f"size: expected a frame of at least {MIN_FRAME_PIXELS}×{MIN_FRAME_PIXELS} "
                         f"pixels to hold the sensor footprint, got {h}×{w}")
    margin = float(margin)
    if not np.isfinite(margin) or margin < 0:
        raise ValueError(f"margin: expected a finite value ≥ 0 mm, got {margin!r}")
    cols, rows, look = view_axes(view)

    tri = mesh.triangles
    if view.half == "facing":
        centroid_depth = ((mesh.points[tri].mean(axis=1) - mesh.centre) @ look)
        tri = tri[centroid_depth <= 0]
    vertices, inverse = np.unique(tri, return_inverse=True)
    tri = inverse.reshape(tri.shape).astype(np.int32)

    p = mesh.points[vertices]
    uv = np.stack([p @ cols, p @ rows], axis=-1)
    lo, hi = uv.min(axis=0) - margin, uv.max(axis=0) + margin
    extent = hi - lo                                   # (cols, rows) extent in mm
    fit = float(max(extent[0] / w, extent[1] / h))
    if mm_per_px is None:
        mm_per_px = fit
    elif positive("mm_per_px", mm_per_px) < fit:
        raise ValueError(f"size: a {h}×{w} frame at mm_per_px={mm_per_px} is too small to hold the "
                         f"{extent[1]:.1f}×{extent[0]:.1f} mm footprint of view '{view.name}' "
                         f"(needs mm_per_px ≥ {fit:.3f} or a larger frame)")
    # Centre the footprint; pixel (0, 0) centre sits half a pixel inside the corner.
    centre = (lo + hi) / 2
    origin = centre - mm_per_px * (np.array([w, h]) - 1) / 2

    plan = FramePlan(view=view, cols=cols, rows=rows, look=look, origin=origin,
                     mm_per_px=float(mm_per_px), shape=(h, w), vertices=vertices.astype(np.int64),
                     triangles=tri, mask=np.zeros((h, w), bool))
    footprint = render(plan, mesh, np.ones((1, mesh.n_vertices)), scale=0.0)[0] > 0
    object.__setattr__(plan, "mask", footprint)
    return plan


def render(plan: FramePlan, mesh: SurfaceMesh, values, scale: float) -> np.ndarray:
    """Tactile frames of one view.

    Args:
        plan: from :func:`make_plan` for this mesh.
        mesh: the surface mesh (M vertices).
        values: (T, M) interpolated activation at every vertex (e.g. kΩ).
        scale: displacement along the normals per unit value, mm per unit.

    Returns:
        (T, H, W) float32: activation at the visible point of each pixel, 0 off the surface.
    """
    values = np.ascontiguousarray(finite_array("values", values, ndim=2, last=mesh.n_vertices))
    h, w = plan.shape
    out = np.zeros((values.shape[0], h, w), np.float32)
    _rasterise(*_kernel_args(plan, mesh, values, scale), out, np.empty((h, w), np.int32), np.empty((h, w, 3)))
    return out


def _kernel_args(plan, mesh, values, scale):
    idx = plan.vertices
    axes = np.stack([plan.cols / plan.mm_per_px, plan.rows / plan.mm_per_px, plan.look], axis=1)
    base = mesh.points[idx] @ axes - np.r_[plan.origin / plan.mm_per_px, 0.0]
    step = mesh.normals[idx] @ axes
    return base, step, idx, values, float(scale), plan.triangles


def linear_operator(plan: FramePlan, mesh: SurfaceMesh) -> np.ndarray:
    """The frame of the *undisplaced* surface as a linear map of the vertex values.

    Returns (H·W, M): ``frame.ravel() = operator @ values`` exactly when ``scale = 0``
    (each covered pixel is a barycentric combination of its visible triangle's vertices).
    Composed with the interpolation weights it renders a frame with one matrix product;
    with ``scale > 0`` it ignores how the displacement moves the silhouette and the
    visible points, so it is an approximation there (see :func:`render`).
    """
    h, w = plan.shape
    winner, bary = np.empty((h, w), np.int32), np.empty((h, w, 3))
    _rasterise(*_kernel_args(plan, mesh, np.zeros((1, mesh.n_vertices)), 0.0),
               np.zeros((1, h, w), np.float32), winner, bary)
    op = np.zeros((h * w, mesh.n_vertices))
    pix = np.flatnonzero(winner.ravel() >= 0)
    corners = plan.vertices[plan.triangles[winner.ravel()[pix]]]        # (P, 3) mesh vertex ids
    np.add.at(op, (np.repeat(pix, 3), corners.ravel()), bary.reshape(-1, 3)[pix].ravel())
    return op


def to_uint8(frames, low: float, high: float) -> np.ndarray:
    """Map activation frames to 8 bits by a fixed scale: ``low`` → 0, ``high`` → 255.

    A fixed scale keeps brightness comparable across frames; per-frame min/max scaling would
    turn a uniform change of pressure into apparent motion. Values outside [low, high]
    saturate at 0 or 255 (that is what an 8-bit image can hold; choose the range to cover
    the activations of the experiment).
    """
    if not (np.isfinite(low) and np.isfinite(high) and high > low):
        raise ValueError(f"intensity range: expected finite low < high, got ({low!r}, {high!r})")
    scaled = (np.asarray(frames, np.float32) - np.float32(low)) * np.float32(255.0 / (high - low))
    return np.clip(np.rint(scaled), 0, 255).astype(np.uint8)


@numba.njit(cache=True, nogil=True)
def _rasterise(base, step, vidx, values, scale, tris, out, winner, bary):
    """Z-buffer the triangles of the displaced surface into ``out`` (T, H, W).

    base, step: (K, 3) each vertex's (col, row, depth) in pixels for the undisplaced surface
    and per mm of displacement along its normal; vertex m of frame t sits at
    base[m] + scale·values[t, vidx[m]]·step[m]. ``winner`` and ``bary`` receive the visible
    triangle and barycentric weights of each pixel for the last frame.
    """
    n_frames, h, w = out.shape
    k = base.shape[0]
    us = np.empty(k)
    vs = np.empty(k)
    ds = np.empty(k)
    vals = np.empty(k)
    depth = np.empty((h, w))
    for t in range(n_frames):
        for m in range(k):
            val = values[t, vidx[m]]
            s = scale * val
            us[m] = base[m, 0] + s * step[m, 0]
            vs[m] = base[m, 1] + s * step[m, 1]
            ds[m] = base[m, 2] + s * step[m, 2]
            vals[m] = val
        depth[:, :] = np.inf
        winner[:, :] = -1
        for f in range(tris.shape[0]):
            a = tris[f, 0]
            b = tris[f, 1]
            c = tris[f, 2]
            ua, ub, uc = us[a], us[b], us[c]
            va, vb, vc = vs[a], vs[b], vs[c]
            lo_u = ua if ua < ub else ub
            lo_u = lo_u if lo_u < uc else uc
            hi_u = ua if ua > ub else ub
            hi_u = hi_u if hi_u > uc else uc
            lo_v = va if va < vb else vb
            lo_v = lo_v if lo_v < vc else vc
            hi_v = va if va > vb else vb
            hi_v = hi_v if hi_v > vc else vc
            j0 = max(0, int(math.ceil(lo_u)))
            j1 = min(w - 1, int(math.floor(hi_u)))
            i0 = max(0, int(math.ceil(lo_v)))
            i1 = min(h - 1, int(math.floor(hi_v)))
            if j0 > j1 or i0 > i1:
                continue
            area = (ub - ua) * (vc - va) - (uc - ua) * (vb - va)
            if area == 0.0:
                continue
            inv_area = 1.0 / area
            for i in range(i0, i1 + 1):
                for j in range(j0, j1 + 1):
                    wa = ((ub - j) * (vc - i) - (uc - j) * (vb - i)) * inv_area
                    wb = ((uc - j) * (va - i) - (ua - j) * (vc - i)) * inv_area
                    wc = 1.0 - wa - wb
                    if wa < -1e-9 or wb < -1e-9 or wc < -1e-9:
                        continue
                    d = wa * ds[a] + wb * ds[b] + wc * ds[c]
                    if d < depth[i, j]:
                        depth[i, j] = d
                        out[t, i, j] = wa * vals[a] + wb * vals[b] + wc * vals[c]
                        winner[i, j] = f
                        bary[i, j, 0] = wa
                        bary[i, j, 1] = wb
                        bary[i, j, 2] = wc

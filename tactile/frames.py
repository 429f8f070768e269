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

Rendering is defined by a z-buffer: every triangle of the displaced mesh is rasterised with
a depth test, so where the displaced surface folds over itself the point nearest the camera
wins, exactly as projecting a 3D surface does. Pixel value = the activation at the visible
point, interpolated linearly inside the triangle. Off-surface pixels are 0 and the view's
``mask`` marks the footprint of the undisplaced sensor.

The z-buffer costs ~20 ns per triangle per frame, and most frames do not need its depth
test: where no triangle of the view has flipped its projected orientation (no fold), the
number of triangles covering a point equals the winding number of the projected outline
around it, so a pixel with winding number 1 lies in exactly one triangle, the visible one.
The renderer finds it by walking across the mesh from the pixel's triangle in the previous
frame (usually zero steps), and falls back to the z-buffer pixel by pixel near folds and
on the outline, and for whole frames that fold a lot. :func:`_fast_frame` gives the
argument; frames equal the z-buffer's up to float rounding (tests/test_frames.py compares
them on folding and non-folding frames), at about half the cost for the default views.

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
        walk: :class:`WalkIndex`, the mesh topology the fast renderer walks on (``None``: the
            view always uses the z-buffer).
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
    walk: "WalkIndex | None" = field(default=None, repr=False)

    def image_to_sensor(self, vectors) -> np.ndarray:
        """Image-plane vectors (..., 2) as (cols, rows) components → sensor-frame (..., 3)."""
        vectors = np.asarray(vectors, dtype=np.float64)
        return vectors[..., :1] * self.cols + vectors[..., 1:2] * self.rows


@dataclass(frozen=True)
class WalkIndex:
    """Topology of a view's triangles for the mesh-walking renderer (see :func:`_fast_frame`).

    Attributes:
        neighbours: (F, 3) uint32, the triangle across the edge opposite corner k, or
            :data:`_NONE` on the view's boundary.
        boundary: (E, 2) uint32 boundary edges, directed as in their triangle's corner order.
        orientation: ±1, sign of the projected area of the view's triangles at rest.
        start: (H, W) uint32 triangle from which the walk of each pixel starts: its visible
            triangle at rest, or for off-footprint pixels the triangle of nearest centroid.
    """

    neighbours: np.ndarray
    boundary: np.ndarray
    orientation: float
    start: np.ndarray


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
    object.__setattr__(plan, "walk", _walk_index(plan, mesh))
    return plan


def _walk_index(plan: FramePlan, mesh: SurfaceMesh) -> WalkIndex | None:
    """The :class:`WalkIndex` of a plan, or ``None`` if its triangles are not a consistently
    oriented manifold (an edge shared by more than two triangles or twice in the same
    direction) or many of them face away from the camera at rest (e.g. a view of both
    halves): the walk's argument does not hold there and the z-buffer renders every frame."""
    tri = plan.triangles
    n_tri = len(tri)
    directed = np.concatenate([tri[:, [1, 2]], tri[:, [2, 0]], tri[:, [0, 1]]])   # edge opposite corner k
    owner = np.tile(np.arange(n_tri), 3)
    corner = np.repeat(np.arange(3), n_tri)
    if len(np.unique(directed, axis=0)) != len(directed):
        return None
    undirected = np.sort(directed, axis=1)
    _, inverse, counts = np.unique(undirected, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    if counts.max() > 2:
        return None
    neighbours = np.full((n_tri, 3), _NONE, np.uint32)
    order = np.argsort(inverse, kind="stable")
    ids = inverse[order]
    pair = np.flatnonzero(ids[1:] == ids[:-1])                   # positions of shared edges
    first, second = order[pair], order[pair + 1]
    neighbours[owner[first], corner[first]] = owner[second]
    neighbours[owner[second], corner[second]] = owner[first]
    boundary = directed[counts[inverse] == 1].astype(np.uint32)

    base, *_ = _kernel_args(plan, mesh, np.zeros((1, mesh.n_vertices)), 0.0)
    p = base[:2].T[tri]                                          # (F, 3, 2) as (col, row)
    area = (p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1]) - (p[:, 2, 0] - p[:, 0, 0]) * (p[:, 1, 1] - p[:, 0, 1])
    orientation = 1.0 if (area > 0).sum() >= (area < 0).sum() else -1.0
    if np.sum(area * orientation < 0) > 0.01 * len(area):
        return None

    h, w = plan.shape
    winner = np.empty((h, w), np.int32)
    _rasterise(*_kernel_args(plan, mesh, np.zeros((1, mesh.n_vertices)), 0.0),
               np.zeros((1, h, w), np.float32), winner, np.empty((h, w, 3)))
    rows, cols = np.mgrid[0:h, 0:w]
    centroid = p.mean(axis=1)                                    # (F, 2) as (col, row)
    d2 = (cols.reshape(-1, 1) - centroid[:, 0]) ** 2 + (rows.reshape(-1, 1) - centroid[:, 1]) ** 2
    d2[:, area == 0] = np.inf                                  # never start on a degenerate triangle
    start = np.where(winner >= 0, winner, np.argmin(d2, axis=1).reshape(h, w)).astype(np.uint32)
    return WalkIndex(neighbours=neighbours, boundary=boundary, orientation=orientation, start=start)


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
    values = finite_array("values", values, ndim=2, last=mesh.n_vertices)
    return _render(plan, mesh, values[:, plan.vertices], scale)[0]


_CHUNK = 128   # frames whose vertex values are computed at a time (≤ 1 MB: stays in cache)


def render_activation(plan: FramePlan, mesh: SurfaceMesh, weights, activation, scale: float,
                      intensity_range: tuple[float, float] | None = None) -> np.ndarray:
    """Tactile frames of one view straight from taxel activation.

    The frames of ``render(plan, mesh, activation @ weights.T, scale)``, but only the view's
    vertices are interpolated and, with ``intensity_range = (low, high)``, the renderer
    writes the 8-bit frames of :func:`to_uint8` itself (no float frames in between).

    Args:
        weights: (M, C) interpolation weights (C = 24 taxels).
        activation: (T, C) taxel values.

    Returns:
        (T, H, W) float32, or uint8 if ``intensity_range`` is given.
    """
    weights = np.asarray(weights, dtype=np.float64)
    activation = finite_array("activation", activation, ndim=2, last=weights.shape[1])
    view_weights = np.ascontiguousarray(weights[plan.vertices].T)

    def chunk(a, b):
        out = np.empty((b - a, view_weights.shape[1]))
        _interpolate(activation[a:b], view_weights, out)
        return out

    return _render(plan, mesh, chunk, scale, intensity_range, n_frames=len(activation))[0]


def _render(plan, mesh, vertex_values, scale, intensity_range=None, fast=True, n_frames=None):
    """Render the values of the plan's vertices: a (T, K) array, or a function (start, stop)
    → that chunk of it for ``n_frames`` frames, called for _CHUNK frames at a time. Returns
    (frames, number of frames z-buffered in full, number of pixels z-tested one by one);
    ``fast=False`` z-buffers every frame (the reference renderer)."""
    if n_frames is None:
        values, n_frames = vertex_values, len(vertex_values)
        vertex_values = lambda a, b: values[a:b]                             # noqa: E731
    h, w = plan.shape
    to_u8 = intensity_range is not None
    low, gain = _u8_mapping(*intensity_range) if to_u8 else (np.float32(0), np.float32(1))
    out = np.zeros((n_frames, h, w), np.uint8 if to_u8 else np.float32)
    none_f, none_u = np.zeros((0, h, w), np.float32), np.zeros((0, h, w), np.uint8)
    geometry = frame_geometry(plan, mesh, scale, fast)
    cache = frame_cache(plan)                    # each pixel's last triangle, across chunks
    stats = np.zeros(2, np.int64)
    for start in range(0, n_frames, _CHUNK):
        stop = min(n_frames, start + _CHUNK)
        chunk = np.ascontiguousarray(vertex_values(start, stop), dtype=np.float64)
        stats += _render_frames(*geometry, chunk, cache, to_u8, low, gain,
                                none_f if to_u8 else out[start:stop], out[start:stop] if to_u8 else none_u)
    return out, int(stats[0]), int(stats[1])


def frame_geometry(plan: FramePlan, mesh: SurfaceMesh, scale: float, fast: bool = True) -> tuple:
    """The per-view constants of the compiled renderer, computed once per plan:
    ``(base, step, scale, tris, neighbours, boundary, orientation, fast)`` as
    :func:`_render_frames` and :func:`_render_frame` take them. ``fast=False`` (or a plan
    without a :class:`WalkIndex`) z-buffers every frame."""
    h, w = plan.shape
    walk = plan.walk
    if not fast or walk is None:                 # dummies of the right types: z-buffer only
        fast = False
        walk = WalkIndex(np.zeros((0, 3), np.uint32), np.zeros((0, 2), np.uint32), 1.0,
                         np.zeros((h, w), np.uint32))
    base, step, _, _, scale, tris = _kernel_args(plan, mesh, None, scale)
    return base, step, scale, tris, walk.neighbours, walk.boundary, float(walk.orientation), bool(fast)


def frame_cache(plan: FramePlan) -> np.ndarray:
    """(H, W) uint32, each pixel's triangle to start the next frame's walk from: a new
    sequence of frames starts from the plan's rest triangles (the renderer updates it)."""
    h, w = plan.shape
    return plan.walk.start.copy() if plan.walk is not None else np.zeros((h, w), np.uint32)


def frame_scratch(plan: FramePlan) -> tuple:
    """Work arrays of :func:`_render_frame` for one view (reusable across frames and
    sequences; nothing in them carries from one frame to the next):
    ``(us, vs, ds, vals, img, depth, winner, bary, slow, slow_px, cross_u, cross_d, n_cross)``.
    ``img`` (H, W) float64 receives the rendered frame."""
    h, w = plan.shape
    k = len(plan.vertices)
    return (np.empty(k), np.empty(k), np.empty(k), np.empty(k), np.zeros((h, w)), np.empty((h, w)),
            np.empty((h, w), np.int32), np.empty((h, w, 3)), np.zeros((h, w), np.bool_),
            np.empty((h * w, 2), np.int64), np.empty((h, _MAX_CROSSINGS)),
            np.empty((h, _MAX_CROSSINGS), np.int64), np.zeros(h, np.int64))


def _kernel_args(plan, mesh, values, scale):
    idx = plan.vertices
    axes = np.stack([plan.cols / plan.mm_per_px, plan.rows / plan.mm_per_px, plan.look], axis=1)
    base = mesh.points[idx] @ axes - np.r_[plan.origin / plan.mm_per_px, 0.0]
    step = mesh.normals[idx] @ axes
    # Unsigned vertex indices: numba then skips the negative-index wraparound on every gather.
    return (np.ascontiguousarray(base.T), np.ascontiguousarray(step.T), idx, values, float(scale),
            plan.triangles.astype(np.uint32))


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
    the activations of the experiment). Arithmetic in float32, rounding half to even.
    """
    low32, gain = _u8_mapping(low, high)
    return np.clip(np.rint((np.asarray(frames, np.float32) - low32) * gain), 0, 255).astype(np.uint8)


def _u8_mapping(low, high) -> tuple[np.float32, np.float32]:
    """(low, 255 / (high − low)) as float32, the arithmetic of :func:`to_uint8`."""
    if not (np.isfinite(low) and np.isfinite(high) and high > low):
        raise ValueError(f"intensity range: expected finite low < high, got ({low!r}, {high!r})")
    return np.float32(low), np.float32(255.0 / (high - low))


# --- compiled kernels ------------------------------------------------------------------------
#
# Coordinates: a vertex's (u, v) = (col, row) in pixels, pixel (i, j) has its centre at
# (u, v) = (j, i); ``d`` = depth along ``look`` (smaller = nearer the camera).

_TOL = 1e-9               # barycentric tolerance of the coverage test (pixels on shared edges)
_NEAR = 1e-6              # px: pixels this close to the boundary or a flipped triangle: z-test
_MAX_CROSSINGS = 32       # boundary crossings per pixel row the fast path has room for
_MAX_SLOW_PIXELS = 8      # pixels per frame z-tested one by one before a full z-buffer is cheaper
_MAX_STEPS = 256          # walk length before a pixel is z-tested instead
_NONE = np.uint32(0xFFFFFFFF)  # "no neighbour" in WalkIndex.neighbours


@numba.njit(cache=True, nogil=True)
def _project(base, step, vertex_values, scale, us, vs, ds, vals):
    """Vertex k of the displaced surface, base[:, k] + scale·value·step[:, k], into
    (us, vs, ds)[k] = (col px, row px, depth mm); its value into vals[k]. ``base`` (3, K) is
    the undisplaced position, ``step`` (3, K) the normal in px, px, mm per mm."""
    for k in range(base.shape[1]):
        val = vertex_values[k]
        s = scale * val
        us[k] = base[0, k] + s * step[0, k]
        vs[k] = base[1, k] + s * step[1, k]
        ds[k] = base[2, k] + s * step[2, k]
        vals[k] = val


@numba.njit(cache=True, nogil=True)
def _min3(a, b, c):
    m = a if a < b else b                  # (explicit: numba's min(a, b, c) is ~2× slower)
    return m if m < c else c


@numba.njit(cache=True, nogil=True)
def _max3(a, b, c):
    m = a if a > b else b
    return m if m > c else c


@numba.njit(cache=True, nogil=True)
def _pixel_box(us, vs, a, b, c, h, w, margin):
    """Pixel centres (j0..j1, i0..i1) in the frame within ``margin`` of triangle (a, b, c)'s box."""
    j0 = max(0, int(math.ceil(_min3(us[a], us[b], us[c]) - margin)))
    j1 = min(w - 1, int(math.floor(_max3(us[a], us[b], us[c]) + margin)))
    i0 = max(0, int(math.ceil(_min3(vs[a], vs[b], vs[c]) - margin)))
    i1 = min(h - 1, int(math.floor(_max3(vs[a], vs[b], vs[c]) + margin)))
    return j0, j1, i0, i1


@numba.njit(cache=True, nogil=True)
def _area(us, vs, a, b, c):
    """Twice the signed projected area of triangle (a, b, c)."""
    return (us[b] - us[a]) * (vs[c] - vs[a]) - (us[c] - us[a]) * (vs[b] - vs[a])


@numba.njit(cache=True, nogil=True)
def _barycentric(us, vs, a, b, c, inv_area, i, j):
    """Barycentric weights of pixel centre (j, i) in triangle (a, b, c); 1/area given."""
    wa = ((us[b] - j) * (vs[c] - i) - (us[c] - j) * (vs[b] - i)) * inv_area
    wb = ((us[c] - j) * (vs[a] - i) - (us[a] - j) * (vs[c] - i)) * inv_area
    return wa, wb, 1.0 - wa - wb


@numba.njit(cache=True, nogil=True)
def _covers(wa, wb, wc):
    """The coverage test of the z-buffer: inside the triangle or within _TOL of its edges."""
    return wa >= -_TOL and wb >= -_TOL and wc >= -_TOL


@numba.njit(cache=True, nogil=True)
def _zbuffer(us, vs, ds, vals, tris, img, depth, winner, bary):
    """The reference renderer: z-buffer every triangle into ``img`` (H, W), 0 off the surface.

    A triangle takes pixel (i, j) if the pixel centre lies in its bounding box, its area is
    non-zero, :func:`_covers` holds and its depth is strictly below the best so far (so of
    equal depths the first triangle wins). ``winner`` and ``bary`` receive the visible
    triangle (−1 off the surface) and its barycentric weights.
    """
    h, w = img.shape
    img[:, :] = 0.0
    depth[:, :] = np.inf
    winner[:, :] = -1
    for f in range(tris.shape[0]):
        a, b, c = tris[f, 0], tris[f, 1], tris[f, 2]
        j0, j1, i0, i1 = _pixel_box(us, vs, a, b, c, h, w, 0.0)
        if j0 > j1 or i0 > i1:
            continue
        area = _area(us, vs, a, b, c)
        if area == 0.0:
            continue
        inv_area = 1.0 / area
        for i in range(i0, i1 + 1):
            for j in range(j0, j1 + 1):
                wa, wb, wc = _barycentric(us, vs, a, b, c, inv_area, i, j)
                if not _covers(wa, wb, wc):
                    continue
                d = wa * ds[a] + wb * ds[b] + wc * ds[c]
                if d < depth[i, j]:
                    depth[i, j] = d
                    img[i, j] = wa * vals[a] + wb * vals[b] + wc * vals[c]
                    winner[i, j] = f
                    bary[i, j, 0] = wa
                    bary[i, j, 1] = wb
                    bary[i, j, 2] = wc


@numba.njit(cache=True, nogil=True)
def _zbuffer_pixel(us, vs, ds, vals, tris, i, j):
    """:func:`_zbuffer`'s value at the single pixel (i, j): the same tests in the same order.
    (For an integer j, ceil(min u) ≤ j ≤ floor(max u) is min u ≤ j ≤ max u.)"""
    best = np.inf
    value = 0.0
    for f in range(tris.shape[0]):
        a, b, c = tris[f, 0], tris[f, 1], tris[f, 2]
        if (_min3(us[a], us[b], us[c]) > j or _max3(us[a], us[b], us[c]) < j
                or _min3(vs[a], vs[b], vs[c]) > i or _max3(vs[a], vs[b], vs[c]) < i):
            continue
        area = _area(us, vs, a, b, c)
        if area == 0.0:
            continue
        wa, wb, wc = _barycentric(us, vs, a, b, c, 1.0 / area, i, j)
        if not _covers(wa, wb, wc):
            continue
        d = wa * ds[a] + wb * ds[b] + wc * ds[c]
        if d < best:
            best = d
            value = wa * vals[a] + wb * vals[b] + wc * vals[c]
    return value


@numba.njit(cache=True, nogil=True)
def _near_segment(j, i, ua, va, ub, vb):
    """Whether the point (j, i) is within _NEAR of the segment (ua, va)–(ub, vb)."""
    du, dv = ub - ua, vb - va
    length2 = du * du + dv * dv
    cross = du * (i - va) - dv * (j - ua)
    if cross * cross > _NEAR * _NEAR * length2:          # farther than _NEAR from the line
        return False
    s = 0.0 if length2 == 0.0 else min(1.0, max(0.0, ((j - ua) * du + (i - va) * dv) / length2))
    eu, ev = ua + s * du - j, va + s * dv - i
    return eu * eu + ev * ev <= _NEAR * _NEAR


@numba.njit(cache=True, nogil=True)
def _mark_near(us, vs, a, b, c, slow, slow_px, n_slow):
    """Append to ``slow_px`` the pixel centres within _NEAR of the closed triangle (a, b, c)
    (the segment a–b if c == b), once each (``slow`` flags them). Returns the new count."""
    h, w = slow.shape
    j0, j1, i0, i1 = _pixel_box(us, vs, a, b, c, h, w, _NEAR)
    if i0 > i1 or j0 > j1:
        return n_slow
    for i in range(i0, i1 + 1):
        for j in range(j0, j1 + 1):
            if slow[i, j]:
                continue
            near = _near_segment(j, i, us[a], vs[a], us[b], vs[b])
            if c != b:
                # Inside: the three edge functions do not disagree in sign (any orientation).
                e0 = (us[b] - us[a]) * (i - vs[a]) - (vs[b] - vs[a]) * (j - us[a])
                e1 = (us[c] - us[b]) * (i - vs[b]) - (vs[c] - vs[b]) * (j - us[b])
                e2 = (us[a] - us[c]) * (i - vs[c]) - (vs[a] - vs[c]) * (j - us[c])
                near = (near or (e0 >= 0 and e1 >= 0 and e2 >= 0) or (e0 <= 0 and e1 <= 0 and e2 <= 0)
                        or _near_segment(j, i, us[b], vs[b], us[c], vs[c])
                        or _near_segment(j, i, us[c], vs[c], us[a], vs[a]))
            if near:
                slow[i, j] = True
                slow_px[n_slow, 0] = i
                slow_px[n_slow, 1] = j
                n_slow += 1
    return n_slow


@numba.njit(cache=True, nogil=True)
def _walk(us, vs, vals, tris, neighbours, f, i, j):
    """Walk from triangle ``f`` towards pixel (i, j): while the z-buffer's coverage test fails,
    cross the edge opposite the most negative barycentric weight. Returns (found, triangle,
    value); not found if the walk leaves the mesh, meets a degenerate triangle or runs long."""
    for _ in range(_MAX_STEPS):            # (no `break` here: numba compiles it ~10× slower)
        a, b, c = tris[f, 0], tris[f, 1], tris[f, 2]
        area = _area(us, vs, a, b, c)
        if area == 0.0:
            return False, f, 0.0
        wa, wb, wc = _barycentric(us, vs, a, b, c, 1.0 / area, i, j)
        if _covers(wa, wb, wc):
            return True, f, wa * vals[a] + wb * vals[b] + wc * vals[c]
        g = neighbours[f, 0 if wa <= wb and wa <= wc else (1 if wb <= wc else 2)]
        if g == _NONE:
            return False, f, 0.0
        f = g
    return False, f, 0.0


@numba.njit(cache=True, nogil=True)
def _mark_flipped(us, vs, tris, orientation, slow, slow_px):
    """Step 1 of :func:`_fast_frame` for the triangles: mark the pixels near every triangle
    whose projected area is not of the sign ``orientation``. Returns the number marked."""
    n_slow = 0
    for f in range(tris.shape[0]):
        a, b, c = tris[f, 0], tris[f, 1], tris[f, 2]
        if _area(us, vs, a, b, c) * orientation <= 0.0:
            n_slow = _mark_near(us, vs, a, b, c, slow, slow_px, n_slow)
    return n_slow


@numba.njit(cache=True, nogil=True)
def _boundary_pass(us, vs, boundary, slow, slow_px, n_slow, cross_u, cross_d, n_cross):
    """Steps 1–2 of :func:`_fast_frame` for the boundary edges: mark the pixels near them and
    list each row's crossings (row i in [min v, max v) of the edge). Returns (slow pixels,
    False if a row has more crossings than ``cross_u`` holds)."""
    h = cross_u.shape[0]
    n_cross[:] = 0
    ok = True
    for e in range(boundary.shape[0]):
        p, q = boundary[e, 0], boundary[e, 1]
        up, vp, uq, vq = us[p], vs[p], us[q], vs[q]
        lo, hi = (vp, vq) if vp < vq else (vq, vp)
        if math.floor(hi + _NEAR) >= math.ceil(lo - _NEAR):      # a pixel row within reach
            n_slow = _mark_near(us, vs, p, q, q, slow, slow_px, n_slow)
        if vp == vq:
            continue
        direction = 1 if vq > vp else -1
        slope = (uq - up) / (vq - vp)
        for i in range(max(0, int(math.ceil(lo))), min(h, int(math.ceil(hi)))):
            k = n_cross[i]
            if k < cross_u.shape[1]:
                cross_u[i, k] = up + (i - vp) * slope
                cross_d[i, k] = direction
                n_cross[i] = k + 1
            else:
                ok = False
    return n_slow, ok


@numba.njit(cache=True, nogil=True)
def _sweep_row(us, vs, vals, tris, neighbours, cache, img, slow, slow_px, n_slow, cross_u, cross_d, n, i):
    """Steps 2–3 of :func:`_fast_frame` for pixel row i with its n boundary crossings
    ``cross_u`` (columns) and ``cross_d`` (±1). Returns the new number of slow pixels.
    (Pixel indices are unsigned: numba then skips negative-index wraparound checks.)"""
    w = img.shape[1]
    i = np.uint64(i)
    for k in range(1, n):                                                  # insertion sort
        cu, cd = cross_u[k], cross_d[k]
        m = k - 1
        while m >= 0 and cross_u[m] > cu:
            cross_u[m + 1] = cross_u[m]
            cross_d[m + 1] = cross_d[m]
            m -= 1
        cross_u[m + 1] = cu
        cross_d[m + 1] = cd
    # Run k: the columns j with exactly k crossings left of them (cross_u < j).
    winding = 0
    j_lo = 0
    for k in range(n + 1):
        j_hi = w - 1 if k == n else min(w - 1, int(math.floor(cross_u[k])))
        for jj in range(j_lo, j_hi + 1):
            j = np.uint64(jj)
            if winding == 0:
                img[i, j] = 0.0
                continue
            found = False
            if winding == 1 or winding == -1:
                found, f, value = _walk(us, vs, vals, tris, neighbours, cache[i, j], i, j)
                if found:
                    cache[i, j] = f
                    img[i, j] = value
            if not found and not slow[i, j]:
                slow[i, j] = True
                slow_px[n_slow, 0] = i
                slow_px[n_slow, 1] = j
                n_slow += 1
        if k < n:
            winding += cross_d[k]
            j_lo = max(j_lo, j_hi + 1)
    return n_slow


@numba.njit(cache=True, nogil=True)
def _fast_frame(us, vs, ds, vals, tris, neighbours, boundary, orientation, cache, img,
                slow, cross_u, cross_d, n_cross, slow_px):
    """Render one frame like :func:`_zbuffer` without a depth buffer. Returns the number of
    pixels it z-tested one by one, or −1 if it declined (then run :func:`_zbuffer`).

    Why it is exact. Give the view's triangles the orientation they have at rest
    (``orientation``; the mesh is consistently oriented, so interior edges cancel and the
    chain's boundary is the view's boundary edges). For a point y on no edge, the triangles
    containing y, counted with the sign of their projected area, sum to the winding number
    of the projected boundary around y (the degree of the projection). So if every
    triangle that could contain y keeps its orientation, the number of triangles containing
    y *equals* |winding(y)|: 0 → y is off the surface, 1 → exactly one triangle contains y,
    and it is the visible one whatever the depths; ≥ 2 → the surface overlaps itself at y.

    Per frame:
    1. Pixel centres within _NEAR px of a triangle whose projected area lost its sign or
       vanished (where the displaced surface folds), or of a boundary edge (where the
       z-buffer's edge tolerance decides), are "slow": the argument is not used there.
       (:func:`_covers` accepts points up to ~3·_TOL·diameter ≈ 1e-8 px outside a
       triangle, far inside _NEAR, so a pixel that is not slow is covered by the z-buffer
       exactly when it is inside the outline.)
    2. The boundary edges' crossings of each pixel row (half-open in v), sorted, split the
       row into runs of constant winding number.
    3. Winding 0 → 0. Winding ±1 → :func:`_walk` from the pixel's triangle in the previous
       frame to the triangle that passes the z-buffer's own coverage test; its
       interpolated value is the pixel. A walk that fails (non-convex outline, long walk)
       and winding ≥ 2 make the pixel slow.
    4. Slow pixels get :func:`_zbuffer_pixel`, the z-buffer restricted to one pixel.
    Too many slow pixels (> _MAX_SLOW_PIXELS) or crossings in a row → decline.

    Pixels on an edge shared by two triangles may be taken from either of them (the
    z-buffer takes the nearer by rounding); both interpolate the edge's two vertices, so
    the values agree to rounding.
    """
    h, w = img.shape
    n_slow = _mark_flipped(us, vs, tris, orientation, slow, slow_px)                 # 1.
    n_slow, ok = _boundary_pass(us, vs, boundary, slow, slow_px, n_slow, cross_u, cross_d, n_cross)
    for i in range(h):
        if ok and n_slow <= _MAX_SLOW_PIXELS:
            n_slow = _sweep_row(us, vs, vals, tris, neighbours, cache, img, slow, slow_px, n_slow,
                                cross_u[i], cross_d[i], n_cross[i], i)
    ok = ok and n_slow <= _MAX_SLOW_PIXELS
    for k in range(n_slow):                                                # 4.
        i, j = slow_px[k, 0], slow_px[k, 1]
        slow[i, j] = False
        if ok:
            img[i, j] = _zbuffer_pixel(us, vs, ds, vals, tris, i, j)
    return n_slow if ok else -1


@numba.njit(cache=True, nogil=True)
def _interpolate(activation, view_weights, out):
    """``out[t, k] = Σ_c activation[t, c]·view_weights[c, k]``, summed in taxel order.

    Every row is computed on its own with the same arithmetic, so a frame's vertex values
    do not depend on the other frames computed with it (a BLAS product's blocking, and
    so its rounding, depends on the number of rows): a frame rendered alone, as
    :mod:`tactile.online` does, is bit-identical to the same frame rendered in a chunk."""
    n_c, n_k = view_weights.shape
    for t in range(activation.shape[0]):
        row = out[t]
        row[:] = 0.0
        for c in range(n_c):
            a = activation[t, c]
            for k in range(n_k):
                row[k] += a * view_weights[c, k]


@numba.njit(cache=True, nogil=True)
def _render_frame(base, step, scale, tris, neighbours, boundary, orientation, fast, vertex_values, cache,
                  us, vs, ds, vals, img, depth, winner, bary, slow, slow_px, cross_u, cross_d, n_cross):
    """Render one frame of (K,) vertex values into ``img`` (H, W) float64: through
    :func:`_fast_frame` if ``fast``, else (or when it declines) through :func:`_zbuffer`.
    Arguments: :func:`frame_geometry`, the values, ``cache`` (:func:`frame_cache`, updated)
    and :func:`frame_scratch`. Returns the pixels z-tested one by one, or −1 if the frame
    was z-buffered in full."""
    _project(base, step, vertex_values, scale, us, vs, ds, vals)
    n_slow = -1
    if fast:
        n_slow = _fast_frame(us, vs, ds, vals, tris, neighbours, boundary, orientation, cache,
                             img, slow, cross_u, cross_d, n_cross, slow_px)
    if n_slow < 0:
        _zbuffer(us, vs, ds, vals, tris, img, depth, winner, bary)
    return n_slow


@numba.njit(cache=True, nogil=True)
def _store_u8(img, low, gain, out):
    """``out`` (H, W) uint8 ← ``img``: (value − low)·gain in float32, rounded half to even,
    clipped to 0..255: exactly :func:`to_uint8`."""
    h, w = img.shape
    for i in range(h):
        for j in range(w):
            x = np.rint((np.float32(img[i, j]) - low) * gain)
            out[i, j] = 0 if x < 0 else (255 if x > 255 else np.uint8(x))


@numba.njit(cache=True, nogil=True)
def _render_activation_u8(activation, view_weights, base, step, scale, tris, neighbours, boundary,
                          orientation, fast, cache, low, gain, out, vertex_values, us, vs, ds, vals, img,
                          depth, winner, bary, slow, slow_px, cross_u, cross_d, n_cross):
    """One 8-bit frame (H, W) into ``out`` from one sample of (C,) taxel ``activation``,
    allocating nothing: :func:`_interpolate` into ``vertex_values`` (K,), :func:`_render_frame`,
    :func:`_store_u8`. Bit-identical to that frame of :func:`render_activation` given the
    same ``cache`` state. Returns as :func:`_render_frame`."""
    _interpolate(activation.reshape(1, -1), view_weights, vertex_values.reshape(1, -1))
    n_slow = _render_frame(base, step, scale, tris, neighbours, boundary, orientation, fast, vertex_values,
                           cache, us, vs, ds, vals, img, depth, winner, bary, slow, slow_px, cross_u,
                           cross_d, n_cross)
    _store_u8(img, low, gain, out)
    return n_slow


@numba.njit(cache=True, nogil=True)
def _render_frames(base, step, scale, tris, neighbours, boundary, orientation, fast, vertex_values, cache,
                   to_u8, low, gain, out_f, out_u):
    """Render (T, K) vertex values into ``out_f`` (T, H, W) float32, or into ``out_u`` as
    8-bit frames (:func:`_store_u8`), one :func:`_render_frame` each; ``cache`` (H, W) holds
    each pixel's triangle to start its walk from and is updated. Returns (frames z-buffered
    in full, pixels z-tested one by one by the fast path)."""
    h, w = cache.shape
    k = base.shape[1]
    us, vs, ds, vals = np.empty(k), np.empty(k), np.empty(k), np.empty(k)
    img, depth = np.zeros((h, w)), np.empty((h, w))
    winner, bary = np.empty((h, w), np.int32), np.empty((h, w, 3))
    slow, slow_px = np.zeros((h, w), np.bool_), np.empty((h * w, 2), np.int64)
    cross_u, cross_d = np.empty((h, _MAX_CROSSINGS)), np.empty((h, _MAX_CROSSINGS), np.int64)
    n_cross = np.zeros(h, np.int64)
    stats = np.zeros(2, np.int64)             # frames z-buffered in full, pixels z-tested alone
    for t in range(vertex_values.shape[0]):
        n_slow = _render_frame(base, step, scale, tris, neighbours, boundary, orientation, fast,
                               vertex_values[t], cache, us, vs, ds, vals, img, depth, winner, bary, slow,
                               slow_px, cross_u, cross_d, n_cross)
        if n_slow < 0:
            stats[0] += 1
        else:
            stats[1] += n_slow
        if to_u8:
            _store_u8(img, low, gain, out_u[t])
        else:
            for i in range(h):
                for j in range(w):
                    out_f[t, i, j] = img[i, j]
    return stats


@numba.njit(cache=True, nogil=True)
def _rasterise(base, step, vidx, values, scale, tris, out, winner, bary):
    """Z-buffer every frame of (T, M) ``values`` into ``out`` (T, H, W); vertex k of the view is
    mesh vertex vidx[k]. ``winner``, ``bary``: visible triangle and weights of the last frame."""
    h, w = winner.shape
    k = base.shape[1]
    us, vs, ds, vals = np.empty(k), np.empty(k), np.empty(k), np.empty(k)
    img, depth = np.zeros((h, w)), np.empty((h, w))
    for t in range(values.shape[0]):
        _project(base, step, values[t][vidx], scale, us, vs, ds, vals)
        _zbuffer(us, vs, ds, vals, tris, img, depth, winner, bary)
        for i in range(h):
            for j in range(w):
                out[t, i, j] = img[i, j]

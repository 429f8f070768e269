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
on the outline, and for whole frames that fold a lot. :func:`_k._fast_frame` gives the
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

from dataclasses import dataclass, field

import numpy as np

from ._checks import finite_array, positive
from ._lazy import lazy_import
from .surface import SurfaceMesh

__all__ = ["DEFAULT_VIEWS", "FramePlan", "View", "WalkIndex", "frame_cache", "frame_geometry",
           "frame_scratch", "linear_operator", "linear_uint8", "make_frame_plan", "render", "render_activation", "to_uint8",
           "view_axes"]

_k = lazy_import("tactile_flow.tactile._frame_kernels")   # numba: compiled on first use

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
    """Topology of a view's triangles for the mesh-walking renderer (see :func:`_k._fast_frame`).

    Attributes:
        neighbours: (F, 3) uint32, the triangle across the edge opposite corner k, or
            :data:`_k._NONE` on the view's boundary.
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


def make_frame_plan(mesh: SurfaceMesh, view: View, size=(32, 32), margin: float = 1.5,
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
    neighbours = np.full((n_tri, 3), _k._NONE, np.uint32)
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
    _k._rasterise(*_kernel_args(plan, mesh, np.zeros((1, mesh.n_vertices)), 0.0),
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
        plan: from :func:`make_frame_plan` for this mesh.
        mesh: the surface mesh (M vertices).
        values: (T, M) interpolated activation at every vertex (e.g. kΩ).
        scale: displacement along the normals per unit value, mm per unit.

    Returns:
        (T, H, W) float32: activation at the visible point of each pixel, 0 off the surface.
    """
    values = finite_array("values", values, ndim=2, last=mesh.n_vertices)
    return _render(plan, mesh, values[:, plan.vertices], scale)[0]


def render_activation(plan: FramePlan, mesh: SurfaceMesh, weights, activation, scale: float,
                      intensity_range: tuple[float, float] | None = None) -> np.ndarray:
    """Tactile frames of one view straight from taxel activation.

    The frames of ``render(plan, mesh, activation @ weights.T, scale)``, but only the view's
    vertices are interpolated, one frame at a time just before it is rendered, and, with
    ``intensity_range = (low, high)``, the renderer writes the 8-bit frames of
    :func:`to_uint8` itself (no float frames in between).

    Args:
        weights: (M, C) interpolation weights (C = 24 taxels).
        activation: (T, C) taxel values.

    Returns:
        (T, H, W) float32, or uint8 if ``intensity_range`` is given.
    """
    weights = np.asarray(weights, dtype=np.float64)
    activation = finite_array("activation", activation, ndim=2, last=weights.shape[1])
    view_weights = np.ascontiguousarray(weights[plan.vertices].T)
    return _render(plan, mesh, None, scale, intensity_range, activation=activation,
                   view_weights=view_weights)[0]


def _render(plan, mesh, vertex_values, scale, intensity_range=None, fast=True, activation=None,
            view_weights=None):
    """Render (T, K) values of the plan's vertices, or if ``view_weights`` (C, K) is given the
    vertex values interpolated from (T, C) ``activation`` frame by frame. Returns (frames,
    number of frames z-buffered in full, number of pixels z-tested one by one);
    ``fast=False`` z-buffers every frame (the reference renderer)."""
    h, w = plan.shape
    k = len(plan.vertices)
    if view_weights is None:
        vertex_values = np.ascontiguousarray(vertex_values, dtype=np.float64)
        activation, view_weights = np.zeros((0, 0)), np.zeros((0, 0))
        n_frames = len(vertex_values)
    else:
        activation = np.ascontiguousarray(activation, dtype=np.float64)
        vertex_values = np.zeros((0, k))
        n_frames = len(activation)
    to_u8 = intensity_range is not None
    low, gain = _u8_mapping(*intensity_range) if to_u8 else (np.float32(0), np.float32(1))
    out = np.zeros((n_frames, h, w), np.uint8 if to_u8 else np.float32)
    none_f, none_u = np.zeros((0, h, w), np.float32), np.zeros((0, h, w), np.uint8)
    cache = frame_cache(plan)                    # each pixel's last triangle
    stats = _k._render_frames(*frame_geometry(plan, mesh, scale, fast), activation, view_weights,
                              vertex_values, cache, to_u8, low, gain, none_f if to_u8 else out,
                              out if to_u8 else none_u)
    return out, int(stats[0]), int(stats[1])


def frame_geometry(plan: FramePlan, mesh: SurfaceMesh, scale: float, fast: bool = True) -> tuple:
    """The per-view constants of the compiled renderer, computed once per plan:
    ``(base, step, scale, tris, neighbours, boundary, orientation, fast)`` as
    :func:`_k._render_frames` and :func:`_k._render_frame` take them. ``fast=False`` (or a plan
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
    """Work arrays of :func:`_k._render_frame` for one view (reusable across frames and
    sequences; nothing in them carries from one frame to the next):
    ``(us, vs, ds, vals, img, depth, winner, bary, slow, slow_px, cross_u, cross_d, n_cross)``.
    ``img`` (H, W) float64 receives the rendered frame."""
    h, w = plan.shape
    k = len(plan.vertices)
    return (np.empty(k), np.empty(k), np.empty(k), np.empty(k), np.zeros((h, w)), np.empty((h, w)),
            np.empty((h, w), np.int32), np.empty((h, w, 3)), np.zeros((h, w), np.bool_),
            np.empty((h * w, 2), np.int64), np.empty((h, _k._MAX_CROSSINGS)),
            np.empty((h, _k._MAX_CROSSINGS), np.int64), np.zeros(h, np.int64))


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
    _k._rasterise(*_kernel_args(plan, mesh, np.zeros((1, mesh.n_vertices)), 0.0),
               np.zeros((1, h, w), np.float32), winner, bary)
    op = np.zeros((h * w, mesh.n_vertices))
    pix = np.flatnonzero(winner.ravel() >= 0)
    corners = plan.vertices[plan.triangles[winner.ravel()[pix]]]        # (P, 3) mesh vertex ids
    np.add.at(op, (np.repeat(pix, 3), corners.ravel()), bary.reshape(-1, 3)[pix].ravel())
    return op


LINEAR_BLOCK = 64
"""Frames the linear renderer computes at a time: 64 float frames of 28 × 40 (287 kB) stay in
the L2 cache between the matrix product and the 8-bit conversion; a whole record's do not."""


def linear_uint8(activation, operator_t, shape: tuple[int, int], low: float, high: float) -> np.ndarray:
    """8-bit frames of the linear renderer: ``to_uint8(activation @ operator_t)``.

    Args:
        activation: (T, C) float32 taxel values.
        operator_t: (C, H·W) float32, the transpose of :func:`linear_operator` composed with the
            interpolation weights.
        shape: (H, W).
        low, high: the intensity range mapped to 0..255 (:func:`to_uint8`).

    Returns:
        (T, H, W) uint8, computed :data:`LINEAR_BLOCK` frames at a time.
    """
    low32, gain = _u8_mapping(low, high)
    out = np.empty((len(activation), shape[0] * shape[1]), np.uint8)
    buffer = np.empty((LINEAR_BLOCK, out.shape[1]), np.float32)
    for s in range(0, len(activation), LINEAR_BLOCK):
        block = activation[s:s + LINEAR_BLOCK]
        values = np.matmul(block, operator_t, out=buffer[:len(block)])
        _k._store_u8(values, low32, gain, out[s:s + len(block)])
    return out.reshape((len(activation),) + tuple(shape))


def to_uint8(frames, low: float, high: float) -> np.ndarray:
    """Map activation frames to 8 bits by a fixed scale: ``low`` → 0, ``high`` → 255.

    A fixed scale keeps brightness comparable across frames; per-frame min/max scaling would
    turn a uniform change of pressure into apparent motion. Values outside [low, high]
    saturate at 0 or 255 (that is what an 8-bit image can hold; choose the range to cover
    the activations of the experiment). Arithmetic in float32, rounding half to even.
    """
    low32, gain = _u8_mapping(low, high)
    values = np.asarray(frames, dtype=np.float32, order="C")
    out = np.empty(values.shape, np.uint8)
    if values.size:                              # one compiled pass (numpy's five took 14× longer)
        rows = (-1, values.shape[-1]) if values.ndim else (1, 1)
        _k._store_u8(values.reshape(rows), low32, gain, out.reshape(rows))
    return out


def _u8_mapping(low, high) -> tuple[np.float32, np.float32]:
    """(low, 255 / (high − low)) as float32, the arithmetic of :func:`to_uint8`."""
    if not (np.isfinite(low) and np.isfinite(high) and high > low):
        raise ValueError(f"intensity range: expected finite low < high, got ({low!r}, {high!r})")
    return np.float32(low), np.float32(255.0 / (high - low))

"""The whole method for a record: counts → activation → smoothed → frames → flow → aggregates.

:class:`TactileConfig` holds every parameter (the ``analysis`` config group maps onto it);
:class:`TactileModel` holds what is computed once per geometry and configuration (the
ellipsoid fit, the mesh, the kernel weights, one :class:`~tactile.frames.FramePlan` per
view) so that processing a record is matrix products, a compiled rasteriser and the flow.

Records are processed in chunks of frames so memory stays bounded for long runs: frames are
kept (uint8, 1 kB per 32×32 frame), flow fields only on request.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from . import flow
from ._checks import finite_array
from ._lazy import lazy_import

__all__ = ["UNLOADED", "TactileConfig", "TactileModel", "ViewResult", "activation_from_counts",
           "process_view"]

# numba kernels and SciPy load on first use: the configs above import in milliseconds
aggregate, frames, geometry = (lazy_import(f"tactile_flow.tactile.{m}") for m in ("aggregate", "frames", "geometry"))
signals, surface = lazy_import("tactile_flow.tactile.signals"), lazy_import("tactile_flow.tactile.surface")


@dataclass(frozen=True)
class TactileConfig:
    """Parameters of the method. Units in brackets.

    Attributes:
        kalman_r, kalman_q: observation and process noise variances of the Kalman filter
            (kΩ²); ``smooth`` runs the RTS smoother after it (offline), else filter only.
        sigma: kernel width σ [mm]. With the method's kernel exp(−d/(2σ²)) the weight falls
            by e over a geodesic distance of 2σ², i.e. 2 mm for σ = 1 mm: about half the
            spacing of neighbouring taxels, so each taxel's influence is local.
        kernel: ``"paper"`` exp(−d/(2σ²)) or ``"squared"`` exp(−d²/(2σ²)).
        geodesic: ``"accurate"`` or ``"paper"`` (see :mod:`tactile.geometry`).
        mesh_spacing: distance between surface-mesh vertices [mm]; about the pixel size, so
            each pixel is covered by one or two triangles.
        scale: displacement of the tactile surface along its normals [mm per kΩ].
        render: ``"exact"`` renders the displaced surface every frame with visibility (the
            method; see :mod:`tactile.frames`); ``"linear"`` renders the undisplaced surface
            with one precomputed matrix product per frame, identical when ``scale = 0`` and
            ~1.5–2× faster, but it
            ignores how the displacement moves silhouettes (mean difference ≈ 0.05 kΩ per
            pixel at the defaults; measure with ``benchmarks/bench_pipeline.py``).
        views: names of the views to render (keys of ``custom_views`` or of
            :data:`tactile.frames.DEFAULT_VIEWS`, or the sensor model's); empty: the sensor's.
        custom_views: extra views defined in config.
        size: frame size (H, W) [px].
        intensity_range: activation mapped to 0 and 255 [kΩ].
        flow: the dense-flow method and its parameters.
        noise: flow magnitude below which a pixel counts as still [px/frame].
        chunk: frames processed at a time.
    """

    kalman_r: float = 0.005
    kalman_q: float = 0.00015
    smooth: bool = True
    sigma: float = 1.0
    kernel: str = "paper"
    geodesic: str = "accurate"
    mesh_spacing: float = 0.9
    scale: float = 0.25
    render: str = "exact"
    views: tuple[str, ...] = ("bottom", "left", "right")
    custom_views: dict[str, frames.View] = field(default_factory=dict)
    size: tuple[int, int] = (28, 40)
    intensity_range: tuple[float, float] = (0.0, 8.0)
    flow: flow.FlowConfig = field(default_factory=flow.FlowConfig)
    noise: float = 0.05
    chunk: int = 256


@dataclass(frozen=True)
class TactileModel:
    """Precomputed geometry for one configuration and one sensor model: build once with :meth:`build`.

    ``taxels`` (N, 3) mm, sensor frame; ``fit`` the ellipsoid the taxels are carried over
    (``None`` for a flat sensor); ``weights`` (M, N) Nadaraya–Watson weights; ``operators``:
    view → (H·W, N) frame of the undisplaced surface; ``sensor``: the model it was built for
    (``None``: taxel positions given as an array)."""

    config: TactileConfig
    taxels: np.ndarray
    fit: "geometry.EllipsoidFit | None"
    mesh: surface.SurfaceMesh
    weights: np.ndarray
    plans: dict[str, frames.FramePlan]
    operators: dict[str, np.ndarray]
    sensor: object = None

    @property
    def n_taxels(self) -> int:
        return len(self.taxels)

    @classmethod
    def build(cls, config: TactileConfig = TactileConfig(), taxels=None, cache_dir=None,
              sensor=None) -> "TactileModel":
        """Fit or take the sensor's surface, mesh it, compute (or load cached) geodesic kernel
        weights and plans. ``sensor``: a :class:`tactile.sensor.SensorModel` (default the
        BioTac SP's); ``taxels``: (N, 3) positions instead, carried over the ellipsoid fitted
        to them. The views rendered are ``config.views``: each a view of the sensor
        (``sensor.views``) or one of ``config.custom_views``."""
        if config.render not in ("exact", "linear"):
            raise ValueError(f"render: expected 'exact' or 'linear', got {config.render!r}")
        taxels, fit, mesh = cls.surface_of(config, taxels, cache_dir, sensor)
        if not config.views:
            config = replace(config, views=tuple(sensor.views) if sensor is not None else tuple(frames.DEFAULT_VIEWS))
        weights = surface.interpolation_weights(mesh, taxels, sigma=config.sigma, kernel=config.kernel,
                                                geodesic=config.geodesic, cache_dir=cache_dir)
        sensor_views = {} if sensor is None else {v: frames.DEFAULT_VIEWS.get(v) or frames.View(v, **sensor.custom_views[v])
                                                  for v in sensor.views}
        known = ({**frames.DEFAULT_VIEWS, **config.custom_views} if sensor is None
                 else {**sensor_views, **config.custom_views})
        unknown = [v for v in config.views if v not in known]
        if unknown:
            whose = "" if sensor is None else f" of sensor {sensor.name}"
            raise ValueError(f"views: unknown view(s) {unknown}{whose}; expected names from {sorted(known)}")
        margin = max(config.scale * config.intensity_range[1], 0.0) + 0.5
        plans = {name: frames.make_frame_plan(mesh, known[name], size=config.size, margin=margin)
                 for name in config.views}
        operators = {name: (frames.linear_operator(plan, mesh) @ weights).astype(np.float32)
                     for name, plan in plans.items()}
        return cls(config=config, taxels=taxels, fit=fit, mesh=mesh, weights=weights, plans=plans,
                   operators=operators, sensor=sensor)

    @staticmethod
    def surface_of(config: TactileConfig = TactileConfig(), taxels=None, cache_dir=None, sensor=None) -> tuple:
        """``(taxels, fit, mesh)`` of :meth:`build`: the sensor's (N, 3) taxels (default: the
        BioTac SP's), its ellipsoid (``None`` for a plane) and the mesh; or for ``taxels`` given,
        the ellipsoid fitted to them (cached on disk)."""
        if taxels is None:
            from .sensor import builtin_sensor
            shape = (sensor or builtin_sensor()).shape
            taxels = np.array((sensor or builtin_sensor()).taxels)
            fit = (geometry.EllipsoidFit(centre=shape.centre, axes=shape.extent, rms=shape.rms_mm)
                   if shape.kind == "ellipsoid" else None)
            return taxels, fit, surface.mesh_of(shape, config.mesh_spacing)
        taxels = finite_array("taxels", taxels, ndim=2, last=3)
        if len(taxels) < 6:
            raise ValueError(f"taxels: expected at least 6 taxel positions to fit a surface to, got {len(taxels)}")
        fit = geometry.cached_fit_ellipsoid(taxels, cache_dir=cache_dir)
        return taxels, fit, surface.build_mesh(fit.centre, fit.axes, spacing=config.mesh_spacing)

    def smooth(self, activation) -> np.ndarray:
        """Kalman (+ RTS if ``config.smooth``) along axis 0 of (T, ..., N) activation, kΩ."""
        c = self.config
        run = signals.kalman_smooth if c.smooth else signals.kalman_filter
        return run(activation, R=c.kalman_r, Q=c.kalman_q)

    def render(self, activation, view: str) -> np.ndarray:
        """Activation frames (T, H, W) float32 [kΩ] of one view for (T, N) activation."""
        return self._render(activation, view, None)

    def render_uint8(self, activation, view: str, intensity_range=None) -> np.ndarray:
        """``to_uint8(render(activation, view))``, the 8-bit frames (T, H, W) the flow sees, with
        ``intensity_range`` (low, high) kΩ mapped to 0..255 (default: the config's).
        The exact renderer writes them directly (no float frames in between)."""
        return self._render(activation, view, intensity_range or self.config.intensity_range)

    def _render(self, activation, view, intensity_range):
        plan = self.plans[view]
        if self.config.render == "linear":
            act = finite_array("activation", activation, ndim=2, last=self.n_taxels).astype(np.float32)
            if intensity_range is None:
                return (act @ self.operators[view].T).reshape((len(act),) + plan.shape)
            return frames.linear_uint8(act, self.operators[view].T, plan.shape, *intensity_range)
        # Interpolates only the view's vertices (frames.render_activation), each frame just before rendering it.
        return frames.render_activation(plan, self.mesh, self.weights, activation, self.config.scale,
                                        intensity_range)

    def to_uint8(self, frames_kohm) -> np.ndarray:
        low, high = self.config.intensity_range
        return frames.to_uint8(frames_kohm, low, high)


UNLOADED = "unloaded"
"""Name of the static-flow reference that is the sensor at rest: zero activation, an empty frame."""


@dataclass
class ViewResult:
    """Flow of one finger in one view.

    Attributes:
        frames: (T, H, W) uint8 tactile frames.
        dynamic: aggregates of the dynamic flow, px/frame (``dynamic.mean[0]`` is zero).
        statics: reference name → aggregates of the static flow from that reference, px.
        references: reference name → frame index, or ``None`` for :data:`UNLOADED`.
        primary: the name of the reference :attr:`static` and :attr:`reference` report.
        intensity_range: (low, high) kΩ mapped to 0..255 in ``frames``.
        dynamic_field, static_field: (T, H, W, 2) float32 flow fields if requested
            (``static_field``: from the primary reference).
    """

    frames: np.ndarray
    dynamic: aggregate.FlowAggregates
    statics: dict = field(default_factory=dict)
    references: dict = field(default_factory=dict)
    primary: str | None = None
    intensity_range: tuple[float, float] = (0.0, 8.0)
    dynamic_field: np.ndarray | None = None
    static_field: np.ndarray | None = None

    @property
    def static(self) -> aggregate.FlowAggregates | None:
        """Aggregates of the static flow from the primary reference, or ``None``."""
        return self.statics.get(self.primary)

    @property
    def reference(self) -> int | None:
        """Frame index of the primary reference (``None`` for the unloaded one or none)."""
        return self.references.get(self.primary)


def process_view(model: TactileModel, activation, view: str, reference: int | None = None, *,
                 references: dict | None = None, primary: str | None = None, intensity_range=None,
                 keep_fields: bool = False, progress=None, static_every: int = 1) -> ViewResult:
    """Frames, dynamic and static flow, and their aggregates for one finger and one view.

    >>> import numpy as np
    >>> model = TactileModel.build(TactileConfig(views=("bottom",), size=(20, 28)))
    >>> act = np.zeros((3, 24)); act[:, 23] = [0.0, 2.0, 2.0]        # taxel 24 pressed
    >>> r = process_view(model, act, "bottom", references={"unloaded": None}, primary="unloaded")
    >>> r.frames.shape, r.static.magnitude.shape
    ((3, 20, 28), (3,))

    Args:
        model: the precomputed model.
        activation: (T, N) smoothed activation of one finger, kΩ (N taxels of the model).
        view: a name in ``model.plans``.
        reference: a frame index for one static flow (named ``"reference"``); kept for
            callers of one reference, same as ``references={"reference": i}``.
        references: name → frame index, or ``None`` for the unloaded sensor (an empty frame:
            zero activation): one static flow per entry.
        primary: the reference :attr:`ViewResult.static` reports (default: the first).
        intensity_range: (low, high) kΩ mapped to 0..255 (default: the config's).
        keep_fields: also return the full (T, H, W, 2) flow fields (every frame: ``static_every``
            is then 1).
        progress: optional callable taking the number of frames just processed.
        static_every: the static flow (a displacement from a fixed reference, which changes
            slowly) is computed on every ``static_every``-th frame, the last and each reference
            frame, and its aggregates interpolated linearly in between.
    """
    activation = finite_array("activation", activation, ndim=2, last=model.n_taxels, min_len=1)
    if view not in model.plans:
        raise ValueError(f"view: expected one of {sorted(model.plans)}, got {view!r}")
    c = model.config
    n = len(activation)
    refs = dict(references or {})
    if reference is not None:
        refs["reference"] = reference
    for name, index in refs.items():
        if index is not None and not 0 <= index < n:
            raise ValueError(f"reference {name}: expected a frame index in [0, {n}), got {index}")
    plan = model.plans[view]
    rng = tuple(intensity_range or c.intensity_range)
    u8 = np.empty((n,) + plan.shape, np.uint8)
    for start in range(0, n, c.chunk):
        stop = min(n, start + c.chunk)
        u8[start:stop] = model.render_uint8(activation[start:stop], view, rng)
        if progress:
            progress(stop - start)

    primary = primary if primary is not None else next(iter(refs), None)
    dyn = flow.dynamic_flow(u8, config=c.flow) if keep_fields else None
    dynamic = aggregate.aggregate_flow(dyn, plan.mask, noise=c.noise) if keep_fields else _dynamic_aggregates(u8, plan, c)
    result = ViewResult(frames=u8, dynamic=dynamic, references=refs, primary=primary, intensity_range=rng,
                        dynamic_field=dyn)
    every = 1 if keep_fields else max(1, int(static_every))
    for name, index in refs.items():
        ref = np.zeros(plan.shape, np.uint8) if index is None else u8[index]
        at = np.unique(np.r_[np.arange(0, n, every), n - 1, [] if index is None else [index]]).astype(int)
        if keep_fields:
            sta = flow.static_flow(u8, ref, config=c.flow)
            agg = aggregate.aggregate_flow(sta, plan.mask, noise=c.noise)
            if name == primary:
                result.static_field = sta
        else:
            agg = _static_aggregates(u8[at], ref, plan, c)
        result.statics[name] = agg if len(at) == n else aggregate.interpolate(agg, at, n)
    return result


FIELD_FRAMES = 512
"""Frames of dense flow field (~9 kB each at 28 × 40) held at once: a long contact's fields are
computed and aggregated this many frames at a time (the same values: each frame's aggregates
are its own)."""


def _dynamic_aggregates(u8: np.ndarray, plan, c) -> aggregate.FlowAggregates:
    """Aggregates of the flow between consecutive frames of ``u8`` (T, H, W), a stretch at a time."""
    parts = []
    for s in range(0, len(u8), FIELD_FRAMES):
        e = min(len(u8), s + FIELD_FRAMES)
        fields = flow.dynamic_flow(u8[max(s - 1, 0):e], config=c.flow)[min(s, 1):]   # from the frame before
        parts.append(aggregate.aggregate_flow(fields, plan.mask, noise=c.noise))
    return aggregate.concatenate(parts)


def _static_aggregates(frames: np.ndarray, ref: np.ndarray, plan, c) -> aggregate.FlowAggregates:
    """Aggregates of the flow from ``ref`` (H, W) to each of ``frames`` (N, H, W), a stretch at a time."""
    return aggregate.concatenate([
        aggregate.aggregate_flow(flow.static_flow(frames[s:s + FIELD_FRAMES], ref, config=c.flow), plan.mask,
                                 noise=c.noise) for s in range(0, len(frames), FIELD_FRAMES)])


def activation_from_counts(counts, baseline_impedance, model: TactileModel) -> np.ndarray:
    """Raw electrode counts (T, ..., N) → smoothed activation (T, ..., N), kΩ.

    ``baseline_impedance`` (..., N) kΩ: from a rest stretch
    (:func:`tactile.signals.baseline_from_rest`) or a stored calibration.
    """
    z = signals.counts_to_impedance(counts) if model.sensor is None else model.sensor.impedance(counts)
    return model.smooth(signals.activation(z, baseline_impedance))

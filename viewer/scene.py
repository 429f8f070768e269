"""What the viewer shows of a recorded run, as arrays (no Rerun here).

:func:`load_scene` reads a run directory — ``run.zarr`` through :func:`analysis.load.load_run`,
plus the ``pour`` and ``live`` groups, and the analysis' ``summary.json`` when there is one —
and prepares the signals as the analysis does (:func:`analysis.preprocess.prepare`: the tare
baseline, the Kalman + RTS smoothed activation, the pressure above rest). :func:`tactile_tracks`
then renders the tactile frames and their dynamic flow, per finger and view, at the shown
frames only.

Intensity: the frames are the analysis' 8-bit frames. With ``analysis.tactile.intensity_range:
contact`` (the default) the analysis scales each contact window (the contact ± the
segmentation margin) from 0 kΩ to the window's peak activation: the viewer takes the windows
from ``summary.json`` and does the same, and shows frames outside every window on the fixed
scale of ``tactile.pipeline.TactileConfig`` (a run not analysed yet: the fixed scale
throughout). With a fixed ``[low, high]``, that scale throughout.

Decimation: images, flow and the fingertip's colours are shown at ``fps`` frames per second
(every ``round(rate / fps)``-th BioTac frame); each shown frame's flow is the method's dynamic
flow from the frame before it (10 ms at 100 Hz), exactly what the analysis computes for that
frame — only frames that are not shown are skipped. Time series (pressure, electrodes, pose,
pump, scale, live verdicts) are shown at their full rate.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from tactile_flow.analysis.config import AnalysisConfigError, for_sensor, load_config
from tactile_flow.analysis.flows import MIN_PEAK_KOHM
from tactile_flow.analysis.load import AnalysisInputError, RunData, load_run
from tactile_flow.analysis.pipeline import get_model
from tactile_flow.analysis.preprocess import PreparedRun, prepare
from tactile_flow.tactile.aggregate import aggregate_flow
from tactile_flow.tactile.flow import FlowEstimator
from tactile_flow.runstore import packed
from tactile_flow.runstore.reader import open_run
from tactile_flow.tactile.sensor import SensorModelError

from . import draw

log = logging.getLogger(__name__)

DEFAULT_FPS = 25.0
ARROW_SPACING = 3          # px between the flow field's arrows


class SceneError(ValueError):
    """The run directory cannot be shown (no run store, unreadable, no tactile data)."""


@dataclass
class TactileTrack:
    """The shown frames of one finger in one view (N = shown frames).

    Attributes:
        finger, view: names.
        frames: (N, H, W) uint8 tactile frames (the flow's input, fixed intensity scale).
        arrows: (N, P, 2) float32 dynamic flow (Δcol, Δrow) px/frame at ``grid``.
        grid: (rows, cols) pixels of the arrows (:func:`viewer.draw.arrow_grid`).
        mean: (N, 2) mean flow over the footprint, px/frame; ``magnitude``, ``direction`` (rad),
            ``confidence`` (N,): :class:`tactile.aggregate.FlowAggregates` of the shown frames.
    """

    finger: str
    view: str
    frames: np.ndarray
    arrows: np.ndarray
    grid: tuple[np.ndarray, np.ndarray]
    mean: np.ndarray
    magnitude: np.ndarray
    direction: np.ndarray
    confidence: np.ndarray


@dataclass
class Scene:
    """One run, ready to be shown. Times are seconds since run start.

    Attributes:
        run_dir: the run directory.  run: :class:`analysis.load.RunData`.
        prepared: the analysis' activation and pressure (:class:`analysis.preprocess.PreparedRun`).
        model: the :class:`tactile.pipeline.TactileModel` of the run's analysis config.
        noise: the flow's still level, px/frame.
        shown: (N,) indices into ``run.time`` of the frames shown (images, flow, fingertip colours).
        ranges: (N, F, 2) the intensity range (low, high) kΩ mapped to 0..255 for each shown frame
            and finger (see the module docstring).
        fps: the shown frame rate asked for.
        summary: ``summary.json`` of the analysis, or ``None`` (not analysed).
        segments: the analysis' segments (``summary.json``), possibly empty.
        pour: ``{"time_pump", "pump_rate", "dispensed", "time_scale", "mass"}`` arrays, or ``None``.
        live: the ``live`` group as arrays (``time_live``, ``magnitude`` (L, F, V), ...) with
            ``live_finger`` and ``view`` names, or ``None`` (no live monitor in this run).
        fingertips: finger → (6,) sensor pose in the TCP frame [x, y, z m, rotvec rad], from the
            run's config (``hardware.fingertips``); fingers without one (imported recordings)
            are laid out 50 mm apart in the TCP frame.
        notes: what could not be shown and why (one sentence each).
    """

    run_dir: Path
    run: RunData
    prepared: PreparedRun
    model: object
    noise: float
    shown: np.ndarray
    ranges: np.ndarray
    fps: float
    summary: dict | None
    segments: list
    pour: dict | None
    live: dict | None
    fingertips: dict
    notes: list = field(default_factory=list)

    @property
    def times(self) -> np.ndarray:
        """(N,) times of the shown frames, s."""
        return self.run.time[self.shown]

    def active_fingers(self) -> list[str]:
        """Fingers that touched something: the analysis' contacts, else a Σ activation above 1.5 kΩ
        (the analysis' ``contact_min_proxy``); every finger if none did."""
        if self.summary and self.summary.get("contacts"):
            found = [f for f in self.run.fingers if self.summary["contacts"].get(f)]
        else:
            found = [f for k, f in enumerate(self.run.fingers) if np.nanmax(self.prepared.proxy[:, k]) > 1.5]
        return found or list(self.run.fingers)


def find_store(run_dir) -> Path:
    """``RUN_DIR/run.zarr`` or ``RUN_DIR/run.zarr.zip`` (or ``run_dir`` itself if it is a run
    store of either layout); :class:`SceneError` if neither."""
    path = Path(run_dir)
    if not path.exists():
        raise SceneError(f"{path}: no such run directory")
    if packed.is_store(path):
        return path
    store = packed.find(path)
    if store is not None:
        return store                            # load_run says what is wrong with it, if anything
    raise SceneError(f"{path}: not a run directory (expected run.zarr inside it, as tactile-run writes, "
                     f"or run.zarr.zip, as tactile-import writes)")


def load_scene(run_dir, fps: float = DEFAULT_FPS) -> Scene:
    """Read a run directory (or a ``run.zarr``) into a :class:`Scene`; :class:`SceneError` (one
    sentence) when it cannot be shown."""
    if not (fps > 0 and np.isfinite(fps)):
        raise SceneError(f"fps: expected a frame rate > 0 per second, got {fps!r}")
    store = find_store(run_dir)
    try:
        run = load_run(store)
    except (AnalysisInputError, SensorModelError) as exc:
        raise SceneError(str(exc)) from None
    notes = [f"{group}: {why}" for group, why in run.missing.items()]
    if run.sensor_how != "recorded":
        notes.append(f"sensor model {run.sensor.name} ({run.sensor_how})")
    try:
        cfg = for_sensor(load_config(run.config.get("analysis")), run.sensor)
    except AnalysisConfigError as exc:
        notes.append(f"the run's analysis config is not valid here ({exc}); the defaults are used")
        cfg = for_sensor(load_config(None), run.sensor)
    model = get_model(cfg.tactile, run.sensor)
    prepared = prepare(run, cfg, model)
    step = max(1, int(round(run.rate_hz / fps)))
    shown = np.arange(min(1, len(run.time) - 1), len(run.time), step)
    summary = _summary(store.parent, notes)
    ranges = intensity_ranges(run, prepared, cfg, (summary or {}).get("contacts"), notes)[shown]
    for f, why in getattr(prepared, "unusable", {}).items():
        notes.append(f"{f}: not analysed ({why})")
    groups = _groups(store)
    tips = ((run.config.get("hardware") or {}).get("fingertips") or {})
    fingertips = {f: np.asarray(tips[f], float) for f in run.fingers if f in tips and len(tips[f]) == 6}
    return Scene(run_dir=store.parent, run=run, prepared=prepared, model=model, noise=cfg.tactile.noise,
                 shown=shown, ranges=ranges, fps=float(fps), summary=summary, segments=(summary or {}).get("segments") or [],
                 pour=groups.get("pour"), live=groups.get("live"), fingertips=fingertips, notes=notes)


def intensity_ranges(run: RunData, prepared: PreparedRun, cfg, contacts: dict | None, notes: list) -> np.ndarray:
    """(T, F, 2) the intensity range of every frame and finger, as the analysis renders it: the
    fixed ``cfg.tactile.intensity_range``, or with ``cfg.intensity == "contact"`` (0, the
    window's peak activation, at least :data:`analysis.flows.MIN_PEAK_KOHM`) over each contact
    window of ``contacts`` (``summary.json``: finger → [[start, end] s]) ± the segmentation margin."""
    T, F = len(run.time), len(run.fingers)
    out = np.empty((T, F, 2))
    out[:] = cfg.tactile.intensity_range
    if cfg.intensity != "contact":
        return out
    if contacts is None:
        notes.append("frames on the fixed intensity scale (the analysis scales each contact window to its peak: "
                     "analyse the run to see its frames)")
        return out
    margin = int(round(cfg.segmentation.margin_s * run.rate_hz))
    for f, intervals in contacts.items():
        if f not in run.fingers:
            continue
        k = run.fingers.index(f)
        for start, end in intervals:
            a, b = np.searchsorted(run.time, [start, end])
            b = T if b >= T - 1 else b
            w0, w1 = max(0, a - margin), min(T, b + margin)
            out[w0:w1, k] = (0.0, max(float(prepared.activation[w0:w1, k].max()), MIN_PEAK_KOHM))
    return out


def _summary(run_dir: Path, notes: list) -> dict | None:
    """The current analysis's ``summary.json`` (``RUN/analysis/``, :mod:`runstore.analyses`)."""
    from tactile_flow.runstore.analyses import SUMMARY, current_dir
    current = current_dir(run_dir)
    path = (current or run_dir) / SUMMARY
    if not path.is_file():
        notes.append("summary.json: not analysed yet (no segments); run tactile-analyze to add them")
        return None
    try:
        return json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        notes.append(f"summary.json: unreadable ({exc}); segments not shown")
        return None


def _groups(store: Path) -> dict:
    """The ``pour`` and ``live`` groups as plain arrays (absent groups are left out)."""
    tree = open_run(store)
    out = {}
    if "pour" in tree.children:
        p = tree["pour"].to_dataset()
        if p.sizes.get("time_pump", 0) or p.sizes.get("time_scale", 0):
            out["pour"] = {k: np.asarray(p[k].values, float) for k in
                           ("time_pump", "pump_rate", "dispensed", "time_scale", "mass") if k in p.variables}
    if "live" in tree.children:
        v = tree["live"].to_dataset()
        if v.sizes.get("time_live", 0):
            out["live"] = {k: np.asarray(v[k].values) for k in v.variables}
            out["live"]["live_finger"] = [str(f) for f in v["live_finger"].values]
            out["live"]["view"] = [str(f) for f in v["view"].values]
    return out


def tactile_tracks(scene: Scene, fingers=None) -> list[TactileTrack]:
    """Frames and dynamic flow of the shown frames, for every finger (or ``fingers``) and view.

    Each shown frame i is rendered with frame i − 1 on frame i's intensity range (``scene.ranges``;
    :meth:`TactileModel.render_uint8`, the analysis' renderer) and the flow between the two is the
    configured method's
    (:class:`tactile.flow.FlowEstimator`); two identical frames (a finger out of contact) have
    zero flow without computing it. Aggregates: :func:`tactile.aggregate.aggregate_flow`.
    """
    model, act = scene.model, scene.prepared.activation
    pairs = np.stack([scene.shown - 1, scene.shown], axis=1).clip(0)
    out = []
    for finger in fingers or scene.run.fingers:
        k = scene.run.fingers.index(finger)
        ranges = scene.ranges[:, k]
        for view, plan in model.plans.items():
            both = np.empty((len(pairs), 2) + plan.shape, np.uint8)
            for rng in np.unique(ranges, axis=0):               # one render per intensity range
                sel = np.all(ranges == rng, axis=1)
                both[sel] = model.render_uint8(act[pairs[sel].ravel(), k], view, tuple(rng)).reshape(
                    (int(sel.sum()), 2) + plan.shape)
            estimate = FlowEstimator(model.config.flow)
            field = np.zeros(both.shape[:1] + plan.shape + (2,), np.float32)
            for j, (prev, cur) in enumerate(both):
                if not np.array_equal(prev, cur):
                    field[j] = estimate(prev, cur)
            agg = aggregate_flow(field, plan.mask, noise=scene.noise)
            grid = draw.arrow_grid(plan.mask, ARROW_SPACING)
            out.append(TactileTrack(finger, view, both[:, 1].copy(), draw.sample_field(field, grid), grid,
                                    agg.mean, agg.magnitude, agg.direction, agg.confidence))
    return out

"""A :class:`viewer.scene.Scene` into a Rerun recording, every stream on one timeline.

The timeline is :data:`viewer.TIMELINE` (``time``): seconds since run start, the run store's
time base, so every stream lines up as recorded. Entities (docs/viewer.md has the table):

- ``tactile/<finger>/<view>/frame`` (image), ``.../flow`` (arrows of the dynamic flow field),
  ``.../direction`` (one arrow: the aggregated direction) — at the shown frames;
- ``flow/<finger>/<view>/direction`` (deg), ``.../magnitude`` (px/frame) — at the shown frames;
- ``signals/pressure/<finger>``, ``signals/electrodes/<finger>`` (24 series) — every frame;
- ``world/tcp`` (TCP pose), ``world/path`` (its path), ``world/tcp/<finger>/mesh`` (the
  fingertip's half-ellipsoid coloured by activation, at the shown frames), ``arm/speed``;
- ``pour/pump_rate``, ``pour/dispensed``, ``pour/mass``;
- ``protocol/step`` and ``segments/<finger>`` (state lanes), ``events`` (text log);
- ``live/...`` (the live monitor's rows, when the run recorded them: :func:`viewer.live.send_live`);
- ``run`` (a text document: the run, its headline results, what was left out, the arrow scale).

Everything temporal is sent in columns (``send_columns``), one call per entity, so a 60 s
run costs a few hundred calls, not hundreds of thousands.
"""

from __future__ import annotations

import json

import numpy as np
import rerun as rr

from tactile_flow.hardware.transforms import rotvec_to_quaternion

from . import TIMELINE, draw
from .live import send_events, send_live
from .scene import ARROW_SPACING, Scene, TactileTrack, tactile_tracks


def times(seconds) -> list:
    """The timeline column for ``seconds`` since run start."""
    return [rr.TimeColumn(TIMELINE, duration=np.asarray(seconds, np.float64))]


def record_scene(rec: rr.RecordingStream, scene: Scene, arrow_gain: float | None = None) -> float:
    """Send the whole scene to ``rec``: the time series first (cheap: a viewer shows the run at
    once), then the tactile frames and flow (:func:`send_tactile`). Returns the arrow gain."""
    send_series(rec, scene)
    return send_tactile(rec, scene, arrow_gain)


def send_series(rec, scene: Scene) -> None:
    """Everything but the tactile frames: signals, pose, states, events, pour, live verdicts,
    and the fingertips' colours."""
    send_signals(rec, scene)
    send_pose(rec, scene)
    send_states(rec, scene)
    if scene.pour is not None:
        send_pour(rec, scene.pour)
    if scene.live is not None:
        send_live(rec, scene.live, scene.live["live_finger"], scene.live["view"], scene.noise)
    send_fingertips(rec, scene)


def send_tactile(rec, scene: Scene, arrow_gain: float | None = None) -> float:
    """The tactile frames and flow: first of the fingers that touched something (their flow sets
    the arrow gain unless ``arrow_gain`` is given), then of the others; then the ``run``
    document, which names the gain. Returns the gain (px drawn per px/frame)."""
    active = scene.active_fingers()
    gain = arrow_gain
    for group in (active, [f for f in scene.run.fingers if f not in active]):
        tracks = tactile_tracks(scene, group) if group else []
        if gain is None:
            gain = draw.nice_gain(np.concatenate([t.arrows.reshape(-1, 2) for t in tracks]), ARROW_SPACING)
        for track in tracks:
            send_track(rec, track, scene, gain)
    rec.log("run", rr.TextDocument(describe(scene, gain), media_type="text/markdown"), static=True)
    return gain


def describe(scene: Scene, gain: float) -> str:
    """The ``run`` document: what the run was, its headline results, the scales, the notes."""
    run = scene.run
    lines = [f"# {run.protocol or 'run'} — {run.status}", "",
             f"`{scene.run_dir}` · {len(run.time)} tactile frames over {run.time[-1]:.2f} s · "
             f"fingers {', '.join(run.fingers)}", "",
             f"Frames, flow and fingertip colours at {len(scene.shown)} frames "
             f"({scene.fps:g} per second); time series at their recorded rates.",
             f"Flow arrows ×{gain:g} (px drawn per px/frame); the green arrow is the aggregated "
             f"direction (shown when the mean flow exceeds {scene.noise / 2:g} px/frame).",
             f"Intensity: {intensity(scene)}.",
             f"Pressure: {scene.prepared.pressure_name} above rest ({scene.prepared.pressure_units}); "
             f"baseline: {scene.prepared.baseline_source}."]
    if scene.summary:
        lines += ["", "## Headline (summary.json)", "", "```", json.dumps(scene.summary.get("headline"), indent=1),
                  "```"]
    if scene.notes:
        lines += ["", "## Not shown", ""] + [f"- {n}" for n in scene.notes]
    return "\n".join(lines)


def intensity(scene: Scene) -> str:
    """How the frames' grey levels map to activation, in words."""
    fixed = np.asarray(scene.model.config.intensity_range, float)
    windows = scene.ranges[..., 1][np.any(scene.ranges != fixed, axis=-1)]
    if windows.size == 0:
        return f"{fixed[0]:g}–{fixed[1]:g} kΩ → 0–255 throughout"
    return (f"each contact window from 0 kΩ to its peak activation ({windows.min():.2f}–{windows.max():.2f} kΩ) "
            f"→ 0–255, as the analysis renders it; outside the windows {fixed[0]:g}–{fixed[1]:g} kΩ")


def send_signals(rec, scene: Scene) -> None:
    """Pressure and the 24 electrodes per finger, every frame."""
    run, p = scene.run, scene.prepared
    col = times(run.time)
    for k, f in enumerate(run.fingers):
        rec.log(f"signals/pressure/{f}", rr.SeriesLines(names=f, colors=draw.FINGER_COLOURS.get(f)), static=True)
        rec.send_columns(f"signals/pressure/{f}", col, rr.Scalars.columns(scalars=p.pressure[:, k]))
        rec.log(f"signals/electrodes/{f}", rr.SeriesLines(names=[f"{f} E{i + 1}" for i in range(24)]), static=True)
        rec.send_columns(f"signals/electrodes/{f}", col,
                         rr.Scalars.columns(scalars=run.electrodes[:, k].ravel()).partition([24] * len(run.time)))


def send_pose(rec, scene: Scene) -> None:
    """The TCP pose over time (the fingertips ride on it), its path, and its speed (mm/s)."""
    run = scene.run
    if run.tcp_pose is None:
        return
    pose = run.tcp_pose
    rec.log("world/tcp", rr.TransformAxes3D(0.02), static=True)
    rec.send_columns("world/tcp", times(run.arm_time),
                     rr.Transform3D.columns(translation=pose[:, :3], quaternion=rotvec_to_quaternion(pose[:, 3:])))
    rec.log("world/path", rr.LineStrips3D([pose[:, :3]], radii=0.0005, colors=[(200, 200, 200, 255)]), static=True)
    if run.tcp_speed is not None:
        rec.log("arm/speed", rr.SeriesLines(names="TCP speed (mm/s)"), static=True)
        rec.send_columns("arm/speed", times(run.arm_time),
                         rr.Scalars.columns(scalars=np.linalg.norm(run.tcp_speed[:, :3], axis=1) * 1e3))


def send_states(rec, scene: Scene) -> None:
    """Every event as a log line, the protocol's steps and the analysis' segments as state lanes."""
    ev = scene.run.events
    if len(ev.time):
        send_events(rec, list(zip(ev.time, ev.kind, ev.name, ev.detail)))
    from tactile_flow.analysis.figures import COLOURS
    for f in scene.run.fingers:
        segs = sorted((s for s in scene.segments if s.get("finger") == f), key=lambda s: s["start_s"])
        if not segs:
            continue
        labels = list(dict.fromkeys(s["label"] for s in segs))
        colours = np.array([draw.hex_rgba(COLOURS.get(x, "#eeeeee")) for x in labels], dtype=np.uint32)   # packed
        rec.log(f"segments/{f}", rr.StateConfiguration(values=labels, colors=colours), static=True)
        for i, s in enumerate(segs):
            rec.set_time(TIMELINE, duration=float(s["start_s"]))
            rec.log(f"segments/{f}", rr.StateChange(state=s["label"]))
            following = segs[i + 1]["start_s"] if i + 1 < len(segs) else None
            if following is None or following > s["end_s"] + 1e-6:
                rec.set_time(TIMELINE, duration=float(s["end_s"]))
                rec.log(f"segments/{f}", rr.StateChange.cleared())
    rec.reset_time()


def send_pour(rec, pour: dict) -> None:
    """Pump rate (ml/min), volume dispensed (ml) and the scale's mass (g)."""
    for name, tkey, unit in (("pump_rate", "time_pump", "ml/min"), ("dispensed", "time_pump", "ml"),
                             ("mass", "time_scale", "g")):
        if name in pour and len(pour.get(tkey, ())):
            rec.log(f"pour/{name}", rr.SeriesLines(names=f"{name} ({unit})"), static=True)
            rec.send_columns(f"pour/{name}", times(pour[tkey]), rr.Scalars.columns(scalars=pour[name]))


def send_track(rec, track: TactileTrack, scene: Scene, gain: float) -> None:
    """One finger × view: frames, flow arrows, the direction arrow, direction and magnitude series."""
    base = f"tactile/{track.finger}/{track.view}"
    n, (h, w) = len(track.frames), track.frames.shape[1:]
    col = times(scene.times)
    fmt = rr.components.ImageFormat(width=w, height=h, color_model="RGB", channel_datatype="U8")
    rec.log(f"{base}/frame", rr.Image.from_fields(format=fmt, magnification_filter="Nearest"), static=True)
    rec.send_columns(f"{base}/frame", col, rr.Image.columns(buffer=draw.colour_frames(track.frames).reshape(n, -1)))
    p = track.arrows.shape[1]
    rec.log(f"{base}/flow", rr.Arrows2D.from_fields(origins=draw.arrow_origins(track.grid), colors=[draw.FLOW_COLOUR],
                                                    radii=0.12), static=True)
    rec.send_columns(f"{base}/flow", col, rr.Arrows2D.columns(vectors=(track.arrows * gain).reshape(-1, 2))
                     .partition([p] * n))
    mask = scene.model.plans[track.view].mask
    rec.log(f"{base}/direction", rr.Arrows2D.from_fields(origins=[draw.footprint_centre(mask)],
                                                         colors=[draw.MEAN_COLOUR], radii=0.35), static=True)
    rec.send_columns(f"{base}/direction", col,
                     rr.Arrows2D.columns(vectors=draw.direction_arrows(track.mean, scene.noise, min(h, w) / 3)))
    rec.log(f"flow/{track.finger}/{track.view}/direction", rr.SeriesLines(names=f"{track.finger} {track.view} (deg)"),
            static=True)
    rec.send_columns(f"flow/{track.finger}/{track.view}/direction", col, rr.Scalars.columns(
        scalars=draw.unwrap_stretches(draw.direction_deg(track.direction, track.magnitude, scene.noise))))
    rec.send_columns(f"flow/{track.finger}/{track.view}/magnitude", col,
                     rr.Scalars.columns(scalars=track.magnitude.astype(float)))


def send_fingertips(rec, scene: Scene) -> None:
    """Each fingertip's half-ellipsoid (mm, sensor frame) placed at its pose in the TCP frame,
    coloured by the smoothed activation interpolated at its vertices, at the shown frames."""
    model = scene.model
    mesh, m = model.mesh, model.mesh.n_vertices
    act = scene.prepared.activation[scene.shown]                 # (N, F, 24)
    for k, f in enumerate(scene.run.fingers):
        pose = scene.fingertips.get(f, np.r_[0.0, 0.05 * k, 0.0, 0.0, 0.0, 0.0])
        rec.log(f"world/tcp/{f}", rr.Transform3D(translation=pose[:3], quaternion=rotvec_to_quaternion(pose[3:]),
                                                 scale=1e-3), static=True)
        rec.log(f"world/tcp/{f}/mesh", rr.Mesh3D(vertex_positions=mesh.points, triangle_indices=mesh.triangles,
                                                 vertex_normals=mesh.normals), static=True)
        colours = draw.activation_colours(act[:, k] @ model.weights.T, scene.ranges[:, k])
        rec.send_columns(f"world/tcp/{f}/mesh", times(scene.times),
                         rr.Mesh3D.columns(vertex_colors=colours.reshape(-1, 4)).partition([m] * len(scene.shown)))

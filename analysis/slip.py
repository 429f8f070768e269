"""Whole-segment slip estimate of one finger: does the contact slip, which way, does it turn.

Evidence (each in the sensor's x–y plane, mm, and about the pad normal, deg):

- ``static_unloaded``: the static tactile flow from the unloaded sensor (an empty frame) to
  each frame, mean over the segment: where the pressure pattern sits relative to the sensor
  at rest. A still finger on an object pulled one way carries the skin (and the pattern)
  that way, so this offset carries the direction even in a record that begins in contact.
  Farnebäck explains a pattern appearing from nothing as the unpressed skin around it moving
  *out* of it, so the mean flow points *away* from the pressed region: opposite to the
  centre of pressure's offset for every real grasp pattern tested (199 of 200 ff/th
  patterns of ``tests/data/biotac_sp_grasps``) and for simulated blobs up to σ ≈ 5 mm
  (the sign turns for a blob covering most of the pad, σ ≈ 9 mm). The combination uses the
  negated vector;
- ``static_onset``: the static flow from the frame where the contact became established (or,
  in a record that begins in contact, its first settled frame), mean over the segment's
  frames after it: how far the pattern moved since;
- ``dynamic``: the frame-to-frame flow summed over the segment: the net motion during it;
- ``cop_unloaded``: the centre of pressure (activation-weighted taxel position) relative to
  where the taxels put an object resting on the pad (a press at the sensor model's lowest point,
  :func:`tactile.aggregate.press_centre`), mean over the segment — no flow at all;
- ``cop_onset``: the centre of pressure relative to its position at the reference frame.

Rotation (deg, + = counter-clockwise seen from outside the pad, i.e. about −z of the sensor
frame): the static flow's rotation from the onset reference (curl / 2 of the displacement
field in the views of ``analysis.slip.views``; the bottom view looks along +z, so its curl is
negated), mean over the segment's frames after the reference; the dynamic flow's summed
rotation beside it as evidence.

Combination (documented in docs/analysis.md):

- the *reference* is the contact onset when the contact begins inside the record after a
  rest, else the unloaded sensor;
- ``slip_direction_sensor_deg``: the direction of the weighted sum of the displacement
  vectors (mm) of the tactile flow from that reference (weight 1; from the unloaded sensor,
  negated as above), the centre of pressure from that reference (weight 1), and, when they
  moved more than ``min_displacement_mm``, the dynamic flow (weight 1/2) and — in a record
  that begins in contact — the static flow from its first settled frame (weight 1/2: the
  motion seen during the record). A source that moved more counts more: a light contact's
  pattern barely shifts from its onset while its flow travels along the slip. The agreement
  |Σ w v| / Σ w |v| (0..1; 1: every source points the same way) is reported;
- ``slip_displacement_mm``: the larger of the centre of pressure's displacement from the
  reference and the net distance the dynamic flow travelled over the segment: a firm contact
  pulled along shifts its pattern by the skin's stretch; a light one slips almost at once,
  its pattern barely shifted, and the stick-slip of the sliding (a slow stretch, a fast
  release the flow under-reads) leaves a net flow along the motion. (The flow's magnitude
  from an empty frame is not a distance: 0.2–0.9 of the centre of pressure's, with the
  pattern's width.)
- ``slip_class``: ``translation`` if the displacement ≥ ``min_displacement_mm``; else
  ``rotation`` if |rotation| ≥ ``min_rotation_deg``; else ``none`` (only touched). A
  translation turns the pattern's flow a little too (up to ~2° in the simulated grid), so the
  displacement decides first;
- ``confidence`` (0..1): translation min(1, d / 2d_min) × the direction's agreement; rotation
  min(1, |rot| / 2θ_min) × (1 − d / d_min); none 1 − max(d / d_min, |rot| / θ_min).
"""

from __future__ import annotations

import math

import numpy as np

from tactile_flow.tactile import aggregate as tagg
from tactile_flow.tactile.pipeline import UNLOADED

from . import flows as fl

ONSET = fl.ONSET
CLASSES = ("translation", "rotation", "none")
WEIGHTS = {"flow": 1.0, "cop": 1.0, "dynamic": 0.5, "change": 0.5}
PAD_NORMAL_COS = 0.9
"""Rotation about the pad normal is read only in views that look along it (|look·z| above this)."""


def _vec(v) -> dict:
    v = np.asarray(v, float)[:2]
    ok = bool(np.all(np.isfinite(v)))
    return {"vector_mm": v.tolist() if ok else None,
            "direction_deg": float(np.degrees(np.arctan2(v[1], v[0]))) if ok and np.any(v) else None,
            "magnitude_mm": float(np.hypot(*v)) if ok else None}


def _static(cf, views, reference, s, e, model, rotation_too=False):
    """Mean static displacement (2,) mm and rotation (deg, about −z) over frames [s, e) (absolute)."""
    vecs, rots = [], []
    for v in views:
        series = fl.static_series(cf, v, reference, model)
        if series is None:
            continue
        disp, rot = series
        a, b = s - cf.window[0], e - cf.window[0]
        if b - a < 1:
            continue
        vecs.append(disp[a:b].mean(axis=0))
        look_z = model.plans[v].look[2]
        if abs(look_z) > PAD_NORMAL_COS:
            rots.append(-np.degrees(rot[a:b].mean()) * np.sign(look_z))
    if not vecs:
        return None, None
    return np.mean(vecs, axis=0), (float(np.mean(rots)) if rotation_too and rots else None)


def _dynamic(cf, views, s, e, model):
    """Net dynamic displacement (2,) mm and summed rotation (deg, about −z) over frames [s, e)."""
    vecs, rots = [], []
    for v in views:
        vr = cf.views.get(v)
        if vr is None:
            continue
        a, b = max(s - cf.window[0], 1), e - cf.window[0]
        if b <= a:
            continue
        plan = model.plans[v]
        vecs.append(plan.image_to_sensor(vr.dynamic.mean[a:b].sum(axis=0)) * plan.mm_per_px)
        if abs(plan.look[2]) > PAD_NORMAL_COS:
            rots.append(-np.degrees(vr.dynamic.curl[a:b].sum() / 2.0) * np.sign(plan.look[2]))
    if not vecs:
        return None, None
    return np.mean(vecs, axis=0), (float(np.mean(rots)) if rots else None)


def estimate(cf, activation, start: int, stop: int, model, cfg) -> dict | None:
    """The slip estimate of one segment [start, stop) (absolute frames) of the finger of ``cf``.

    ``activation``: (T, 24) smoothed activation of that finger, kΩ; ``cfg``: the
    ``analysis.slip`` config (:class:`analysis.config.Slip`). ``None`` when no flow window
    covers the segment.
    """
    if cf is None or stop - start < 2:
        return None
    views = [v for v in cfg.views if v in cf.views]
    onset = cf.reference
    true_onset = onset is not None and not cf.begins_in_contact and onset < stop
    ref_name = ONSET if true_onset else UNLOADED
    after = max(start, onset) if onset is not None else start
    evidence = {}
    flow_u, _ = _static(cf, views, UNLOADED, start, stop, model)
    evidence["static_unloaded"] = _vec(flow_u if flow_u is not None else [np.nan] * 2)
    flow_o = rot_o = None
    if onset is not None and after < stop:
        flow_o, rot_o = _static(cf, views, ONSET, after, stop, model, rotation_too=True)
    evidence["static_onset"] = {**_vec(flow_o if flow_o is not None else [np.nan] * 2),
                                "rotation_deg": rot_o, "true_onset": true_onset}
    dyn, dyn_rot = _dynamic(cf, views, start, stop, model)
    evidence["dynamic"] = {**_vec(dyn if dyn is not None else [np.nan] * 2), "rotation_deg": dyn_rot}
    cop, _ = tagg.centre_of_pressure(activation[start:stop], model.taxels)
    good = np.all(np.isfinite(cop), axis=1)
    # where the taxels put an object resting on the pad: a press at the sensor model's lowest point
    centroid = (model.taxels.mean(axis=0) if model.sensor is None
                else tagg.press_centre(model.taxels, model.sensor.shape.pole))
    cop_u = cop[good].mean(axis=0) - centroid if good.any() else np.full(3, np.nan)
    evidence["cop_unloaded"] = _vec(cop_u)
    cop_o = np.full(3, np.nan)
    if onset is not None and after < stop:
        ref_cop, _ = tagg.centre_of_pressure(activation[onset:onset + 1], model.taxels)
        seg = cop[after - start:][good[after - start:]]
        if len(seg) and np.all(np.isfinite(ref_cop)):
            cop_o = seg.mean(axis=0) - ref_cop[0]
    evidence["cop_onset"] = _vec(cop_o)
    if good.any():
        evidence["cop_trajectory_mm"] = {"first": cop[good][0][:2].tolist(), "last": cop[good][-1][:2].tolist(),
                                         "mean": cop[good].mean(axis=0)[:2].tolist()}

    flow_vec = flow_o if true_onset else (None if flow_u is None else -flow_u)
    cop_vec = cop_o if true_onset else cop_u
    parts = [(WEIGHTS["flow"], flow_vec), (WEIGHTS["cop"], cop_vec)]
    if dyn is not None and np.hypot(*dyn[:2]) >= cfg.min_displacement_mm:
        parts.append((WEIGHTS["dynamic"], dyn))
    if not true_onset and flow_o is not None and np.hypot(*flow_o[:2]) >= cfg.min_displacement_mm:
        parts.append((WEIGHTS["change"], flow_o))
    vectors, weights = [], []
    for w, v in parts:
        if v is None or not np.all(np.isfinite(v[:2])) or not np.any(v[:2]):
            continue
        vectors.append(np.asarray(v[:2], float))
        weights.append(w)
    direction = agreement = None
    if vectors:
        total = np.sum([w * v for w, v in zip(weights, vectors)], axis=0)
        agreement = float(np.hypot(*total) / sum(w * np.hypot(*v) for w, v in zip(weights, vectors)))
        direction = float(np.degrees(np.arctan2(total[1], total[0]))) if np.any(total) else None
    travelled = [np.hypot(*v[:2]) for v in (cop_vec, dyn) if v is not None and np.all(np.isfinite(v[:2]))]
    displacement = float(max(travelled)) if travelled else None
    rotation = rot_o
    slip_class, confidence = classify(displacement, rotation, agreement, cfg)
    return {"slip_direction_sensor_deg": direction, "slip_displacement_mm": displacement, "rotation_deg": rotation,
            "slip_class": slip_class, "confidence": confidence, "direction_agreement": agreement,
            "reference": ref_name, "begins_in_contact": bool(cf.begins_in_contact), "evidence": evidence}


def classify(displacement, rotation, agreement, cfg) -> tuple[str | None, float | None]:
    """``(slip_class, confidence)`` from the displacement (mm), rotation (deg) and the direction's
    agreement (module doc); ``(None, None)`` without a displacement."""
    if displacement is None or not math.isfinite(displacement):
        return None, None
    d = displacement / max(cfg.min_displacement_mm, 1e-9)
    rot = abs(rotation) if rotation is not None and math.isfinite(rotation) else 0.0
    r = rot / max(cfg.min_rotation_deg, 1e-9)
    if d >= 1.0:
        return "translation", float(min(1.0, d / 2.0) * (agreement or 0.0))
    if r >= 1.0:
        return "rotation", float(min(1.0, r / 2.0) * (1.0 - d))
    return "none", float(max(0.0, 1.0 - max(d, r)))

"""Whole-segment slip estimate of one finger: did the contact slip, which way, did it turn, when.

A record of a real contact usually begins in contact and has no tare: the pattern's offset from
the unloaded sensor then says *where* the touch sits, not whether anything moved. So whether it
slipped — and how — is decided on **motion since the contact's own first settled frames** (its
*reference window*, :mod:`analysis.slip_motion`), and the unloaded sensor is used only for what
it means: the direction in which the skin, and the pattern, were dragged.

Evidence (sensor x–y plane, mm; about the pad normal, deg, + = counter-clockwise seen from
outside the pad, i.e. about the sensor's −z):

- ``motion``: the centre of pressure's displacement from the reference window, frame by frame
  (its 90th percentile over the contact is ``slip_displacement_mm``), and the pattern's shape
  change (``analysis.slip_motion``);
- ``rotation``: the dynamic flow's rotation summed over the contact's frames where the pattern
  moves (curl / 2 per frame, in the views that look along the pad normal, frames where at least
  ``moving_confidence`` of the footprint moves); the static flow's rotation from the
  reference window; and the turn of the pattern's second moments (the antisymmetric part of
  the electrode change: a twisted skin loads two opposite quadrants of an elongated contact);
- ``onset``: when the motion began and when the skin broke away (:mod:`analysis.slip_onset`);
- as before: ``static_unloaded`` (the static flow from an empty frame, mean over the segment;
  Farnebäck explains a pattern appearing from nothing as the unpressed skin moving *out* of it,
  so it points *away* from the pressed region: negated where it is used), ``static_onset`` (from
  the reference frame), ``dynamic`` (the frame-to-frame flow summed), ``cop_unloaded`` (the
  centre of pressure − where the taxels put an object resting on the pad: the centroid of the
  sensor model's pad taxels, :attr:`tactile.sensor.SensorModel.pad_centre`), ``cop_onset``
  (− its position at the reference) and ``cop_trajectory_mm``.

Decision (documented in docs/analysis.md, constants in ``analysis.slip``):

- **slipped or only touched**: the contact slipped when its pattern moved at least
  ``min_displacement_mm`` from the reference window, or turned significantly (below); a touch
  held still — however far from the pad's middle it sits, however its load wanders — does not;
- **rotation or translation**: a turn is significant when, for a contact that moved, the
  dynamic and the static flows' end values averaged (a pull's spurious turn, which grows on the
  way, halves in them) reach ``min_rotation_deg``; for one whose centre of pressure stayed
  within ``min_displacement_mm``, when the static flow's rotation since the reference window
  rose in its one ramp by ``min_still_rotation_deg`` (:func:`static_rise`) or how far the flows' mean turned reaches
  ``min_rotation_deg`` (:func:`turn`); the
  contact *rotated* when that turn, as the arc it sweeps at the contact's radius, is at least
  ``arc_ratio`` of the displacement (an object turned about an axis away from the contact also
  drags the contact sideways; a translation's own spurious turn is far smaller than its
  displacement);
- ``slip_direction_sensor_deg`` (the direction the object moves relative to the finger): the
  weighted sum of the unit vectors of the centre of pressure's motion from the reference window
  (weight 2), its offset from the taxels' centroid (weight 1: the stretched skin carries the
  pattern the way the object was dragged, even where the record began after the drag) and the
  negated static flow from the unloaded sensor (weight 1); ``direction_agreement`` is
  |Σ w u| / Σ w;
- ``confidence`` (0..1): how far the deciding evidence is past its threshold, times the
  direction's agreement for a translation;
- a contact the record does not show well enough to decide — shorter than ``min_decision_s``
  after its reference window, crossed by a gap in time, or with bridged (out-of-range)
  electrode samples — gets ``slip_class`` ``None`` and a ``reason``; never a confident class.
"""

from __future__ import annotations

import math

import numpy as np

from tactile_flow.tactile import aggregate as tagg
from tactile_flow.tactile.pipeline import UNLOADED

from . import flows as fl
from .slip_motion import pattern_motion
from .slip_onset import knee

ONSET = fl.ONSET
CLASSES = ("translation", "rotation", "none")
FIRST_SETTLED = "first_settled"
"""``reference`` of a contact the record begins in: its motion is measured from its first settled frames."""
DIRECTION_WEIGHTS = {"motion": 2.0, "cop_unloaded": 1.0, "static_unloaded": 1.0}
PAD_NORMAL_COS = 0.9
"""Rotation about the pad normal is read only in views that look along it (|look·z| above this)."""
GAP_FACTOR = 3.0
"""A frame interval this many times the record's median is a gap in time."""
MAX_BRIDGED = 0.05
"""A contact with more of its frames bridged (electrodes out of range) than this is not decided."""


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


def _normal_views(cf, views, model) -> list:
    return [v for v in views if v in cf.views and abs(model.plans[v].look[2]) > PAD_NORMAL_COS]


def rotation_series(cf, views, s, e, model, moving: float = 0.0) -> np.ndarray | None:
    """Per-frame rotation (deg, + about −z) of the dynamic flow over frames [s, e) (absolute),
    mean over the views along the pad normal (frame s is the first pair's end), counting only
    frames where at least ``moving`` of the footprint moves (the flow's confidence): the flow of
    a still pattern under a real sensor's drift turns by a few thousandths of a degree a frame,
    always the same way, which over a record adds up to degrees. ``None`` without such a view."""
    parts = []
    for v in _normal_views(cf, views, model):
        agg = cf.views[v].dynamic
        a, b = s - cf.window[0], e - cf.window[0]
        c = np.where(agg.confidence[a:b] >= moving, agg.curl[a:b], 0.0)
        parts.append(-np.degrees(c / 2.0) * np.sign(model.plans[v].look[2]))
    return np.mean(parts, axis=0) if parts else None


def static_rotation_series(cf, views, ref: int, e: int, model) -> np.ndarray | None:
    """Rotation (deg, + about −z) of the pattern since frame ``ref`` over frames [ref, e) (absolute),
    from the static flow of the contact's onset reference: its rotation at each frame minus its
    rotation at ``ref`` (small turns compose by adding). ``None`` without such a flow."""
    parts = []
    for v in _normal_views(cf, views, model):
        series = fl.static_series(cf, v, ONSET, model)
        if series is not None:
            a, b = ref - cf.window[0], e - cf.window[0]
            rot = -np.degrees(series[1][a:b]) * np.sign(model.plans[v].look[2])
            parts.append(rot - rot[0])
    return np.mean(parts, axis=0) if parts else None


def _unfit(time, valid, start, stop) -> str | None:
    """Why frames [start, stop) cannot be decided on (a gap in time, bridged samples), or None."""
    if time is not None and stop - start > 2:
        steps = np.diff(np.asarray(time[start:stop], float))
        whole = np.diff(np.asarray(time, float))
        typical = float(np.median(whole)) if len(whole) else 0.0
        if typical > 0 and steps.max() > GAP_FACTOR * typical:
            i = int(np.argmax(steps))
            return (f"the record has a gap of {steps[i]:.3f} s at {float(time[start + i]):.2f} s inside this "
                    f"contact (frames every {typical:.3f} s): its motion cannot be followed across it")
    if valid is not None:
        bad = int((~np.asarray(valid[start:stop], bool)).sum())
        if bad > MAX_BRIDGED * (stop - start):
            return (f"{bad} of this contact's {stop - start} frames had electrodes out of range (saturated or "
                    f"dead) and were bridged: too many to decide whether it slipped")
    return None


def motion_reference(cf, activation, start: int, stop: int, rate: float, cfg) -> int:
    """First frame of the reference window (absolute). A contact that begins inside the record
    was pressed: its reference is the first frame whose total positive activation reaches
    :data:`LOADED` of its median over the ``reference_horizon_s`` after the contact settled (the
    press has finished; a later slip that loads the skin's leading side cannot move the
    reference past its own start, as a median over the whole contact would). A contact the
    record begins in has no press to wait for: its first settled frame."""
    first = max(start, cf.settled if cf.settled is not None else start)
    if first >= stop or cf.begins_in_contact:
        return min(first, stop - 1)
    horizon = max(2, int(round(cfg.reference_horizon_s * rate)))
    load = np.clip(np.asarray(activation[first:min(stop, first + horizon)], float), 0.0, None).sum(axis=1)
    hits = np.flatnonzero(load >= LOADED * float(np.median(load)))
    return first + (int(hits[0]) if hits.size else 0)


LOADED = 0.95
"""The reference window starts once the press has brought the load to this share of its level
over the time after settling (``analysis.slip.reference_horizon_s``). At 0.8 the press's last
fifth, after the reference, changed a real contact frame's shape enough for the static flow to
read a turn of up to 0.95° (0.44° at the 95th percentile: ``tests/real_touch.py``'s 90 records
reached from rest); at 0.95 at most 0.23–0.35° over two draws of the resting noise — under
``min_still_rotation_deg``."""


def _loaded_end(load, fraction: float) -> int:
    """Frames of ``load`` (after the reference) before the contact unloads: up to the last frame at
    least ``fraction`` of the median load."""
    keep = np.flatnonzero(load >= fraction * np.median(load))
    return int(keep[-1]) + 1 if len(keep) else len(load)


def estimate(cf, activation, start: int, stop: int, model, cfg, time=None, valid=None, raw=None) -> dict | None:
    """The slip estimate of one segment [start, stop) (absolute frames) of the finger of ``cf``.

    ``activation``: (T, n) smoothed activation of that finger, kΩ; ``cfg``: the ``analysis.slip``
    config (:class:`analysis.config.Slip`); ``time`` (T,) s, the record's frame times;
    ``valid`` (T,) bool, that finger's frames whose electrodes were all in range; ``raw`` (T, n)
    its unsmoothed activation, kΩ (the slip onset's release is dated on it: the smoother spreads a
    sudden change over a tenth of a second either way). ``None`` when no flow window covers the
    segment.
    """
    if cf is None or stop - start < 2:
        return None
    views = [v for v in cfg.views if v in cf.views]
    onset = cf.reference
    true_onset = onset is not None and not cf.begins_in_contact and onset < stop
    rate = 1.0 / float(np.median(np.diff(time))) if time is not None and len(time) > 1 else 100.0
    ref = motion_reference(cf, activation, start, stop, rate, cfg)
    evidence = _legacy_evidence(cf, activation, start, stop, max(start, onset) if onset is not None else start,
                                onset, views, model)
    out = {"slip_direction_sensor_deg": None, "slip_displacement_mm": None, "rotation_deg": None,
           "slip_class": None, "confidence": None, "direction_agreement": None, "slip_onset_s": None,
           "slip_onset_uncertainty_s": None, "reason": None,
           "reference": ONSET if true_onset else FIRST_SETTLED, "reference_s": None,
           "begins_in_contact": bool(cf.begins_in_contact), "evidence": evidence}
    reason = _unfit(time, valid, ref, stop)
    n_ref = max(2, int(round(cfg.reference_s * rate)))
    pm = pattern_motion(activation, model.taxels, ref, stop, n_ref) if reason is None else None
    if reason is None and pm is None:
        reason = "too little of the pattern is pressed after the contact's first settled frames to follow it"
    if pm is not None:
        end = _loaded_end(pm.load, cfg.loaded_fraction)
        span = (end - pm.reference_frames) / rate
        if span < cfg.min_decision_s:
            reason = (f"contact too short to decide: {span:.2f} s after its first settled frames "
                      f"(analysis.slip.min_decision_s = {cfg.min_decision_s} s)")
    if time is not None and ref < len(time):
        out["reference_s"] = float(time[ref])
    if reason is not None:
        out["reason"] = reason
        return out
    motion = _motion_evidence(pm, end)
    rotation, turned, static_turn = _rotation_evidence(cf, views, ref, ref + end, model, pm, end,
                                                       cfg.moving_confidence)
    evidence["motion"], evidence["rotation"] = motion, rotation
    direction, agreement = _direction(motion, evidence)
    slip_class, confidence = classify(motion["displacement_mm"], rotation, pm.radius_mm, agreement, cfg)
    rotation["turn_deg"], rotation["read_as"] = turn(motion["displacement_mm"], rotation, cfg)
    if rotation["read_as"] == "static" and static_turn is not None and \
            (rotation["dynamic_deg"] or 0.0) * rotation["turn_deg"] <= 0:
        # the summed curl dates a twist (finer in time) where it turned the way that was read;
        # turned the other way it is noise (a third of a degree spread over a second), and the
        # static turn dates it
        turned = static_turn
    translated = slip_class == "translation"
    out.update(slip_direction_sensor_deg=direction if translated else None,
               slip_displacement_mm=motion["displacement_mm"], rotation_deg=rotation["turn_deg"],
               slip_class=slip_class, confidence=confidence,
               direction_agreement=agreement if translated else None)
    evidence["direction"] = {"direction_deg": direction, "agreement": agreement}
    when = _onset(pm, end, turned, slip_class)
    if when is not None and raw is not None:
        seg = np.asarray(activation[ref:ref + end], float)
        _release(when, np.asarray(raw[ref:ref + end], float), pm.reference_frames, rate,
                 seg[when["slip_frame"]] - seg[when["motion_frame"]])
    evidence["onset"] = when
    if slip_class in ("translation", "rotation") and when is not None and time is not None:
        out["slip_onset_s"] = float(time[ref + when["slip_frame"]])
        out["slip_onset_uncertainty_s"] = when["uncertainty_frames"] / rate
        when["motion_onset_s"] = float(time[ref + when["motion_frame"]])
    return out


def _legacy_evidence(cf, activation, start, stop, ref, onset, views, model) -> dict:
    """The static, dynamic and centre-of-pressure evidence of the whole segment (module docstring)."""
    evidence = {}
    flow_u, _ = _static(cf, views, UNLOADED, start, stop, model)
    evidence["static_unloaded"] = _vec(flow_u if flow_u is not None else [np.nan] * 2)
    flow_o = rot_o = None
    if onset is not None and ref < stop:
        flow_o, rot_o = _static(cf, views, ONSET, ref, stop, model, rotation_too=True)
    evidence["static_onset"] = {**_vec(flow_o if flow_o is not None else [np.nan] * 2), "rotation_deg": rot_o,
                                "true_onset": bool(onset is not None and not cf.begins_in_contact)}
    vecs, rots = [], []
    for v in views:
        vr = cf.views.get(v)
        a, b = max(start - cf.window[0], 1), stop - cf.window[0]
        if vr is None or b <= a:
            continue
        plan = model.plans[v]
        vecs.append(plan.image_to_sensor(vr.dynamic.mean[a:b].sum(axis=0)) * plan.mm_per_px)
        if abs(plan.look[2]) > PAD_NORMAL_COS:
            rots.append(-np.degrees(vr.dynamic.curl[a:b].sum() / 2.0) * np.sign(plan.look[2]))
    dyn = np.mean(vecs, axis=0) if vecs else np.full(2, np.nan)
    evidence["dynamic"] = {**_vec(dyn), "rotation_deg": float(np.mean(rots)) if rots else None}
    cop, _ = tagg.centre_of_pressure(activation[start:stop], model.taxels)
    good = np.all(np.isfinite(cop), axis=1)
    # where the taxels put an object resting on the pad: the centroid of the pad's taxels (of all
    # of them on the SP; the classic BioTac's whole centroid is 3.2 mm off its pad)
    centroid = model.taxels.mean(axis=0) if model.sensor is None else model.sensor.pad_centre
    evidence["cop_unloaded"] = _vec(cop[good].mean(axis=0) - centroid if good.any() else np.full(3, np.nan))
    cop_o = np.full(3, np.nan)
    if onset is not None and ref < stop:
        ref_cop, _ = tagg.centre_of_pressure(activation[onset:onset + 1], model.taxels)
        seg = cop[ref - start:][good[ref - start:]]
        if len(seg) and np.all(np.isfinite(ref_cop)):
            cop_o = seg.mean(axis=0) - ref_cop[0]
    evidence["cop_onset"] = _vec(cop_o)
    if good.any():
        evidence["cop_trajectory_mm"] = {"first": cop[good][0][:2].tolist(), "last": cop[good][-1][:2].tolist(),
                                         "mean": cop[good].mean(axis=0)[:2].tolist()}
    return evidence


def _motion_evidence(pm, end: int) -> dict:
    """The pattern's motion since its reference window, over its loaded frames [0, end)."""
    d = pm.displacement[:end]
    mag = np.hypot(d[:, 0], d[:, 1])
    moved = float(np.percentile(mag, 90))
    far = mag >= 0.5 * mag.max() if mag.max() > 0 else np.ones(len(mag), bool)
    vec = d[far].mean(axis=0)
    return {**_vec(vec), "displacement_mm": moved, "final_mm": float(np.hypot(*d[-max(1, end // 5):].mean(axis=0))),
            "cop_noise_mm": pm.cop_noise_mm, "change": float(np.percentile(pm.change[:end], 90)),
            "change_noise": pm.change_noise, "radius_mm": pm.radius_mm, "elongation": pm.elongation,
            "reference_frames": pm.reference_frames, "frames": int(end)}


def _rotation_evidence(cf, views, ref, stop, model, pm, end, moving) -> tuple[dict, np.ndarray | None,
                                                                              np.ndarray | None]:
    """Rotation about the pad normal over the contact's loaded frames [ref, stop) (module
    docstring), the dynamic rotation summed frame by frame from the reference and the static
    flow's rotation since the reference, frame by frame (deg; ``None`` where not measured)."""
    per_frame = rotation_series(cf, views, ref + 1, stop, model, moving)
    dynamic = moving_frames = None
    if per_frame is not None and len(per_frame) > 1:
        dynamic = float(per_frame.sum())
        moving_frames = int(np.count_nonzero(per_frame))
    static = series = straightness = None
    if cf.reference is not None:
        series = static_rotation_series(cf, views, ref, stop, model)
        if series is not None and len(series):
            static = float(np.median(series[-max(1, len(series) // 5):]))
            path = float(np.abs(np.diff(series)).sum())
            straightness = abs(static) / path if path > 0 else None
    rise = static_rise(series)
    tail = pm.turn_deg[max(0, end - max(1, end // 5)):end]
    turn = float(np.median(tail)) if len(tail) else None
    both = [v for v in (dynamic, static) if v is not None]
    evidence = {"rotation_deg": float(np.mean(both)) if both else None, "dynamic_deg": dynamic,
                "moving_frames": moving_frames,
                "static_deg": static, "static_rise_deg": rise, "static_straightness": straightness,
                "pattern_turn_deg": turn, "pattern_elongation": pm.elongation,
                "peak_deg": _peak_turn(per_frame, series)}
    return evidence, (None if per_frame is None else np.r_[0.0, np.cumsum(per_frame)]), series


def static_rise(series) -> float | None:
    """How far the static flow's turn since the reference window went in its one ramp (deg,
    signed): the rise of the still → ramp → slower fit of ``series`` (N,) deg
    (:func:`analysis.slip_onset.knee`), 0 for a flat series, ``None`` without one (fewer than 8
    frames). A twist turns the stuck skin's pattern in one ramp until the skin breaks away; after
    that the pattern rides, drifts back or unloads, so its end value (``static_deg``, the median
    of the last fifth) can be well below how far it turned. A still touch's static turn wanders
    or drifts slowly, and its best ramp is no larger than that wander. A shape's height read by
    least squares, in the turn's own unit: the same threshold as the end value."""
    if series is None or len(series) < 8:
        return None
    k = knee(series)
    return float(k.rise) if k is not None else 0.0


def _peak_turn(per_frame, series, q: float = 90.0) -> float | None:
    """How far the pattern turned (deg, signed), not where it ended: the ``q``-th percentile of
    |the mean of the summed dynamic rotation and the static rotation since the reference|, frame
    by frame, with the sense of its largest excursion (the turn's analogue of
    ``slip_displacement_mm``). The decision reads it for a contact that stayed in place
    (:func:`turn`); for one that moved it would read more pulls as twists (docs/analysis.md)."""
    if per_frame is None or series is None:
        return None
    summed = np.r_[0.0, np.cumsum(per_frame)]
    n = min(len(summed), len(series))
    if n < 2:
        return None
    r = 0.5 * (summed[:n] + series[:n])
    k = int(np.argmax(np.abs(r)))
    return float(np.sign(r[k]) * np.percentile(np.abs(r), q))


def _direction(motion: dict, evidence: dict) -> tuple[float | None, float | None]:
    """Direction (deg) of the weighted unit vectors of the motion, the offset from the centroid and
    the negated unloaded static flow (module docstring), and their agreement (0..1)."""
    parts = []
    for name, w in DIRECTION_WEIGHTS.items():
        v = (motion if name == "motion" else evidence.get(name, {})).get("vector_mm")
        if v is None or not np.any(v):
            continue
        v = np.asarray(v, float) * (-1.0 if name == "static_unloaded" else 1.0)
        parts.append((w, v / np.hypot(*v)))
    if not parts:
        return None, None
    total = np.sum([w * u for w, u in parts], axis=0)
    agreement = float(np.hypot(*total) / sum(w for w, _ in parts))
    return (float(np.degrees(np.arctan2(total[1], total[0]))) if np.any(total) else None), agreement


def turn(displacement, rotation: dict, cfg) -> tuple[float | None, str]:
    """The turn about the pad normal the decision reads (deg, + = counter-clockwise seen from
    outside the pad) and which reading it is.

    ``"end"``: the dynamic and the static flows' end values averaged (``rotation["rotation_deg"]``).
    A contact that moved (its centre of pressure ``cfg.min_displacement_mm`` or more from its
    reference window) is always read so: a pull turns the rendered pattern by up to 0.7°/mm on
    the way (docs/analysis.md), and the two flows' opposite spurious turns halve in their end
    values. ``"static"``: for a contact that stayed in place, how far the static flow's rotation
    since the reference window went in its one ramp (``rotation["static_rise_deg"]``,
    :func:`static_rise`; ``static_deg``, its end value, where that is not given) where it reaches
    ``cfg.min_still_rotation_deg``:
    nothing pulled the contact, and at the shear the real contact frames allow a twist turns the
    pattern by a third of a degree to a degree — one comparison with the reference keeps it (16
    of 16 twists in the right sense on the SP grid at gain 3), while the frame-to-frame curl
    summed loses it in its noise (4 of 16) and averaging the two halves it (docs/analysis.md, "At
    the shear gain the real frames allow"). Otherwise, for a contact that stayed in place,
    ``"peak"``: how far the two flows' mean turned (``rotation["peak_deg"]``, the 90th
    percentile over the contact) where that reads more than the end values — a light twist's
    pattern can drift back once the object stops (a turn reached only in the contact's last
    frames is read fully by its end values); both held to ``cfg.min_rotation_deg``."""
    end = rotation.get("rotation_deg")
    peak = rotation.get("peak_deg")
    static = rotation.get("static_rise_deg", rotation.get("static_deg"))
    still = displacement is not None and math.isfinite(displacement) and displacement < cfg.min_displacement_mm
    if still and static is not None and math.isfinite(static) and abs(static) >= cfg.min_still_rotation_deg:
        return float(static), "static"
    if still and peak is not None and math.isfinite(peak) and (end is None or abs(peak) > abs(end)):
        return float(peak), "peak"
    return end, "end"


def classify(displacement, rotation: dict, radius_mm: float, agreement, cfg) -> tuple[str | None, float | None]:
    """``(slip_class, confidence)`` from the displacement since the reference window (mm), the
    rotation evidence (read by :func:`turn`), the contact's radius (mm) and the direction's
    agreement (module docstring); ``(None, None)`` without a displacement."""
    if displacement is None or not math.isfinite(displacement):
        return None, None
    d = displacement / max(cfg.min_displacement_mm, 1e-9)
    rot, reading = turn(displacement, rotation, cfg)
    least = cfg.min_still_rotation_deg if reading == "static" else cfg.min_rotation_deg
    turned = 0.0
    if rot is not None and math.isfinite(rot):
        turned = abs(rot) / max(least, 1e-9)
    arc = abs(rot or 0.0) * math.pi / 180.0 * max(radius_mm, 0.0)
    if turned >= 1.0 and arc >= cfg.arc_ratio * displacement:
        return "rotation", float(min(1.0, turned / 2.0))
    if d >= 1.0:
        return "translation", float(min(1.0, d / 2.0) * (agreement or 0.0))
    return "none", float(max(0.0, 1.0 - max(d, turned)))


def _onset(pm, end: int, turned, slip_class: str | None) -> dict | None:
    """The knee of the motion (:mod:`analysis.slip_onset`): the centre of pressure's travel along
    its direction for a translation (or a touch: reported as evidence only), the summed dynamic
    rotation for a rotation (the static flow's rotation since the reference for one read by its
    static turn whose summed curl turned the other way); frames relative to the reference
    window's first."""
    d = pm.displacement[:end]
    mag = np.hypot(d[:, 0], d[:, 1])
    if slip_class == "rotation" and turned is not None:
        signal, what = turned, "rotation"
    else:
        far = mag >= 0.5 * mag.max() if mag.max() > 0 else np.ones(len(mag), bool)
        u = d[far].mean(axis=0)
        n = float(np.hypot(*u))
        signal, what = (d @ (u / n) if n > 0 else mag), "displacement"
    k = knee(signal)
    if k is None:
        return None
    return {"signal": what, "motion_frame": k.motion, "slip_frame": k.slip,
            "uncertainty_frames": max(0.5, (k.slip_hi - k.slip_lo) / 2.0), "slowed": k.slowed,
            "rise": k.rise, "dated_by": "knee", "release_from": k.wide_lo}


def _release(when: dict, raw, n_ref: int, rate: float, along=None) -> None:
    """Date gross slip by the skin's release (in place in ``when``): when the whole contact breaks
    away, the stretch (or twist) the stuck skin had built up is let go at once and the traction
    (torque) falls to the kinetic level, so the electrode change the stuck skin made — loading
    ahead of the drag, unloading behind it; for a twist two opposite quadrants of the contact —
    falls back along its own pattern within a few frames (the first tooth of the stick-slip;
    ``tactile.slip``'s ``release`` criterion sees the same thing live). That pattern is
    ``along`` (n,) kΩ: the smoothed activation's change from the motion onset to the knee, less
    its part along the reference pattern (:func:`_shape_change`: a press that goes on loading
    the contact is not the stretch); the
    unsmoothed activation's change since the reference window is projected on it (without it:
    its total positive change, which sees only the loading side and little of a twist, whose
    loads and unloads nearly cancel), running-median filtered over 3 frames. The first fall
    after the motion onset, from a new high at least :data:`RELEASE_HEIGHT` of the way up to the
    window's highest, by at least :data:`RELEASE_SHARE` of the rise so far and
    :data:`RELEASE_NOISE` × its frame-to-frame noise (over the still frames up to the motion
    onset: a ratio to the signal's own noise, whatever the sensor's shear gain) marks it (a press that settles, or the
    holder's wander, lowers the load too, but not from the top of a stretch): the slip onset is
    the frame before the fall (uncertainty: the fall's length). Without such a fall the knee
    stands. A fall is a release only from ``when["release_from"]`` on, the knee's earliest slip
    onset at two standard errors: before it the motion went on at the stuck skin's pace, so the
    skin had not broken away (a faint twist's noise falls on the way up). For a translation a
    fall from within :data:`RELEASE_NEAR` of the rise below the running high counts too: a pull's
    stretch can ease off its high for a few frames before the skin breaks away (a firm pull on
    the cylinder), and its release is tens of times its noise; a faint twist's plateau wanders
    by its noise, so a twist's release is a fall from a new high."""
    ref = raw[:n_ref].mean(axis=0)
    along = _shape_change(along, ref)
    if along is not None:
        load = (raw - ref) @ (along / np.linalg.norm(along))
    else:
        load = np.clip(raw - ref, 0.0, None).sum(axis=1)
    if len(load) < 8:
        return
    smooth = _running_median3(load)
    start = when["motion_frame"]
    # the signal's own noise: its frame-to-frame steps while the contact was still (the reference
    # window and on to the motion onset; the window's 10 frames alone give a noise that is itself
    # ±25 % noisy, and a fall of 4 of them is then a frame or two of noise on a faint twist)
    still = max(start, n_ref) if n_ref > 2 else len(smooth) - 1
    steps = np.diff(smooth[:still + 1])
    noise = 1.4826 * float(np.median(np.abs(steps - np.median(steps)))) if len(steps) else 0.0
    horizon = min(len(smooth), when["slip_frame"] + int(round(RELEASE_AFTER_S * rate)) + 1)
    fall = max(1, int(round(RELEASE_FRAMES)))
    top = float(smooth[start:horizon].max()) - smooth[start]
    near = RELEASE_NEAR if when.get("signal") == "displacement" else 0.0
    earliest = when.get("release_from", 0)
    for i in range(max(start + 1, earliest - 1), horizon - 1):
        rise = smooth[i] - smooth[start]
        drop = smooth[i] - smooth[i + 1:i + 1 + fall].min()
        high = smooth[start:i + 1].max() - smooth[start]                  # the running high so far
        if rise >= RELEASE_HEIGHT * top > 0 and rise >= (1.0 - near) * high and \
                drop >= max(RELEASE_SHARE * rise, RELEASE_NOISE * noise):
            bottom = i + 1 + int(np.argmin(smooth[i + 1:i + 1 + fall]))
            when.update(slip_frame=i + 1, uncertainty_frames=max(1.0, float(bottom - i)), dated_by="release")
            return


def _shape_change(along, ref) -> np.ndarray | None:
    """``along`` (n,) kΩ less its part along the reference pattern ``max(ref, 0)`` (n,): a firmer
    or lighter press of the same shape is not a stretch (a tared press still settling after its
    reference window loads every electrode of the contact in proportion, and would otherwise be
    most of what a faint twist's pattern holds). ``None`` where nothing is left."""
    if along is None or not np.all(np.isfinite(along)) or not np.any(along):
        return None
    shape = np.clip(np.asarray(ref, float), 0.0, None)
    norm = float(np.linalg.norm(shape))
    if norm > 0 and np.all(np.isfinite(shape)):
        along = along - (along @ shape) / norm ** 2 * shape
    return along if np.linalg.norm(along) > 0 else None


def _running_median3(x: np.ndarray) -> np.ndarray:
    """``np.median`` of each frame's window ``x[i-1:i+2]`` (two values at either end), bit for
    bit as one ``np.median`` per frame, in one call over the interior windows."""
    if len(x) < 3:
        return np.array([np.median(x[max(0, i - 1):i + 2]) for i in range(len(x))])
    inner = np.median(np.stack([x[:-2], x[1:-1], x[2:]], axis=1), axis=1)
    return np.concatenate([[np.median(x[:2])], inner, [np.median(x[-2:])]])


RELEASE_SHARE = 0.1
RELEASE_HEIGHT = 0.5
RELEASE_NOISE = 4.0
RELEASE_FRAMES = 3
RELEASE_AFTER_S = 0.4
"""The release is looked for up to this long after the knee (the knee lands early on a partial slip)."""
RELEASE_NEAR = 0.1
"""A translation's release may fall from this fraction of its rise below the running high (:func:`_release`)."""



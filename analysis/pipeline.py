"""The analysis of one loaded run, in memory: contacts → flow → segments → aggregates → estimates.

:func:`analyse` is the whole computation (no files); :mod:`analysis.run` wraps it with loading,
writing, figures and scoring.
"""

from __future__ import annotations

import functools
import time as _time
from dataclasses import dataclass, field

import numpy as np

from tactile_flow.tactile import contact as tcontact
from tactile_flow.tactile import warmup

from . import estimates as est
from . import flows as fl
from . import labels as labelling
from . import segments as seg
from . import slip as slp
from .chunking import centre_of_pressure, finger_activation
from .config import for_sensor
from .load import RunData
from .preprocess import PreparedRun, prepare

_MODELS: dict = {}
EDGE_REACH_S = 0.2
"""How far (s) a contact's edge may move from where the smoothed score put it (tactile.contact.refine_edges)."""


def get_model(tactile_config, sensor=None):
    """The :class:`tactile.pipeline.TactileModel` for a config and a sensor model (default the
    BioTac SP), built once per process."""
    from tactile_flow.tactile.pipeline import TactileModel
    key = (repr(tactile_config), None if sensor is None else sensor.sha256)
    if key not in _MODELS:
        _MODELS[key] = TactileModel.build(tactile_config, sensor=sensor)
    return _MODELS[key]


@dataclass
class Analysis:
    """Everything computed for one run (see :mod:`analysis.results` for the stored layout)."""

    run: RunData
    prepared: PreparedRun
    scheme: str
    contacts: dict                       # finger → [(start, stop)]
    thresholds: dict                     # finger → pressure threshold
    extrema: dict                        # finger → seg.Extrema
    bumps: dict                          # finger → [[Bump per contact]]
    segments: list                       # [labelling.Segment] with ids
    skipped: list                        # [{"what", "finger", "reason", ...}]
    aggregates: list                     # rows: segment id, view, kind, values
    crossings: list                      # sweep estimates per crossing
    pour: dict                           # pour estimates (onsets in s per finger and overall)
    whole_run: list                      # rows: finger, view, kind, values
    flows: list                          # [fl.ContactFlow]
    contact_method: str = "pressure"     # how contacts were found: pressure | pattern
    slips: dict = field(default_factory=dict)   # segment id → slip estimate (analysis.slip.estimate)
    timing: dict = field(default_factory=dict)
    plateaus: dict = field(default_factory=dict)  # sweep: (finger, start, stop) → (texture's, width's) TaxelPlateaus


def contact_method(prepared: PreparedRun, cfg) -> str:
    """``analysis.contact.method`` resolved: ``auto`` is the pressure after a tare, the electrode
    pattern otherwise (no rest stretch to measure a pressure's noise on, or none at all)."""
    if cfg.contact.method != "auto":
        return cfg.contact.method
    return "pressure" if prepared.baseline.kind == "tare" else "pattern"


def static_views(cfg, scheme: str) -> tuple[str, ...]:
    """Views that get the static flow from the primary reference (besides the slip's evidence
    views, which get it from every reference): every view with ``analysis.flow.static=all`` and
    for a pour (its rotation phase is the static rotation averaged over the views); none
    otherwise: no sweep or generic estimate reads it."""
    if cfg.static_flow == "all" or scheme == labelling.POUR:
        return tuple(cfg.views)
    return ()


def _threshold(prepared: PreparedRun, k: int, cfg) -> float:
    s = cfg.segmentation
    floor = s.contact_min_pdc if prepared.pressure_name == "pdc" else s.contact_min_proxy
    if prepared.baseline.kind != "tare":
        # without a tare the rest level is only known up to the sensor's drift over the record
        floor *= cfg.baseline_fallback_contact_min / s.contact_min_pdc
    return max(s.contact_threshold_sigma * float(prepared.rest_noise[k]), floor)


def analyse(run: RunData, cfg, model=None) -> Analysis:
    """Run the whole computation on ``run`` with the validated config ``cfg`` (AnalysisConfig;
    views left unset are the run's sensor model's: :func:`analysis.config.for_sensor`)."""
    t_start = _time.perf_counter()
    if run.sensor is not None:
        cfg = for_sensor(cfg, run.sensor)
    model = model or get_model(cfg.tactile, run.sensor)
    if run.sensor is not None and model.n_taxels != run.n_taxels:
        raise ValueError(f"model: built for {model.n_taxels} taxels, the run has {run.n_taxels} "
                         f"(sensor {run.sensor.name}); build it with get_model(cfg.tactile, run.sensor)")
    s = cfg.segmentation
    rate = run.rate_hz
    T = len(run.time)
    scheme = labelling.scheme(run.labels)
    prepared = prepare(run, cfg, model, causal_proxy=scheme == labelling.POUR)
    t_prep = _time.perf_counter()
    skipped: list[dict] = []
    for group, why in run.missing.items():
        skipped.append({"what": f"group {group}", "reason": why})
    if run.status not in ("success", "unknown"):
        skipped.append({"what": "run", "reason": f"run status is {run.status!r}: only the recorded part "
                                                 f"({run.time[-1]:.2f} s) is analysed"})
    for f, why in prepared.unusable.items():
        skipped.append({"what": "finger", "finger": f, "reason": f"not analysed: {why}"})
    for f, n in prepared.repaired.items():
        skipped.append({"what": "samples", "finger": f, "frames": n,
                        "reason": "electrodes outside their usable counts (1..4094 on a BioTac) in these frames: "
                                  "bridged by interpolation"})
    for d in run.dropped:
        skipped.append({**d, "what": f"{d['frames']} {d['what']}"})
    method = contact_method(prepared, cfg)
    signal = {}                          # finger → (T,) the signal its contacts are found on
    contacts, thresholds, extrema, bumps = {}, {}, {}, {}
    for k, f in enumerate(run.fingers):
        if f in prepared.unusable:
            continue
        p = seg.smooth(prepared.pressure[:, k], rate, s.smooth_s)
        if method == "pattern":
            signal[f], thr = prepared.score[:, k], cfg.contact.threshold_sigma
        else:
            signal[f], thr = p.astype(prepared.pressure.dtype, copy=False), _threshold(prepared, k, cfg)
        ivs = seg.contact_intervals(signal[f], thr, rate, s.min_contact_s, s.merge_gap_s)
        if method == "pattern":
            reach = int(round(EDGE_REACH_S * rate))
            ivs = tcontact.refine_edges(ivs, prepared.fine_score[:, k], thr, reach)
        if not ivs:
            continue
        contacts[f], thresholds[f] = ivs, thr
        absolute = s.prominence_pdc if prepared.pressure_name == "pdc" else s.prominence_proxy
        rng = float(np.ptp(p))
        extrema[f] = seg.extrema(p, rate, max(absolute, s.prominence * rng), s.distance_s)
        bumps[f] = [seg.bumps(p, iv, extrema[f].peaks, s.plateau_level) for iv in ivs]
    if not contacts:
        skipped.append({"what": "run", "reason": "no finger in contact at any time: no segments, no flow"})
    plateaus: dict = {}
    if scheme == labelling.SWEEP:
        # the 'during' plateau is measured on the pad electrodes' sum (or the PDC with
        # width_signal=pdc): with width_signal=proxy the segment and the width estimate (plateau
        # duration x speed) describe the same stretch; with taxels the width is each electrode's
        # own plateau (estimates.feature_width_per_taxel), and so is the segment: it lasts as
        # long as the width's electrodes' median plateau (the boundaries and the width agree)
        wsig = prepared.pressure if cfg.estimates.width_signal == "pdc" else prepared.pad_proxy
        plateaus = _electrode_plateaus(run, cfg, prepared, bumps, rate)
        for f in bumps:
            k = run.fingers.index(f)
            ws = seg.smooth(wsig[:, k], rate, s.smooth_s)
            ps = seg.smooth(prepared.pressure[:, k], rate, s.smooth_s)
            bumps[f] = [[seg.replateau(ws, ps, b, s.plateau_level, _plateau_frames(plateaus.get((f, b.start, b.stop)),
                                                                                  cfg, rate))
                         for b in bl] for bl in bumps[f]]

    margin = int(round(s.margin_s * rate))
    plan = fl.FlowPlan(primary=fl.primary_reference(cfg.reference, prepared.baseline.kind),
                       reference_frame=None if cfg.reference_time_s is None else
                       int(np.searchsorted(run.time, cfg.reference_time_s)),
                       evidence_views=tuple(cfg.slip.views), static_views=static_views(cfg, scheme),
                       intensity=cfg.intensity, load_fraction=s.load_fraction, static_every=cfg.static_every)
    flows, flow_s = fl.compute(prepared, contacts, run.fingers, model, margin, signal, thresholds, s.settle_frames,
                               plan, keep_fields=cfg.save_fields, progress=cfg.progress,
                               workers=cfg.workers or warmup.available_cores())
    t_flow = _time.perf_counter()

    segments: list[labelling.Segment] = []
    pour: dict = {}
    if scheme == labelling.SWEEP:
        for f, ivs in contacts.items():
            segments += labelling.sweep_segments(f, T, ivs, bumps[f])
    elif scheme == labelling.POUR:
        pour = _pour(run, cfg, prepared, contacts, flows, segments, skipped, margin)
    else:
        for f, ivs in contacts.items():
            segments += labelling.generic_segments(f, T, ivs, run.labels)
    kept = []
    for sg in segments:
        if sg.frames() < 2:
            skipped.append({"what": f"segment {sg.label}", "finger": sg.finger, "feature": sg.feature,
                            "start_s": float(run.time[min(sg.start, T - 1)]), "frames": sg.frames(),
                            "reason": "shorter than two frames: no flow"})
            continue
        kept.append(sg)
    kept.sort(key=lambda x: (run.fingers.index(x.finger), x.start, x.stop))
    for i, sg in enumerate(kept):
        sg.id = i

    aggregates = _segment_aggregates(run, prepared, kept, contacts, flows, model, rate, skipped)
    slips = {}
    for sg in kept:
        k = run.fingers.index(sg.finger)
        est_ = slp.estimate(fl.find(flows, sg.finger, sg.start, sg.stop),
                            finger_activation(prepared.activation, k), sg.start, sg.stop, model, cfg.slip,
                            time=run.time, valid=None if run.valid is None else run.valid[:, k],
                            raw=finger_activation(prepared.raw_activation, k))
        if est_ is not None:
            slips[sg.id] = est_
    crossings = _crossings(run, cfg, prepared, bumps, plateaus, flows, model, rate, skipped) \
        if scheme == labelling.SWEEP else []
    whole = _whole_run(flows, model, rate)
    t_end = _time.perf_counter()
    timing = {"prepare_s": t_prep - t_start, "flow_s": flow_s, "flow_stage_s": t_flow - t_prep,
              "estimates_s": t_end - t_flow, "total_s": t_end - t_start,
              "frames_processed": int(sum(cf.window[1] - cf.window[0] for cf in flows)) * len(model.plans),
              "frames_total": T * len(run.fingers) * len(model.plans)}
    return Analysis(run, prepared, scheme, contacts, thresholds, extrema, bumps, kept, skipped, aggregates,
                    crossings, pour, whole, flows, method, slips, timing, plateaus)


# ----------------------------------------------------------------------------- aggregates

AGG_FIELDS = ("sensor_x", "sensor_y", "sensor_z", "magnitude", "direction", "curl", "divergence", "rotation",
              "confidence")


def _row(w) -> dict:
    return {"sensor_x": float(w["sensor"][0]), "sensor_y": float(w["sensor"][1]), "sensor_z": float(w["sensor"][2]),
            "magnitude": float(np.linalg.norm(w["sensor"])), "direction": w["direction"], "curl": w["curl"],
            "divergence": w["divergence"], "rotation": w["rotation"], "confidence": w["confidence"]}


def _segment_aggregates(run, prepared, segments, contacts, flows, model, rate, skipped) -> list[dict]:
    """Per segment: its centre of pressure (mean and displacement over its frames in contact:
    none for a no_contact, approach or lift stretch) and its flow aggregates per view."""
    rows = []
    for sg in segments:
        cf = fl.find(flows, sg.finger, sg.start, sg.stop)
        k = run.fingers.index(sg.finger)
        touching = [(max(a, sg.start), min(b, sg.stop)) for a, b in contacts.get(sg.finger, [])
                    if a < sg.stop and b > sg.start]
        cop = np.concatenate([centre_of_pressure(prepared.activation, k, a, b, model.taxels) for a, b in touching]
                             or [np.zeros((0, 3))])
        good = np.all(np.isfinite(cop), axis=1)
        cop_mean = cop[good].mean(axis=0) if good.any() else np.full(3, np.nan)
        cop_disp = cop[good][-1] - cop[good][0] if good.sum() > 1 else np.full(3, np.nan)
        base = {"segment": sg.id, "cop": cop_mean, "cop_displacement": cop_disp}
        if cf is None:
            if sg.label not in ("approach", "lift", "no_contact"):
                skipped.append({"what": f"flow of segment {sg.id} ({sg.label})", "finger": sg.finger,
                                "reason": "segment not inside a contact window: no tactile flow computed"})
            rows.append({**base, "flows": {}})
            continue
        per = {}
        for v in cf.views:
            for kind in ("dynamic", "static"):
                w = fl.window_summary(cf, v, sg.start, sg.stop, model, rate, kind)
                if w is not None:
                    per[(v, kind)] = _row(w)
        rows.append({**base, "flows": per})
    return rows


def _whole_run(flows, model, rate) -> list[dict]:
    """Per finger and view: the mean over all in-contact frames (dynamic and static)."""
    out = []
    fingers = list(dict.fromkeys(cf.finger for cf in flows))
    for f in fingers:
        for v in model.plans:
            for kind in ("dynamic", "static"):
                rows, weights = [], []
                for cf in flows:
                    if cf.finger != f:
                        continue
                    w = fl.window_summary(cf, v, cf.contact[0], cf.contact[1], model, rate, kind)
                    if w is not None:
                        rows.append(_row(w))
                        weights.append(cf.contact[1] - cf.contact[0])
                if rows:
                    wt = np.asarray(weights, float) / sum(weights)
                    out.append({"finger": f, "view": v, "kind": kind,
                                **{key: float(sum(r[key] * x for r, x in zip(rows, wt))) for key in AGG_FIELDS}})
    return out


# ----------------------------------------------------------------------------- estimates

def _speed(run):
    """(T,) TCP speed (mm/s) at the BioTac frames, or None without an arm record."""
    if run.arm_time is None or run.tcp_speed is None:
        return None
    return est.speed_mm_s(run.arm_time, run.tcp_speed, run.time)


def _electrode_plateaus(run, cfg, prepared, bumps, rate) -> dict:
    """(finger, bump start, bump stop) → (texture's, width's) plateaus of the pad electrodes that
    felt the crossing (:func:`estimates.taxel_plateaus`; ``None`` when nothing rose); empty
    without a TCP speed. The texture angle's are read on the activation, at texture_taxel_fraction;
    the width's on it less each electrode's share of the pad's load (width_load_fraction: the
    skin's stretch that outlasts the feature), at width_taxel_fraction."""
    e = cfg.estimates
    speed = _speed(run)
    if speed is None:
        return {}
    pad = run.sensor.pad if run.sensor is not None and run.sensor.pad is not None else slice(None)
    out = {}
    for f, per_contact in bumps.items():
        k = run.fingers.index(f)
        for bl in per_contact:
            for b in bl:
                act = seg.smooth(np.asarray(prepared.activation[b.start:b.stop, k], float)[:, pad], rate,
                                 cfg.segmentation.smooth_s)
                t, v = run.time[b.start:b.stop], speed[b.start:b.stop]
                out[(f, b.start, b.stop)] = (
                    est.taxel_plateaus(act, t, v, e.width_level, e.texture_taxel_fraction),
                    est.taxel_plateaus(act, t, v, e.width_level, e.width_taxel_fraction, e.width_load_fraction))
    return out


def _plateau_frames(read, cfg, rate) -> float | None:
    """How long (frames) a crossing's ``during`` lasts when widths are read per electrode: the
    median plateau of the width's electrodes (``read``: :func:`_electrode_plateaus`' pair);
    None (the pad sum's plateau) otherwise."""
    if cfg.estimates.width_signal != "taxels" or read is None or read[1] is None:
        return None
    return float(np.median(read[1].duration_s)) * rate


def _crossings(run, cfg, prepared, bumps, plateaus, flows, model, rate, skipped) -> list[dict]:
    """One row per feature crossed: direction (sensor, world), width, height, texture angle;
    ``plateaus``: :func:`_electrode_plateaus` of the crossings."""
    out = []
    e = cfg.estimates
    width_sig = prepared.pressure if e.width_signal == "pdc" else prepared.pad_proxy
    pad = run.sensor.pad if run.sensor is not None and run.sensor.pad is not None else slice(None)
    speed = _speed(run)
    for f, per_contact in bumps.items():
        k = run.fingers.index(f)
        feature = 0
        sig = seg.smooth(width_sig[:, k], rate, cfg.segmentation.smooth_s)
        for bl in per_contact:
            for b in bl:
                row = {"finger": f, "feature": feature, "peak_time": float(run.time[b.peak]),
                       "start_time": float(run.time[b.start]), "end_time": float(run.time[min(b.stop, len(run.time) - 1)]),
                       "plateau_start": float(run.time[b.plateau[0]]),
                       "plateau_end": float(run.time[min(b.plateau[1], len(run.time) - 1)]),
                       "height": b.height, "height_units": prepared.pressure_units}
                feature += 1
                cf = fl.find(flows, f, b.start, b.stop)
                d_s = np.full(3, np.nan)
                if cf is not None:
                    vec = fl.combined_direction(cf, b.start, b.stop, model, rate)
                    if np.linalg.norm(vec[:2]) > 0:
                        d_s = est.motion_direction_sensor(vec)
                        row["flow_px_per_frame"] = fl.combined_flow_px(cf, b.start, b.stop, model, rate)
                else:
                    skipped.append({"what": "direction", "finger": f, "feature": row["feature"],
                                    "reason": "no tactile flow over this crossing"})
                row["direction_sensor"] = d_s
                d_w = np.full(3, np.nan)
                tip = run.fingertip_rotvec(f)
                if run.tcp_pose is not None and tip is not None and np.all(np.isfinite(d_s)):
                    pose = est.pose_at(run.arm_time, run.tcp_pose, float(run.time[b.peak]))
                    d_w = est.unit(est.sensor_to_world(pose[3:], tip) @ d_s)
                elif np.all(np.isfinite(d_s)):
                    skipped.append({"what": "direction_world", "finger": f, "feature": row["feature"],
                                    "reason": "no arm pose or no fingertip pose in the run's config"})
                row["direction_world"] = d_w
                passing = None
                if speed is not None:
                    # read once (_electrode_plateaus): the texture's and the width's
                    passing, widths = plateaus.get((f, b.start, b.stop), (None, None))
                    if e.width_signal == "taxels":
                        width, dur, v, _ = est.width_from_plateaus(widths, speed[b.start:b.stop], e.min_speed_mm_s)
                    else:
                        width, dur, v = est.feature_width(sig, b, run.time, speed, cfg.segmentation.plateau_level,
                                                          e.min_speed_mm_s)
                    row.update(width_mm=width, plateau_s=dur, speed_mm_s=v)
                    if not np.isfinite(width):
                        skipped.append({"what": "width", "finger": f, "feature": row["feature"],
                                        "reason": f"TCP speed {v:.2f} mm/s below {e.min_speed_mm_s} mm/s"})
                else:
                    row.update(width_mm=float("nan"), plateau_s=float("nan"), speed_mm_s=float("nan"))
                    skipped.append({"what": "width", "finger": f, "feature": row["feature"],
                                    "reason": "no TCP speed recorded (arm group missing)"})
                ridge, why = None, None
                if e.texture_angle == "passing":
                    if passing is None:
                        why = "no TCP speed recorded" if speed is None else "no electrode rose over the crossing"
                    else:
                        ridge, unc, why = est.ridge_from_passing(passing, model.taxels[pad],
                                                                 e.texture_max_uncertainty_deg)
                        row["texture_angle_uncertainty_deg"] = unc
                elif cf is not None and "bottom" in cf.views:
                    vr = cf.views["bottom"]
                    ridge = est.ridge_axis(vr.frames[b.peak - cf.window[0]], model.plans["bottom"].mask,
                                           model.plans["bottom"])
                    why = None if ridge is not None else "the pressed region at the peak is round"
                else:
                    why = "no bottom view over this crossing"
                row["texture_angle_deg"] = est.texture_angle_deg(ridge, d_s)
                if why is not None:
                    skipped.append({"what": "texture_angle", "finger": f, "feature": row["feature"], "reason": why})
                out.append(row)
    for f in {r["finger"] for r in out}:
        rows = [r for r in out if r["finger"] == f]
        for r, rank in zip(rows, est.height_ranks([r["height"] for r in rows])):
            r["height_rank"] = int(rank)
    return out


def _shared_initial_slip(found, distance) -> int | None:
    """The bottle gives under every grasp finger at once: the initial slip's onset as the first
    fall most fingers share (:func:`segments.shared_first_drop`, each finger's fall in units of
    its own noise) between the latest pour start and the earliest full slip's edge, or None
    (each finger keeps its own first fall). ``found``: finger → (its phases, its pressure, ...)."""
    searched = [ph.slip_search for ph, *_ in found.values() if ph.slip_search is not None]
    if not searched:
        return None
    start, stop = max(s for s, _ in searched), min(e for _, e in searched)
    return seg.shared_first_drop([fast for _, fast, *_ in found.values()], start, stop, distance)


def _pour(run, cfg, prepared, contacts, flows, segments, skipped, margin) -> dict:
    """Pour phases per grasp finger (its longest contact) and the run's onsets (median)."""
    rate = run.rate_hz
    pour_event = reaction = None
    for t, name, _ in run.events.of_kind("pour"):
        pour_event = int(np.searchsorted(run.time, t))
        break
    for t, name, _ in run.events.of_kind("reaction"):
        reaction = int(np.searchsorted(run.time, t))
        break
    per_finger, not_reached, found = {}, {}, {}
    for f, ivs in contacts.items():
        k = run.fingers.index(f)
        ci = int(np.argmax([b - a for a, b in ivs]))
        a, b = ivs[ci]
        cf = fl.find(flows, f, a, b)
        rot = np.full(len(run.time), np.nan)
        ref = None
        if cf is not None and cf.reference is not None:
            ref = cf.settled
            parts = [cf.views[v].static for v in cf.views if cf.views[v].static is not None]
            if parts:
                curl = np.mean([p.curl for p in parts], axis=0) / 2.0
                rot[cf.window[0]:cf.window[1]] = seg.smooth(curl, rate, 0.5)
        p = seg.smooth(prepared.pad_proxy[:, k], rate, 0.5)
        if reaction is None:
            fast = seg.smooth(prepared.pad_proxy[:, k], rate, cfg.segmentation.smooth_s)
        else:
            # the grasp tightened right after the slip: a smoothed pressure would carry that rise
            # back over the slip's fall, so the slip is dated on the causal (filter-only) proxy
            fast = np.asarray(prepared.causal_proxy[:, k], float)
        phases = functools.partial(labelling.pour_phases, run.time, p, (a, b), ref, rot, pour_event,
                                   cfg.pour.rotation_noise_k, cfg.pour.trough_prominence,
                                   int(round(cfg.segmentation.distance_s * rate)), cfg.segmentation.plateau_level,
                                   fast=fast, reaction=reaction)
        found[f] = (phases(), fast, (a, b), ci, phases)
    shared = _shared_initial_slip(found, int(round(cfg.segmentation.distance_s * rate))) \
        if reaction is None and len(found) > 1 else None
    if shared is not None:                       # every finger's later phases follow the shared slip
        found = {f: (again(shared_slip=shared), fast, ab, ci, again)
                 for f, (_, fast, ab, ci, again) in found.items()}
    for f, (ph, fast, (a, b), ci, _) in found.items():
        for name, why in ph.reasons.items():
            skipped.append({"what": f"phase {name}", "finger": f, "reason": why})
        if ph.not_reached:                        # a result (the grasp held), not a skipped estimate
            not_reached[f] = dict(ph.not_reached)
        segments += labelling.pour_segments(f, len(run.time), ph, (a, b), ci, margin)
        per_finger[f] = {n: (float(run.time[i]) if i is not None else None) for n, i in ph.onsets.items()}
    overall = {}
    for n in labelling.POUR_PHASES:
        vals = [v[n] for v in per_finger.values() if v.get(n) is not None]
        overall[n] = float(np.median(vals)) if vals else None
    return {"onsets": overall, "per_finger": per_finger, "not_reached": not_reached,
            "gravity_sensor": None if run.gravity_sensor() is None else run.gravity_sensor().tolist()}

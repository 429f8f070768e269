"""Labelled results: the ``analysis.zarr`` tree and the JSON of ``summary.json`` (where they go:
:mod:`runstore.analyses`).

Layout of ``analysis.zarr`` (beside ``run.zarr``; docs/analysis.md):

- ``/segments`` (segment): ``label``, ``finger``, ``start``, ``end`` (s), ``start_index``,
  ``stop_index`` (BioTac frames), ``feature`` (crossing index, −1), ``frames``;
- ``/aggregates`` (segment, view, kind) with kind = dynamic | static: ``sensor_x/y/z`` (mean flow
  in the sensor frame, mm/s dynamic, mm static), ``magnitude``, ``direction`` (image angle, rad),
  ``curl``, ``divergence``, ``rotation`` (rad/s dynamic, rad static), ``confidence``; and
  (segment, axis3) ``cop`` (mm), ``cop_displacement`` (mm);
- ``/whole_run`` (finger, view, kind): the same over all in-contact frames;
- ``/estimates/crossings`` (crossing): direction in the sensor and world frame, width, height,
  rank, texture angle; ``/estimates/pour`` (phase): onset times;
- ``/fields`` (optional, ``save_fields=true``): flow fields per contact window.

Root attributes: ``analysis_id``, ``provenance`` (config, code version, input checksum).
"""

from __future__ import annotations

import json
import math

import numpy as np

from tactile_flow.runstore.labelled import Dataset, Tree, Variable

from .pipeline import AGG_FIELDS, Analysis

KINDS = ("dynamic", "static")


def _clean(x):
    """JSON-ready: numpy → python, NaN → None."""
    if isinstance(x, dict):
        return {str(k): _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_clean(v) for v in x]
    if isinstance(x, np.ndarray):
        return _clean(x.tolist())
    if isinstance(x, (np.floating, float)):
        v = float(x)
        return None if not math.isfinite(v) else v
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x


def _var(values, dims, units, long_name) -> Variable:
    return Variable(tuple(dims), values, {"units": units, "long_name": long_name})


def to_tree(a: Analysis, views: list[str], attrs: dict, fields: bool = False) -> Tree:
    """The analysis as a :data:`~runstore.labelled.Tree` (see module doc), written by
    :func:`~runstore.labelled.write_tree` and read back by ``xarray.open_datatree``."""
    t = a.run.time
    T = len(t)
    segs = a.segments
    n = len(segs)
    seg_ds = Dataset(
        {"label": _var(np.array([s.label for s in segs], dtype=str), ("segment",), "", "segment label"),
         "finger": _var(np.array([s.finger for s in segs], dtype=str), ("segment",), "", "finger"),
         "start": _var(np.array([t[s.start] for s in segs], float), ("segment",), "s", "segment start since run start"),
         "end": _var(np.array([t[s.stop - 1] + 1.0 / a.run.rate_hz if s.stop >= T else t[s.stop] for s in segs], float),
                     ("segment",), "s", "segment end since run start"),
         "start_index": _var(np.array([s.start for s in segs], np.int64), ("segment",), "1", "first BioTac frame"),
         "stop_index": _var(np.array([s.stop for s in segs], np.int64), ("segment",), "1", "BioTac frame after the last"),
         "feature": _var(np.array([s.feature for s in segs], np.int64), ("segment",), "1",
                         "index of the feature crossed (-1: none)"),
         "frames": _var(np.array([s.frames() for s in segs], np.int64), ("segment",), "1", "frames in the segment")},
        coords={"segment": np.arange(n, dtype=np.int64)})
    agg = {f: np.full((n, len(views), 2), np.nan) for f in AGG_FIELDS}
    cop = np.full((n, 3), np.nan)
    disp = np.full((n, 3), np.nan)
    for row in a.aggregates:
        i = row["segment"]
        cop[i], disp[i] = row["cop"], row["cop_displacement"]
        for (v, kind), vals in row["flows"].items():
            if v in views:
                for f in AGG_FIELDS:
                    agg[f][i, views.index(v), KINDS.index(kind)] = vals[f]
    units = {"sensor_x": "mm s-1 (dynamic), mm (static)", "sensor_y": "mm s-1 (dynamic), mm (static)",
             "sensor_z": "mm s-1 (dynamic), mm (static)", "magnitude": "mm s-1 (dynamic), mm (static)",
             "direction": "rad", "curl": "px frame-1 px-1 (dynamic), 1 (static)",
             "divergence": "px frame-1 px-1 (dynamic), 1 (static)", "rotation": "rad s-1 (dynamic), rad (static)",
             "confidence": "1"}
    names = {"sensor_x": "mean flow, sensor x", "sensor_y": "mean flow, sensor y", "sensor_z": "mean flow, sensor z",
             "magnitude": "magnitude of the mean flow", "direction": "direction of the mean flow in the image",
             "curl": "mean curl", "divergence": "mean divergence", "rotation": "rotation (curl / 2)",
             "confidence": "fraction of footprint pixels moving"}
    agg_ds = Dataset({f: _var(agg[f], ("segment", "view", "kind"), units[f], names[f]) for f in AGG_FIELDS},
                     coords={"segment": np.arange(n, dtype=np.int64), "view": np.array(views, dtype=str),
                             "kind": np.array(KINDS, dtype=str), "axis3": np.array(["x", "y", "z"], dtype=str)})
    agg_ds.data_vars["cop"] = _var(cop, ("segment", "axis3"), "mm", "centre of pressure (sensor frame)")
    agg_ds.data_vars["cop_displacement"] = _var(disp, ("segment", "axis3"), "mm",
                                                "centre-of-pressure displacement over the segment")
    fingers = sorted({r["finger"] for r in a.whole_run}, key=a.run.fingers.index)
    whole = {f: np.full((len(fingers), len(views), 2), np.nan) for f in AGG_FIELDS}
    for r in a.whole_run:
        if r["view"] in views:
            for f in AGG_FIELDS:
                whole[f][fingers.index(r["finger"]), views.index(r["view"]), KINDS.index(r["kind"])] = r[f]
    whole_ds = Dataset({f: _var(whole[f], ("finger", "view", "kind"), units[f], names[f] + " (all in-contact frames)")
                        for f in AGG_FIELDS},
                       coords={"finger": np.array(fingers, dtype=str), "view": np.array(views, dtype=str),
                               "kind": np.array(KINDS, dtype=str)})
    cr = a.crossings
    m = len(cr)
    get = lambda k: np.array([c.get(k, np.nan) for c in cr], float)  # noqa: E731
    cr_ds = Dataset(
        {"finger": _var(np.array([c["finger"] for c in cr], dtype=str), ("crossing",), "", "finger"),
         "feature": _var(np.array([c["feature"] for c in cr], np.int64), ("crossing",), "1", "feature index (order crossed)"),
         "peak_time": _var(get("peak_time"), ("crossing",), "s", "time of the pressure peak"),
         "plateau_start": _var(get("plateau_start"), ("crossing",), "s", "start of the pressure plateau"),
         "plateau_end": _var(get("plateau_end"), ("crossing",), "s", "end of the pressure plateau"),
         "direction_sensor": _var(np.array([c["direction_sensor"] for c in cr], float).reshape(m, 3),
                                  ("crossing", "axis3"), "1", "direction of motion of the finger, sensor frame"),
         "direction_world": _var(np.array([c["direction_world"] for c in cr], float).reshape(m, 3),
                                 ("crossing", "axis3"), "1", "direction of motion of the finger, world (base) frame"),
         "width": _var(get("width_mm"), ("crossing",), "mm", "feature width (plateau duration x TCP speed)"),
         "plateau_duration": _var(get("plateau_s"), ("crossing",), "s", "plateau duration"),
         "tcp_speed": _var(get("speed_mm_s"), ("crossing",), "mm s-1", "TCP speed over the plateau"),
         "height": _var(get("height"), ("crossing",), a.prepared.pressure_units, "pressure peak height above rest"),
         "height_rank": _var(np.array([c.get("height_rank", -1) for c in cr], np.int64), ("crossing",), "1",
                             "rank of the peak height among the finger's features (1 = highest)"),
         "texture_angle": _var(get("texture_angle_deg"), ("crossing",), "degree",
                               "angle between the feature's ridge and the direction of motion")},
        coords={"crossing": np.arange(m, dtype=np.int64), "axis3": np.array(["x", "y", "z"], dtype=str)})
    tree = {"/": Dataset(attrs=attrs), "/segments": seg_ds, "/aggregates": agg_ds, "/whole_run": whole_ds,
            "/estimates/crossings": cr_ds, "/estimates/slip": slip_dataset(a)}
    if a.pour:
        phases = list(a.pour["onsets"])
        tree["/estimates/pour"] = Dataset(
            {"onset": _var(np.array([np.nan if a.pour["onsets"][p] is None else a.pour["onsets"][p] for p in phases]),
                           ("phase",), "s", "phase onset (median over grasp fingers)")},
            coords={"phase": np.array(phases, dtype=str)})
    if fields:
        for i, cf in enumerate(a.flows):
            for v, vr in cf.views.items():
                ds = Dataset({"frames": _var(vr.frames, ("time", "row", "col"), "1", "tactile frame (0..255)")},
                             coords={"time": t[cf.window[0]:cf.window[1]]},
                             attrs={"finger": cf.finger, "view": v})
                if vr.dynamic_field is not None:
                    ds.data_vars["dynamic"] = _var(vr.dynamic_field, ("time", "row", "col", "component"),
                                                   "px frame-1", "dynamic flow (col, row)")
                if vr.static_field is not None:
                    ds.data_vars["static"] = _var(vr.static_field, ("time", "row", "col", "component"), "px",
                                                  "static flow (col, row)")
                tree[f"/fields/{cf.finger}_{i}_{v}"] = ds
    return tree


EVIDENCE = ("static_unloaded", "static_onset", "dynamic", "cop_unloaded", "cop_onset")


def slip_dataset(a: Analysis) -> Dataset:
    """``/estimates/slip`` (segment): the slip estimate of every segment that has one, with the
    evidence vectors beside it (see :mod:`analysis.slip`)."""
    ids = sorted(a.slips)
    rows = [a.slips[i] for i in ids]
    num = lambda k: np.array([np.nan if r[k] is None else r[k] for r in rows], float)  # noqa: E731
    ev = np.full((len(rows), len(EVIDENCE), 2), np.nan)
    ev_rot = np.full((len(rows), 2), np.nan)
    for i, r in enumerate(rows):
        for j, name in enumerate(EVIDENCE):
            v = r["evidence"].get(name, {}).get("vector_mm")
            if v is not None:
                ev[i, j] = v
        for j, name in enumerate(("static_onset", "dynamic")):
            rot = r["evidence"].get(name, {}).get("rotation_deg")
            ev_rot[i, j] = np.nan if rot is None else rot
    return Dataset(
        {"slip_class": _var(np.array([r["slip_class"] or "" for r in rows], dtype=str), ("segment",), "",
                            "translation | rotation | none (touch)"),
         "slip_direction_sensor": _var(num("slip_direction_sensor_deg"), ("segment",), "degree",
                                       "direction the object moves relative to the finger (0 = +x, 90 = +y)"),
         "slip_displacement": _var(num("slip_displacement_mm"), ("segment",), "mm",
                                   "displacement of the contact pattern from its reference (tactile flow)"),
         "rotation": _var(num("rotation_deg"), ("segment",), "degree",
                          "rotation of the pattern about the pad normal, + counter-clockwise seen from outside"),
         "confidence": _var(num("confidence"), ("segment",), "1", "confidence of slip_class"),
         "slip_onset": _var(num("slip_onset_s"), ("segment",), "s",
                            "when the skin broke away and the contact slipped (NaN: a touch, or undecided)"),
         "slip_onset_uncertainty": _var(num("slip_onset_uncertainty_s"), ("segment",), "s",
                                        "half-width of the slip onset's interval"),
         "direction_agreement": _var(num("direction_agreement"), ("segment",), "1",
                                     "agreement of the direction evidence (1: all agree)"),
         "reference": _var(np.array([r["reference"] for r in rows], dtype=str), ("segment",), "",
                           "reference of the displacement: contact_onset | unloaded"),
         "evidence": _var(ev, ("segment", "source", "axis2"), "mm", "evidence vectors, sensor x-y"),
         "evidence_rotation": _var(ev_rot, ("segment", "rotation_source"), "degree",
                                   "rotation evidence: static flow from the onset, dynamic flow summed")},
        coords={"segment": np.array(ids, dtype=np.int64), "source": np.array(EVIDENCE, dtype=str),
                "axis2": np.array(["x", "y"], dtype=str),
                "rotation_source": np.array(["static_onset", "dynamic"], dtype=str)})


def dumps(obj) -> str:
    return json.dumps(_clean(obj), indent=2, sort_keys=False, allow_nan=False) + "\n"

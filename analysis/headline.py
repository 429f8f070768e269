"""The headline of an analysis: the few numbers ``summary.json`` leads with, from an
:class:`~analysis.pipeline.Analysis` and its score."""

from __future__ import annotations

import math

import numpy as np


def headline(a, score: dict | None) -> dict:
    """The numbers a researcher reads first (``summary.json``'s ``headline``): segments, contact,
    crossings (width, direction, texture angle), the pour's onsets, each finger's slip, and on
    simulated runs the score's summary. ``a``: the :class:`~analysis.pipeline.Analysis`."""
    h = {"segments": len(a.segments), "skipped": len(a.skipped),
         "fingers_in_contact": len(a.contacts), "status": "ok" if a.contacts else "no_contact"}
    if a.crossings:
        h["crossings"] = len(a.crossings)
        widths = [c["width_mm"] for c in a.crossings if math.isfinite(c.get("width_mm", float("nan")))]
        h["width_mm_median"] = float(np.median(widths)) if widths else None
        d = np.array([c["direction_sensor"] for c in a.crossings], float)
        d = d[np.all(np.isfinite(d), axis=1)]
        if len(d):
            m = d.mean(axis=0)
            h["direction_sensor_deg"] = float(np.degrees(np.arctan2(m[1], m[0])))
        ang = [c["texture_angle_deg"] for c in a.crossings if math.isfinite(c.get("texture_angle_deg", float("nan")))]
        h["texture_angle_deg_median"] = float(np.median(ang)) if ang else None
    if a.pour:
        for k, v in a.pour["onsets"].items():
            h[f"onset_{k}_s"] = v
    slips = whole_contact_slips(a)
    if slips:
        h["slip"] = {f: {k: e[k] for k in ("slip_class", "slip_direction_sensor_deg", "slip_displacement_mm",
                                           "rotation_deg", "confidence")} for f, e in slips.items()}
    if score:
        s = score["summary"]
        for k in ("direction_correct_fraction", "width_error_mm_median", "boundary_error_mm_median",
                  "boundary_error_ms_median",
                  "slip_onset_error_ms", "slip_direction_correct_fraction", "rotation_sense_correct_fraction",
                  "touch_vs_slip_correct_fraction", "slip_class_correct_fraction"):
            if s.get(k) is not None:
                h[f"score_{k}"] = s[k]
        h["score_all_targets_met"] = score.get("all_targets_met")
    return h


def whole_contact_slips(a) -> dict:
    """Finger → the slip estimate of its whole contact: the ``all`` segment (imported records and
    other generic protocols), else its longest ``contact`` segment; fingers without either are left out."""
    out = {}
    for label in ("contact", "all"):
        for sg in sorted(a.segments, key=lambda x: x.frames()):
            if sg.label == label and sg.id in a.slips:
                out[sg.finger] = a.slips[sg.id]
    return out

"""The headline of an analysis: the few numbers ``summary.json`` leads with, from an
:class:`~analysis.pipeline.Analysis` and its score (every field and its unit: docs/analysis.md).

Directions are averaged only where they belong together: the crossings are grouped by the
heading the finger moved in (the arm's TCP velocity at each crossing, or where the arm was not
recorded the estimated direction itself), and each group gets its circular mean and spread. A
sweep across a board and back reports both headings; the vector mean of the two, which points
nowhere the finger went, is never reported."""

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
        groups = direction_groups(a)
        h["direction_groups"] = groups
        if len(groups) == 1:
            h["direction_sensor_deg"] = groups[0]["direction_sensor_deg"]
        ang = [c["texture_angle_deg"] for c in a.crossings if math.isfinite(c.get("texture_angle_deg", float("nan")))]
        h["texture_angle_deg_median"] = float(np.median(ang)) if ang else None
    if a.pour:
        for k, v in a.pour["onsets"].items():
            h[f"onset_{k}_s"] = v
    slips = whole_contact_slips(a)
    if slips:
        h["slip"] = {f: {k: e.get(k) for k in HEADLINE_SLIP_KEYS} for f, e in slips.items()}
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


HEADLINE_SLIP_KEYS = ("slip_class", "slip_direction_sensor_deg", "slip_displacement_mm", "rotation_deg",
                      "confidence", "slip_onset_s", "reason")
SAME_HEADING_DEG = 45.0
"""Crossings whose headings are closer than this share a group (a sweep's heading is constant;
a there-and-back sweep's two are 180° apart)."""


def circular_mean_deg(angles_deg) -> tuple[float | None, float | None]:
    """``(mean, spread)`` of angles (deg): the direction of the mean unit vector and the circular
    standard deviation √(−2 ln R̄) (deg; R̄ the mean resultant length: 0 for angles that agree);
    ``(None, None)`` for none, the mean ``None`` if they cancel."""
    a = np.radians(np.asarray(angles_deg, float))
    a = a[np.isfinite(a)]
    if not len(a):
        return None, None
    c, s = float(np.cos(a).mean()), float(np.sin(a).mean())
    r = math.hypot(c, s)
    if r < 1e-9:
        return None, None
    return float(np.degrees(math.atan2(s, c))), float(np.degrees(math.sqrt(max(-2.0 * math.log(min(r, 1.0)), 0.0))))


def _angle_between(a_deg: float, b_deg: float) -> float:
    return abs((a_deg - b_deg + 180.0) % 360.0 - 180.0)


def crossing_headings(a) -> list[float | None]:
    """The heading (deg, world x–y plane) the finger moved in at each crossing's peak: the arm's
    TCP velocity; ``None`` where the arm was not recorded or stood still."""
    run = a.run
    if run.arm_time is None or run.tcp_speed is None or not len(run.arm_time):
        return [None] * len(a.crossings)
    out = []
    for c in a.crossings:
        i = int(np.clip(np.searchsorted(run.arm_time, c["peak_time"]), 0, len(run.arm_time) - 1))
        v = np.asarray(run.tcp_speed[i][:2], float)
        out.append(float(np.degrees(math.atan2(v[1], v[0]))) if np.hypot(*v) > 1e-6 else None)
    return out


def direction_groups(a) -> list[dict]:
    """The crossings grouped by heading (module docstring), in order of first crossing: for each,
    ``heading_world_deg`` (the group's circular mean TCP heading, or ``None`` when grouped by the
    estimate), ``crossings`` (how many), ``direction_sensor_deg`` (circular mean of their
    estimated directions of motion, sensor x–y plane) and ``direction_spread_deg`` (their
    circular standard deviation)."""
    headings = crossing_headings(a)
    dirs = []
    for c in a.crossings:
        d = np.asarray(c["direction_sensor"], float)
        dirs.append(float(np.degrees(math.atan2(d[1], d[0]))) if np.all(np.isfinite(d[:2])) else None)
    by_arm = any(h is not None for h in headings)
    keys = headings if by_arm else dirs
    groups: list[dict] = []
    for key, d in zip(keys, dirs):
        if key is None:
            continue
        for g in groups:
            if _angle_between(key, g["_key"]) < SAME_HEADING_DEG:
                g["_keys"].append(key)
                g["_dirs"].append(d)
                g["_key"] = circular_mean_deg(g["_keys"])[0]
                break
        else:
            groups.append({"_key": key, "_keys": [key], "_dirs": [d]})
    out = []
    for g in groups:
        mean, spread = circular_mean_deg([d for d in g["_dirs"] if d is not None])
        out.append({"heading_world_deg": circular_mean_deg(g["_keys"])[0] if by_arm else None,
                    "crossings": len(g["_dirs"]), "direction_sensor_deg": mean, "direction_spread_deg": spread})
    return out


def whole_contact_slips(a) -> dict:
    """Finger → the slip estimate of its whole contact: the ``all`` segment (imported records and
    other generic protocols), else its longest ``contact`` segment. A finger set aside as unusable
    (saturated, dead) gets an estimate of nulls with the reason; fingers without a contact are
    left out."""
    out = {}
    for label in ("contact", "all"):
        for sg in sorted(a.segments, key=lambda x: x.frames()):
            if sg.label == label and sg.id in a.slips:
                out[sg.finger] = a.slips[sg.id]
    for f, why in getattr(a.prepared, "unusable", {}).items():
        out[f] = {**{k: None for k in NULL_SLIP_KEYS}, "reason": f"finger not analysed: {why}", "evidence": {}}
    return out


NULL_SLIP_KEYS = ("slip_direction_sensor_deg", "slip_displacement_mm", "rotation_deg", "slip_class", "confidence",
                  "direction_agreement", "slip_onset_s", "slip_onset_uncertainty_s", "reference", "reference_s",
                  "begins_in_contact")

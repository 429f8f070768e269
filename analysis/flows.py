"""Tactile frames and flow for every finger in contact, only over its contacts (plus margins).

For each contact window [start − margin, stop + margin) of a finger and each configured view,
:func:`tactile.pipeline.process_view` renders the frames and computes the dynamic flow and the
static flow from the frame where the contact became established
(:func:`tactile.flow.contact_reference`). Frames out of contact are never rendered.
"""

from __future__ import annotations

import time as _time
from dataclasses import dataclass, field

import numpy as np

from tactile import aggregate as tagg
from tactile import flow as tflow
from tactile.pipeline import ViewResult, process_view


@dataclass
class ContactFlow:
    """The flow of one finger over one contact window.

    Attributes:
        finger: finger name; ``k``: its index in the run.
        contact: (start, stop) frame indices of the contact itself.
        window: (w0, w1) frames processed (contact plus margins), absolute indices.
        reference: absolute frame index of the static-flow reference (contact established) or None.
        views: view name → :class:`tactile.pipeline.ViewResult` (indices relative to ``w0``).
    """

    finger: str
    k: int
    contact: tuple[int, int]
    window: tuple[int, int]
    reference: int | None
    views: dict[str, ViewResult] = field(default_factory=dict)

    def covers(self, start: int, stop: int) -> bool:
        return self.window[0] <= start and stop <= self.window[1]


def compute(prepared, contacts: dict[str, list[tuple[int, int]]], fingers: list[str], model, margin: int,
            threshold: dict[str, float], settle: int, keep_fields: bool = False, progress: bool = True):
    """Flow for every (finger, contact). Returns (list of ContactFlow, seconds spent in flow+render).

    ``contacts``: finger → contact intervals; ``threshold``: finger → pressure threshold used
    for the static reference.
    """
    from tqdm import tqdm
    views = list(model.plans)
    T = prepared.activation.shape[0]
    jobs = []
    for f, ivs in contacts.items():
        k = fingers.index(f)
        for a, b in ivs:
            jobs.append((f, k, (a, b), (max(0, a - margin), min(T, b + margin))))
    total = sum((w1 - w0) * len(views) for *_, (w0, w1) in jobs)
    bar = tqdm(total=total, unit="frame", desc="tactile flow", leave=False, disable=not progress or total == 0,
               dynamic_ncols=True)
    out, spent = [], 0.0
    try:
        for f, k, (a, b), (w0, w1) in jobs:
            act = prepared.activation[w0:w1, k]
            ref = None
            try:
                ref = w0 + tflow.contact_reference(prepared.pressure[w0:w1, k], threshold[f],
                                                   settle=min(settle, max(1, b - a)))
            except ValueError:
                ref = None
            cf = ContactFlow(f, k, (a, b), (w0, w1), ref)
            t0 = _time.perf_counter()
            for v in views:
                cf.views[v] = process_view(model, act, v, reference=None if ref is None else ref - w0,
                                           keep_fields=keep_fields, progress=bar.update)
            spent += _time.perf_counter() - t0
            out.append(cf)
    finally:
        bar.close()
    return out, spent


def find(flows: list[ContactFlow], finger: str, start: int, stop: int) -> ContactFlow | None:
    """The contact window of ``finger`` that covers frames [start, stop)."""
    for cf in flows:
        if cf.finger == finger and cf.covers(start, stop):
            return cf
    return None


def window_summary(cf: ContactFlow, view: str, start: int, stop: int, model, rate_hz: float,
                   kind: str = "dynamic") -> dict | None:
    """Aggregates of frames [start, stop) (absolute) of one view, with the mean vector in the
    sensor frame: mm/s for the dynamic flow, mm for the static flow. ``None`` if unavailable."""
    vr = cf.views.get(view)
    if vr is None:
        return None
    agg = vr.dynamic if kind == "dynamic" else vr.static
    if agg is None:
        return None
    s, e = start - cf.window[0], stop - cf.window[0]
    if kind == "dynamic":
        s = max(s, 1)            # dynamic flow of the window's first frame is zero by construction
    if not 0 <= s < e <= len(agg.magnitude):
        return None
    w = tagg.window(agg, s, e)
    plan = model.plans[view]
    scale = plan.mm_per_px * (rate_hz if kind == "dynamic" else 1.0)
    vec = plan.image_to_sensor(np.array([w["mean_col"], w["mean_row"]])) * scale
    w["sensor"] = vec                         # (3,) mm/s or mm
    w["units"] = "mm s-1" if kind == "dynamic" else "mm"
    # curl of a displacement field is twice the rotation angle (rad), of a velocity field 2ω (per frame)
    w["rotation"] = w["curl"] / 2.0 * (rate_hz if kind == "dynamic" else 1.0)
    return w


def combined_direction(cf: ContactFlow, start: int, stop: int, model, rate_hz: float):
    """Confidence-weighted sum over views of the dynamic mean flow in the sensor frame (3,) mm/s."""
    total = np.zeros(3)
    for v in cf.views:
        w = window_summary(cf, v, start, stop, model, rate_hz, "dynamic")
        if w is not None:
            total += w["sensor"] * max(w["confidence"], 1e-3)
    return total

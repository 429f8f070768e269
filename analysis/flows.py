"""Tactile frames and flow for every finger in contact, only over its contacts (plus margins).

For each contact window [start − margin, stop + margin) of a finger and each configured view,
:func:`tactile.pipeline.process_view` renders the frames and computes the dynamic flow and
the static flow from the run's primary reference (``analysis.flow.reference``):

- ``contact_onset``: the frame where the contact became established: settled above its
  threshold (:func:`tactile.flow.contact_reference` on the contact signal) and loaded to
  ``segmentation.load_fraction`` of its median load (:func:`tactile.flow.loaded_reference` on
  the contact score: the most pressed taxel's change, free of drift and of the far field's
  rise) — the default of a run with a tare, whose contacts begin inside the record; in a
  record that begins in contact, its first settled frame;
- ``unloaded``: the sensor at rest (zero activation, an empty frame) — the default without a
  tare: a record that begins in contact has no onset, and the pattern's offset from the
  unloaded state is what carries a slip's direction there;
- ``time``: the frame at ``analysis.flow.reference_time_s``.

The static flow is computed only where an estimate reads it (``analysis.flow.static: auto``):
the views of the slip estimate (``analysis.slip.views``) get it from every available reference,
as evidence, and a pour's rotation phase reads the primary reference's rotation in every view;
the crossings of a sweep read the dynamic flow alone. ``analysis.flow.static: all`` computes the
primary static flow in every view (their ``static`` aggregates in ``summary.json``) as well.

``workers`` threads run the (contact window, view) jobs at once: rendering (numba, ``nogil``)
and OpenCV's flow release the GIL, and every job is independent and written to its own slot,
so the results are the same, bit for bit, with any number of workers. Frames out of contact are never rendered. Intensity
(``analysis.tactile.intensity_range``): ``contact`` maps 0 kΩ … the window's peak activation
to 0 … 255, so a light contact uses the whole 8-bit range as a firm one does (Farnebäck's
estimate shrinks with the image's contrast: at 1/50 of full scale it reports 2 % of a
blob's true shift); a fixed ``[low, high]`` maps the same kΩ to the same grey in every window.
"""

from __future__ import annotations

import time as _time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from tactile_flow.tactile import aggregate as tagg
from tactile_flow.tactile import flow as tflow
from tactile_flow.tactile.pipeline import UNLOADED, ViewResult, process_view

ONSET, TIME = "contact_onset", "time"
MIN_PEAK_KOHM = 0.1
"""Smallest top of a contact window's intensity range (kΩ): noise alone is never stretched to full scale."""


@dataclass
class ContactFlow:
    """The flow of one finger over one contact window.

    Attributes:
        finger: finger name; ``k``: its index in the run.
        contact: (start, stop) frame indices of the contact itself.
        window: (w0, w1) frames processed (contact plus margins), absolute indices.
        reference: absolute frame index where the contact became established (settled and
            loaded: the static-flow reference ``contact_onset``), or None.
        settled: absolute frame index where the contact first settled above its threshold.
        begins_in_contact: the record is already in contact at its first frame (there is no
            onset to see: ``reference`` is then only the first settled frame).
        views: view name → :class:`tactile.pipeline.ViewResult` (indices relative to ``w0``).
    """

    finger: str
    k: int
    contact: tuple[int, int]
    window: tuple[int, int]
    reference: int | None
    settled: int | None = None
    begins_in_contact: bool = False
    views: dict[str, ViewResult] = field(default_factory=dict)

    def covers(self, start: int, stop: int) -> bool:
        return self.window[0] <= start and stop <= self.window[1]


@dataclass(frozen=True)
class FlowPlan:
    """What :func:`compute` computes: the primary static reference and the extra evidence.

    ``primary``: ``contact_onset``, ``unloaded`` or ``time``; ``reference_frame``: absolute
    frame of the ``time`` reference; ``evidence_views``: views that get the static flow from
    every available reference; ``static_views``: views that get the static flow from the
    primary reference; ``intensity``: ``contact`` or ``fixed``; ``load_fraction``: of
    the contact's median load, reached at the contact onset; ``static_every``: frames
    between two static-flow computations (interpolated in between)."""

    primary: str
    reference_frame: int | None = None
    evidence_views: tuple[str, ...] = ()
    static_views: tuple[str, ...] = ()
    intensity: str = "contact"
    load_fraction: float = 0.8
    static_every: int = 1


def primary_reference(setting: str, baseline_kind: str) -> str:
    """``analysis.flow.reference`` resolved: ``auto`` is the contact onset after a tare, else unloaded."""
    if setting != "auto":
        return setting
    return ONSET if baseline_kind == "tare" else UNLOADED


def compute(prepared, contacts: dict[str, list[tuple[int, int]]], fingers: list[str], model, margin: int,
            signal: dict[str, np.ndarray], threshold: dict[str, float], settle: int, plan: FlowPlan,
            keep_fields: bool = False, progress: bool = True, workers: int = 1):
    """Flow for every (finger, contact). Returns (list of ContactFlow, CPU seconds of the
    rendering and flow jobs: their wall time summed, so the same with any ``workers``).

    ``contacts``: finger → contact intervals; ``signal``: finger → (T,) contact signal and
    ``threshold``: finger → its level, for the contact onset; ``workers``: threads
    running the (window, view) jobs.
    """
    from tactile_flow.cliapp.progress import progress_bar
    views = list(model.plans)
    T = prepared.activation.shape[0]
    jobs = []
    for f, ivs in contacts.items():
        k = fingers.index(f)
        for a, b in ivs:
            jobs.append((f, k, (a, b), (max(0, a - margin), min(T, b + margin))))
    total = sum((w1 - w0) * len(views) for *_, (w0, w1) in jobs)
    bar = progress_bar(total=total, unit="frame", desc="tactile flow", leave=False, disable=not progress or total == 0,
               dynamic_ncols=True)
    out, tasks = [], []
    for f, k, (a, b), (w0, w1) in jobs:
        act = prepared.activation[w0:w1, k]
        try:
            settled = onset = w0 + tflow.contact_reference(signal[f][w0:w1], threshold[f],
                                                           settle=min(settle, max(1, b - a)))
            if a > 0:           # a record that begins in contact begins loaded: its first settled frame
                onset = tflow.loaded_reference(prepared.score[:b, k], onset, plan.load_fraction)
        except ValueError:
            settled = onset = None
        cf = ContactFlow(f, k, (a, b), (w0, w1), onset, settled, begins_in_contact=a == 0)
        refs = {UNLOADED: None}
        if onset is not None:
            refs[ONSET] = onset - w0
        if plan.reference_frame is not None and w0 <= plan.reference_frame < w1:
            refs[TIME] = plan.reference_frame - w0
        intensity = None
        if plan.intensity == "contact":
            intensity = (0.0, max(float(act.max()), MIN_PEAK_KOHM))
        for v in views:
            if v in plan.evidence_views:
                wanted = refs
            elif v in plan.static_views:
                wanted = {r: i for r, i in refs.items() if r == plan.primary}
            else:
                wanted = {}
            tasks.append((cf, v, act, wanted, intensity))
        out.append(cf)

    def job(task):
        cf, v, act, wanted, intensity = task
        t0 = _time.perf_counter()
        result = process_view(model, act, v, references=wanted, primary=plan.primary, static_every=plan.static_every,
                              intensity_range=intensity, keep_fields=keep_fields, progress=bar.update)
        return result, _time.perf_counter() - t0

    try:
        if workers > 1 and len(tasks) > 1:
            with ThreadPoolExecutor(max_workers=min(workers, len(tasks))) as pool:
                done = list(pool.map(job, tasks))
        else:
            done = [job(t) for t in tasks]
    finally:
        bar.close()
    for (cf, v, *_), (result, _) in zip(tasks, done):
        cf.views[v] = result
    spent = sum(s for _, s in done)
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
    sensor frame: mm/s for the dynamic flow, mm for the static flow. ``kind``: ``dynamic``,
    ``static`` (the primary reference) or a reference's name (``unloaded``,
    ``contact_onset``, ``time``). ``None`` if unavailable."""
    vr = cf.views.get(view)
    if vr is None:
        return None
    if kind == "dynamic":
        agg = vr.dynamic
    else:
        agg = vr.static if kind == "static" else vr.statics.get(kind)
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


def static_series(cf: ContactFlow, view: str, reference: str, model) -> tuple[np.ndarray, np.ndarray] | None:
    """Per-frame static flow of a window from ``reference``: the mean vector in the sensor
    frame (W, 3) mm and the rotation (W,) rad (curl / 2 of a displacement field, about the
    view's look axis), or ``None`` if that flow was not computed."""
    vr = cf.views.get(view)
    agg = None if vr is None else vr.statics.get(reference)
    if agg is None:
        return None
    plan = model.plans[view]
    return plan.image_to_sensor(agg.mean) * plan.mm_per_px, agg.curl / 2.0


def combined_direction(cf: ContactFlow, start: int, stop: int, model, rate_hz: float):
    """Confidence-weighted mean over views of the dynamic mean flow in the sensor frame (3,) mm/s.

    Each sensor axis is averaged over the views that see it, each view weighted on axis k by
    1 − look_k² (the share of axis k in its image plane: 1 for the two axes of an axis-aligned
    view, 0 for the one it looks along). Summed instead, the bottom view's y would count once
    against x three times (bottom, left, right), turning every direction off the finger's axis
    toward x (a 45° sweep read as 9°)."""
    total, weight = np.zeros(3), np.zeros(3)
    for v in cf.views:
        w = window_summary(cf, v, start, stop, model, rate_hz, "dynamic")
        if w is not None:
            seen = 1.0 - np.asarray(model.plans[v].look, float) ** 2
            c = max(w["confidence"], 1e-3)
            total += w["sensor"] * c
            weight += seen * c
    return np.divide(total, weight, out=np.zeros(3), where=weight > 0)


def combined_flow_px(cf: ContactFlow, start: int, stop: int, model, rate_hz: float) -> float | None:
    """Confidence-weighted mean over views of the dynamic mean flow's magnitude over frames
    [start, stop), px/frame: how fast the pattern moved in the tactile frames. Not a sliding
    speed: the frames' flow under-reads the pattern's motion by a factor that changes with
    the speed, the feature and the press (docs/analysis.md, "Flow magnitudes are not speeds")."""
    total = weight = 0.0
    for v in cf.views:
        w = window_summary(cf, v, start, stop, model, rate_hz, "dynamic")
        if w is not None:
            c = max(w["confidence"], 1e-3)
            total += c * w["magnitude"]                     # tagg.window's magnitude: px/frame
            weight += c
    return total / weight if weight > 0 else None

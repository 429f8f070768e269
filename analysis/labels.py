"""Segments and their labels, assigned from the data.

The protocol declares its labels (root attribute ``labels``); which scheme applies follows
from them:

- **sweep** (labels include ``during``): per finger, ``approach`` (start of the record to its
  first contact), for every pressure bump (a feature crossed) ``before`` (contact start to
  plateau), ``during`` (the plateau), ``after`` (plateau to contact end / the trough before the
  next bump), and ``lift`` (last contact to the end);
- **pour** (labels include ``initial_slip`` or ``rotation``): per grasp finger, over its main
  contact, ``pour`` → ``initial_slip`` → ``rotation`` → ``downward`` → ``full_slip`` from the
  onsets found by :func:`pour_phases`;
- **generic** (anything else, e.g. an imported recording): ``contact`` and ``no_contact``
  stretches (the first and last named ``approach`` and ``lift`` when the protocol declares
  those), and one ``all`` segment covering the whole contact when the protocol declares it or
  declares no labels at all (an imported recording). No undeclared label is produced.

All indices are frame indices into the run's BioTac time axis; segments are ``[start, stop)``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from tactile_flow.validation import ConfigError, brief, suggest

from . import segments as seg

SWEEP, POUR, GENERIC = "sweep", "pour", "generic"
POUR_PHASES = ("pour", "initial_slip", "rotation", "downward", "full_slip", "held")


@dataclass
class Segment:
    """One labelled stretch of one finger's record."""

    label: str
    finger: str
    start: int
    stop: int
    feature: int = -1          # crossing index (sweeps), −1 otherwise
    contact: int = -1          # index of the finger's contact, −1 if out of contact
    id: int = -1

    def frames(self) -> int:
        return self.stop - self.start


#: the labels each scheme can produce
SCHEME_LABELS = {SWEEP: ("approach", "before", "during", "after", "lift"), POUR: POUR_PHASES,
                 GENERIC: ("approach", "contact", "no_contact", "all", "lift")}


def check_labels(labels, key: str = "protocol.labels") -> None:
    """Refuse declared ``labels`` that would silently change the analysis, before a run records:
    a label one edit from a scheme's label (a misspelt ``durign`` selects the generic scheme:
    no crossings, widths or directions), named with the nearest label; and a scheme's label
    the labels do not select (``before`` without ``during`` selects the generic scheme, so it
    would never appear). A label of one's own, like no scheme's, names a generic run
    (``docs/protocols.md``, section 3). Raises :class:`validation.ConfigError` naming ``key[i]``."""
    if labels is None:
        return
    if not isinstance(labels, (list, tuple)) or not all(isinstance(x, str) for x in labels):
        raise ConfigError(key, f"got {brief(labels)}; expected a list of segment labels")
    chosen = scheme(labels)
    known = sorted({x for names in SCHEME_LABELS.values() for x in names})
    for i, label in enumerate(labels):                 # a misspelt label first: it may be what changed the scheme
        near = suggest(label, known) if label not in known else None
        if near is not None:
            owner = next(name for name, names in SCHEME_LABELS.items() if near in names)
            raise ConfigError(f"{key}[{i}]", f"unknown label {label!r}, close to the {owner} scheme's `{near}`; "
                                             f"expected a scheme's label, or one of your own unlike them (for the "
                                             f"generic scheme); did you mean `{near}`?")
    for i, label in enumerate(labels):
        if label in SCHEME_LABELS[chosen] or label not in known:
            continue
        others = [name for name, names in SCHEME_LABELS.items() if label in names]
        raise ConfigError(f"{key}[{i}]", f"{label!r} is a label of the {' and '.join(others)} scheme, but these labels "
                                         f"select the {chosen} scheme ({_why(chosen)}), which produces only "
                                         f"{', '.join(SCHEME_LABELS[chosen])}")


def _why(chosen: str) -> str:
    return {SWEEP: "they include during", POUR: "they include a pour phase",
            GENERIC: "no during, no pour phase"}[chosen]


def scheme(labels) -> str:
    labels = set(labels or [])
    if "during" in labels:
        return SWEEP
    if labels & {"initial_slip", "rotation", "downward", "full_slip"}:
        return POUR
    return GENERIC


def sweep_segments(finger: str, T: int, contacts, bumps_per_contact) -> list[Segment]:
    """Approach, before/during/after for every bump, lift (see module doc)."""
    out: list[Segment] = []
    if not contacts:
        return out
    if contacts[0][0] > 0:
        out.append(Segment("approach", finger, 0, contacts[0][0]))
    feature = 0
    for c, (bumps) in enumerate(bumps_per_contact):
        for b in bumps:
            i0, i1 = b.plateau
            out.append(Segment("before", finger, b.start, i0, feature, c))
            out.append(Segment("during", finger, i0, i1, feature, c))
            out.append(Segment("after", finger, i1, b.stop, feature, c))
            feature += 1
    if contacts[-1][1] < T:
        out.append(Segment("lift", finger, contacts[-1][1], T))
    return out


def generic_segments(finger: str, T: int, contacts, declared=()) -> list[Segment]:
    """``no_contact`` / ``contact`` stretches and one ``all`` over the whole contact, as the
    ``declared`` labels allow (module doc; none declared: all of them)."""
    declared = set(declared or ())
    first = "approach" if "approach" in declared else "no_contact"
    last = "lift" if "lift" in declared else "no_contact"
    out: list[Segment] = []
    pos = 0
    for c, (a, b) in enumerate(contacts):
        if a > pos:
            out.append(Segment(first if c == 0 else "no_contact", finger, pos, a))
        out.append(Segment("contact", finger, a, b, contact=c))
        pos = b
    if contacts:
        if pos < T:
            out.append(Segment(last, finger, pos, T))
        if not declared or "all" in declared:
            out.append(Segment("all", finger, contacts[0][0], contacts[-1][1], contact=0))
    return out


@dataclass
class PourPhases:
    """Onsets (frame indices, None if not found); ``reasons``: why a phase that should be in the
    record was not found (a skipped estimate); ``not_reached``: phases the run never got to (the
    grasp held: a reactive pour tightened in time, or the record ends before the bottle fell),
    which is a result, not something the analysis missed."""

    onsets: dict
    reasons: dict
    not_reached: dict = field(default_factory=dict)
    #: [start, stop) frames searched for the initial slip (the pour start to the full slip's edge)
    slip_search: tuple | None = None


def pour_phases(t, pressure, contact, reference, rotation, pour_event: int | None, rotation_noise_k: float,
                trough_prominence: float, distance: int, level: float = 0.5, fast=None,
                reaction: int | None = None, shared_slip: int | None = None) -> PourPhases:
    """Onsets of the pour phases of one grasp finger.

    Args:
        t: (T,) s. pressure: (T,) pressure above rest. contact: (a, b) the grasp contact.
        reference: frame where the contact became established (static-flow reference) or None.
        rotation: (T,) static-flow rotation (rad, curl/2; NaN outside the flow window).
        pour_event: frame of the protocol's ``pour`` step, if recorded (refines the start).
        rotation_noise_k: how many times its own noise the static-flow rotation must turn
            within ``distance`` frames to mark the rotation phase.
        trough_prominence: fraction of the pressure's range (pour start to full slip) the
            initial-slip fall must reach.
        distance: frames over which that fall is measured.
        level: the full slip starts when the pressure falls for good below this fraction of
            the way from its level after the contact to its median over the contact.
        fast: (T,) a less smoothed pressure for the full-slip edge (default ``pressure``).
        reaction: frame of the protocol's first slip reaction (a reactive pour), or None.
        shared_slip: the initial slip's onset when the grasp's fingers date it together (the
            fall they share, :func:`segments.shared_first_drop`); the later phases follow it.

    - pour: the pour step if recorded inside the contact, else the contact reference;
    - initial_slip: the first sudden fall of ``fast`` after the pour start, deeper than
      ``trough_prominence`` × the pressure's range there and well above its noise
      (:func:`segments.first_drop`): the trough as the bottle first gives;
    - rotation: the knee (:func:`segments.knee`) of the largest sudden turn of the static-flow
      rotation between the pour start and the full slip's edge, a turn within ``distance``
      frames of more than ``rotation_noise_k`` × its own noise
      (:func:`segments.largest_change`): the torsional breakaway, where the bottle starts to
      turn; its size (which scales with the sensor's shear gain) does not decide;
    - downward: the deepest sudden fall of ``fast`` (one well above its noise; its depth is
      not compared with the pressure's range, which its slow trend with the load dominates on a
      sensor of low shear gain) after the rotation (or slip, or pour) onset and before the
      full slip's edge: the contact breaks away and the pad keeps only the kinetic friction (the skin stretch,
      the tangential load, falls); without one (a creeping slide) the maximum of ``pressure``
      there: the tangential load stops growing;
    - full_slip: the contact's final fall (the steepest step of ``fast`` within ``distance`` of
      the contact's end) where it passes ``level`` of its own depth, from the level just before
      it down to the level after the contact (:func:`segments.edge_crossing`): the bottle
      leaves the grasp.

    A reactive pour (``reaction`` inside the contact: the protocol tightened the grasp the
    moment the live detector saw the slip) has ``pour``, ``initial_slip`` (searched up to a
    few frames after the reaction) and ``held`` from the reaction to the contact's end: the
    later phases of a falling bottle do not follow.
    """
    a, b = contact
    p = np.asarray(pressure, float)
    onsets, reasons = {}, {}
    start = reference if reference is not None else a
    if pour_event is not None and a <= pour_event < b:
        start = max(start, pour_event)
    onsets["pour"] = start
    q = p if fast is None else np.asarray(fast, float)
    if reaction is not None and start < reaction < b:
        return _reactive_phases(q, onsets, start, reaction, b, trough_prominence, distance, t)
    # the level after the contact (the pad unloaded, up to drift), 0 if the record ends in it
    post = float(np.median(q[b:b + max(distance, 5)])) if b < len(q) else 0.0
    full = b
    if b < len(q) - 1:
        # the final fall: its steepest step near the contact's end, read at `level` of its own
        # depth (the pad's level before it moves with the shear term: a level fixed by the
        # contact's median would be crossed early by a pressure that sinks as the load grows)
        lo, hi = max(start, b - distance), min(len(q) - 1, b + distance)
        if hi - lo > 2:
            steepest = lo + int(np.argmin(np.diff(q[lo:hi + 1])))
            full = min(b, seg.edge_crossing(q, steepest, start, distance, post, level))
    # where the final fall (the full slip's edge) begins: the earlier phases come before it
    edge = min(full, len(q) - 1)
    while edge > start + 1 and q[edge - 1] > q[edge]:
        edge -= 1
    edge = max(start, edge - 3)
    # the bottle first gives: the first sudden fall of the (lightly smoothed) pressure between
    # the pour start and the full slip's edge (stored strain released, load taken off the pad)
    slip_edge = edge
    slip = seg.first_drop(q[:edge], start, trough_prominence, distance) if shared_slip is None else shared_slip
    if slip is None:
        reasons["initial_slip"] = ("no pressure trough (a sudden fall: the bottle giving) between the pour start "
                                   "and the full slip")
    onsets["initial_slip"] = slip
    rot = np.asarray(rotation, float)
    valid = np.isfinite(rot)
    r_on = None
    # the rotation's own smoothing spreads the full slip's edge back: stop a window before it
    stop = full - distance
    if valid[start:stop].sum() > distance + 3:
        r = np.where(valid, rot, 0.0)
        turn = seg.largest_change(r, start, stop, distance, rotation_noise_k)
        if turn is not None:
            steep = turn[0]
            r_on = seg.knee(t, r, max(start, steep - 2 * distance), steep)
    if r_on is None:
        reasons["rotation"] = (f"no sudden turn of the static-flow rotation (more than {rotation_noise_k:g} × its noise "
                               f"within {distance} frames) between the pour start and the full slip")
    onsets["rotation"] = r_on
    # the contact breaks away: the pad keeps only the kinetic friction, the skin's stretch
    # falls: the deepest sudden fall after the slip / rotation onsets and before the full slip
    # (out of the noise; not a share of the range, which the pressure's drift with the load sets)
    after = max(x for x in (start, slip, r_on) if x is not None)
    edge = max(after, edge)
    down = seg.first_drop(q[:edge], after, 0.0, distance, largest=True) if edge - after > 3 else None
    if down is not None and down >= edge - 2:
        down = None
    if down is None and full - after > 3:
        # no breakaway drop (a creeping slide): the tangential load stops growing instead
        down = after + int(np.argmax(p[after:full]))
        if down >= full - 2:
            down = None
    if down is None:
        reasons["downward"] = "no sudden pressure fall (the grasp breaking away) nor pressure maximum before the full slip"
    onsets["downward"] = down
    onsets["full_slip"] = full if b < len(p) else None
    not_reached = {}
    if onsets["full_slip"] is None:
        not_reached["full_slip"] = "the grasp holds until the record ends"
    return PourPhases(onsets, reasons, not_reached, (start, slip_edge))


REACTED_FRAMES = 3     # frames after the reaction still searched for the initial slip's fall


def _reactive_phases(q, onsets, start, reaction, b, trough_prominence, distance, t) -> PourPhases:
    """:func:`pour_phases` of a pour whose protocol reacted to the slip at frame ``reaction``."""
    reasons = {}
    end = min(b, reaction + REACTED_FRAMES)
    slip = seg.first_drop(q[:end], start, trough_prominence, distance)
    if slip is None:
        reasons["initial_slip"] = "no pressure trough between the pour start and the protocol's reaction"
    onsets["initial_slip"] = slip
    why = f"the protocol reacted to the slip at {t[reaction]:.2f} s and the grasp held"
    not_reached = {}
    for name in ("rotation", "downward", "full_slip"):
        onsets[name] = None
        not_reached[name] = why
    onsets["held"] = reaction
    return PourPhases(onsets, reasons, not_reached)


def pour_segments(finger: str, T: int, phases: PourPhases, contact, contact_index: int, margin: int):
    """Segments from the onsets; a phase ends where the next found phase begins."""
    found = [(name, phases.onsets[name]) for name in POUR_PHASES if phases.onsets.get(name) is not None]
    found.sort(key=lambda x: x[1])
    out = []
    end = min(T, contact[1] + margin)
    for i, (name, s) in enumerate(found):
        e = found[i + 1][1] if i + 1 < len(found) else (end if name == "full_slip" else contact[1])
        out.append(Segment(name, finger, int(s), int(e), contact=contact_index))
    return out

"""The run store's layout: blocks of variables that grow together, their dimensions, dtypes,
units and long names, and the fixed coordinates (``docs/run_store.md``).

The layout is derived from the streams the devices declare (:mod:`hardware.streams`: each
sample type's ``describe()``), plus the run's own ``events`` and, with the online flow, its
``live`` block. A *block* is one stream's samples in one group; ``dims[0]`` of every variable
of a block is its append dimension, the stream's time coordinate. :data:`SCHEMA_VERSION` is
written to every store's root attributes; :mod:`runstore.reader` refuses a newer major version.
"""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np

from tactile_flow.hardware.arm import AXIS6, ArmState  # noqa: F401  (AXIS6 re-exported)
from tactile_flow.hardware.biotac import FINGERS, BiotacFrame
from tactile_flow.hardware.hand import HandState
from tactile_flow.hardware.pour import PumpState, ScaleReading
from tactile_flow.hardware.stage import STAGE_AXES, StageState  # noqa: F401  (STAGE_AXES re-exported)
from tactile_flow.hardware.streams import Column, Stream

from .jsonvalues import jsonable
from .status import STORE_STATUSES as STATUSES  # noqa: F401  (re-exported)

SCHEMA_VERSION = "1.0"
EVENTS_CHUNK = 256
LIVE_RATE_HZ = 100.0

#: a stored variable (a stream's :class:`~hardware.streams.Column`)
Var = Column


@dataclass(frozen=True)
class Block:
    """Variables of one group that grow together along ``dim`` (one stream's samples)."""

    name: str
    group: str
    dim: str
    chunk: int
    vars: tuple[Column, ...]


def lab_streams(fingers=FINGERS, stage: bool = False, sensor=None) -> dict[str, Stream]:
    """The streams of a lab run, by name: what the sample types of the BioTacs (of model
    ``sensor``, default the BioTac SP), the arm, the hand, the pump, the scale and (``stage``)
    the object stage declare."""
    types = [BiotacFrame.describe(tuple(fingers), sensor), ArmState.describe(), HandState.describe(),
             PumpState.describe(), ScaleReading.describe(), *([StageState.describe()] if stage else [])]
    return {s.name: s for declared in types for s in declared}


def run_schema(chunk_s: float = 5.0, live: bool = False, stage: bool = False, *,
               streams: dict[str, Stream] | None = None) -> dict[str, Block]:
    """The blocks of a run store, by name: one per stream (``streams``; by default
    :func:`lab_streams` with ``stage``), ``events``, and with ``live`` the online tactile
    flow ``live``. ``chunk_s``: seconds of data per chunk at the nominal rate. Non-leading
    dimensions (finger, taxel, axis6, joint, live_finger, view) are sized at creation."""
    def chunk(rate_hz):
        return max(1, int(round(rate_hz * chunk_s)))

    streams = lab_streams(stage=stage) if streams is None else streams
    blocks = [Block(s.name, s.group, s.time, chunk(s.rate_hz), s.all_columns) for s in streams.values()]
    blocks.append(Block("events", "events", "event", EVENTS_CHUNK, (
        Var("time", ("event",), "f8", "s", "event time since run start"),
        Var("kind", ("event",), "str", "", "event kind (step_start, step_end, interlock, fault, gap, info, ...)"),
        Var("name", ("event",), "str", "", "step, interlock, stream or device the event is about"),
        Var("detail", ("event",), "str", "", "details as JSON text"))))
    if live:
        blocks.append(_live_block(chunk(LIVE_RATE_HZ)))
    return {b.name: b for b in blocks}


def event_columns(rows) -> dict[str, np.ndarray]:
    """``events`` columns of ``(time s, kind, name, detail)`` rows; ``detail`` (anything
    JSON-like, numpy values included; other objects as their text) stored as JSON text."""
    return {"time": np.array([r[0] for r in rows], float),
            "kind": np.array([str(r[1]) for r in rows], dtype=object),
            "name": np.array([str(r[2]) for r in rows], dtype=object),
            "detail": np.array(["" if r[3] is None else json.dumps(jsonable(r[3], fallback=str)) for r in rows],
                               dtype=object)}


def _live_block(chunk: int) -> Block:
    """The online tactile flow computed during the run (:mod:`protocols.live`), one row per
    BioTac frame processed, so every reaction can be audited against what was seen."""
    T, TF, TFV = ("time_live",), ("time_live", "live_finger"), ("time_live", "live_finger", "view")
    per_view = [("flow_col", "px frame-1", "mean tactile flow along the view's columns"),
                ("flow_row", "px frame-1", "mean tactile flow along the view's rows"),
                ("magnitude", "px frame-1", "magnitude of the mean tactile flow"),
                ("direction", "rad", "direction of the mean tactile flow in the view, atan2(row, col)"),
                ("divergence", "frame-1", "mean divergence of the tactile flow"),
                ("curl", "frame-1", "mean curl of the tactile flow"),
                ("confidence", "1", "fraction of the footprint whose flow exceeds the noise level")]
    return Block("live", "live", "time_live", chunk, (
        Var("time_live", T, "f8", "s", "host receipt time of the BioTac frame since run start"),
        Var("processed_time", T, "f8", "s", "when the frame's online flow and slip verdict were ready, since run start"),
        Var("seq", T, "i8", "1", "BioTac frame sequence number (joins biotac/seq)"),
        Var("processed", TF, "bool", "1", "the finger's sample was valid and processed (else skipped: NaN values)"),
        Var("activation_total", TF, "f8", "kOhm", "sum of the Kalman-filtered taxel activations (PDC proxy)"),
        Var("activation_contact", TF, "f8", "kOhm", "sum of their absolute values (keeps a pressed finger armed while the robot is still)"),
        *(Var(name, TFV, "f8", units, long) for name, units, long in per_view),
        Var("slip_fired", TF, "bool", "1", "the slip detector fired for the finger in this frame"),
        Var("slip_cause", TF, "i1", "1", "what fired: 0 none, 1 release, 2 creep, 3 rotation (tactile.slip.CAUSES)"),
        Var("slip_detected", T, "bool", "1", "slip detected in this frame or earlier in the current reacting step")))


def fixed_coords(streams: dict[str, Stream], live) -> dict[str, dict[str, tuple]]:
    """Fixed coordinate variables by group: name -> (values, units, long_name); ``live``:
    ``(fingers, views)`` of the online flow, or None."""
    out: dict[str, dict[str, tuple]] = {}
    for s in streams.values():
        for c in s.coords:
            values = np.asarray(c.values)
            out.setdefault(s.group, {})[c.name] = (values.astype(str) if values.dtype.kind in "UO" else values,
                                                   c.units, c.long_name)
    if live:
        out["live"] = {"live_finger": (np.array(live[0], dtype=str), "", "finger processed online (Shadow order)"),
                       "view": (np.array(live[1], dtype=str), "", "tactile-frame view (tactile.frames)")}
    return out


def dim_sizes(coords: dict[str, dict[str, tuple]]) -> dict[str, int]:
    """Length of every non-append dimension, from the fixed coordinates."""
    return {name: len(values) for group in coords.values() for name, (values, _, _) in group.items()}


def time_coords(schema: dict[str, Block]) -> tuple[str, ...]:
    """The time coordinates (append dimensions) of ``schema``'s sample blocks (not ``event``)."""
    return tuple(b.dim for b in schema.values() if b.name != "events")


#: the time coordinate of every stream a lab run store may hold (seconds since run start)
TIME_COORDS = time_coords(run_schema(live=True, stage=True))

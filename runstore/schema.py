"""The run store's layout: blocks of variables that grow together, their dimensions, dtypes,
units and long names, and the fixed coordinates (``docs/run_store.md``).

A *block* is one stream's samples in one group; ``dims[0]`` of every variable of a block is
the block's append dimension, whose name is the stream's time coordinate
(:data:`TIME_COORDS`). :data:`SCHEMA_VERSION` is written to every store's root attributes;
:mod:`runstore.reader` refuses a store of a newer major version.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hardware.biotac import FINGERS, N_TAXELS, PAC_RATE_HZ
from hardware.hand import JOINT_NAMES

SCHEMA_VERSION = "1.0"
STATUSES = ("running", "success", "aborted", "failed", "crashed")
AXIS6 = ("x", "y", "z", "rx", "ry", "rz")

#: nominal sample rates (Hz), used only to size chunks
NOMINAL_RATE_HZ = {"biotac": 100.0, "biotac_pac": PAC_RATE_HZ, "arm": 500.0, "hand": 100.0,
                   "pump": 10.0, "scale": 10.0, "live": 100.0, "stage": 100.0}
STAGE_AXES = ("x", "y", "rz")
EVENTS_CHUNK = 256


@dataclass(frozen=True)
class Var:
    """One stored variable: ``dims[0]`` is its block's append dimension."""

    name: str
    dims: tuple[str, ...]
    dtype: str
    units: str
    long_name: str


@dataclass(frozen=True)
class Block:
    """Variables of one group that grow together along ``dim`` (one stream's samples)."""

    name: str
    group: str
    dim: str
    chunk: int
    vars: tuple[Var, ...]


def _time_vars(dim: str, device_name: str, host_name: str, what: str,
               device_long: str) -> tuple[Var, ...]:
    return (Var(dim, (dim,), "f8", "s", f"{what} time since run start (clock model of the device time)"),
            Var(device_name, (dim,), "f8", "s", device_long),
            Var(host_name, (dim,), "f8", "s", f"host receipt time of the {what} sample since run start"))


def run_schema(chunk_s: float = 5.0, live: bool = False, stage: bool = False) -> dict[str, Block]:
    """The blocks of a run store, by name (``biotac``, ``biotac_pac``, ``arm``, ``hand``,
    ``pump``, ``scale``, ``events``, with ``live`` the online tactile flow ``live``, with
    ``stage`` the object stage's ``stage``).
    ``chunk_s``: seconds of data per chunk at the nominal rate. Non-leading dimensions
    (finger, taxel, axis6, joint, live_finger, view) are sized at creation."""
    def chunk(name):
        return max(1, int(round(NOMINAL_RATE_HZ[name] * chunk_s)))

    T = ("time",)
    TF = ("time", "finger")
    blocks = [
        Block("biotac", "biotac", "time", chunk("biotac"), (
            *_time_vars("time", "device_time", "host_time", "BioTac frame",
                        "sensor bridge timestamp of the frame (device clock)"),
            Var("seq", T, "i8", "1", "frame sequence number (one per frame, all fingers)"),
            Var("valid", T, "bool", "1", "every channel of the frame within 0..4095"),
            Var("electrodes", (*TF, "taxel"), "i2", "count", "electrode impedance reading, raw 12-bit counts"),
            Var("pdc", TF, "i2", "count", "static pressure (PDC), raw counts"),
            Var("tdc", TF, "i2", "count", "temperature (TDC), raw counts"),
            Var("tac", TF, "i2", "count", "temperature change (TAC), raw counts"))),
        Block("biotac_pac", "biotac_pac", "time_pac", chunk("biotac_pac"), (
            *_time_vars("time_pac", "device_time", "host_time", "PAC",
                        "device time of the PAC sample (its frame's timestamp minus the later "
                        "samples of the frame at 2.2 kHz)"),
            Var("pac", ("time_pac", "finger"), "i2", "count", "dynamic pressure (PAC) at 2.2 kHz, raw counts"))),
        Block("arm", "arm", "time_arm", chunk("arm"), (
            *_time_vars("time_arm", "controller_time", "host_time", "arm state",
                        "controller timestamp (s since controller start)"),
            Var("tcp_pose", ("time_arm", "axis6"), "f8", "m, rad",
                "TCP pose [x, y, z] m and axis-angle [rx, ry, rz] rad, robot base frame"),
            Var("tcp_speed", ("time_arm", "axis6"), "f8", "m s-1, rad s-1", "TCP linear and angular velocity"),
            Var("tcp_wrench", ("time_arm", "axis6"), "f8", "N, N m",
                "force [Fx, Fy, Fz] N and torque [Tx, Ty, Tz] N m on the tool, base frame"),
            Var("protective_stopped", ("time_arm",), "bool", "1", "controller protective-stop flag"))),
        Block("hand", "hand", "time_hand", chunk("hand"), (
            *_time_vars("time_hand", "device_time", "host_time", "hand joint state",
                        "hand joint-state stamp (device clock)"),
            Var("position", ("time_hand", "joint"), "f8", "rad", "measured joint angle"),
            Var("target", ("time_hand", "joint"), "f8", "rad", "commanded joint angle"))),
        Block("pump", "pour", "time_pump", chunk("pump"), (
            *_time_vars("time_pump", "pump_device_time", "pump_host_time", "pump",
                        "pump timestamp (device clock)"),
            Var("pump_rate", ("time_pump",), "f8", "ml min-1", "pump flow rate"),
            Var("dispensed", ("time_pump",), "f8", "ml", "volume dispensed since the pump connected"),
            Var("pump_running", ("time_pump",), "bool", "1", "pump running"))),
        Block("scale", "pour", "time_scale", chunk("scale"), (
            *_time_vars("time_scale", "scale_device_time", "scale_host_time", "scale",
                        "scale timestamp (device clock)"),
            Var("mass", ("time_scale",), "f8", "g", "net mass on the scale (since the last tare)"),
            Var("stable", ("time_scale",), "bool", "1", "scale stability flag"))),
        Block("events", "events", "event", EVENTS_CHUNK, (
            Var("time", ("event",), "f8", "s", "event time since run start"),
            Var("kind", ("event",), "str", "", "event kind (step_start, step_end, interlock, fault, gap, info, ...)"),
            Var("name", ("event",), "str", "", "step, interlock, stream or device the event is about"),
            Var("detail", ("event",), "str", "", "details as JSON text"))),
    ]
    if live:
        blocks.append(_live_block(chunk("live")))
    if stage:
        blocks.append(Block("stage", "stage", "time_stage", chunk("stage"), (
            *_time_vars("time_stage", "device_time", "host_time", "object stage",
                        "stage controller timestamp (device clock)"),
            Var("pose", ("time_stage", "stage_axis"), "f8", "m, rad",
                "object stage pose [x, y] m from home (robot base axes) and rotation rz rad about +z "
                "(counter-clockwise seen from above)"),
            Var("velocity", ("time_stage", "stage_axis"), "f8", "m s-1, rad s-1", "object stage velocity"),
            Var("moving", ("time_stage",), "bool", "1", "a commanded stage motion is under way"))))
    return {b.name: b for b in blocks}


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
        Var("activation_total", TF, "f8", "kOhm", "sum of the 24 Kalman-filtered taxel activations (PDC proxy)"),
        *(Var(name, TFV, "f8", units, long) for name, units, long in per_view),
        Var("slip_fired", TF, "bool", "1", "the slip detector fired for the finger in this frame"),
        Var("slip_cause", TF, "i1", "1", "what fired: 0 none, 1 release, 2 creep, 3 rotation (tactile.slip.CAUSES)"),
        Var("slip_detected", T, "bool", "1", "slip detected in this frame or earlier in the current reacting step")))


def fixed_coords(fingers: tuple[str, ...], live) -> dict[str, dict[str, tuple]]:
    """Fixed coordinate variables by group: name -> (values, units, long_name)."""
    finger = (np.array(fingers, dtype=str), "", "finger (Shadow order)")
    stage = {"stage_axis": (np.array(STAGE_AXES, dtype=str), "", "object stage pose / velocity component")}
    live_coords = {} if not live else {"live": {
        "live_finger": (np.array(live[0], dtype=str), "", "finger processed online (Shadow order)"),
        "view": (np.array(live[1], dtype=str), "", "tactile-frame view (tactile.frames)")}}
    return {**live_coords, "biotac": {"finger": finger,
                       "taxel": (np.arange(1, N_TAXELS + 1, dtype=np.int16), "1", "taxel number (SynTouch)")},
            "biotac_pac": {"finger": finger},
            "arm": {"axis6": (np.array(AXIS6, dtype=str), "", "pose / twist / wrench component")},
            "hand": {"joint": (np.array(JOINT_NAMES, dtype=str), "", "Shadow Hand joint name")},
            "stage": stage}




def dim_sizes(fingers: tuple[str, ...], live) -> dict[str, int]:
    """Length of every non-append dimension (``live``: ``(fingers, views)`` or None)."""
    sizes = {"finger": len(fingers), "taxel": N_TAXELS, "axis6": len(AXIS6), "joint": len(JOINT_NAMES),
             "stage_axis": len(STAGE_AXES)}
    if live:
        sizes.update(live_finger=len(live[0]), view=len(live[1]))
    return sizes


def time_coords(schema: dict[str, Block]) -> tuple[str, ...]:
    """The time coordinates (append dimensions) of ``schema``'s sample blocks (not ``event``)."""
    return tuple(b.dim for b in schema.values() if b.name != "events")


#: every time coordinate a run store may hold (seconds since run start)
TIME_COORDS = time_coords(run_schema(live=True, stage=True))

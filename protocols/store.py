"""The run store: one zarr v3 hierarchy per run (``run.zarr``), read as one ``xarray.DataTree``.

Layout and units: :func:`run_schema` and ``docs/run_store.md``. Every variable carries
CF-style ``units`` and ``long_name`` attributes and names its dimensions through zarr v3
``dimension_names``, so ``xr.open_datatree(path, engine="zarr")`` sees them.

Crash safety. Data are appended to the arrays in place (resize, then write the new rows:
only the chunks they touch are rewritten, each file atomically by zarr's LocalStore) and
become visible only at :meth:`RunStore.commit`, which rewrites the root ``zarr.json`` with
the *consolidated* metadata of every array (one atomic file replace). xarray reads shapes
from the consolidated metadata, so a reader, or a process opening the store after a
SIGKILL, sees the state of the last commit: every variable of a group has the same length,
and rows appended after it are invisible even though their chunks may be on disk. A chunk
rewritten after a commit still holds every committed row (appends only add rows).
"""

from __future__ import annotations

import asyncio
import math
import os
import shutil
import threading
import uuid
import warnings
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import zarr
from zarr.core.sync import sync

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


def utc_now() -> str:
    """Current UTC time, ISO 8601 with microseconds and ``Z``."""
    return datetime.now(timezone.utc).isoformat(timespec="microseconds").replace("+00:00", "Z")


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


def _coords(fingers: tuple[str, ...], live) -> dict[str, dict[str, tuple]]:
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


def jsonable(obj):
    """``obj`` with numpy values turned into plain Python and non-finite floats into None,
    so that it is valid JSON (zarr attributes, run.json)."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return jsonable(obj.item())
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, (str, int, float, bool)) or obj is None:
        return obj
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON-serialisable: {type(obj).__name__} {obj!r:.80}")


def _zarr_dtype(dtype: str):
    return str if dtype == "str" else np.dtype(dtype)


def _fill(dtype: str):
    return {"f8": float("nan"), "str": "", "bool": False}.get(dtype, 0)


class RunStore:
    """Writer of one run store. Thread-safe; normally driven by a single writer thread.

    Create with :meth:`create`. :meth:`append` adds rows to a block (invisible to readers),
    :meth:`commit` publishes every append and attribute change atomically, :meth:`close`
    sets the final status and end time.
    """

    def __init__(self, path: Path, root: zarr.Group, schema: dict[str, Block], fingers: tuple[str, ...]):
        self.path = Path(path)
        self.schema = schema
        self.fingers = fingers
        self._root = root
        self._lock = threading.RLock()
        self._arrays = {b: {v.name: root[f"{blk.group}/{v.name}"] for v in blk.vars}
                        for b, blk in schema.items()}
        self._length = {b: 0 for b in schema}
        self._attrs: dict = {}
        self._attrs_dirty = False
        self.closed = False
        self.n_commits = 0

    # ---------------------------------------------------------------- creation
    @classmethod
    def create(cls, path, *, protocol: str, fingers=FINGERS, run_id: str | None = None,
               provenance: dict | None = None, attrs: dict | None = None,
               chunk_s: float = 5.0, live: tuple | None = None, stage: bool = False) -> "RunStore":
        """Create ``path`` (must not exist) with every group, coordinate and empty variable,
        root attributes (``run_id``, ``protocol``, ``status="running"``, ``start_time``,
        ``schema_version``, ``provenance``) and commit it. ``live``: ``(fingers, views)``
        of the online tactile flow, to add the ``live`` group; ``stage``: add the object
        stage's ``stage`` group.

        Atomic: everything is made in a hidden directory beside ``path`` and renamed into
        place, so an interrupted creation leaves no half-made store (at most the hidden
        ``.<name>.creating-*`` directory, which :func:`remove_debris` clears)."""
        path = Path(path)
        if path.exists():
            raise FileExistsError(f"run store {path} already exists")
        fingers = tuple(fingers)
        schema = run_schema(chunk_s, live=bool(live), stage=stage)
        prov = provenance or {}
        root_attrs = jsonable(dict(run_id=run_id or prov.get("run_id") or str(uuid.uuid4()), protocol=protocol,
                                   status="running", start_time=prov.get("start_time") or utc_now(), end_time=None,
                                   schema_version=SCHEMA_VERSION, fingers=list(fingers), provenance=prov,
                                   **(attrs or {})))
        tmp = path.with_name(f".{path.name}.creating-{uuid.uuid4().hex[:8]}")
        try:
            _make_tree(tmp, schema, fingers, live, root_attrs)
            if path.exists():
                raise FileExistsError(f"run store {path} already exists")
            os.rename(tmp, path)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
        store = cls(path, zarr.open_group(str(path), mode="r+", use_consolidated=False), schema, fingers)
        store._attrs = dict(root_attrs)
        store.n_commits = 1
        return store

    # ---------------------------------------------------------------- writing
    @property
    def run_id(self) -> str:
        return self._attrs["run_id"]

    def length(self, block: str) -> int:
        """Rows appended to ``block`` so far (committed or not)."""
        return self._length[block]

    def set_attrs(self, **attrs) -> None:
        """Set root attributes (JSON-serialisable values); written at the next commit."""
        with self._lock:
            self._attrs.update(jsonable(attrs))
            self._attrs_dirty = True

    @property
    def attrs(self) -> dict:
        with self._lock:
            return dict(self._attrs)

    def set_group_attrs(self, group: str, **attrs) -> None:
        """Set attributes of a group (written at once; published at the next commit)."""
        with self._lock:
            self._root[group].attrs.update(jsonable(attrs))

    def append(self, block: str, data: dict[str, np.ndarray]) -> int:
        """Append rows to every variable of ``block``; returns the number of rows.

        ``data`` maps each variable name of the block to an array whose first axis is the
        new rows (the same count for all) and whose other axes match the schema. Not
        visible to readers until :meth:`commit`.
        """
        return self.append_many({block: data})[block]

    def append_many(self, blocks: dict[str, dict[str, np.ndarray]]) -> dict[str, int]:
        """:meth:`append` for several blocks at once: every resize and chunk write runs
        concurrently in one call into zarr's event loop (much cheaper than one call per
        array when other threads hold the GIL). On failure every block is rolled back."""
        items, counts = [], {}
        for block, data in blocks.items():
            blk = self.schema[block]
            names = {v.name for v in blk.vars}
            if set(data) != names:
                raise ValueError(f"{block}: expected variables {sorted(names)}, got {sorted(data)}")
            lengths = {k: len(a) for k, a in data.items()}
            if len(set(lengths.values())) != 1:
                raise ValueError(f"{block}: variables of different lengths {lengths}")
            counts[block] = next(iter(lengths.values()))
        with self._lock:
            self._check_open()
            for block, n in counts.items():
                n0 = self._length[block]
                if n:
                    items += [(self._arrays[block][name], n0, np.asarray(a)) for name, a in blocks[block].items()]
            try:
                sync(_append_arrays(items))
            except BaseException:
                for block in counts:
                    self._rollback(block, self._length[block])
                raise
            for block, n in counts.items():
                self._length[block] += n
        return counts

    def _rollback(self, block: str, n0: int) -> None:
        """Shrink every array of ``block`` back to ``n0`` rows after a failed append (best
        effort: if even that fails, :meth:`commit` refuses to publish the block)."""
        for arr in self._arrays[block].values():
            try:
                if arr.shape[0] != n0:
                    arr.resize((n0, *arr.shape[1:]))
            except Exception:
                pass

    def rewrite(self, block: str, var: str, values: np.ndarray) -> None:
        """Overwrite the whole of ``var`` (e.g. a time coordinate after the final clock-model
        refit); ``values`` must have the current length. Chunks are replaced one by one, so a
        crash in the middle leaves a mix of old and new values, never a torn chunk."""
        with self._lock:
            self._check_open()
            arr = self._arrays[block][var]
            if len(values) != self._length[block] or arr.shape[0] != self._length[block]:
                raise ValueError(f"{block}/{var}: rewrite with {len(values)} rows, store has {self._length[block]}")
            if len(values):
                arr[:] = np.asarray(values)

    def transform(self, block: str, var: str, source: str, fn, chunks_per_step: int = 16) -> None:
        """Overwrite ``var`` with ``fn(source)`` piece by piece (``chunks_per_step`` chunks at a
        time, aligned to chunks so each is written once): bounded memory for a whole-run
        rewrite such as the final clock-model refit of a time coordinate."""
        with self._lock:
            self._check_open()
            n, step = self._length[block], self.schema[block].chunk * chunks_per_step
            dst, src = self._arrays[block][var], self._arrays[block][source]
            for i in range(0, n, step):
                j = min(n, i + step)
                dst[i:j] = fn(src[i:j])

    def read(self, block: str, var: str, step: int = 1) -> np.ndarray:
        """Every ``step``-th row of ``var`` written so far (including uncommitted ones)."""
        with self._lock:
            return self._arrays[block][var][: self._length[block]: step]

    def write_tree(self, group: str, tree: dict, attrs: dict | None = None) -> None:
        """Write a nested dict of arrays/scalars/strings once as ``group`` (e.g. ``truth``):
        nested dicts become subgroups; in a subgroup whose arrays share their first length,
        that axis is the dimension named after the subgroup, other axes are ``<var>_dim<k>``.
        Units come from the name (see :func:`_guess_units`)."""
        with self._lock:
            self._check_open()
            g = self._root.require_group(group)
            g.attrs.update(jsonable(attrs or {}))
            _write_tree(g, tree, group.rsplit("/", 1)[-1])

    def write_variable(self, group: str, name: str, values, dims: tuple[str, ...], units: str, long_name: str,
                       **attrs) -> None:
        """Write a fixed (non-growing) variable once, e.g. ``biotac/baseline`` (finger, taxel)."""
        values = np.asarray(values)
        with self._lock:
            self._check_open()
            a = self._root[group].create_array(name, shape=values.shape, chunks=values.shape, dtype=values.dtype,
                                               dimension_names=list(dims),
                                               attributes=jsonable({"units": units, "long_name": long_name, **attrs}))
            a[...] = values

    def commit(self) -> None:
        """Publish every append and attribute change: one atomic rewrite of the root
        metadata (consolidated metadata of all nodes)."""
        with self._lock:
            self._check_consistent()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")     # "consolidated metadata not in the v3 spec"
                if self._attrs_dirty:
                    # A handle opened on the consolidated metadata rewrites zarr.json with it,
                    # so the root stays consolidated (at the previous commit) while the
                    # attributes change; then the consolidation moves every shape forward.
                    zarr.open_group(str(self.path), mode="r+", use_consolidated=None).update_attributes(self._attrs)
                    self._attrs_dirty = False
                zarr.consolidate_metadata(str(self.path))
            self.n_commits += 1

    def _check_consistent(self) -> None:
        for b, arrays in self._arrays.items():
            bad = {k: a.shape[0] for k, a in arrays.items() if a.shape[0] != self._length[b]}
            if bad:
                raise RuntimeError(f"run store {self.path}: block {b} has inconsistent lengths {bad} "
                                   f"(expected {self._length[b]}); refusing to commit")

    def _check_open(self) -> None:
        if self.closed:
            raise RuntimeError(f"run store {self.path} is closed")

    def close(self, status: str, **attrs) -> None:
        """Set ``status`` (one of :data:`STATUSES`), ``end_time`` and ``attrs``; final commit."""
        if status not in STATUSES:
            raise ValueError(f"status {status!r} not one of {STATUSES}")
        with self._lock:
            if self.closed:
                return
            self.set_attrs(status=status, end_time=utc_now(), **attrs)
            self.commit()
            self.closed = True


def _make_tree(path: Path, schema: dict[str, Block], fingers: tuple[str, ...], live, attrs: dict) -> None:
    """Every group, coordinate and empty variable of a new store at ``path``, with the root
    ``attrs``, consolidated (the first commit)."""
    sizes = {"finger": len(fingers), "taxel": N_TAXELS, "axis6": 6, "joint": len(JOINT_NAMES),
             "stage_axis": len(STAGE_AXES)}
    if live:
        sizes.update(live_finger=len(live[0]), view=len(live[1]))
    root = zarr.open_group(str(path), mode="w-", zarr_format=3)
    coords = _coords(fingers, live)
    for group in dict.fromkeys(b.group for b in schema.values()):
        g = root.create_group(group)
        for name, (values, units, long_name) in coords.get(group, {}).items():
            a = g.create_array(name, shape=values.shape, dtype=str if values.dtype.kind == "U" else values.dtype,
                               dimension_names=[name], attributes={"units": units, "long_name": long_name})
            a[:] = values
    for blk in schema.values():
        g = root[blk.group]
        for v in blk.vars:
            shape = (0, *(sizes[d] for d in v.dims[1:]))
            g.create_array(v.name, shape=shape, chunks=(blk.chunk, *shape[1:]), dtype=_zarr_dtype(v.dtype),
                           fill_value=_fill(v.dtype), dimension_names=list(v.dims),
                           attributes={"units": v.units, "long_name": v.long_name})
    root.update_attributes(attrs)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")     # "consolidated metadata not in the v3 spec"
        zarr.consolidate_metadata(str(path))


def remove_debris(directory) -> list[Path]:
    """Remove the hidden ``.*.creating-*`` directories that an interrupted :meth:`RunStore.create`
    left in ``directory``; returns them."""
    found = sorted(Path(directory).glob(".*.creating-*"))
    for p in found:
        shutil.rmtree(p, ignore_errors=True)
    return found


async def _append_arrays(items) -> None:
    """Resize each zarr array to ``n0 + len(data)`` and write ``data`` at ``n0``, concurrently."""
    async def one(arr, n0, data):
        aa = arr.async_array
        await aa.resize((n0 + len(data), *aa.shape[1:]))
        await aa.setitem(slice(n0, n0 + len(data)), data)
    # every write finishes before a failure is raised, so the caller's rollback cannot race
    # a resize still in flight
    results = await asyncio.gather(*(one(*it) for it in items), return_exceptions=True)
    errors = [r for r in results if isinstance(r, BaseException)]
    if errors:
        raise errors[0]


# ------------------------------------------------------------------------ tree writing
_UNIT_SUFFIXES = (("_m_s", "m s-1"), ("_mm_s", "mm s-1"), ("_deg_s", "degree s-1"), ("_mm", "mm"), ("_m", "m"),
                  ("_rad", "rad"), ("_deg", "degree"), ("_n", "N"), ("_g", "g"), ("_ml", "ml"), ("_s", "s"))
_TIME_NAMES = {"start", "end", "entry", "exit", "centre_time", "time", "pour_start", "slip_onset",
               "rotation", "downward", "full_slip"}


def _guess_units(name: str, values: np.ndarray) -> str:
    """Units of a ground-truth variable from its name: ``*_m`` m, ``*_rad`` rad, times s, ...;
    strings ``""``; other numbers ``"1"``."""
    if values.dtype.kind in "USOT":
        return ""
    if name in _TIME_NAMES:
        return "s"
    for suffix, units in _UNIT_SUFFIXES:
        if name.endswith(suffix):
            return units
    return "1"


def _write_tree(g: zarr.Group, tree: dict, label: str) -> None:
    arrays = {k: np.asarray(v) for k, v in tree.items() if not isinstance(v, dict)}
    lengths = {a.shape[0] for a in arrays.values() if a.ndim >= 1}
    shared = len(lengths) == 1 and sum(a.ndim >= 1 for a in arrays.values()) > 1
    for name, a in arrays.items():
        if a.dtype.kind in "UST" or a.dtype == object:
            a = a.astype(str)
            dtype = str
        else:
            dtype = a.dtype
        dims = [label if (k == 0 and shared) else f"{name}_dim{k}" for k in range(a.ndim)]
        arr = g.create_array(name, shape=a.shape, chunks=tuple(max(1, s) for s in a.shape),
                             dtype=dtype, dimension_names=dims or None,
                             attributes={"units": _guess_units(name, a),
                                         "long_name": f"{g.path.replace('/', ' ')} {name}".strip()})
        if a.size:
            arr[...] = a
    for name, sub in tree.items():
        if isinstance(sub, dict):
            _write_tree(g.create_group(name), sub, name)


def open_run(path):
    """The run store as an ``xarray.DataTree`` (through the consolidated metadata)."""
    import xarray as xr
    return xr.open_datatree(str(path), engine="zarr", consolidated=True)

"""The run store's writer, :class:`RunStore`, and its commit protocol (``docs/run_store.md``).

One zarr v3 hierarchy per run (``run.zarr``), read as one ``xarray.DataTree``
(:func:`runstore.reader.open_run`). Layout and units: :func:`runstore.layout.run_schema`.
Every variable carries CF-style ``units`` and ``long_name`` attributes and names its
dimensions through zarr v3 ``dimension_names``.

Commit protocol (crash safety). Data are appended to the arrays in place (the new rows:
only the chunks they touch are rewritten, each file atomically, then the array's own
``zarr.json``; :mod:`runstore.appender`) and become visible only at :meth:`RunStore.commit`,
which rewrites the root ``zarr.json`` with the *consolidated* metadata of every array (one
atomic file replace).
Readers open the store through the consolidated metadata, so a reader, or a process opening
the store after a SIGKILL, sees the state of the last commit: every variable of a group has
the same length, and rows appended after it are invisible even though their chunks may be on
disk. A chunk rewritten after a commit still holds every committed row (appends only add
rows). :mod:`runstore.recover` trims the uncommitted rows of a store its writer never closed.
Consolidated metadata is a zarr-python convention outside the v3 specification: the store is
therefore read with zarr-python (version range bounded in ``pyproject.toml``), and a reader
that ignores it sees every array at its own (possibly longer) length.
"""

from __future__ import annotations

import json
import os
import shutil
import threading
import uuid
import warnings
from pathlib import Path

import numpy as np
import zarr

from tactile_flow.hardware.biotac import FINGERS

from . import inflight
from .appender import GrowingArray, MetadataTemplate, atomic_write, write_all
from .room import RoomToClose, room_path
from .jsonvalues import jsonable, utc_now
from .status import RunStatus
from .layout import SCHEMA_VERSION, STATUSES, Block, dim_sizes, fixed_coords, lab_streams, run_schema


def _zarr_dtype(dtype: str):
    return str if dtype == "str" else np.dtype(dtype)


def _fill(dtype: str):
    return {"f8": float("nan"), "str": "", "bool": False}.get(dtype, 0)


def row_counts(blocks: dict[str, dict[str, np.ndarray]], names) -> dict[str, int]:
    """The rows each block of ``blocks`` adds; ``ValueError`` naming a block whose variables are
    not ``names(block)`` (a set) or differ in length."""
    counts = {}
    for block, data in blocks.items():
        expected = names(block)
        if set(data) != expected:
            raise ValueError(f"{block}: expected variables {sorted(expected)}, got {sorted(data)}")
        lengths = {k: len(a) for k, a in data.items()}
        if len(set(lengths.values())) != 1:
            raise ValueError(f"{block}: variables of different lengths {lengths}")
        counts[block] = next(iter(lengths.values()))
    return counts


class RunStore:
    """Writer of one run store. Thread-safe; normally driven by a single writer thread.

    Create with :meth:`create`. :meth:`append` adds rows to a block (invisible to readers),
    :meth:`commit` publishes every append and attribute change atomically, :meth:`close`
    sets the final status and end time.
    """

    def __init__(self, path: Path, root: zarr.Group, schema: dict[str, Block], fingers: tuple[str, ...],
                 streams: dict | None = None):
        self.path = Path(path)
        self.schema = schema
        self.fingers = fingers
        self.streams = dict(streams or {})      # name -> hardware.streams.Stream: what the recorder fills
        self._root = root
        self._lock = threading.RLock()
        # the root zarr.json (consolidated metadata included) as last committed: a commit
        # moves its shapes and attributes forward and rewrites it in one piece
        self._root_meta = json.loads((self.path / "zarr.json").read_bytes())
        consolidated = self._root_meta["consolidated_metadata"]["metadata"]
        self._arrays = {b: {v.name: GrowingArray(self.path / blk.group / v.name, consolidated[f"{blk.group}/{v.name}"])
                            for v in blk.vars} for b, blk in schema.items()}
        self._length = {b: a[next(iter(a))].rows if a else 0 for b, a in self._arrays.items()}
        self._relist = False           # groups or arrays changed through zarr: consolidate by listing
        self._template: MetadataTemplate | None = None       # the root zarr.json, rows left open
        self._attrs: dict = {}
        self._attrs_dirty = False
        self.closed = False
        self.n_commits = 0

    # ---------------------------------------------------------------- creation
    @classmethod
    def create(cls, path, *, protocol: str, fingers=FINGERS, run_id: str | None = None,
               provenance: dict | None = None, attrs: dict | None = None,
               chunk_s: float = 5.0, live: tuple | None = None, stage: bool = False,
               streams: dict | None = None, room_bytes: int = 0, sensor=None) -> "RunStore":
        """Create ``path`` (must not exist) with every group, coordinate and empty variable,
        root attributes (``run_id``, ``protocol``, ``status="running"``, ``start_time``,
        ``schema_version``, ``provenance``) and commit it. ``live``: ``(fingers, views)``
        of the online tactile flow, to add the ``live`` group. ``streams``: the device
        streams it records (name → :class:`hardware.streams.Stream`, as the sample types'
        ``describe()`` declare them); by default the lab's
        (:func:`~runstore.layout.lab_streams` of ``fingers``, with ``stage`` the object stage's).
        ``sensor``: the :class:`tactile.sensor.SensorModel` of the tactile sensors, recorded in
        the root attributes ``sensor`` (name, taxels, checksum, file) and ``sensor_model`` (the
        whole model), so that an analysis reads the geometry the run used
        (:func:`runstore.sensor_of`); the BioTac SP's by default when ``streams`` is not given.

        Atomic: everything is made in a hidden directory beside ``path`` and renamed into
        place, so an interrupted creation leaves no half-made store (at most the hidden
        ``.<name>.creating-*`` directory, which :func:`remove_debris` clears).

        ``room_bytes``: disk held beside the store until :meth:`close` gives it back for the
        close's own writes (:mod:`runstore.room`); a disk without that much room refuses the
        store (``OSError``) before anything is written."""
        path = Path(path)
        if path.exists():
            raise FileExistsError(f"run store {path} already exists")
        fingers, streams, schema, root_attrs = plan(protocol=protocol, fingers=fingers, run_id=run_id,
                                                    provenance=provenance, attrs=attrs, chunk_s=chunk_s, live=live,
                                                    stage=stage, streams=streams, sensor=sensor)
        room = None
        if room_bytes:
            try:
                room = RoomToClose(room_path(path), room_bytes)
            except OSError as exc:
                refused = OSError(f"no room on the disk of {path.parent} to record: {room_bytes >> 10} kB are kept "
                                  f"from the start to close the run ({exc.strerror or exc})")
                refused.errno = exc.errno
                raise refused from None
        tmp = path.with_name(f".{path.name}.creating-{uuid.uuid4().hex[:8]}")
        try:
            _make_tree(tmp, schema, fixed_coords(streams, live), root_attrs)
            if path.exists():
                raise FileExistsError(f"run store {path} already exists")
            os.rename(tmp, path)
        except BaseException:
            inflight.settle()                    # an interrupt may have left zarr writing into it
            shutil.rmtree(tmp, ignore_errors=True)
            if room is not None:
                room.release()
            raise
        store = cls(path, zarr.open_group(str(path), mode="r+", use_consolidated=False), schema, fingers, streams)
        store._attrs = dict(root_attrs)
        store.n_commits = 1
        store._room = room
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
            self._relist = True

    def append(self, block: str, data: dict[str, np.ndarray]) -> int:
        """Append rows to every variable of ``block``; returns the number of rows.

        ``data`` maps each variable name of the block to an array whose first axis is the
        new rows (the same count for all) and whose other axes match the schema. Not
        visible to readers until :meth:`commit`.
        """
        return self.append_many({block: data})[block]

    def append_many(self, blocks: dict[str, dict[str, np.ndarray]]) -> dict[str, int]:
        """:meth:`append` for several blocks at once. Every array's new chunks are encoded
        first (bad rows raise before anything is written), then written with the arrays' own
        ``zarr.json`` (:mod:`runstore.appender`). On failure every block is rolled back."""
        counts = row_counts(blocks, lambda block: {v.name for v in self.schema[block].vars})
        with self._lock:
            self._check_open()
            write_all([self._arrays[block][name].encode(self._length[block], a)
                       for block, n in counts.items() if n for name, a in blocks[block].items()])
            for block, n in counts.items():
                self._length[block] += n
        return counts

    def _zarr_array(self, block: str, var: str) -> zarr.Array:
        """A zarr handle on ``var`` of ``block`` as its own ``zarr.json`` describes it now."""
        return self._root[f"{self.schema[block].group}/{var}"]

    def rewrite(self, block: str, var: str, values: np.ndarray) -> None:
        """Overwrite the whole of ``var`` (e.g. a time coordinate after the final clock-model
        refit); ``values`` must have the current length. Chunks are replaced one by one, so a
        crash in the middle leaves a mix of old and new values, never a torn chunk."""
        with self._lock:
            self._check_open()
            arr = self._zarr_array(block, var)
            if len(values) != self._length[block] or arr.shape[0] != self._length[block]:
                raise ValueError(f"{block}/{var}: rewrite with {len(values)} rows, store has {self._length[block]}")
            if len(values):
                arr[:] = np.asarray(values)
                self._arrays[block][var].forget_tail()

    def transform(self, block: str, var: str, source: str, fn, chunks_per_step: int = 16) -> None:
        """Overwrite ``var`` with ``fn(source)`` piece by piece (``chunks_per_step`` chunks at a
        time, aligned to chunks so each is written once): bounded memory for a whole-run
        rewrite such as the final clock-model refit of a time coordinate."""
        with self._lock:
            self._check_open()
            n, step = self._length[block], self.schema[block].chunk * chunks_per_step
            dst, src = self._zarr_array(block, var), self._zarr_array(block, source)
            for i in range(0, n, step):
                j = min(n, i + step)
                dst[i:j] = fn(src[i:j])
            self._arrays[block][var].forget_tail()

    def read(self, block: str, var: str, step: int = 1) -> np.ndarray:
        """Every ``step``-th row of ``var`` written so far (including uncommitted ones)."""
        with self._lock:
            return self._zarr_array(block, var)[: self._length[block]: step]

    def write_tree(self, group: str, tree: dict, attrs: dict | None = None) -> None:
        """Write a nested dict of arrays/scalars/strings once as ``group`` (e.g. ``truth``):
        nested dicts become subgroups; in a subgroup whose arrays share their first length,
        that axis is the dimension named after the subgroup, other axes are ``<var>_dim<k>``.
        Units come from the name (see :func:`_guess_units`)."""
        with self._lock:
            self._check_open()
            self._relist = True
            self._root.require_group(group).attrs.update(jsonable(attrs or {}))
            _write_tree(self._own_group(group), tree, group.rsplit("/", 1)[-1], group)

    def write_variable(self, group: str, name: str, values, dims: tuple[str, ...], units: str, long_name: str,
                       **attrs) -> None:
        """Write a fixed (non-growing) variable once, e.g. ``biotac/baseline`` (finger, taxel)."""
        values = np.asarray(values)
        with self._lock:
            self._check_open()
            self._relist = True
            a = self._own_group(group).create_array(
                name, shape=values.shape, chunks=values.shape, dtype=values.dtype, dimension_names=list(dims),
                attributes=jsonable({"units": units, "long_name": long_name, **attrs}))
            a[...] = values

    def _own_group(self, group: str) -> zarr.Group:
        """``group`` opened as a store of its own, to add nodes to it. Through the root, zarr
        re-reads every parent's ``zarr.json`` for each node it adds, the root's with the
        consolidated metadata of the whole store (150 kB: ~3 ms per node)."""
        return zarr.open_group(str(self.path / group), mode="r+", zarr_format=3)

    def commit(self) -> None:
        """Publish every append and attribute change: one atomic rewrite of the root
        metadata (consolidated metadata of all nodes).

        The consolidated metadata is the last commit's with the growing arrays' shapes (and
        the root attributes) moved forward: the same JSON ``zarr.consolidate_metadata`` would
        write, without listing and re-reading every node. After a change made through zarr
        (group attributes, the ``truth`` tree, a fixed variable) the store is listed once,
        by ``zarr.consolidate_metadata`` itself."""
        with self._lock:
            self._check_consistent()
            if self._relist:
                self._consolidate()
            else:
                if self._template is None or self._attrs_dirty:
                    self._root_meta["attributes"].update(self._attrs)
                    self._template = MetadataTemplate(self._root_meta, list(self._growing()))
                atomic_write(self.path / "zarr.json", self._template.fill([a.rows for a in self._growing().values()]))
            self._attrs_dirty = False
            self.n_commits += 1

    def _growing(self) -> dict[str, GrowingArray]:
        """Every growing array by its path in the store (``biotac/electrodes``)."""
        return {f"{blk.group}/{name}": a for blk, arrays in zip(self.schema.values(), self._arrays.values())
                for name, a in arrays.items()}

    def _consolidate(self) -> None:
        """Commit by zarr's own ``consolidate_metadata`` (lists and reads every node)."""
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")     # "consolidated metadata not in the v3 spec"
            if self._attrs_dirty:
                # A handle opened on the consolidated metadata rewrites zarr.json with it,
                # so the root stays consolidated (at the previous commit) while the
                # attributes change; then the consolidation moves every shape forward.
                zarr.open_group(str(self.path), mode="r+", use_consolidated=None).update_attributes(self._attrs)
            zarr.consolidate_metadata(str(self.path))
        self._root_meta = json.loads((self.path / "zarr.json").read_bytes())
        self._relist, self._template = False, None

    def _check_consistent(self) -> None:
        for b, arrays in self._arrays.items():
            bad = {k: a.rows for k, a in arrays.items() if a.rows != self._length[b]}
            if bad:
                raise RuntimeError(f"run store {self.path}: block {b} has inconsistent lengths {bad} "
                                   f"(expected {self._length[b]}); refusing to commit")

    def _check_open(self) -> None:
        if self.closed:
            raise RuntimeError(f"run store {self.path} is closed")

    def close(self, status: str, **attrs) -> None:
        """Set ``status`` (one of :data:`STATUSES`), ``end_time`` and ``attrs``; final commit
        (into the room held since the creation, if any: released first)."""
        if status not in STATUSES:
            raise ValueError(f"status {status!r} not one of {STATUSES}")
        with self._lock:
            if self.closed:
                return
            room = self._room
            if room is not None:
                room.release()                   # the room kept for these writes (runstore.room)
            self.set_attrs(status=status, end_time=utc_now(), **attrs)
            self.commit()
            self.closed = True


def plan(*, protocol: str, fingers=FINGERS, run_id: str | None = None, provenance: dict | None = None,
         attrs: dict | None = None, chunk_s: float = 5.0, live: tuple | None = None, stage: bool = False,
         streams: dict | None = None, sensor=None) -> tuple[tuple, dict, dict[str, Block], dict]:
    """What :meth:`RunStore.create` makes a store of (its arguments, the same defaults):
    ``(fingers, streams, schema, root attributes)``, the status ``running``."""
    fingers = tuple(fingers)
    if sensor is None and streams is None:
        from tactile_flow.tactile.sensor import builtin_sensor
        sensor = builtin_sensor()
    streams = lab_streams(fingers, stage, sensor) if streams is None else dict(streams)
    schema = run_schema(chunk_s, live=bool(live), streams=streams)
    prov = provenance or {}
    recorded = {} if sensor is None else {"sensor": sensor.summary(), "sensor_model": sensor.spec}
    root_attrs = jsonable(dict(run_id=run_id or prov.get("run_id") or str(uuid.uuid4()), protocol=protocol,
                               status=RunStatus.RUNNING, start_time=prov.get("start_time") or utc_now(), end_time=None,
                               schema_version=SCHEMA_VERSION, fingers=list(fingers), provenance=prov,
                               **recorded, **(attrs or {})))
    return fingers, streams, schema, root_attrs


def _make_tree(path: Path, schema: dict[str, Block], coords: dict, attrs: dict) -> None:
    """Every group, coordinate (``coords``: :func:`~runstore.layout.fixed_coords`) and empty
    variable of a new store at ``path``, with the root ``attrs``, consolidated (the first commit)."""
    sizes = dim_sizes(coords)
    root = zarr.open_group(str(path), mode="w-", zarr_format=3)
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


def _write_tree(g: zarr.Group, tree: dict, label: str, where: str) -> None:
    """``tree`` into ``g``, which is at ``where`` in the run store (``truth/crossings``)."""
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
                                         "long_name": f"{where.replace('/', ' ')} {name}".strip()})
        if a.size:
            arr[...] = a
    for name, sub in tree.items():
        if isinstance(sub, dict):
            _write_tree(g.create_group(name), sub, name, f"{where}/{name}")

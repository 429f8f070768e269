"""A run store made in memory and written once, packed: what an import of a short record writes.

:class:`RunStore` makes a store as a directory — one ``zarr.json`` per node through zarr, each
append's chunks as files, a consolidation by listing the store — because a recording
streams and must survive a crash. An imported file needs none of that: its store is written
once and then packed into one zip (:mod:`.packed`). :class:`MemoryRunStore` builds the same
store as ``{key: bytes}`` in memory — the same nodes, metadata and chunks (the appends encoded
by :class:`.appender.GrowingArray`, as :class:`RunStore` encodes them; the ``zarr.json``
documents as zarr-python writes them) — and :meth:`MemoryRunStore.write` writes the zip in one
go, aside and renamed (:func:`.packed.write_zip`). Its members are byte for byte those of the
directory store packed (``tests/test_inmemory_store.py`` compares them), without ~250 file
operations and some 40 calls through zarr's event loop per record (~0.09 CPU s of a short
import's 0.13: ``docs/performance.md``, "Datasets").

Memory: every chunk of the store, encoded — an importer uses it only for a file that fits in
one import chunk (:data:`importers.recording.CHUNK_FRAMES` frames), which it holds anyway.
"""

from __future__ import annotations

import threading
from pathlib import Path

import numpy as np

from . import packed
from .appender import GrowingArray, metadata_bytes
from .jsonvalues import jsonable, utc_now
from .layout import STATUSES, dim_sizes, fixed_coords
from .writer import _fill, plan, row_counts

_ZSTD = {"name": "zstd", "configuration": {"level": 0, "checksum": False}}
#: a group's view in the consolidated metadata (zarr-python's: an empty inline block of its own)
_INLINE_EMPTY = {"kind": "inline", "must_understand": False, "metadata": {}}


def array_meta(shape, chunks, dtype: str, fill, dims, attrs: dict) -> dict:
    """An array's ``zarr.json`` as zarr-python's ``create_array`` writes it (codecs ``bytes``
    (little-endian) or ``vlen-utf8``, then ``zstd`` level 0; ``dtype`` a numpy type name or
    ``"str"``; ``fill`` the fill value)."""
    if dtype == "str":
        data_type, codec, fill_value = "string", {"name": "vlen-utf8", "configuration": {}}, str(fill)
    else:
        dt = np.dtype(dtype)
        data_type = dt.name
        codec = {"name": "bytes"} if dt.itemsize == 1 else {"name": "bytes", "configuration": {"endian": "little"}}
        fill_value = _fill_json(dt, fill)
    return {"shape": [int(n) for n in shape], "data_type": data_type,
            "chunk_grid": {"name": "regular", "configuration": {"chunk_shape": [int(c) for c in chunks]}},
            "chunk_key_encoding": {"name": "default", "configuration": {"separator": "/"}},
            "fill_value": fill_value, "codecs": [codec, _ZSTD], "attributes": attrs,
            "dimension_names": list(dims), "zarr_format": 3, "node_type": "array", "storage_transformers": []}


def _fill_json(dt: np.dtype, fill):
    if dt.kind == "f":
        f = float(fill)
        return "NaN" if np.isnan(f) else ("Infinity" if f == np.inf else "-Infinity" if f == -np.inf else f)
    if dt.kind == "b":
        return bool(fill)
    return int(fill)


def group_meta(attrs: dict) -> dict:
    """A group's ``zarr.json``."""
    return {"attributes": attrs, "zarr_format": 3, "node_type": "group"}


def member_order(key: str) -> tuple:
    """Sort key of a store's members in the order :func:`.packed.pack` walks a directory store:
    depth first, in each directory its files before its subdirectories, names sorted."""
    parts = key.split("/")
    return (*((1, p) for p in parts[:-1]), (0, parts[-1]))


class MemoryRunStore:
    """A run store built in memory (what :meth:`RunStore.create` makes, with the same
    arguments) and written once by :meth:`write` as a packed store. The writing calls an
    import makes of a :class:`RunStore` work alike: :meth:`append`, :meth:`append_many`,
    :meth:`set_attrs`, :meth:`set_group_attrs`, :meth:`write_variable`,
    :meth:`remove_variable`, :meth:`close`; nothing is on disk before :meth:`write`."""

    def __init__(self, *, protocol: str, **create):
        self.fingers, self.streams, self.schema, attrs = plan(protocol=protocol, **create)
        self._lock = threading.RLock()
        self._attrs = dict(attrs)
        self._groups: dict[str, dict] = {}                 # group path -> its attributes
        self._arrays: dict[str, GrowingArray] = {}         # "biotac/electrodes" -> the array
        self._chunks: dict[str, bytes] = {}                # "biotac/electrodes/c/0/0/0" -> bytes
        self._blocks = {b: {v.name: f"{blk.group}/{v.name}" for v in blk.vars} for b, blk in self.schema.items()}
        self._length = dict.fromkeys(self.schema, 0)
        coords = fixed_coords(self.streams, create.get("live"))
        sizes = dim_sizes(coords)
        for group in dict.fromkeys(b.group for b in self.schema.values()):
            self._groups[group] = {}
            for name, (values, units, long_name) in coords.get(group, {}).items():
                dtype = "str" if values.dtype.kind == "U" else values.dtype.name
                self._fixed(f"{group}/{name}", values, dtype, _fill(dtype) if dtype == "str" else 0, [name],
                            {"units": units, "long_name": long_name})
        for blk in self.schema.values():
            for v in blk.vars:
                shape = (0, *(sizes[d] for d in v.dims[1:]))
                dtype = v.dtype if v.dtype == "str" else np.dtype(v.dtype).name
                meta = array_meta(shape, (blk.chunk, *shape[1:]), dtype, _fill(v.dtype), v.dims,
                                  {"units": v.units, "long_name": v.long_name})
                self._arrays[f"{blk.group}/{v.name}"] = GrowingArray(Path(blk.group, v.name), meta)
        self.closed = False

    # ---------------------------------------------------------------- writing
    def length(self, block: str) -> int:
        return self._length[block]

    @property
    def attrs(self) -> dict:
        with self._lock:
            return dict(self._attrs)

    def set_attrs(self, **attrs) -> None:
        """Set root attributes (JSON-serialisable values)."""
        with self._lock:
            self._attrs.update(jsonable(attrs))

    def set_group_attrs(self, group: str, **attrs) -> None:
        with self._lock:
            self._groups[group].update(jsonable(attrs))

    def append(self, block: str, data: dict[str, np.ndarray]) -> int:
        return self.append_many({block: data})[block]

    def append_many(self, blocks: dict[str, dict[str, np.ndarray]]) -> dict[str, int]:
        """Rows appended to several blocks (as :meth:`RunStore.append_many`: every variable of
        a block, the same count of rows; encoded before anything is kept)."""
        counts = row_counts(blocks, lambda block: set(self._blocks[block]))
        with self._lock:
            self._check_open()
            pending = [(self._blocks[block][name], self._arrays[self._blocks[block][name]].encode(self._length[block], a))
                       for block, n in counts.items() if n for name, a in blocks[block].items()]
            for key, p in pending:
                self._keep(key, p)
            for block, n in counts.items():
                self._length[block] += n
        return counts

    def write_variable(self, group: str, name: str, values, dims: tuple[str, ...], units: str, long_name: str,
                       **attrs) -> None:
        """A fixed variable written once, one chunk (as :meth:`RunStore.write_variable`)."""
        values = np.asarray(values)
        with self._lock:
            self._fixed(f"{group}/{name}", values, values.dtype.name, 0, dims,
                        jsonable({"units": units, "long_name": long_name, **attrs}))

    def remove_variable(self, group: str, name: str) -> None:
        """Remove the array ``group/name`` and its chunks (a channel the source lacks)."""
        key = f"{group}/{name}"
        with self._lock:
            del self._arrays[key]
            for k in [k for k in self._chunks if k.startswith(key + "/")]:
                del self._chunks[k]
            for names in self._blocks.values():
                if names.get(name) == key:
                    del names[name]

    def close(self, status: str, **attrs) -> None:
        """Set ``status``, ``end_time`` and ``attrs``; nothing more can be appended."""
        if status not in STATUSES:
            raise ValueError(f"status {status!r} not one of {STATUSES}")
        with self._lock:
            if not self.closed:
                self.set_attrs(status=status, end_time=utc_now(), **attrs)
                self.closed = True

    def read(self, block: str, var: str) -> np.ndarray:
        """Every row of the numeric variable ``var`` of ``block`` appended so far."""
        with self._lock:
            a = self._arrays[self._blocks[block][var]]
            n, parts = self._length[block], []
            for i in range(0, n, a.chunk):
                data = self._chunks.get(f"{self._blocks[block][var]}/{a.key(i // a.chunk)}")
                parts.append(np.full((a.chunk, *a.row_shape), a.fill, a.dtype) if data is None else
                             np.frombuffer(a.decode(data), a.dtype).reshape(a.chunk, *a.row_shape))
            return np.concatenate(parts)[:n] if parts else np.empty((0, *a.row_shape), a.dtype)

    # ---------------------------------------------------------------- the store
    def members(self) -> dict[str, bytes]:
        """The store as ``{key: bytes}`` in :func:`.packed.pack`'s order: every node's
        ``zarr.json``, its chunks, the root's with the consolidated metadata of every node."""
        with self._lock:
            nodes: dict[str, dict] = {g: group_meta(a) for g, a in self._groups.items()}
            nodes.update((k, a.meta) for k, a in self._arrays.items())
            files = {f"{k}/zarr.json": metadata_bytes(m) for k, m in nodes.items()}
            files.update(self._chunks)
            consolidated = {k: ({"attributes": nodes[k]["attributes"], "zarr_format": 3,
                                 "consolidated_metadata": _INLINE_EMPTY, "node_type": "group"}
                                if nodes[k]["node_type"] == "group" else nodes[k])
                            for k in sorted(nodes, key=lambda k: (k.count("/"), k))}
            files["zarr.json"] = metadata_bytes({"attributes": self._attrs, "zarr_format": 3, "consolidated_metadata": {
                **_INLINE_EMPTY, "metadata": consolidated}, "node_type": "group"})
            return {k: files[k] for k in sorted(files, key=member_order)}

    def write(self, target) -> Path:
        """Write the store as the packed store ``target`` (``*.zarr.zip``, must not exist):
        whole or absent (:func:`.packed.write_zip`)."""
        return packed.write_zip(self.members().items(), target)

    # ---------------------------------------------------------------- helpers
    def _fixed(self, key: str, values: np.ndarray, dtype: str, fill, dims, attrs: dict) -> None:
        """A fixed array ``key`` of ``values``, one chunk."""
        shape = values.shape
        a = GrowingArray(Path(key), array_meta((0, *shape[1:]), [max(1, n) for n in shape], dtype, fill, dims, attrs))
        if len(values):
            self._keep(key, a.encode(0, values))
        self._arrays[key] = a

    def _keep(self, key: str, p) -> None:
        """Keep an encoded append's chunks (a chunk of fill values only: none) and rows."""
        for chunk, data in p.files:
            if data is None:
                self._chunks.pop(f"{key}/{chunk}", None)
            else:
                self._chunks[f"{key}/{chunk}"] = data
        p.array.advance(p)

    def _check_open(self) -> None:
        if self.closed:
            raise RuntimeError("run store is closed")

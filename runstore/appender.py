"""Rows appended to the run store's growing arrays as zarr v3 files, written directly.

A growing array of the run store is fully described by its ``zarr.json`` (the zarr v3
specification): a regular chunk grid that grows along its first axis only, the ``default``
chunk-key encoding (``c/i/0/0``), and the codecs ``bytes`` (little-endian, C order) or
``vlen-utf8`` followed by ``zstd``. Appending ``k`` rows to an array of ``n0`` rows writes the
chunks that rows ``n0 .. n0+k`` touch — the last partial chunk (whose rows are kept in memory,
so it is never read back and decoded) and any new ones — each through a temporary file and a
rename, as zarr-python's ``LocalStore`` does, then the array's ``zarr.json`` with the new shape.
The files are byte for byte those zarr-python writes for the same rows (the same numcodecs
codecs and JSON; ``tests/test_appender.py`` compares them), and a chunk holding nothing but the
fill value is not written, as with zarr's default ``write_empty_chunks=False``.

Why not zarr's ``resize`` and ``setitem``: each call goes through zarr's event loop, a
thread-pool hop per file, a re-validation of the metadata and a read-back of the partial chunk,
about 1.5 ms of CPU per array and commit; with some 45 arrays committed every 0.4–0.75 s that
was most of the recorder's cost (``docs/performance.md``, "Recording cost").
"""

from __future__ import annotations

import itertools
import json
import os
import re
import uuid
from dataclasses import dataclass
from pathlib import Path

import numcodecs
import numpy as np
import zarr

# Metadata without indentation, zarr's own writes included (its ``json_indent``, 2 by default): a
# short run's metadata is most of its bytes (the root ``zarr.json`` with the consolidated metadata
# of every array: 29 kB indented, 14 kB compact for an imported 275-frame record). Set once, for
# the process, so that every ``zarr.json`` of a store is written one way (ours and zarr's alike);
# readers are unaffected (JSON is JSON).
zarr.config.set({"json_indent": None})

_TYPES = {"bool", "int8", "int16", "int32", "int64", "uint8", "uint16", "uint32", "uint64", "float32", "float64",
          "string"}


@dataclass(frozen=True)
class Pending:
    """An append encoded and not yet written: the chunk files (key → bytes, ``None`` for a
    chunk that holds only the fill value), the rows after it and the new partial last chunk."""

    array: "GrowingArray"
    rows: int
    files: tuple[tuple[str, bytes | None], ...]
    tail: np.ndarray


class GrowingArray:
    """One array of the run store that grows along its first axis.

    ``directory``: the array's directory; ``meta``: its ``zarr.json`` as a dict. Raises
    ``ValueError`` (naming the array and what it holds) for metadata outside what this writer
    knows: a regular grid chunked along the first axis only, the ``default`` chunk-key
    encoding, ``bytes``/``vlen-utf8`` then at most ``zstd``, a numeric, boolean or string type.
    """

    def __init__(self, directory: Path, meta: dict):
        self.directory = Path(directory)
        self.meta = meta
        self.rows = int(meta["shape"][0])            # the rows its zarr.json says
        self.row_shape = tuple(meta["shape"][1:])
        _check(meta, f"run store array {self.directory}")
        self.chunk = int(meta["chunk_grid"]["configuration"]["chunk_shape"][0])
        self._sep = meta["chunk_key_encoding"].get("configuration", {}).get("separator", "/")
        self._text = meta["data_type"] == "string"
        self.dtype = np.dtype(object) if self._text else np.dtype(meta["data_type"]).newbyteorder("<")
        self.fill = meta["fill_value"] if self._text else np.array(meta["fill_value"], self.dtype)[()]
        zstd = [c.get("configuration", {}) for c in meta["codecs"] if c["name"] == "zstd"]
        self._zstd = (numcodecs.Zstd(level=zstd[0].get("level", 0), checksum=zstd[0].get("checksum", False))
                      if zstd else None)
        self._tail: np.ndarray | None = (np.empty((0, *self.row_shape), self.dtype)
                                         if self.rows % self.chunk == 0 else None)   # None: read it back
        self._dirs: set[Path] = set()
        self._template = MetadataTemplate(meta)

    # ------------------------------------------------------------------ appending
    def encode(self, n0: int, values) -> Pending:
        """Encode the append of ``values`` (rows, then this array's other axes) at row ``n0``
        (the rows the array holds): nothing is written yet. Raises ``ValueError`` for rows of
        the wrong shape."""
        a = self._cast(values)
        if a.shape[1:] != self.row_shape:
            raise ValueError(f"run store array {self.directory}: rows of shape {a.shape[1:]}, "
                             f"expected {self.row_shape}")
        first = n0 - n0 % self.chunk
        tail = self._tail_rows(first, n0)
        rows = np.concatenate([tail, a]) if len(tail) else a
        files = tuple((self._key((first + i) // self.chunk), self._encode_chunk(rows[i:i + self.chunk]))
                      for i in range(0, len(rows), self.chunk))
        return Pending(self, n0 + len(a), files, rows[len(rows) - len(rows) % self.chunk:].copy())

    def write(self, p: Pending) -> None:
        """Write ``p``'s chunks (each atomically), then the ``zarr.json`` with its shape."""
        for key, data in p.files:
            path = self.directory / key
            if data is None:
                path.unlink(missing_ok=True)         # all fill value: zarr writes no chunk
            else:
                self._mkdir(path.parent)
                atomic_write(path, data)
        self.set_rows(p.rows)
        self._tail = p.tail

    def set_rows(self, rows: int) -> None:
        """Rewrite the ``zarr.json`` with ``rows`` rows (chunks are left as they are)."""
        atomic_write(self.directory / "zarr.json", self._template.fill([rows]))
        self.meta, self.rows = {**self.meta, "shape": [rows, *self.row_shape]}, rows

    def advance(self, p: Pending) -> None:
        """Take ``p`` as written elsewhere (in memory: :class:`.inmemory.MemoryRunStore`): its
        rows (the ``zarr.json`` it would write) and the partial last chunk."""
        self.meta, self.rows = {**self.meta, "shape": [p.rows, *self.row_shape]}, p.rows
        self._tail = p.tail

    def key(self, i: int) -> str:
        """The chunk key of the ``i``-th chunk along the first axis (``c/i/0/0``)."""
        return self._key(i)

    def decode(self, data: bytes) -> bytes:
        """A numeric chunk's raw bytes from its file content."""
        return bytes(self._zstd.decode(data)) if self._zstd is not None else data

    def forget_tail(self) -> None:
        """The last chunk was rewritten by other means (zarr): read it back at the next append."""
        self._tail = None

    # ------------------------------------------------------------------ helpers
    def _cast(self, values) -> np.ndarray:
        """``values`` in this array's type, as zarr's ``setitem`` casts them (text through numpy's
        ``StringDType``, so a number becomes its ``str``)."""
        if self._text:
            return np.asarray(values, dtype=np.dtypes.StringDType()).astype(object)
        return np.asarray(values, dtype=self.dtype)

    def _tail_rows(self, first: int, n0: int) -> np.ndarray:
        """Rows ``first .. n0`` of the last partial chunk, from memory (or read back once)."""
        if self._tail is None or len(self._tail) != n0 - first:
            self._tail = self._cast(zarr.open_array(str(self.directory), mode="r")[first:n0])
        return self._tail

    def _key(self, i: int) -> str:
        return self._sep.join(map(str, ("c", i, *(0 for _ in self.row_shape))))

    def _encode_chunk(self, rows: np.ndarray) -> bytes | None:
        """One chunk's file content (``rows`` padded with the fill value), ``None`` if it holds
        only the fill value."""
        if len(rows) == self.chunk:
            chunk = rows
        else:
            chunk = np.full((self.chunk, *self.row_shape), self.fill, self.dtype)
            chunk[:len(rows)] = rows
        if all_fill(chunk, self.fill):
            return None
        raw = numcodecs.VLenUTF8().encode(chunk) if self._text else np.ascontiguousarray(chunk).tobytes()
        return bytes(self._zstd.encode(raw)) if self._zstd is not None else bytes(raw)

    def _mkdir(self, d: Path) -> None:
        if d not in self._dirs:
            d.mkdir(parents=True, exist_ok=True)
            self._dirs.add(d)


def _check(meta: dict, where: str) -> None:
    """Refuse (``ValueError`` naming the array) metadata this writer does not write."""
    name, grid, key = meta.get("data_type"), meta.get("chunk_grid", {}), meta.get("chunk_key_encoding", {})
    codecs = meta.get("codecs", [])
    if name not in _TYPES:
        raise ValueError(f"{where}: data type {name!r} not one the run store appends; expected one of {sorted(_TYPES)}")
    if grid.get("name") != "regular" or list(grid["configuration"]["chunk_shape"][1:]) != list(meta["shape"][1:]):
        raise ValueError(f"{where}: chunk grid {grid} not regular along the first axis only")
    if key.get("name") != "default":
        raise ValueError(f"{where}: chunk-key encoding {key} not zarr's 'default'")
    names = [c.get("name") for c in codecs]
    endian = codecs[0].get("configuration", {}).get("endian", "little") if codecs else None
    if names not in (["bytes"], ["bytes", "zstd"], ["vlen-utf8"], ["vlen-utf8", "zstd"]) or (
            names[0] == "bytes" and endian != "little"):
        raise ValueError(f"{where}: codecs {codecs} not bytes (little-endian) or vlen-utf8, then zstd")


def write_all(pending: list[Pending]) -> None:
    """Write every pending append. On failure (a full disk) every array's ``zarr.json`` is set
    back to its rows before (best effort) and the error re-raised: chunks written meanwhile
    still hold every earlier row, since an append only adds rows behind them."""
    before = [(p.array, p.array.rows, p.array._tail) for p in pending]
    try:
        for p in pending:
            p.array.write(p)
    except BaseException:
        for array, rows, tail in before:
            array._tail = tail
            try:
                if array.rows != rows:
                    array.set_rows(rows)
            except Exception:                    # noqa: BLE001 - the store refuses to commit instead
                pass
        raise


def metadata_bytes(meta: dict) -> bytes:
    """A ``zarr.json`` as zarr-python serialises it (its configured indent, none in a process that
    imported this module; NaN allowed)."""
    return json.dumps(meta, allow_nan=True, indent=zarr.config.get("json_indent")).encode()


class MetadataTemplate:
    """:func:`metadata_bytes` of a ``zarr.json`` in which only arrays' row counts change,
    serialised once with a slot for each count and then filled in by a join: Python's JSON
    encoder is pure Python when it indents (some 30 ms for a run's 150 kB root metadata).

    ``meta``: an array's ``zarr.json`` (one slot, its first dimension), or with ``keys`` a
    group's whose consolidated metadata holds the arrays ``keys`` (a slot for each)."""

    def __init__(self, meta: dict, keys: list[str] | None = None):
        token = uuid.uuid4().hex

        def slotted(m: dict, i: int) -> dict:
            return {**m, "shape": [f"{token}:{i}", *m["shape"][1:]]}

        if keys is None:
            meta = slotted(meta, 0)
        else:
            cm = meta["consolidated_metadata"]
            inner = dict(cm["metadata"])
            inner.update((k, slotted(inner[k], i)) for i, k in enumerate(keys))
            meta = {**meta, "consolidated_metadata": {**cm, "metadata": inner}}
        pieces = re.split(rb'"%s:(\d+)"' % token.encode(), metadata_bytes(meta))
        self._text, self._slots = pieces[0::2], [int(i) for i in pieces[1::2]]

    def fill(self, rows: list[int]) -> bytes:
        """The ``zarr.json`` with ``rows[i]`` rows in slot ``i``."""
        out = [self._text[0]]
        for slot, text in zip(self._slots, self._text[1:]):
            out += (str(rows[slot]).encode(), text)
        return b"".join(out)


_tmp_names = itertools.count()


def atomic_write(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file and a rename: a reader, or a process
    killed meanwhile, finds the old file or the new one, never a torn one."""
    tmp = path.with_name(f"{path.name}.{os.getpid()}-{next(_tmp_names)}.partial")
    try:
        with open(tmp, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def all_fill(chunk: np.ndarray, fill) -> bool:
    """Whether every element is the fill value, as zarr decides it (NaN equals NaN; a zero
    float fill compares bit patterns, so -0.0 is data)."""
    if chunk.dtype.kind == "f":
        if np.isnan(fill):
            return bool(np.isnan(chunk).all())
        if fill == 0:
            return not chunk.view(f"u{chunk.itemsize}").any()
    return bool((chunk == fill).all())

"""A small packed store read without zarr-python: the whole zip read once, its arrays decoded here.

Opening a packed ``run.zarr.zip`` through zarr-python and reading the dozen arrays the
analysis needs costs some 30 calls through zarr's event-loop thread, ~10 ms of CPU for a
275-frame import, more than the arrays' decoding. A packed store is written once and never
appended to, so its consolidated metadata (the root ``zarr.json``) is every node's own; for a
short store (at most :data:`MAX_BYTES`) :func:`open_small` reads the zip in one go and
returns a read-only :class:`Group` with the few operations the analysis's loader uses
(``group_keys``, ``groups``, ``arrays``, ``g["biotac"]["time"][...]``, ``attrs``, an array's
``shape`` and ``metadata.dimension_names``), decoding exactly the zarr v3 this project writes:
a regular chunk grid, the default chunk-key encoding, ``bytes`` (little-endian) or
``vlen-utf8`` then ``zstd``, core numeric and boolean types and ``string``. Anything else
(another codec, a bigger store, a damaged zip or metadata) returns ``None``: the caller opens
the store with zarr-python, which reads everything and says what is wrong.

The values are zarr-python's, array for array (``tests/test_packed_read.py``); text comes
back as an ``object`` array of ``str``.
"""

from __future__ import annotations

import itertools
import json
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numcodecs
import numpy as np

#: packed stores up to this size (bytes) are read here, whole; larger ones through zarr
MAX_BYTES = 4 << 20
_NUMERIC = {"bool", "int8", "int16", "int32", "int64", "uint8", "uint16", "uint32", "uint64", "float32", "float64"}


@dataclass(frozen=True)
class Metadata:
    dimension_names: tuple[str, ...] | None


class Array:
    """One array of a packed store, decoded on first read (whole)."""

    def __init__(self, key: str, meta: dict, members: dict[str, bytes]):
        self.key, self._meta, self._members = key, meta, members
        self.shape = tuple(int(n) for n in meta["shape"])
        self.ndim = len(self.shape)
        names = meta.get("dimension_names")
        self.metadata = Metadata(tuple(names) if names is not None else None)
        self.attrs = dict(meta.get("attributes") or {})
        self._text = meta["data_type"] == "string"
        self.dtype = np.dtype(object) if self._text else np.dtype(meta["data_type"]).newbyteorder("<")
        self._values: np.ndarray | None = None

    def __getitem__(self, key):
        if self._values is None:
            self._values = self._read()
        out = self._values[key]
        return out.copy() if isinstance(out, np.ndarray) else out

    def _read(self) -> np.ndarray:
        chunks = [int(c) for c in self._meta["chunk_grid"]["configuration"]["chunk_shape"]]
        sep = self._meta["chunk_key_encoding"].get("configuration", {}).get("separator", "/")
        fill = self._meta["fill_value"]
        if self._text:
            out = np.full(self.shape, fill, dtype=object)
        else:
            out = np.full(self.shape, float(fill) if isinstance(fill, str) else fill, self.dtype)
        zstd = any(c["name"] == "zstd" for c in self._meta["codecs"])
        for index in itertools.product(*(range(-(-n // c)) for n, c in zip(self.shape, chunks))):
            data = self._members.get(f"{self.key}/" + sep.join(map(str, ("c", *index))))
            if data is None:
                continue                                  # a chunk of fill values only is not stored
            raw = numcodecs.Zstd().decode(data) if zstd else data
            if self._text:
                block = np.asarray(numcodecs.VLenUTF8().decode(raw), dtype=object).reshape(chunks)
            else:
                block = np.frombuffer(raw, self.dtype).reshape(chunks)
            where = tuple(slice(i * c, min(n, (i + 1) * c)) for i, c, n in zip(index, chunks, self.shape))
            out[where] = block[tuple(slice(0, s.stop - s.start) for s in where)]
        return out


class Group:
    """A group of a packed store: its children by name, ``attrs``."""

    def __init__(self, path: str, nodes: dict[str, dict], members: dict[str, bytes]):
        self._path, self._nodes, self._members = path, nodes, members
        self.attrs = dict(nodes[path].get("attributes") or {})

    def _children(self):
        prefix = f"{self._path}/" if self._path else ""
        for key, meta in self._nodes.items():
            if key and key.startswith(prefix) and "/" not in key[len(prefix):]:
                yield key[len(prefix):], key, meta

    def group_keys(self):
        return [name for name, _, meta in self._children() if meta["node_type"] == "group"]

    def groups(self):
        return [(name, Group(key, self._nodes, self._members)) for name, key, meta in self._children()
                if meta["node_type"] == "group"]

    def arrays(self):
        return [(name, Array(key, meta, self._members)) for name, key, meta in self._children()
                if meta["node_type"] == "array"]

    def __contains__(self, name: str) -> bool:
        return self._key(name) in self._nodes

    def __getitem__(self, name: str):
        key = self._key(name)
        meta = self._nodes.get(key)
        if meta is None:
            raise KeyError(name)
        return Group(key, self._nodes, self._members) if meta["node_type"] == "group" else \
            Array(key, meta, self._members)

    def _key(self, name: str) -> str:
        return f"{self._path}/{name}" if self._path else name


def open_small(path) -> Group | None:
    """The packed store at ``path`` as a :class:`Group`, read whole, or ``None`` when it is
    larger than :data:`MAX_BYTES` or holds anything this reader does not decode (the caller
    then opens it with zarr-python)."""
    path = Path(path)
    try:
        if path.stat().st_size > MAX_BYTES:
            return None
        with zipfile.ZipFile(path) as z:
            members = {i.filename: z.read(i) for i in z.infolist()}
        root = json.loads(members["zarr.json"])
        nodes = {"": root, **root["consolidated_metadata"]["metadata"]}
    except Exception:  # noqa: BLE001 - zarr-python reads it and names what is wrong
        return None
    if not all(_readable(meta) for key, meta in nodes.items() if key):
        return None
    return Group("", nodes, members)


def _readable(meta: dict) -> bool:
    """Whether :class:`Array` decodes this node (groups: always)."""
    if meta.get("node_type") == "group":
        return True
    try:
        names = [c["name"] for c in meta["codecs"]]
        endian = meta["codecs"][0].get("configuration", {}).get("endian", "little")
        return (meta["chunk_grid"]["name"] == "regular" and meta["chunk_key_encoding"]["name"] == "default"
                and not meta.get("storage_transformers")
                and ((meta["data_type"] in _NUMERIC and names in (["bytes"], ["bytes", "zstd"]) and endian == "little")
                     or (meta["data_type"] == "string" and names in (["vlen-utf8"], ["vlen-utf8", "zstd"]))))
    except (KeyError, TypeError, IndexError, AttributeError):
        return False

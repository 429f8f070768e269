"""Labelled arrays written as xarray writes them, without importing xarray.

A :data:`Tree` maps group paths (``"/segments"``, ``"/estimates/crossings"``) to
:class:`Dataset` s of named :class:`Variable` s (dimension names, values, CF-style ``units`` and
``long_name``) and dimension coordinates. :func:`write_tree` writes it as the zarr v3 files
``xarray.DataTree.to_zarr(..., zarr_format=3, consolidated=True)`` writes for the same tree,
byte for byte (``tests/test_results_store.py`` compares them, for every kind of array the
analysis writes), so ``xarray.open_datatree`` reads it as it reads xarray's own;
:func:`to_xarray` gives that DataTree in memory.

Why not xarray itself: importing it (and pandas) costs ~0.6 s, a tenth of a dry run, and
the analysis needs none of its operations to write a few dozen small arrays.
"""

from __future__ import annotations

import base64
import itertools
import struct
from dataclasses import dataclass, field
from pathlib import Path

import numcodecs
import numpy as np

from . import packed
from .appender import all_fill, metadata_bytes

# xarray's fill value for floating-point variables (FillValueCoder: NaN packed as "<d")
_NAN_FILL = base64.standard_b64encode(struct.pack("<d", float("nan"))).decode()


@dataclass(frozen=True)
class Variable:
    """An array with named dimensions: ``values`` of shape ``len(dims)``-D, ``attrs`` (units,
    long_name)."""
    dims: tuple[str, ...]
    values: np.ndarray
    attrs: dict = field(default_factory=dict)


@dataclass
class Dataset:
    """One group: data variables, dimension coordinates (name → 1-D values) and attributes."""
    data_vars: dict[str, Variable] = field(default_factory=dict)
    coords: dict[str, np.ndarray] = field(default_factory=dict)
    attrs: dict = field(default_factory=dict)


Tree = dict[str, Dataset]


def _groups(tree: Tree) -> list[str]:
    """Every group of ``tree`` in writing order: the root, then each path after its parents."""
    paths = ["/"]
    for path in tree:
        parts = path.strip("/").split("/") if path.strip("/") else []
        for i in range(1, len(parts) + 1):
            p = "/" + "/".join(parts[:i])
            if p not in paths:
                paths.append(p)
    return paths


def _variables(ds: Dataset):
    """(name, dims, values, attrs) in xarray's order (data variables, then coordinates)."""
    for name, v in ds.data_vars.items():
        yield name, v.dims, np.asarray(v.values), v.attrs
    for name, values in ds.coords.items():
        if name not in ds.data_vars:
            yield name, (name,), np.asarray(values), {}


def write_tree(tree: Tree, path: Path) -> None:
    """Write ``tree`` as a zarr v3 store at ``path``: a new directory, or with a name ending in
    ``.zip`` one packed file (:mod:`.packed`: the same keys in a zip, written in one go), its
    metadata consolidated at the root (:func:`store_members`)."""
    members = store_members(tree)
    path = Path(path)
    if path.name.endswith(packed.SUFFIX):
        packed.write_zip(members.items(), path)
        return
    for key, data in members.items():
        file = path / key
        file.parent.mkdir(parents=True, exist_ok=True)
        file.write_bytes(data)


def store_members(tree: Tree) -> dict[str, bytes]:
    """The store of ``tree`` as ``{key: bytes}``, its metadata consolidated at the root, as
    xarray's writer through zarr-python would write it: the same ``zarr.json`` files, chunk
    grid, codecs (``bytes`` then ``zstd`` level 0, as :mod:`.appender` writes them) and
    chunks, where a chunk holding only the fill value is not written.

    Why not through zarr: its machinery costs ~3.5 ms per array (metadata objects, its event
    loop, each parent's ``zarr.json`` written again), ~0.25 s for an analysis's ~60 arrays."""
    from zarr.core.chunk_grids import normalize_chunks

    files: dict[str, bytes] = {}
    consolidated: dict[str, dict] = {}
    for group in _groups(tree):
        ds = tree.get(group, Dataset())
        prefix = group.strip("/")
        if prefix:
            consolidated[prefix] = _group_meta(ds.attrs, _INLINE_EMPTY)
            files[f"{prefix}/zarr.json"] = metadata_bytes(_group_meta(ds.attrs))
        for name, dims, values, attrs in _variables(ds):
            key = f"{prefix}/{name}" if prefix else name
            values = np.ascontiguousarray(values, values.dtype.newbyteorder("<"))
            chunks = [int(c) for c in normalize_chunks(None, values.shape, values.dtype.itemsize)]
            meta = _array_meta(values, chunks, dims, attrs)
            consolidated[key] = meta
            files[f"{key}/zarr.json"] = metadata_bytes(meta)
            files.update((f"{key}/{k}", b) for k, b in _chunks(values, chunks, _fill_value(values.dtype)))
    order = sorted(consolidated, key=lambda k: (k.count("/"), k))
    files["zarr.json"] = metadata_bytes(_group_meta(tree.get("/", Dataset()).attrs, {
        **_INLINE_EMPTY, "metadata": {k: consolidated[k] for k in order}}))
    return files


_INLINE_EMPTY = {"kind": "inline", "must_understand": False, "metadata": {}}
_ZSTD = {"name": "zstd", "configuration": {"level": 0, "checksum": False}}


def _group_meta(attrs: dict, consolidated: dict | None = None) -> dict:
    """A group's ``zarr.json`` (with ``consolidated``: its consolidated metadata)."""
    extra = {} if consolidated is None else {"consolidated_metadata": consolidated}
    return {"attributes": attrs, "zarr_format": 3, **extra, "node_type": "group"}


def _array_meta(values: np.ndarray, chunks: list[int], dims, attrs: dict) -> dict:
    dtype = values.dtype
    if dtype.kind not in "biufU":
        raise TypeError(f"labelled array: data type {dtype} not written here; expected bool, integer, "
                        f"float or fixed-length text")
    attrs = {**attrs, "_FillValue": _NAN_FILL} if dtype.kind == "f" else dict(attrs)
    if dtype.kind == "U":
        data_type = {"name": "fixed_length_utf32", "configuration": {"length_bytes": dtype.itemsize}}
    else:
        data_type = dtype.name
    fill = _fill_value(dtype)
    return {"shape": list(values.shape), "data_type": data_type,
            "chunk_grid": {"name": "regular", "configuration": {"chunk_shape": chunks}},
            "chunk_key_encoding": {"name": "default", "configuration": {"separator": "/"}},
            "fill_value": "NaN" if dtype.kind == "f" else fill,
            "codecs": [{"name": "bytes"} if dtype.itemsize == 1 else
                       {"name": "bytes", "configuration": {"endian": "little"}}, _ZSTD],
            "attributes": attrs, "dimension_names": list(dims), "zarr_format": 3, "node_type": "array",
            "storage_transformers": []}


def _chunks(values: np.ndarray, chunks: list[int], fill):
    """(key, file content) of every chunk of ``values`` that holds more than the fill value; an
    edge chunk is padded with the fill value to the full chunk shape."""
    if values.size == 0:
        return
    codec = numcodecs.Zstd(level=0, checksum=False)
    grid = [range(0, n, c) for n, c in zip(values.shape, chunks)]
    for start in itertools.product(*grid):
        part = values[tuple(slice(a, a + c) for a, c in zip(start, chunks))]
        if part.shape != tuple(chunks):
            padded = np.full(chunks, fill, values.dtype)
            padded[tuple(slice(0, n) for n in part.shape)] = part
            part = padded
        if not all_fill(part, fill):
            key = "/".join(["c", *(str(a // c) for a, c in zip(start, chunks))])
            yield key, bytes(codec.encode(np.ascontiguousarray(part).tobytes()))


def _fill_value(dtype: np.dtype):
    return {"f": np.nan, "U": "", "b": False}.get(dtype.kind, 0)


def to_xarray(tree: Tree):
    """``tree`` as an ``xarray.DataTree`` (imports xarray)."""
    import xarray as xr
    return xr.DataTree.from_dict({
        path: xr.Dataset({n: xr.Variable(v.dims, v.values, attrs=v.attrs) for n, v in ds.data_vars.items()},
                         coords=ds.coords, attrs=ds.attrs)
        for path, ds in tree.items()})

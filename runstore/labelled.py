"""Labelled arrays written as xarray writes them, without importing xarray.

A :data:`Tree` maps group paths (``"/segments"``, ``"/estimates/crossings"``) to
:class:`Dataset` s of named :class:`Variable` s (dimension names, values, CF-style ``units`` and
``long_name``) and dimension coordinates. :func:`write_tree` writes it as the zarr v3 files
``xarray.DataTree.to_zarr(..., zarr_format=3, consolidated=True)`` writes for the same tree,
byte for byte (``tests/test_results_store.py``), so ``xarray.open_datatree`` reads it as it
reads xarray's own; :func:`to_xarray` gives that DataTree in memory.

Why not xarray itself: importing it (and pandas) costs ~0.6 s, a tenth of a dry run, and
the analysis needs none of its operations to write a few dozen small arrays.
"""

from __future__ import annotations

import base64
import struct
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

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
    """Write ``tree`` as a zarr v3 store at ``path`` (a new directory), consolidated once at the
    root. The files are encoded in memory and then written plainly: zarr's local store costs an
    asynchronous file operation per key, about a third more CPU for the same bytes."""
    import zarr

    keys: dict = {}
    store = zarr.storage.MemoryStore(keys)
    with warnings.catch_warnings():      # zarr 3: fixed-length strings and consolidated metadata are
        warnings.simplefilter("ignore")  # not in the v3 spec yet (same as the run store)
        root = zarr.open_group(store, mode="w", zarr_format=3)
        for group in _groups(tree):
            ds = tree.get(group, Dataset())
            g = root if group == "/" else root.require_group(group.strip("/"))
            g.update_attributes(ds.attrs)
            for name, dims, values, attrs in _variables(ds):
                attrs = dict(attrs)
                if values.dtype.kind == "f":
                    attrs["_FillValue"] = _NAN_FILL
                a = g.create_array(name, shape=values.shape, dtype=values.dtype, dimension_names=list(dims),
                                   attributes=attrs, fill_value=_fill_value(values.dtype))
                if values.size:
                    a[...] = values
        zarr.consolidate_metadata(store)
    for key, buffer in keys.items():
        file = path / key
        file.parent.mkdir(parents=True, exist_ok=True)
        file.write_bytes(buffer.to_bytes())


def _fill_value(dtype: np.dtype):
    return {"f": np.nan, "U": "", "b": False}.get(dtype.kind, 0)


def to_xarray(tree: Tree):
    """``tree`` as an ``xarray.DataTree`` (imports xarray)."""
    import xarray as xr
    return xr.DataTree.from_dict({
        path: xr.Dataset({n: xr.Variable(v.dims, v.values, attrs=v.attrs) for n, v in ds.data_vars.items()},
                         coords=ds.coords, attrs=ds.attrs)
        for path, ds in tree.items()})

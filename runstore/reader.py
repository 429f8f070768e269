"""Reading a run store: :func:`open_run` (the whole store as an ``xarray.DataTree``, at its
last commit), :func:`open_group` (the same state as a read-only ``zarr.Group``: plain arrays
for the analysis, without xarray's import cost) and :func:`check_version` (the schema
versions this reader understands).

Stores of schema 1.x open as they are; a store of a newer major version is refused with
one line naming the versions, never misread.
"""

from __future__ import annotations

from pathlib import Path

from .layout import SCHEMA_VERSION


class StoreVersionError(ValueError):
    """The store was written by a newer, incompatible schema."""


def check_version(attrs, where="run store") -> str:
    """The store's ``schema_version`` (root attribute); ``StoreVersionError`` if its major
    version is newer than :data:`~runstore.layout.SCHEMA_VERSION`'s. Stores older than the
    attribute (none known) count as 1.0."""
    version = str(attrs.get("schema_version") or "1.0")
    major = version.split(".", 1)[0]
    if not major.isdigit() or int(major) > int(SCHEMA_VERSION.split(".", 1)[0]):
        raise StoreVersionError(f"{where}: schema_version {version!r} is newer than this reader's "
                                f"{SCHEMA_VERSION}; expected 1.x (update tactile-flow to read it)")
    return version


def open_run(path):
    """The run store at ``path`` as an ``xarray.DataTree``, through the consolidated metadata
    (the state of its last commit); a store of an unknown major schema version is refused."""
    import xarray as xr
    tree = xr.open_datatree(str(path), engine="zarr", consolidated=True)
    check_version(tree.attrs, str(Path(path)))
    return tree


def open_group(path):
    """The run store at ``path`` as a read-only ``zarr.Group``, through the consolidated metadata
    (the state of its last commit, as :func:`open_run`); a store of an unknown major schema
    version is refused. ``group["biotac/time"][...]`` reads an array whole."""
    import zarr
    group = zarr.open_group(str(path), mode="r", use_consolidated=True)
    check_version(group.attrs, str(Path(path)))
    return group


def data_arrays(group) -> dict:
    """The arrays of one group that xarray counts as data variables (not named after a
    dimension), by name."""
    arrays = dict(group.arrays())
    dims = {d for a in arrays.values() for d in (a.metadata.dimension_names or ())}
    return {name: a for name, a in arrays.items() if name not in dims}

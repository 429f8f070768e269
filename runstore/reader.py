"""Reading a run store: :func:`open_run` (the whole store as an ``xarray.DataTree``, at its
last commit), :func:`open_group` (the same state as a read-only ``zarr.Group``: plain arrays
for the analysis, without xarray's import cost) and :func:`check_version` (the schema
versions this reader understands).

These are the project's one way in to a store — a run's ``run.zarr`` or an analysis's
``analysis.zarr`` — whatever its layout: a directory store (a recording, or any store
written before 0.3) or a packed one (``run.zarr.zip``, ``analysis.zarr.zip``: one zip file,
:mod:`.packed`). :func:`zarr_store` is what zarr-python is handed for either;
:func:`store_url` the string to give xarray or zarr yourself (``zip::/abs/run.zarr.zip`` for a
packed store, read through fsspec). A packed store is read through zarr's ``ZipStore``
(half the time of fsspec's zip file system per open, measured on a short import).

Stores of schema 1.x open as they are; a store of a newer major version is refused with
one line naming the versions, never misread.
"""

from __future__ import annotations

from pathlib import Path

from . import packed
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


def zarr_store(path):
    """What zarr-python (or xarray) is handed to read the store at ``path``, read-only: a
    ``zarr.storage.ZipStore`` for a packed store (a ``*.zip`` file), the path itself (a
    string) for a directory store."""
    if packed.is_packed(path):
        from zarr.storage import ZipStore
        return ZipStore(Path(path), mode="r")
    return str(path)


def store_url(path) -> str:
    """The string that opens the store at ``path`` in zarr-python or xarray without this
    package: ``zip::/absolute/run.zarr.zip`` for a packed store (fsspec's zip file system,
    which zarr uses for URLs), the path for a directory store."""
    if packed.is_packed(path):
        return "zip::" + Path(path).resolve().as_posix()
    return str(path)


def open_run(path, where: str | None = None):
    """The store at ``path`` (a directory store or a packed ``*.zip``) as an
    ``xarray.DataTree``, through the consolidated metadata (the state of its last commit); a
    store of an unknown major schema version is refused (``where`` names it in the error;
    default the path)."""
    import xarray as xr
    tree = xr.open_datatree(zarr_store(path), engine="zarr", consolidated=True)
    check_version(tree.attrs, where or str(Path(path)))
    return tree


def open_group(path, where: str | None = None, consolidated: bool = True):
    """The store at ``path`` (a directory store or a packed ``*.zip``) as a read-only
    ``zarr.Group``, through the consolidated metadata (the state of its last commit, as
    :func:`open_run`; ``consolidated=False``: every node's own ``zarr.json``, which is what
    a checksum of the arrays on disk reads); a store of an unknown major schema version is
    refused. ``group["biotac/time"][...]`` reads an array whole."""
    import zarr
    group = zarr.open_group(zarr_store(path), mode="r", use_consolidated=consolidated)
    check_version(group.attrs, where or str(Path(path)))
    return group


def data_arrays(group) -> dict:
    """The arrays of one group that xarray counts as data variables (not named after a
    dimension), by name."""
    arrays = dict(group.arrays())
    dims = {d for a in arrays.values() for d in (a.metadata.dimension_names or ())}
    return {name: a for name, a in arrays.items() if name not in dims}

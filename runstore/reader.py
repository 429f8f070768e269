"""Reading a run store: :func:`open_run` (the whole store as an ``xarray.DataTree``, at its
last commit), :func:`open_group` (the same state as a read-only ``zarr.Group``: plain arrays
for the analysis, without xarray's import cost) and :func:`check_version` (the schema
versions this reader understands).

These are the project's one way in to a store — a run's ``run.zarr`` or an analysis's
``analysis.zarr`` — whatever its layout: a directory store (a recording, or any store
written by 0.2.0 or before) or a packed one (``run.zarr.zip``, ``analysis.zarr.zip``: one zip file,
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
    ``zarr.storage.ZipStore`` for a packed store (a ``*.zip`` file; one that reopens its file
    in a forked process, :func:`_fork_safe_zip_store`), the path itself (a string) for a
    directory store."""
    if packed.is_packed(path):
        return _fork_safe_zip_store()(Path(path), mode="r")
    return str(path)


_ZIP_STORE = None


def _fork_safe_zip_store():
    """zarr's ``ZipStore``, each open one reopened in a process forked from the one that
    opened it. A forked process shares its parent's open file, *and its offset*: zipfile reads
    a member by a seek then a read, so a parent and a child (figure workers, dataset workers)
    reading at once would read at each other's positions; and a lock held by the parent's I/O
    thread at the fork would never be released in the child. A fresh open and a fresh lock
    have neither problem."""
    global _ZIP_STORE
    if _ZIP_STORE is None:
        import os
        import weakref

        from zarr.storage import ZipStore

        opened = weakref.WeakSet()

        class ForkSafeZipStore(ZipStore):
            __hash__ = object.__hash__                  # ZipStore defines __eq__ only; kept in a WeakSet

            def _sync_open(self) -> None:
                super()._sync_open()
                opened.add(self)

        def reopen_in_child() -> None:
            for store in list(opened):
                if store._is_open:
                    store._is_open = False          # the parent's file object stays the parent's
                    store._sync_open()              # a new file (own offset) and a new lock

        os.register_at_fork(after_in_child=reopen_in_child)
        _ZIP_STORE = ForkSafeZipStore
    return _ZIP_STORE


def store_url(path) -> str:
    """The string that opens the store at ``path`` in zarr-python or xarray without this
    package: ``zip::/absolute/run.zarr.zip`` for a packed store (fsspec's zip file system,
    which zarr uses for URLs), the path for a directory store."""
    if packed.is_packed(path):
        return "zip::" + Path(path).resolve().as_posix()
    return str(path)


def open_run(path):
    """The store at ``path`` (a directory store or a packed ``*.zip``) as an
    ``xarray.DataTree``, through the consolidated metadata (the state of its last commit); a
    store of an unknown major schema version is refused."""
    import xarray as xr
    tree = xr.open_datatree(zarr_store(path), engine="zarr", consolidated=True)
    check_version(tree.attrs, str(Path(path)))
    return tree


def open_group(path, consolidated: bool = True):
    """The store at ``path`` (a directory store or a packed ``*.zip``) as a read-only
    ``zarr.Group``, through the consolidated metadata (the state of its last commit, as
    :func:`open_run`; ``consolidated=False``: every node's own ``zarr.json``, which is what
    a checksum of the arrays on disk reads); a store of an unknown major schema version is
    refused. ``group["biotac/time"][...]`` reads an array whole."""
    import zarr
    group = zarr.open_group(zarr_store(path), mode="r", use_consolidated=consolidated)
    check_version(group.attrs, str(Path(path)))
    return group


def data_arrays(group) -> dict:
    """The arrays of one group that xarray counts as data variables (not named after a
    dimension), by name."""
    arrays = dict(group.arrays())
    dims = {d for a in arrays.values() for d in (a.metadata.dimension_names or ())}
    return {name: a for name, a in arrays.items() if name not in dims}

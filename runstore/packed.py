"""The packed layout of a finished store: one zip file (``run.zarr.zip``, ``analysis.zarr.zip``).

A zarr v3 directory store is one file per node and per chunk: a short imported record's
``run.zarr`` is some 30 small files, an analysis's some 125 (``docs/run_store.md``, "Files
per run"). A store that is written once and never appended to — an import, an analysis — is
packed into a single zip of the same keys (:func:`pack`): the zip's member names are the
store's keys, so zarr-python (``zarr.storage.ZipStore``, or the URL ``zip::PATH`` through
fsspec), xarray (``xarray.open_datatree("zip::PATH", engine="zarr")``) and tensorstore (its
``zip`` kvstore) read it as they read the directory. A recording stays a directory store: it
streams, and crash recovery appends to it.

Each member is stored or deflated by what it holds: the chunks are already zstd-compressed
(deflating them gains nothing: measured −1 % to +3 %), so they are *stored*; the ``zarr.json``
metadata, half of a short store's bytes, is *deflated* (~50 %). Measured on a 275-frame
one-finger import (``benchmarks/bench_store_files.py``): all stored 41.7 kB (3.03× raw), all
deflated 23.9 kB, this mix 23.9 kB (1.74× raw).

Where a store is (:func:`find`): ``DIR/run.zarr`` (a directory: a recording, or any store
written before the packed layout) or ``DIR/run.zarr.zip`` (a file).
"""

from __future__ import annotations

import os
import tempfile
import time
import zipfile
from pathlib import Path

SUFFIX = ".zip"
#: metadata members, deflated; every other member (a chunk, zstd inside) is stored
METADATA = "zarr.json"


def packed_name(name: str) -> str:
    """``run.zarr`` → ``run.zarr.zip``."""
    return name if name.endswith(SUFFIX) else name + SUFFIX


def is_packed(path) -> bool:
    """Whether ``path`` is a packed store (a regular file named ``*.zip``)."""
    p = Path(path)
    return p.name.endswith(SUFFIX) and p.is_file()


def is_store(path) -> bool:
    """Whether ``path`` is a store of either layout: a directory holding a root ``zarr.json``,
    or a packed store (a ``*.zip`` file)."""
    p = Path(path)
    return (p / METADATA).is_file() or is_packed(p)


def find(directory, name: str = "run.zarr") -> Path | None:
    """The store ``name`` in ``directory``: ``directory/name`` if it exists (a directory
    store), else ``directory/name.zip`` if it is a file (packed), else ``None``."""
    d = Path(directory)
    plain, packed = d / name, d / packed_name(name)
    if os.path.lexists(plain):
        return plain
    if packed.is_file():
        return packed
    return None


def read_member(store, key: str) -> bytes:
    """The bytes of ``key`` (``"zarr.json"``, ``"biotac/zarr.json"``) in the store at ``store``,
    of either layout, without zarr; ``OSError`` (``FileNotFoundError``, ``zipfile.BadZipFile``)
    or ``KeyError`` if it cannot be read."""
    store = Path(store)
    if is_packed(store):
        with zipfile.ZipFile(store) as z:
            return z.read(key)
    return (store / key).read_bytes()


def run_store(run_dir, info: dict | None = None) -> Path:
    """The run store of the run directory ``run_dir``: the one its ``run.json`` (``info``)
    names as ``store``, else :func:`find` (``run.zarr`` or ``run.zarr.zip``), else the
    path ``run_dir/run.zarr`` (missing: the caller says so)."""
    named = (info or {}).get("store")
    if named:
        return Path(run_dir) / str(named)
    return find(run_dir) or Path(run_dir) / "run.zarr"


def pack(source, target) -> Path:
    """Pack the directory store ``source`` into the zip ``target`` (must not exist): every
    file below ``source`` under its relative path (:func:`write_zip`: ``zarr.json`` deflated,
    chunks stored, whole or absent). The files are streamed into the zip one at a time, so
    memory stays bounded whatever the store's size. Links and other non-regular files in
    ``source`` are an error (a store holds none). Returns ``target``."""
    source = Path(source)
    members = []
    for here, dirs, files in os.walk(source):
        dirs.sort()
        for f in sorted(files):
            p = Path(here) / f
            if p.is_symlink() or not p.is_file():
                raise ValueError(f"{p}: not a regular file; a store to pack holds only files")
            members.append((p.relative_to(source).as_posix(), p))
    return write_zip(members, target)


def write_zip(members, target) -> Path:
    """Write the zip ``target`` (must not exist) of ``members`` — ``(key, content)`` pairs, the
    content a file's :class:`~pathlib.Path` (streamed) or ``bytes`` — each ``zarr.json``
    deflated, every other member stored; to a temporary file beside ``target``, fsynced, then
    renamed (never over an existing file), so ``target`` is whole or absent. Returns ``target``."""
    target = Path(target)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".part", dir=target.parent)
    try:
        with os.fdopen(fd, "wb") as raw:
            with zipfile.ZipFile(raw, "w", allowZip64=True) as z:
                for key, content in members:
                    kind = zipfile.ZIP_DEFLATED if key.rsplit("/", 1)[-1] == METADATA else zipfile.ZIP_STORED
                    if isinstance(content, Path):
                        z.write(content, key, compress_type=kind)
                    else:
                        info = zipfile.ZipInfo(key, date_time=time.localtime()[:6])
                        info.external_attr = 0o644 << 16
                        z.writestr(info, content, compress_type=kind)
            raw.flush()
            os.fsync(raw.fileno())
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)                 # mkstemp makes it 0600; a store is not private
        if os.path.lexists(target):
            raise FileExistsError(f"{target} already exists")
        os.rename(tmp, target)
    except BaseException:
        if os.path.lexists(tmp):
            os.unlink(tmp)
        raise
    return target

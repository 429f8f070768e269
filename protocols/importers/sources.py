"""What a ``source=PATH`` holds: which files to import, with which reader, and their checksums."""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

from .bag import bag_files, is_bag
from .csv import is_csv
from .recording import ImportInputError

KINDS = ("bag", "csv")


@dataclass(frozen=True)
class Source:
    """One file (or ROS2 bag directory) to import as one run store.

    ``kind``: ``bag`` or ``csv``; ``name``: the run directory's name (file stem).
    """

    path: Path
    kind: str
    name: str


def sha256_file(path: Path, block: int = 1 << 20) -> str:
    """SHA-256 (hex) of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while chunk := f.read(block):
            h.update(chunk)
    return h.hexdigest()


def checksum(src: Source) -> dict:
    """``{"sha256", "bytes", "files": [{name, bytes, sha256}]}``. A single file's ``sha256`` is
    the file's; a ROS2 bag's is the SHA-256 of its files' ``"<sha256>  <name>\\n"`` lines (as
    ``sha256sum`` prints them), sorted by name."""
    files = bag_files(src.path) if src.kind == "bag" else [src.path]
    rows = [{"name": p.name, "bytes": p.stat().st_size, "sha256": sha256_file(p)} for p in files]
    if src.path.is_file():
        digest = rows[0]["sha256"]
    else:
        digest = hashlib.sha256("".join(f"{r['sha256']}  {r['name']}\n" for r in rows).encode()).hexdigest()
    return {"sha256": digest, "bytes": sum(r["bytes"] for r in rows), "files": rows}


def discover(path) -> list[Source]:
    """The sources under ``path``: a ``.bag`` file, a ROS2 bag directory, a ``.csv`` file, or a
    directory of those (each one run store, sorted by name). Raises
    :class:`ImportInputError` for a missing path, an unknown file type or an empty directory."""
    path = Path(path)
    if not path.exists():
        raise ImportInputError(f"source={path}: no such file or directory")
    if is_bag(path):
        return [Source(path, "bag", path.stem if path.is_file() else path.name)]
    if path.is_file():
        if is_csv(path):
            return [Source(path, "csv", path.stem)]
        raise ImportInputError(f"source={path}: unknown file type {path.suffix or '(no suffix)'!r}; "
                               f"expected a .bag file, a ROS2 bag directory, a .csv file or a directory of them")
    found = [Source(p, "bag" if is_bag(p) else "csv", p.stem if p.is_file() else p.name)
             for p in sorted(path.iterdir()) if not p.name.startswith(".") and (is_bag(p) or is_csv(p))]
    if not found:
        raise ImportInputError(f"source={path}: a directory with no .bag, .csv or ROS2 bag in it")
    names = [s.name for s in found]
    return [Source(s.path, s.kind, s.path.name.replace(".", "_") if names.count(s.name) > 1 else s.name)
            for s in found]

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

    ``kind``: ``bag`` or ``csv``; ``name``: the run directory's name (file stem);
    ``subfolder``: the folder holding it, relative to the imported directory (POSIX, ``""``
    at its top), which the output tree mirrors.
    """

    path: Path
    kind: str
    name: str
    subfolder: str = ""

    def target(self, out: Path) -> Path:
        """The run directory under ``out``: ``out/<subfolder>/<name>``."""
        return Path(out) / self.subfolder / self.name if self.subfolder else Path(out) / self.name


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
    directory of those, its subfolders included (one per condition or object, as published
    datasets are laid out), each one run store, in sorted order. Hidden entries, symbolic
    links to folders and run stores (``*.zarr``) are not entered. Raises
    :class:`ImportInputError` for a missing path, an unknown file type or a tree without one."""
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
    found = []
    for folder in _folders(path):
        sub = folder.relative_to(path).as_posix() if folder != path else ""
        here = [Source(p, "bag" if is_bag(p) else "csv", p.stem if p.is_file() else p.name, sub)
                for p in sorted(folder.iterdir()) if not p.name.startswith(".") and (is_bag(p) or is_csv(p))]
        names = [s.name for s in here]                  # a.csv beside a.bag: a_csv, a_bag
        found += [Source(s.path, s.kind, s.path.name.replace(".", "_") if names.count(s.name) > 1 else s.name, sub)
                  for s in here]
    if not found:
        raise ImportInputError(f"source={path}: a directory with no .bag, .csv or ROS2 bag in it or in its "
                               f"subfolders")
    return found


def _folders(root: Path) -> list[Path]:
    """``root`` and every folder below it that may hold sources, depth first, sorted."""
    out, stack = [], [root]
    while stack:
        folder = stack.pop()
        out.append(folder)
        stack += reversed([p for p in sorted(folder.iterdir())
                           if p.is_dir() and not p.is_symlink() and not p.name.startswith(".")
                           and p.suffix != ".zarr" and not is_bag(p)])
    return out

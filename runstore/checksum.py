"""The checksum of a store's data: every array's values, not its files or attributes.

Two stores hold the same data when every array has the same name, dtype, shape and values,
whatever their chunking, compression or attributes (run id, start time and provenance
differ from one run to the next by design). :func:`store_checksum` gives one SHA-256 per
array and one for the whole store; ``tactile-run`` records it in ``run.json``
(``store_checksum``) when a run closes, and ``tactile-runs reproduce`` compares a
reproduction's with it. Arrays are read a slab of rows at a time, so memory stays bounded
on long records.
"""

from __future__ import annotations

import hashlib
import warnings
from pathlib import Path

import numpy as np

ROWS_PER_READ = 1 << 18


def _digest(arr) -> str:
    h = hashlib.sha256()
    h.update(f"{arr.dtype}|{tuple(arr.shape)}|".encode())
    n = arr.shape[0] if arr.ndim else 1
    step = ROWS_PER_READ if arr.ndim else 1
    for start in range(0, max(n, 1), step):
        values = np.asarray(arr[start:start + step] if arr.ndim else arr[()])
        if values.dtype.kind in "OUT":
            text = "\x1f".join(str(v) for v in values.ravel().tolist())
            h.update(text.encode("utf-8", "surrogatepass"))
        else:
            h.update(np.ascontiguousarray(values).tobytes())
    return h.hexdigest()


def array_checksums(path) -> dict[str, str]:
    """``{"group/array": sha256}`` of every array in the zarr store at ``path`` (a directory
    store or a packed one; sorted)."""
    from .reader import open_group
    out = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        root = open_group(path, consolidated=False)

        def visit(group, prefix):
            for name, arr in sorted(group.arrays(), key=lambda kv: kv[0]):
                out[f"{prefix}{name}"] = _digest(arr)
            for name, sub in sorted(group.groups(), key=lambda kv: kv[0]):
                visit(sub, f"{prefix}{name}/")
        visit(root, "")
    return out


def store_checksum(path) -> dict:
    """``{"sha256": whole store, "arrays": {name: sha256}}`` of the store at ``path``."""
    arrays = array_checksums(Path(path))
    whole = hashlib.sha256("".join(f"{k}:{v}\n" for k, v in arrays.items()).encode()).hexdigest()
    return {"sha256": whole, "arrays": arrays}


def differing(a: dict, b: dict) -> list[str]:
    """The arrays whose checksums differ between two :func:`store_checksum` results (those
    in only one of them too), sorted."""
    x, y = a.get("arrays") or {}, b.get("arrays") or {}
    return sorted(k for k in set(x) | set(y) if x.get(k) != y.get(k))

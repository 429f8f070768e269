"""Geodesic distances computed once and kept on disk (atomic writes, checksummed reads)."""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
import warnings
from pathlib import Path

import numpy as np

from .ellipsoid import _check_axes, _check_on_surface
from .geodesic import ALGORITHM_VERSION, GEODESIC_METHODS, geodesic_distances

__all__ = ["cached_geodesic_distances", "default_cache_dir"]


def default_cache_dir() -> Path:
    """$TACTILE_CACHE_DIR, else $XDG_CACHE_HOME/tactile-flow, else ~/.cache/tactile-flow."""
    if os.environ.get("TACTILE_CACHE_DIR"):
        return Path(os.environ["TACTILE_CACHE_DIR"])
    if os.environ.get("XDG_CACHE_HOME"):
        return Path(os.environ["XDG_CACHE_HOME"]) / "tactile-flow"
    return Path.home() / ".cache" / "tactile-flow"


def _cache_key(ax: np.ndarray, pa: np.ndarray, pb: np.ndarray, method: str, kw: dict) -> str:
    h = hashlib.sha256()
    h.update(ALGORITHM_VERSION.encode())
    h.update(method.encode())
    h.update(json.dumps(kw, sort_keys=True, default=repr).encode())
    for arr in (ax, pa, pb):
        arr = np.ascontiguousarray(arr, dtype="<f8")
        h.update(repr(arr.shape).encode())
        h.update(arr.tobytes())
    return h.hexdigest()


def _checksum(arr: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(arr, dtype="<f8").tobytes()).hexdigest()


def _read_cache(path: Path, shape: tuple[int, int]) -> np.ndarray:
    # Open the file ourselves: np.load leaks its handle when the zip is unreadable.
    with open(path, "rb") as fh, np.load(fh, allow_pickle=False) as data:
        dist = np.array(data["distances"], dtype="<f8")
        stored = str(data["checksum"])
    if dist.shape != shape:
        raise ValueError(f"shape {dist.shape}, expected {shape}")
    if _checksum(dist) != stored:
        raise ValueError("checksum mismatch")
    return dist.astype(np.float64)


def _write_cache(path: Path, dist: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name + ".", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            np.savez(fh, distances=dist, checksum=np.array(_checksum(dist)))
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def cached_geodesic_distances(axes, points_a, points_b, *, method: str = "accurate",
                              cache_dir=None, **kw) -> np.ndarray:
    """:func:`geodesic_distances`, computed once and cached on disk.

    The .npz file in ``cache_dir`` (default :func:`default_cache_dir`) is named by a
    SHA-256 of the axes, the points' bytes, ``method``, ``kw`` and
    :data:`ALGORITHM_VERSION`, and stores the array with a checksum of its bytes. A file
    that cannot be read, has the wrong shape or fails the checksum is reported with a
    warning and rebuilt. Writes are atomic (temporary file + ``os.replace``).
    """
    ax = _check_axes(axes)
    if method not in GEODESIC_METHODS:
        raise ValueError(f"method: expected one of {GEODESIC_METHODS}, got {method!r}")
    pa = _check_on_surface("points_a", ax, points_a)
    pb = _check_on_surface("points_b", ax, points_b)
    directory = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    path = directory / f"geodesic-{_cache_key(ax, pa, pb, method, kw)}.npz"
    shape = (len(pa), len(pb))
    if path.exists():
        try:
            return _read_cache(path, shape)
        except Exception as exc:  # any damage: report and rebuild
            warnings.warn(f"geodesic cache file {path} is unusable ({exc!r}); recomputing",
                          RuntimeWarning, stacklevel=2)
    dist = geodesic_distances(ax, pa, pb, method=method, **kw)
    try:
        _write_cache(path, dist)
    except OSError as exc:  # an unwritable cache must not cost the result
        warnings.warn(f"could not write geodesic cache file {path} ({exc!r})",
                      RuntimeWarning, stacklevel=2)
    return dist

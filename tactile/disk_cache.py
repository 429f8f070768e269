"""What is costly to compute and the same every time, computed once and kept on disk (atomic
writes, checksummed reads): the geodesic distances of the interpolation kernel, and the
ellipsoid fitted to the taxels (its optimiser, SciPy's, costs ~0.3 s of start-up to import)."""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
import warnings
from pathlib import Path

import numpy as np

from ._checks import finite_array
from .ellipsoid import EllipsoidFit, _check_axes, _check_on_surface, fit_ellipsoid, fit_ellipsoid_with_normals
from .geodesic import ALGORITHM_VERSION, GEODESIC_METHODS, geodesic_distances

__all__ = ["cached_fit_ellipsoid", "cached_geodesic_distances", "default_cache_dir", "geodesic_cache_file"]

FIT_VERSION = "1"
"""Part of the ellipsoid fit's cache key: change it when :func:`fit_ellipsoid` changes its result."""


def default_cache_dir() -> Path:
    """$TACTILE_CACHE_DIR, else $XDG_CACHE_HOME/tactile-flow, else ~/.cache/tactile-flow."""
    if os.environ.get("TACTILE_CACHE_DIR"):
        return Path(os.environ["TACTILE_CACHE_DIR"])
    if os.environ.get("XDG_CACHE_HOME"):
        return Path(os.environ["XDG_CACHE_HOME"]) / "tactile-flow"
    return Path.home() / ".cache" / "tactile-flow"


def _cache_key(*arrays: np.ndarray, tags: tuple = ()) -> str:
    """SHA-256 of ``tags`` (strings, JSON-able) and the arrays' shapes and bytes."""
    h = hashlib.sha256()
    for tag in tags:
        h.update(tag.encode() if isinstance(tag, str) else json.dumps(tag, sort_keys=True, default=repr).encode())
    for arr in arrays:
        arr = np.ascontiguousarray(arr, dtype="<f8")
        h.update(repr(arr.shape).encode())
        h.update(arr.tobytes())
    return h.hexdigest()


def _checksum(arr: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(arr, dtype="<f8").tobytes()).hexdigest()


def _read_cache(path: Path, shape: tuple) -> np.ndarray:
    # Open the file ourselves: np.load leaks its handle when the zip is unreadable.
    # (The array is stored as "distances" for every kind: the files written before the fit's stay valid.)
    with open(path, "rb") as fh, np.load(fh, allow_pickle=False) as data:
        values = np.array(data["distances"], dtype="<f8")
        stored = str(data["checksum"])
    if values.shape != shape:
        raise ValueError(f"shape {values.shape}, expected {shape}")
    if _checksum(values) != stored:
        raise ValueError("checksum mismatch")
    return values.astype(np.float64)


def _write_cache(path: Path, values: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name + ".", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            np.savez(fh, distances=values, checksum=np.array(_checksum(values)))
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def geodesic_cache_file(axes, points_a, points_b, *, method: str = "accurate", cache_dir=None, **kw) -> Path:
    """The file in which :func:`cached_geodesic_distances` keeps these distances (it may not
    exist yet)."""
    return _geodesic_file(*_checked(axes, points_a, points_b, method), method, cache_dir, kw)


def _checked(axes, points_a, points_b, method: str) -> tuple:
    """(axes, points_a, points_b) checked as :func:`geodesic_distances` checks them."""
    ax = _check_axes(axes)
    if method not in GEODESIC_METHODS:
        raise ValueError(f"method: expected one of {GEODESIC_METHODS}, got {method!r}")
    return ax, _check_on_surface("points_a", ax, points_a), _check_on_surface("points_b", ax, points_b)


def _geodesic_file(ax, pa, pb, method: str, cache_dir, kw: dict) -> Path:
    directory = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    return directory / f"geodesic-{_cache_key(ax, pa, pb, tags=(ALGORITHM_VERSION, method, kw))}.npz"


def cached_geodesic_distances(axes, points_a, points_b, *, method: str = "accurate",
                              cache_dir=None, **kw) -> np.ndarray:
    """:func:`geodesic_distances`, computed once and cached on disk.

    The .npz file in ``cache_dir`` (default :func:`default_cache_dir`) is named by a
    SHA-256 of the axes, the points' bytes, ``method``, ``kw`` and
    :data:`ALGORITHM_VERSION`, and stores the array with a checksum of its bytes. A file
    that cannot be read, has the wrong shape or fails the checksum is reported with a
    warning and rebuilt. Writes are atomic (temporary file + ``os.replace``).
    """
    ax, pa, pb = _checked(axes, points_a, points_b, method)
    path = _geodesic_file(ax, pa, pb, method, cache_dir, kw)
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


def cached_fit_ellipsoid(points, *, normals=None, normal_weight: float = 3.0, cache_dir=None) -> EllipsoidFit:
    """:func:`fit_ellipsoid` of ``points`` (N, 3) mm — or with ``normals`` (N, 3),
    :func:`fit_ellipsoid_with_normals` — computed once and kept on disk like the geodesic
    distances: an .npz named by a SHA-256 of the points (and normals, weight),
    :data:`FIT_VERSION` and SciPy's version, holding centre, semi-axes and rms (mm). A damaged
    file is reported with a warning and the fit recomputed; an unwritable cache costs only the time."""
    from importlib.metadata import version
    pts = finite_array("points", points, ndim=2, last=3)
    directory = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    if normals is None:
        key = _cache_key(pts, tags=(FIT_VERSION, version('scipy')))
    else:
        nrm = finite_array("normals", normals, ndim=2, last=3)
        key = _cache_key(pts, nrm, tags=(FIT_VERSION, version('scipy'), "normals", float(normal_weight)))
    path = directory / f"ellipsoid-{key}.npz"
    if path.exists():
        try:
            v = _read_cache(path, (7,))
            return EllipsoidFit(centre=v[:3], axes=v[3:6], rms=float(v[6]))
        except Exception as exc:  # any damage: report and refit
            warnings.warn(f"ellipsoid cache file {path} is unusable ({exc!r}); fitting again",
                          RuntimeWarning, stacklevel=2)
    fit = fit_ellipsoid(pts) if normals is None else fit_ellipsoid_with_normals(pts, nrm, normal_weight)
    try:
        _write_cache(path, np.r_[fit.centre, fit.axes, fit.rms])
    except OSError as exc:
        warnings.warn(f"could not write ellipsoid cache file {path} ({exc!r})", RuntimeWarning, stacklevel=2)
    return fit

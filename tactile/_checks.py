"""Input validation shared by the ``tactile`` modules.

Every check raises ``ValueError`` naming the argument and what was expected, so a caller
sees one clear line instead of a NumPy traceback from deep inside a computation.
"""

from __future__ import annotations

import numpy as np


def finite_array(name: str, value, *, ndim: int | tuple[int, ...] | None = None,
                 last: int | None = None, min_len: int | None = None) -> np.ndarray:
    """Return ``value`` as a float64 array after checking shape and finiteness.

    ``ndim``: allowed number(s) of dimensions; ``last``: required size of the last axis;
    ``min_len``: minimum size of the first axis (e.g. 1 to refuse zero-length records).
    """
    arr = np.asarray(value, dtype=np.float64)
    if ndim is not None:
        allowed = (ndim,) if isinstance(ndim, int) else ndim
        if arr.ndim not in allowed:
            raise ValueError(f"{name}: expected an array with {' or '.join(map(str, allowed))} "
                             f"dimensions, got shape {arr.shape}")
    if last is not None and (arr.ndim == 0 or arr.shape[-1] != last):
        raise ValueError(f"{name}: expected the last axis to have {last} entries, got shape {arr.shape}")
    if min_len is not None and (arr.ndim == 0 or arr.shape[0] < min_len):
        raise ValueError(f"{name}: expected at least {min_len} sample(s) along the first axis, "
                         f"got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        bad = int(np.size(arr) - np.count_nonzero(np.isfinite(arr)))
        raise ValueError(f"{name}: expected finite values, found {bad} NaN or infinite value(s)")
    return arr


def positive(name: str, value: float) -> float:
    """Return ``value`` as a float after checking it is finite and > 0."""
    v = float(value)
    if not np.isfinite(v) or v <= 0:
        raise ValueError(f"{name}: expected a finite value > 0, got {value!r}")
    return v

"""Contact from the electrodes' pattern, judged against the record's own noise.

A BioTac SP pressed anywhere squeezes the conductive fluid away from the electrodes under
the contact: their impedance rises (counts fall) far above the noise, while the electrodes
away from it rise a little in counts as the displaced fluid thickens over them. Between a
calibration and a record, and over a long record, the sensor drifts as it warms up, and
that drift is mostly common to all 24 electrodes (about 0.5–1 count/s on every electrode of
the real resting recording in ``tests/data``). So contact is read from the *shape* of the
impedance change, not its sum:

    r_k = ln(Z_k / Z_rest,k)                 (relative impedance change of taxel k)
    d_k = r_k − median_j r_j                 (the common mode removed)
    s   = max_k d_k / sqrt(σ_k² + u_k²)      (contact score, in noise units)

with σ_k the record's own white-noise level of ln Z_k (:func:`residual_noise` about the
smoothed signal, robust to the contact itself and to glitches) and u_k the uncertainty of the rest impedance (0 for a tare taken in the
same record; the stated uncertainty of a calibration or of an estimate across files). A
finger is in contact where ``s`` stays above a threshold of several noise units: a light
touch that lowers a few electrodes by 50 counts (≈ 10 σ of the resting noise) is found,
and so is a record that begins in contact, without any absolute floor tuned to one sensor.

All functions are pure and vectorised over leading axes; taxels are the last axis.
"""

from __future__ import annotations

import numpy as np

from ._checks import finite_array

__all__ = ["P90_TO_STD", "residual_noise", "noise_from_residuals", "relative_change", "contact_score", "refine_edges",
           "counts_uncertainty_to_log"]

P90_TO_STD = 1.645
"""90th percentile of |N(0, σ²)| in units of σ."""


def residual_noise(signal, smoothed, *, axis: int = 0, floor: float = 1e-9) -> np.ndarray:
    """White-noise level of each channel: the spread of ``signal`` about its ``smoothed``
    version, as the 90th percentile of the absolute residual over 1.645 (the standard
    deviation for normal noise). A real BioTac's noise is mostly a few counts with a rare
    glitch of 100+ counts on one electrode for a frame or two; a standard deviation would
    count the glitches, a median would miss most of the noise (the counts are integers),
    the 90th percentile does neither.

    >>> import numpy as np
    >>> x = np.random.default_rng(0).normal(0.0, 2.0, (5000, 3))
    >>> np.round(residual_noise(x, np.zeros_like(x)), 1)
    array([2., 2., 2.])

    Args:
        signal: (T, ...) samples, T ≥ 1 along ``axis``; ``smoothed``: the same shape.
        axis: the time axis.
        floor: smallest value returned (keeps divisions finite for a channel that never moves).
    Returns: the shape of ``signal`` without ``axis``, in the units of ``signal``.
    """
    x = finite_array("signal", signal)
    y = finite_array("smoothed", smoothed)
    if x.shape != y.shape or x.ndim == 0 or x.shape[axis] < 1:
        raise ValueError(f"signal, smoothed: expected two arrays of the same shape with samples along axis "
                         f"{axis}, got {x.shape} and {y.shape}")
    return noise_from_residuals(x - y, axis=axis, floor=floor, overwrite=True)


def noise_from_residuals(residuals: np.ndarray, *, axis: int = 0, floor: float = 1e-9,
                         overwrite: bool = False) -> np.ndarray:
    """:func:`residual_noise` of residuals already computed (``signal − smoothed``): the 90th
    percentile of their absolute value over 1.645, at least ``floor``. ``overwrite=True`` lets
    it work in ``residuals`` itself (no copy: for a long record's large sample)."""
    r = residuals if overwrite else np.array(residuals, float)
    np.abs(r, out=r)
    return np.maximum(np.percentile(r, 90, axis=axis, overwrite_input=True) / P90_TO_STD, floor)


def relative_change(impedance, rest_impedance) -> np.ndarray:
    """``ln(Z / Z_rest) − median over taxels``: each taxel's relative impedance change with
    the change common to all taxels (drift, temperature) removed. Positive where pressed.

    Args:
        impedance: (T, ..., 24) kΩ, > 0.
        rest_impedance: (..., 24) kΩ, > 0, broadcastable against ``impedance``.
    Returns: (T, ..., 24), dimensionless (≈ fraction of the rest impedance).
    """
    z = finite_array("impedance", impedance)
    z0 = finite_array("rest_impedance", rest_impedance)
    if np.any(z <= 0) or np.any(z0 <= 0):
        raise ValueError("impedance, rest_impedance: expected values > 0 kΩ (counts below 4095)")
    r = np.log(z) - np.log(z0)
    return r - np.median(r, axis=-1, keepdims=True)


def contact_score(change, noise, uncertainty=0.0) -> np.ndarray:
    """Contact score: the largest pressed deviation in units of noise and rest uncertainty.

    >>> import numpy as np
    >>> change = np.zeros((2, 24)); change[1, 5] = 0.08        # one taxel 8 % above rest
    >>> contact_score(change, noise=np.full(24, 0.01))
    array([0., 8.])

    Args:
        change: (T, ..., 24) from :func:`relative_change`.
        noise: (..., 24) white-noise level of ln Z per taxel (:func:`residual_noise`).
        uncertainty: (..., 24) or scalar, uncertainty of ln Z_rest (0 for a tare).
    Returns: (T, ...) the score, ≥ 0.
    """
    d = finite_array("change", change)
    scale = np.sqrt(np.asarray(noise, float) ** 2 + np.asarray(uncertainty, float) ** 2)
    if np.any(~np.isfinite(scale)) or np.any(scale <= 0):
        raise ValueError("noise, uncertainty: expected finite values with noise > 0")
    return np.maximum((d / scale).max(axis=-1), 0.0)


def counts_uncertainty_to_log(counts, sigma_counts) -> np.ndarray:
    """An uncertainty of ``sigma_counts`` on raw counts ``E`` as an uncertainty of ln Z.

    ``Z = (4095/E − 1)·10 kΩ`` gives ``|d ln Z / dE| = 4095 / (E·(4095 − E))``.
    Both arguments broadcast; ``counts`` within (0, 4095).
    """
    e = np.clip(finite_array("counts", counts), 1.0, 4094.0)
    return np.asarray(sigma_counts, float) * 4095.0 / (e * (4095.0 - e))


def refine_edges(intervals, fine_score, threshold: float, reach: int) -> list[tuple[int, int]]:
    """Contact intervals found on a well-smoothed score, with their edges moved to where a
    lightly smoothed ``fine_score`` (T,) crosses ``threshold``.

    A smoother that looks both ways (RTS) starts a sharp contact's rise early and ends its
    fall late; the lightly smoothed score is too noisy to find light contacts with, but
    dates the edges of those it reaches. Each edge moves at most ``reach`` frames inward
    (to the first / last frame above threshold within ``reach`` of the edge); an interval the
    fine score never crosses keeps its edges.

    >>> refine_edges([(289, 511)], np.r_[np.zeros(300), np.full(200, 80.0), np.zeros(100)], 6.0, 20)
    [(300, 500)]
    """
    fine = np.asarray(fine_score, float)
    out = []
    for a, b in intervals:
        head = np.flatnonzero(fine[a:min(b, a + reach)] > threshold)
        tail = np.flatnonzero(fine[max(a, b - reach):b] > threshold)
        a2 = a + int(head[0]) if head.size else a
        b2 = max(a, b - reach) + int(tail[-1]) + 1 if tail.size else b
        out.append((a2, b2) if b2 > a2 else (a, b))
    return out

"""Summaries of a tactile-flow field over the sensor footprint, per frame and per time window.

Image components are (col, row) as in :mod:`tactile.flow`. Because a view's axes satisfy
cols × rows = look, a positive ``curl`` is a rotation counter-clockwise about the view's
``look`` axis (right-hand rule), and a positive ``divergence`` is a pattern spreading out
(pressing in) while a negative one is a pattern contracting (releasing).
"""

# numba's on-disk cache is checked against this file's size and time and names the module it was
# compiled in: this file changed when the package moved under tactile_flow (0.2), so a cache from
# before the move is not loaded.

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numba
import numpy as np

from ._checks import finite_array

__all__ = ["FlowAggregates", "aggregate_flow", "aggregation_constants", "centre_of_pressure",
           "flow_functionals", "window"]


@dataclass(frozen=True)
class FlowAggregates:
    """Per-frame summaries of one view's flow. All arrays have length T.

    Attributes:
        mean: (T, 2) mean flow vector over the footprint (flow units, e.g. px/frame).
        magnitude: (T,) |mean|.
        direction: (T,) angle of ``mean`` in the image, rad, atan2(row, col).
        divergence: (T,) mean ∂u/∂col + ∂v/∂row over the footprint interior (1/frame for px/frame).
        curl: (T,) mean ∂v/∂col − ∂u/∂row over the footprint interior (same units).
        confidence: (T,) fraction of footprint pixels whose flow exceeds the noise level.
    """

    mean: np.ndarray
    magnitude: np.ndarray
    direction: np.ndarray
    divergence: np.ndarray
    curl: np.ndarray
    confidence: np.ndarray


def concatenate(parts: list[FlowAggregates]) -> FlowAggregates:
    """The aggregates of consecutive stretches of frames as those of the whole."""
    return FlowAggregates(*(np.concatenate([getattr(a, f.name) for a in parts])
                            for f in dataclasses.fields(FlowAggregates)))


def interpolate(agg: FlowAggregates, at: np.ndarray, n: int) -> FlowAggregates:
    """Aggregates known at frames ``at`` (ascending, with 0 and n − 1) on every frame 0..n−1:
    mean flow, divergence, curl and confidence interpolated linearly, magnitude and direction
    from the interpolated mean."""
    t = np.arange(n)
    mean = np.stack([np.interp(t, at, agg.mean[:, i]) for i in range(agg.mean.shape[1])], axis=1)
    return FlowAggregates(mean=mean, magnitude=np.hypot(mean[:, 0], mean[:, 1]),
                          direction=np.arctan2(mean[:, 1], mean[:, 0]),
                          divergence=np.interp(t, at, agg.divergence), curl=np.interp(t, at, agg.curl),
                          confidence=np.interp(t, at, agg.confidence))


def aggregate_flow(flow, mask, *, noise: float = 0.05) -> FlowAggregates:
    """Summarise a flow field (T, H, W, 2) over the footprint ``mask`` (H, W) bool.

    ``noise``: magnitude (flow units) below which a pixel counts as not moving, for
    ``confidence``. Divergence and curl are means of central differences over the mask
    eroded by one pixel, so the footprint's edge (where flow meets the zero background)
    does not leak into them. Mean flow, divergence and curl are linear in the field: per
    frame they are the sums Σ_p weights[p]·flow[p] with the weights of
    :func:`flow_functionals`, which :func:`_aggregate` computes in one pass over each frame
    together with the confidence count (float64 sums; |flow|² in float32).
    """
    flow = np.asarray(flow, dtype=np.float32)
    mask = np.asarray(mask, dtype=bool)
    if flow.ndim != 4 or flow.shape[-1] != 2 or flow.shape[1:3] != mask.shape:
        raise ValueError(f"flow: expected (T, H, W, 2) matching mask {mask.shape}, got {flow.shape}")
    if not mask.any():
        raise ValueError("mask: expected a footprint with at least one pixel, got an empty mask")
    n = len(flow)
    sums, moving = np.empty((n, 4)), np.empty(n, np.float32)
    _aggregate(np.ascontiguousarray(flow).reshape(n, -1), *aggregation_constants(mask, noise), sums, moving)
    mean, divergence, curl = sums[:, :2].copy(), sums[:, 2].copy(), sums[:, 3].copy()
    return FlowAggregates(mean=mean, magnitude=np.hypot(mean[:, 0], mean[:, 1]),
                          direction=np.arctan2(mean[:, 1], mean[:, 0]),
                          divergence=divergence, curl=curl, confidence=moving / np.float64(mask.sum()))


def aggregation_constants(mask, noise: float) -> tuple:
    """The constant arguments of :func:`_aggregate` for a footprint (H, W) bool and a noise
    level: ``(in_mask, d_col, d_row, mask01, noise2)``, computed once per view."""
    mask = np.asarray(mask, dtype=bool)
    weights = flow_functionals(mask).reshape(-1, 2, 4)                     # (H·W, 2, 4)
    return (np.ascontiguousarray(weights[:, 0, 0]), np.ascontiguousarray(weights[:, 0, 2]),
            np.ascontiguousarray(weights[:, 1, 2]), mask.ravel().astype(np.float32),
            np.float32(noise) ** 2)


@numba.njit(cache=True, nogil=True, fastmath={"reassoc"})
def _aggregate(flow, in_mask, d_col, d_row, mask01, noise2, sums, moving):
    """One pass per frame over (T, 2P) ``flow`` (u, v interleaved): Σ in_mask·(u, v),
    Σ d_col·u + d_row·v (divergence), Σ d_col·v − d_row·u (curl) into ``sums`` (T, 4), and
    the number of mask pixels with u² + v² > noise2 (float32, as NumPy would) into
    ``moving``. The weights are those of :func:`flow_functionals` (in_mask = mask / mask.sum();
    the curl's weights are the divergence's, swapped). ``reassoc`` lets the sums vectorise."""
    for t in range(flow.shape[0]):
        f = flow[t]
        su = sv = div = curl = 0.0
        count = np.float32(0.0)
        for p in range(in_mask.shape[0]):
            u, v = f[2 * p], f[2 * p + 1]
            su += in_mask[p] * u
            sv += in_mask[p] * v
            div += d_col[p] * u + d_row[p] * v
            curl += d_col[p] * v - d_row[p] * u
            count += mask01[p] * (u * u + v * v > noise2)
        sums[t, 0], sums[t, 1], sums[t, 2], sums[t, 3] = su, sv, div, curl
        moving[t] = count


def _eroded(mask: np.ndarray) -> np.ndarray:
    """The pixels of ``mask`` (H, W) bool whose four neighbours are in it too, outside the
    array counting as out (``scipy.ndimage.binary_erosion(mask, border_value=0)``)."""
    p = np.pad(mask, 1)
    return p[1:-1, 1:-1] & p[:-2, 1:-1] & p[2:, 1:-1] & p[1:-1, :-2] & p[1:-1, 2:]


def flow_functionals(mask) -> np.ndarray:
    """Weights (H·W·2, 4) such that ``flow.reshape(T, -1) @ weights`` gives, per frame, the
    mean (col, row) flow over ``mask`` and the mean divergence and curl over its interior.

    Central difference ∂f/∂c at p is (f[p+c] − f[p−c])/2; summed over the interior that is
    Σ_q f[q]·(I[q−c] − I[q+c])/2 with I the interior indicator. The interior (mask eroded,
    border excluded) never touches the array edge, so no one-sided differences arise.
    """
    mask = np.asarray(mask, dtype=bool)
    interior = _eroded(mask)
    if not interior.any():
        interior = np.zeros_like(mask)
        interior[1:-1, 1:-1] = mask[1:-1, 1:-1]
    ind = np.pad(interior.astype(np.float64), 1) / (2.0 * max(interior.sum(), 1))
    d_col = ind[1:-1, :-2] - ind[1:-1, 2:]              # weight of f[q] in Σ ∂f/∂col
    d_row = ind[:-2, 1:-1] - ind[2:, 1:-1]              # weight of f[q] in Σ ∂f/∂row
    h, w = mask.shape
    weights = np.zeros((h, w, 2, 4))
    weights[..., 0, 0] = mask / mask.sum()
    weights[..., 1, 1] = mask / mask.sum()
    weights[..., 0, 2], weights[..., 1, 2] = d_col, d_row        # divergence = ∂u/∂c + ∂v/∂r
    weights[..., 1, 3], weights[..., 0, 3] = d_col, -d_row       # curl = ∂v/∂c − ∂u/∂r
    return weights.reshape(h * w * 2, 4)


def window(agg: FlowAggregates, start: int, stop: int) -> dict[str, float]:
    """Summary of frames [start, stop): mean vector, its direction and magnitude, mean curl,
    divergence and confidence. Empty windows are a ``ValueError``."""
    if not 0 <= start < stop <= len(agg.magnitude):
        raise ValueError(f"window: expected 0 ≤ start < stop ≤ {len(agg.magnitude)}, got [{start}, {stop})")
    mean = agg.mean[start:stop].mean(axis=0)
    return {"mean_col": float(mean[0]), "mean_row": float(mean[1]),
            "magnitude": float(np.hypot(*mean)), "direction": float(np.arctan2(mean[1], mean[0])),
            "curl": float(agg.curl[start:stop].mean()),
            "divergence": float(agg.divergence[start:stop].mean()),
            "confidence": float(agg.confidence[start:stop].mean())}


def centre_of_pressure(activation, taxels) -> tuple[np.ndarray, np.ndarray]:
    """Activation-weighted taxel position and total activation.

    Args:
        activation: (..., N) activation (kΩ, positive under pressure).
        taxels: (N, 3) taxel positions, mm.

    Returns:
        ``(cop, total)``: (..., 3) centre of pressure in mm, weighted by the positive part of
        the activation (NaN where nothing is pressed), and (...,) total activation (kΩ).
    """
    taxels = finite_array("taxels", taxels, ndim=2, last=3)
    activation = finite_array("activation", activation, last=len(taxels))
    load = np.clip(activation, 0.0, None)
    weight = load.sum(axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        cop = np.where(weight > 0, (load @ taxels) / weight, np.nan)
    return cop, activation.sum(axis=-1)


"""What the viewer draws, as plain arrays: colours of frames and meshes, flow arrows, poses.

Pure numpy (and matplotlib's colour map);
shared by the replay (:mod:`viewer.record`) and the live viewer (:mod:`viewer.live`), so both draw the same way.
Image coordinates are Rerun's: x = column, y = row, pixel (row i, col j) spans
[j, j + 1) × [i, i + 1), so its centre is (j + 0.5, i + 0.5).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from tactile_flow.tactile.frames import to_uint8

FLOW_COLOUR = (80, 220, 255, 255)          # flow-field arrows: cyan, visible on the colour map
MEAN_COLOUR = (140, 255, 90, 255)          # the aggregated direction: green
FINGER_COLOURS = {"ff": (228, 26, 28, 255), "mf": (55, 126, 184, 255), "rf": (77, 175, 74, 255),
                  "lf": (152, 78, 163, 255), "th": (255, 127, 0, 255)}


@lru_cache(maxsize=1)
def colour_map() -> np.ndarray:
    """(256, 3) uint8: 8-bit frame intensity → RGB (matplotlib's ``magma``: dark = no activation)."""
    from matplotlib import colormaps
    return np.round(colormaps["magma"](np.arange(256) / 255.0)[:, :3] * 255).astype(np.uint8)


def colour_frames(frames_u8) -> np.ndarray:
    """(..., H, W) uint8 tactile frames (the flow's input) → (..., H, W, 3) uint8 RGB."""
    return colour_map()[np.asarray(frames_u8, np.uint8)]


def activation_colours(values, ranges) -> np.ndarray:
    """(N, M) activation (kΩ) at mesh vertices → (N, M, 4) RGBA uint8, row n on the intensity
    range ``ranges[n]`` = (low, high) kΩ (:func:`tactile.frames.to_uint8`, as the frames are
    drawn), so a vertex and a pixel of equal activation look the same."""
    values, ranges = np.asarray(values), np.broadcast_to(np.asarray(ranges, float), (len(values), 2))
    u8 = np.empty(values.shape, np.uint8)
    for rng in np.unique(ranges, axis=0):
        sel = np.all(ranges == rng, axis=1)
        u8[sel] = to_uint8(values[sel], *rng)
    rgb = colour_map()[u8]
    return np.concatenate([rgb, np.full(rgb.shape[:-1] + (1,), 255, np.uint8)], axis=-1)


def arrow_grid(mask, spacing: int) -> tuple[np.ndarray, np.ndarray]:
    """Pixels (rows, cols) of a regular grid, ``spacing`` px apart, inside the footprint ``mask``
    (H, W) bool, centred in the frame: where the flow field is drawn as arrows."""
    mask = np.asarray(mask, bool)
    h, w = mask.shape
    rows = np.arange((h - 1) % spacing // 2, h, spacing)
    cols = np.arange((w - 1) % spacing // 2, w, spacing)
    rr, cc = np.meshgrid(rows, cols, indexing="ij")
    keep = mask[rr, cc]
    return rr[keep], cc[keep]


def arrow_origins(grid: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """(P, 2) float32 image positions (x, y) of the grid pixels' centres."""
    rows, cols = grid
    return np.stack([cols + 0.5, rows + 0.5], axis=-1).astype(np.float32)


def sample_field(field, grid) -> np.ndarray:
    """(..., H, W, 2) flow (Δcol, Δrow) px/frame → (..., P, 2) float32 at the grid pixels."""
    rows, cols = grid
    return np.asarray(field, np.float32)[..., rows, cols, :]


def nice_gain(vectors, spacing: float) -> float:
    """An arrow gain (px drawn per px/frame of flow) such that the 99th percentile of the moving
    ``vectors`` (..., 2) is drawn about ``spacing`` px long, rounded down to 1, 2 or 5 × 10^k so
    that the legend reads simply. 1 when nothing moves."""
    mag = np.hypot(*np.moveaxis(np.asarray(vectors, np.float64).reshape(-1, 2), -1, 0))
    mag = mag[mag > 1e-6]
    if mag.size == 0:
        return 1.0
    raw = spacing / max(float(np.percentile(mag, 99)), 1e-6)
    decade = 10.0 ** np.floor(np.log10(raw))
    return float(max(m for m in (1.0, 2.0, 5.0) if m * decade <= raw) * decade)


def direction_arrows(mean, noise: float, length: float) -> np.ndarray:
    """The aggregated direction as (T, 2) image vectors ``length`` px long along ``mean`` (T, 2)
    (mean flow, px/frame); zero where the mean moves less than ``noise`` / 2 (the live
    line's "still", :meth:`protocols.live.LiveMonitor.line`) or is not finite."""
    mean = np.asarray(mean, np.float64)
    mag = np.hypot(mean[:, 0], mean[:, 1])
    moving = np.isfinite(mag) & (mag >= noise / 2)
    out = np.zeros_like(mean, dtype=np.float32)
    out[moving] = (mean[moving] / mag[moving, None] * length).astype(np.float32)
    return out


def direction_deg(direction_rad, magnitude, noise: float) -> np.ndarray:
    """Image direction of the mean flow in degrees in [0, 360) (atan2(row, col): 0 = +col,
    90 = +row), NaN where the mean moves less than ``noise`` / 2: a still pattern has no
    direction. [0, 360) rather than (−180, 180]: a sweep along the finger (−col, 180°) then
    plots as one line instead of jumping between ±180."""
    d = np.mod(np.degrees(np.asarray(direction_rad, np.float64)), 360.0)
    return np.where(np.asarray(magnitude, np.float64) >= noise / 2, d, np.nan)


def unwrap_stretches(deg) -> np.ndarray:
    """(T,) directions in degrees with NaN gaps → each stretch between gaps unwrapped (no jump of
    360 between neighbours) and shifted by a multiple of 360 so that its median lies in
    [0, 360): a direction that hovers about 0° plots as one line instead of jumping to 360."""
    deg = np.array(deg, np.float64)
    ok = np.isfinite(deg)
    edges = np.flatnonzero(np.diff(np.r_[False, ok, False].astype(np.int8)))
    for a, b in zip(edges[::2], edges[1::2]):
        stretch = np.degrees(np.unwrap(np.radians(deg[a:b])))
        deg[a:b] = stretch - 360.0 * np.floor(np.median(stretch) / 360.0)
    return deg


def footprint_centre(mask) -> np.ndarray:
    """(2,) image position (x, y) of the footprint's centroid: where the direction arrow starts."""
    rows, cols = np.nonzero(np.asarray(mask, bool))
    return np.array([cols.mean() + 0.5, rows.mean() + 0.5], np.float32)


def hex_rgba(colour: str) -> int:
    """``#rrggbb`` → 0xRRGGBBFF (Rerun's packed colour)."""
    return (int(colour.lstrip("#"), 16) << 8) | 0xFF

"""Farnebäck's dense flow for tactile frames, each frame's polynomial expansion shared.

OpenCV's ``calcOpticalFlowFarneback`` expands both frames of every pair it is given into
quadratic polynomials; in a sequence every frame is expanded twice (once as the later frame of
a pair, once as the earlier one), and a static flow expands its reference once per frame.
Here each frame is expanded once and the pairs reuse the expansions (Farnebäck's method allows
it: a frame's expansion does not depend on the other frame). The arithmetic is OpenCV's, step
for step, so the flow is ``cv2.calcOpticalFlowFarneback``'s **to the bit**
(``tests/test_farneback.py``). On 28 × 40 frames a pair of consecutive frames costs ~0.64 of
OpenCV's call, a pair from one reference ~0.66 (``docs/performance.md``).

Covered: what the analysis uses, a single pyramid level (OpenCV builds none for frames under
64 px with ``pyr_scale=0.5``), the box window (``flags=0``), ``poly_n`` 5 or 7, no initial flow.
Anything else (:func:`supports` is false) is passed to OpenCV by :mod:`tactile.flow`.

Frames: (T, H, W) uint8; flows: (…, H, W, 2) float32, (Δcol, Δrow) in pixels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ._lazy import lazy_import

__all__ = ["Expansions", "Stream", "expand", "pair_flows", "supports"]

_MIN_PYRAMID = 32
"""OpenCV builds a pyramid level only where the scaled frame is at least this many pixels."""

_k = lazy_import("tactile_flow.tactile._farneback_kernels")   # numba: compiled on first use


def supports(shape, config) -> bool:
    """Whether frames of ``shape`` (…, H, W) with ``config`` (a :class:`tactile.flow.FlowConfig`)
    are flowed here: one pyramid level, box window, no initial flow, ``poly_n`` 5 or 7.

    >>> from tactile_flow.tactile.flow import FlowConfig
    >>> supports((28, 40), FlowConfig()), supports((480, 640), FlowConfig())
    (True, False)
    """
    h, w = shape[-2:]
    one_level = int(config.levels) == 0 or min(h, w) * float(config.pyr_scale) < _MIN_PYRAMID
    return (config.method == "farneback" and one_level and int(config.flags) == 0
            and int(config.poly_n) in (5, 7) and min(h, w) >= 2)


@lru_cache(maxsize=8)
def _applicability(n: int, sigma: float):
    """OpenCV's ``FarnebackPrepareGaussian``: the Gaussian ``g`` over -n..n and its moments
    ``x·g``, ``x²·g`` (float32, as OpenCV rounds them), and four entries of the inverse of the
    Gram matrix of the quadratic basis (float64, through OpenCV's Cholesky inverse)."""
    if sigma < np.finfo(np.float32).eps:
        sigma = n * 0.3
    f32 = np.float32
    xs = range(-n, n + 1)
    g = [f32(math.exp(-x * x / (2 * sigma * sigma))) for x in xs]
    s = 0.0
    for v in g:
        s += float(v)
    s = 1.0 / s
    g = [f32(float(v) * s) for v in g]
    xg = [f32(x) * v for x, v in zip(xs, g)]
    xxg = [f32(x * x) * v for x, v in zip(xs, g)]
    G = np.zeros((6, 6))
    for yi, y in enumerate(xs):
        for xi, x in enumerate(xs):
            p = g[yi] * g[xi]                         # float32 products, summed in float64
            G[0, 0] += float(p)
            G[1, 1] += float(p * f32(x) * f32(x))
            G[3, 3] += float(p * f32(x) * f32(x) * f32(x) * f32(x))
            G[5, 5] += float(p * f32(x) * f32(x) * f32(y) * f32(y))
    G[2, 2] = G[0, 3] = G[0, 4] = G[3, 0] = G[4, 0] = G[1, 1]
    G[4, 4] = G[3, 3]
    G[3, 4] = G[4, 3] = G[5, 5]
    inv = _cholesky_inverse(G)
    arrays = tuple(np.array(a, np.float32) for a in (g, xg, xxg))
    return arrays + (float(inv[1, 1]), float(inv[0, 3]), float(inv[3, 3]), float(inv[5, 5]))


def _cholesky_inverse(a: np.ndarray) -> np.ndarray:
    """A⁻¹ of a symmetric positive definite matrix as OpenCV's ``invert(…, DECOMP_CHOLESKY)``
    computes it (L with reciprocal diagonal, then L y = I and Lᵀ x = y), the same roundings."""
    m = len(a)
    L = a.copy()
    for i in range(m):
        for j in range(i):
            s = L[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s * L[j, j]
        s = L[i, i]
        for k in range(i):
            s -= L[i, k] * L[i, k]
        L[i, i] = 1.0 / math.sqrt(s)
    b = np.eye(m)
    for i in range(m):
        for j in range(m):
            s = b[i, j]
            for k in range(i):
                s -= L[i, k] * b[k, j]
            b[i, j] = s * L[i, i]
    for i in range(m - 1, -1, -1):
        for j in range(m):
            s = b[i, j]
            for k in range(m - 1, i, -1):
                s -= L[k, i] * b[k, j]
            b[i, j] = s * L[i, i]
    return b


@dataclass(frozen=True)
class Expansions:
    """Polynomial expansions of frames, computed once for every flow that needs them."""

    values: np.ndarray
    """(T, H, W, 5) float32: per pixel the quadratic's (b_y, b_x, a_yy, a_xx, a_xy)."""
    empty: np.ndarray
    """(T,) bool: the frame is all zero."""


def expand(frames, config) -> Expansions:
    """:class:`Expansions` of ``frames`` (T, H, W) or (H, W) uint8 with ``config``'s
    ``poly_n`` (OpenCV takes it as the half-width of the applicability) and ``poly_sigma``."""
    frames = np.ascontiguousarray(frames, dtype=np.uint8)
    if frames.ndim == 2:
        frames = frames[None]
    n = int(config.poly_n)
    g, xg, xxg, ig11, ig03, ig33, ig55 = _applicability(n, float(config.poly_sigma))
    values = np.empty(frames.shape + (5,), np.float32)
    _k.expand(frames, values, n, g, xg, xxg, ig11, ig03, ig33, ig55)
    return Expansions(values, ~frames.reshape(len(frames), -1).any(axis=1))


def pair_flows(first: Expansions, second: Expansions, pairs, config, out=None) -> np.ndarray:
    """Flow from frame ``pairs[k, 0]`` of ``first`` to frame ``pairs[k, 1]`` of ``second`` for
    each row of ``pairs`` (K, 2) int → (K, H, W, 2) float32 px, into ``out`` if given.

    A pair of two empty frames gets a zero flow without computing it (OpenCV's is exactly zero).
    """
    pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
    both_empty = first.empty[pairs[:, 0]] & second.empty[pairs[:, 1]]
    todo = np.where(both_empty[:, None], -1, pairs)
    if out is None:
        out = np.empty((len(pairs),) + first.values.shape[1:3] + (2,), np.float32)
    _k.flows(first.values, second.values, todo, out, int(config.winsize), int(config.iterations))
    return out


class Stream:
    """The flow of each new frame from the one before, for a live stream of (H, W) uint8 frames
    (``tactile.online``): each frame is expanded once, when it arrives, and kept for the next.
    Every work array is made here, so that a frame allocates nothing."""

    def __init__(self, shape, config):
        h, w = shape
        n, winsize = int(config.poly_n), int(config.winsize)
        self._params = (n, *_applicability(n, float(config.poly_sigma)), winsize, int(config.iterations))
        self._expanded = np.zeros((2, h, w, 5), np.float32)
        self._scratch = (np.empty((h, w), np.float32), np.empty((3, w + 2 * n), np.float32),
                         np.empty((6, w), np.float64), np.empty((h, w, 5), np.float32),
                         np.empty((w + 2 * (winsize // 2 + 1)) * 5, np.float64))
        self._no_field = np.empty((h, w, 2), np.float32)
        self._slot = 0
        self._advance = _k.advance

    def push(self, frame: np.ndarray, field: np.ndarray | None = None) -> None:
        """Take ``frame`` (H, W) uint8; if ``field`` ((H, W, 2) float32, C-contiguous) is given,
        write into it the flow from the previously pushed frame to this one."""
        self._slot = 1 - self._slot
        self._advance(frame, self._expanded[1 - self._slot], self._expanded[self._slot],
                      self._no_field if field is None else field, field is not None, *self._params, *self._scratch)

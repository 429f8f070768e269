"""The compiled (numba) kernels of :mod:`tactile.farneback`: Farnebäck's dense flow on small
frames, with each frame's polynomial expansion computed once and shared by every pair it is in.

The arithmetic is OpenCV's (``modules/video/src/optflowgf.cpp``: ``FarnebackPolyExp``,
``FarnebackUpdateMatrices``, ``FarnebackUpdateFlow_Blur``) operation for operation, in the same
order and the same precision (float32 where OpenCV computes in ``float``, float64 where in
``double``), so that the flow equals ``cv2.calcOpticalFlowFarneback``'s to the bit on frames too
small for its pyramid (``tests/test_farneback.py``). OpenCV is under the Apache License 2.0;
this is a reimplementation of its arithmetic in numba, not a copy of its code.

Private to :mod:`tactile.farneback`. Arrays: a frame (H, W) uint8; its expansion R (H, W, 5)
float32 = the quadratic's coefficients (b_y, b_x, a_yy, a_xx, a_xy) per pixel; the matrices M
(H, W, 5) float32 = (G11, G12, G22, h1, h2); a flow (H, W, 2) float32 = (Δcol, Δrow) in pixels.
"""

# numba's on-disk cache is checked against this file's size and time and names the module it was
# compiled in: this file changed when the package moved under tactile_flow (0.2), so a cache from
# before the move is not loaded.

from __future__ import annotations

import numba
import numpy as np

_F32 = np.float32
_BORDER = np.array([0.14, 0.14, 0.4472, 0.4472, 0.4472], np.float32)
"""OpenCV's weights of the matrices in the 5 pixels next to the frame's edge."""
_U32 = 0xFFFFFFFF


@numba.njit(cache=True, nogil=True)
def _blur3(frame, out):
    """``GaussianBlur(float32(frame), (3, 3), 0)`` (kernel ¼ ½ ¼, reflected border) into ``out``
    (H, W) float32: every value is a multiple of 1/16 below 256, exact in float32 in any order."""
    h, w = frame.shape
    for y in range(h):
        ya = y - 1 if y > 0 else 1
        yb = y + 1 if y < h - 1 else h - 2
        for x in range(w):
            out[y, x] = (_F32(0.25) * _F32(frame[ya, x]) + _F32(0.5) * _F32(frame[y, x])
                         + _F32(0.25) * _F32(frame[yb, x]))
    for y in range(h):
        left = out[y, 1]                                  # the values before this pass
        for x in range(w):
            here = out[y, x]
            right = out[y, x + 1] if x < w - 1 else left
            out[y, x] = _F32(0.25) * left + _F32(0.5) * here + _F32(0.25) * right
            left = here


@numba.njit(cache=True, nogil=True)
def _poly_exp(src, dst, n, g, xg, xxg, ig11, ig03, ig33, ig55, rows, sums):
    """Polynomial expansion of ``src`` (H, W) float32 into ``dst`` (H, W, 5) float32.

    ``g``, ``xg``, ``xxg`` (2n + 1,) float32: the Gaussian applicability and its first and
    second moments, centre at index n; ``ig*``: entries of the inverse of its Gram matrix.
    Scratch: ``rows`` (3, W + 2n) float32, ``sums`` (6, W) float64. Each pixel's sums are
    taken in OpenCV's order, the loops running along the row innermost."""
    h, w = src.shape
    r0, r1, r2 = rows[0], rows[1], rows[2]
    b1, b2, b3, b4, b5, b6 = sums[0], sums[1], sums[2], sums[3], sums[4], sums[5]
    for y in range(h):
        # vertical part, float32: Σ g·I, Σ y·g·I, Σ y²·g·I down the column, pixel x at n + x
        g0 = g[n]
        for x in range(w):
            r0[n + x] = src[y, x] * g0
            r1[n + x] = _F32(0.0)
            r2[n + x] = _F32(0.0)
        for k in range(1, n + 1):
            gk = g[n + k]
            xgk = xg[n + k]
            xxgk = xxg[n + k]
            above = src[max(y - k, 0)]
            below = src[min(y + k, h - 1)]
            for x in range(w):
                a = above[x]
                b = below[x]
                p = a + b
                r0[n + x] = r0[n + x] + gk * p
                r1[n + x] = r1[n + x] + xgk * (b - a)
                r2[n + x] = r2[n + x] + xxgk * p
        for x in range(n):                               # replicate the first and last pixel
            r0[x] = r0[n]
            r1[x] = r1[n]
            r2[x] = r2[n]
            r0[w + n + x] = r0[w + n - 1]
            r1[w + n + x] = r1[w + n - 1]
            r2[w + n + x] = r2[w + n - 1]
        # horizontal part: float64 sums of float32 terms, as OpenCV
        for x in range(w):
            b1[x] = r0[n + x] * g0
            b2[x] = 0.0
            b3[x] = r1[n + x] * g0
            b4[x] = 0.0
            b5[x] = r2[n + x] * g0
            b6[x] = 0.0
        for k in range(1, n + 1):
            gk = g[n + k]
            xgk = xg[n + k]
            xxgk = xxg[n + k]
            for x in range(w):
                right = n + x + k
                left = n + x - k
                tg = np.float64(r0[right] + r0[left])
                b1[x] += tg * gk
                b4[x] += tg * xxgk
                b2[x] += (r0[right] - r0[left]) * xgk
                b3[x] += (r1[right] + r1[left]) * gk
                b6[x] += (r1[right] - r1[left]) * xgk
                b5[x] += (r2[right] + r2[left]) * gk
        for x in range(w):
            dst[y, x, 0] = _F32(b3[x] * ig11)
            dst[y, x, 1] = _F32(b2[x] * ig11)
            dst[y, x, 2] = _F32(b1[x] * ig03 + b5[x] * ig33)
            dst[y, x, 3] = _F32(b1[x] * ig03 + b4[x] * ig33)
            dst[y, x, 4] = _F32(b6[x] * ig55)


@numba.njit(cache=True, nogil=True, inline="always")
def _floor(v):
    """``cvFloor``: the largest integer ≤ ``v`` (truncation, then one less below zero)."""
    i = int(v)
    return i - 1 if v < i else i


@numba.njit(cache=True, nogil=True)
def _update_matrices(r0, r1, flow, m):
    """The matrices ``m`` (H, W, 5) of every pixel from the expansions ``r0`` of the first frame,
    ``r1`` of the second (sampled bilinearly where ``flow`` carries the pixel) and ``flow``."""
    h, w = flow.shape[:2]
    a = r0.reshape(h * w * 5)                            # flat views: one offset per pixel
    b = r1.reshape(h * w * 5)
    f = flow.reshape(h * w * 2)
    out = m.reshape(h * w * 5)
    step = w * 5
    half = _F32(0.5)
    quarter = _F32(0.25)
    one = _F32(1.0)
    for y in range(h):
        for x in range(w):
            i = y * w + x
            o = i * 5
            dx = f[i * 2]
            dy = f[i * 2 + 1]
            fx = _F32(x) + dx
            fy = _F32(y) + dy
            x1 = _floor(fx)
            y1 = _floor(fy)
            if 0 <= x1 < w - 1 and 0 <= y1 < h - 1:
                fx = fx - _F32(x1)
                fy = fy - _F32(y1)
                a00 = (one - fx) * (one - fy)
                a01 = fx * (one - fy)
                a10 = (one - fx) * fy
                a11 = fx * fy
                p = y1 * step + x1 * 5
                r2 = a00 * b[p] + a01 * b[p + 5] + a10 * b[p + step] + a11 * b[p + step + 5]
                r3 = a00 * b[p + 1] + a01 * b[p + 6] + a10 * b[p + step + 1] + a11 * b[p + step + 6]
                r4 = a00 * b[p + 2] + a01 * b[p + 7] + a10 * b[p + step + 2] + a11 * b[p + step + 7]
                r5 = a00 * b[p + 3] + a01 * b[p + 8] + a10 * b[p + step + 3] + a11 * b[p + step + 8]
                r6 = a00 * b[p + 4] + a01 * b[p + 9] + a10 * b[p + step + 4] + a11 * b[p + step + 9]
                r4 = (a[o + 2] + r4) * half
                r5 = (a[o + 3] + r5) * half
                r6 = (a[o + 4] + r6) * quarter
            else:
                r2 = _F32(0.0)
                r3 = _F32(0.0)
                r4 = a[o + 2]
                r5 = a[o + 3]
                r6 = a[o + 4] * half
            r2 = (a[o] - r2) * half
            r3 = (a[o + 1] - r3) * half
            r2 = r2 + (r4 * dy + r6 * dx)
            r3 = r3 + (r6 * dy + r5 * dx)
            # OpenCV's test compares as unsigned: on frames under 10 px it skips some pixels
            if ((x - 5) & _U32) >= ((w - 10) & _U32) or ((y - 5) & _U32) >= ((h - 10) & _U32):
                scale = (_BORDER[x] if x < 5 else one) * (_BORDER[w - x - 1] if x >= w - 5 else one)
                scale = scale * (_BORDER[y] if y < 5 else one) * (_BORDER[h - y - 1] if y >= h - 5 else one)
                r2 = r2 * scale
                r3 = r3 * scale
                r4 = r4 * scale
                r5 = r5 * scale
                r6 = r6 * scale
            out[o] = r4 * r4 + r6 * r6
            out[o + 1] = (r4 + r5) * r6
            out[o + 2] = r5 * r5 + r6 * r6
            out[o + 3] = r4 * r2 + r6 * r3
            out[o + 4] = r6 * r2 + r5 * r3


@numba.njit(cache=True, nogil=True)
def _solve_blurred(m, flow, winsize, vsum):
    """The flow of every pixel from the box-filtered (``winsize``², replicated border) matrices:
    (ΣG)·flow = Σh, OpenCV's running sums in float64. ``vsum`` a float64 scratch of
    (W + 2·(winsize // 2 + 1)) · 5."""
    h, w = flow.shape[:2]
    r = winsize // 2
    pad = r + 1                                           # vsum pixel x lives at index x + pad
    scale = 1.0 / (winsize * winsize)
    for x in range(w):
        for c in range(5):
            vsum[(x + pad) * 5 + c] = np.float64(m[0, x, c] * _F32(r + 2))
    for yy in range(1, r):
        s = min(yy, h - 1)
        for x in range(w):
            for c in range(5):
                vsum[(x + pad) * 5 + c] += m[s, x, c]
    for y in range(h):
        a = max(y - r - 1, 0)
        b = min(y + r, h - 1)
        for x in range(w):
            for c in range(5):
                vsum[(x + pad) * 5 + c] += m[b, x, c] - m[a, x, c]
        for x in range(pad):
            for c in range(5):
                vsum[x * 5 + c] = vsum[pad * 5 + c]
                vsum[(w + pad + x) * 5 + c] = vsum[(w + pad - 1) * 5 + c]
        o = pad * 5
        g11 = vsum[o] * (r + 2)
        g12 = vsum[o + 1] * (r + 2)
        g22 = vsum[o + 2] * (r + 2)
        h1 = vsum[o + 3] * (r + 2)
        h2 = vsum[o + 4] * (r + 2)
        for x in range(1, r):
            p = (x + pad) * 5
            g11 += vsum[p]
            g12 += vsum[p + 1]
            g22 += vsum[p + 2]
            h1 += vsum[p + 3]
            h2 += vsum[p + 4]
        for x in range(w):
            p = (x + r + pad) * 5
            q = (x - r - 1 + pad) * 5
            g11 += vsum[p] - vsum[q]
            g12 += vsum[p + 1] - vsum[q + 1]
            g22 += vsum[p + 2] - vsum[q + 2]
            h1 += vsum[p + 3] - vsum[q + 3]
            h2 += vsum[p + 4] - vsum[q + 4]
            g11_ = g11 * scale
            g12_ = g12 * scale
            g22_ = g22 * scale
            h1_ = h1 * scale
            h2_ = h2 * scale
            idet = 1.0 / (g11_ * g22_ - g12_ * g12_ + 1e-3)
            flow[y, x, 0] = _F32((g11_ * h2_ - g12_ * h1_) * idet)
            flow[y, x, 1] = _F32((g22_ * h1_ - g12_ * h2_) * idet)


@numba.njit(cache=True, nogil=True)
def _flow_pair(r0, r1, flow, m, vsum, winsize, iterations):
    """Farnebäck's flow from the frame expanded into ``r0`` to the one in ``r1``, into ``flow``
    (from zero, one pyramid level)."""
    flow[...] = 0.0
    _update_matrices(r0, r1, flow, m)
    for i in range(iterations):
        _solve_blurred(m, flow, winsize, vsum)
        if i < iterations - 1:
            _update_matrices(r0, r1, flow, m)


@numba.njit(cache=True, nogil=True)
def _expand_one(frame, out, n, g, xg, xxg, ig11, ig03, ig33, ig55, blurred, rows, sums):
    """Polynomial expansion of ``frame`` (H, W) uint8 into ``out`` (H, W, 5); an empty frame's
    is written as zeros (what the arithmetic gives, +0.0 included)."""
    if frame.any():
        _blur3(frame, blurred)
        _poly_exp(blurred, out, n, g, xg, xxg, ig11, ig03, ig33, ig55, rows, sums)
    else:
        out[...] = 0.0


@numba.njit(cache=True, nogil=True)
def expand(frames, out, n, g, xg, xxg, ig11, ig03, ig33, ig55):
    """Polynomial expansion of every frame of ``frames`` (T, H, W) uint8 into ``out`` (T, H, W, 5)."""
    t, h, w = frames.shape
    blurred = np.empty((h, w), np.float32)
    rows = np.empty((3, w + 2 * n), np.float32)
    sums = np.empty((6, w), np.float64)
    for i in range(t):
        _expand_one(frames[i], out[i], n, g, xg, xxg, ig11, ig03, ig33, ig55, blurred, rows, sums)


@numba.njit(cache=True, nogil=True)
def advance(frame, r_prev, r_cur, field, with_flow, n, g, xg, xxg, ig11, ig03, ig33, ig55, winsize, iterations,
            blurred, rows, sums, m, vsum):
    """Streaming: ``frame`` (H, W) expanded into ``r_cur``; with ``with_flow``, the flow from the
    frame expanded in ``r_prev`` to it into ``field`` (H, W, 2). The scratch arrays are the
    caller's (nothing is allocated per frame)."""
    _expand_one(frame, r_cur, n, g, xg, xxg, ig11, ig03, ig33, ig55, blurred, rows, sums)
    if with_flow:
        _flow_pair(r_prev, r_cur, field, m, vsum, winsize, iterations)


@numba.njit(cache=True, nogil=True)
def flows(r_from, r_to, pairs, out, winsize, iterations):
    """``out[k]`` = the flow from ``r_from[pairs[k, 0]]`` to ``r_to[pairs[k, 1]]`` for each row
    of ``pairs`` (K, 2); a row with a negative entry gives a zero flow (two empty frames)."""
    h, w = out.shape[1:3]
    m = np.empty((h, w, 5), np.float32)
    vsum = np.empty((w + 2 * (winsize // 2 + 1)) * 5, np.float64)
    for k in range(pairs.shape[0]):
        if pairs[k, 0] < 0:
            out[k] = 0.0
        else:
            _flow_pair(r_from[pairs[k, 0]], r_to[pairs[k, 1]], out[k], m, vsum, winsize, iterations)

"""The compiled (numba) kernels of :mod:`tactile.frames`: projection, coverage tests, the
z-buffer, the triangle walk of the fast path, and the 8-bit store.

Kept apart from the API (as scikit-image keeps its ``_kernels``) so that importing
:mod:`tactile.frames` compiles nothing: this module loads the first time a frame is rendered.
Everything here is private to :mod:`tactile.frames` and :mod:`tactile.online`.
"""

# numba's on-disk cache is checked against this file's size and time and names the module it was
# compiled in: this file changed when the package moved under tactile_flow (0.2), so a cache from
# before the move is not loaded.

from __future__ import annotations

import math

import numba
import numpy as np

# --- compiled kernels ------------------------------------------------------------------------
#
# Coordinates: a vertex's (u, v) = (col, row) in pixels, pixel (i, j) has its centre at
# (u, v) = (j, i); ``d`` = depth along ``look`` (smaller = nearer the camera).

_TOL = 1e-9               # barycentric tolerance of the coverage test (pixels on shared edges)
_NEAR = 1e-6              # px: pixels this close to the boundary or a flipped triangle: z-test
_MAX_CROSSINGS = 32       # boundary crossings per pixel row the fast path has room for
_MAX_SLOW_PIXELS = 8      # pixels per frame z-tested one by one before a full z-buffer is cheaper
_MAX_STEPS = 256          # walk length before a pixel is z-tested instead
_NONE = np.uint32(0xFFFFFFFF)  # "no neighbour" in WalkIndex.neighbours


@numba.njit(cache=True, nogil=True)
def _project(base, step, vertex_values, scale, us, vs, ds, vals):
    """Vertex k of the displaced surface, base[:, k] + scale·value·step[:, k], into
    (us, vs, ds)[k] = (col px, row px, depth mm); its value into vals[k]. ``base`` (3, K) is
    the undisplaced position, ``step`` (3, K) the normal in px, px, mm per mm."""
    for k in range(base.shape[1]):
        val = vertex_values[k]
        s = scale * val
        us[k] = base[0, k] + s * step[0, k]
        vs[k] = base[1, k] + s * step[1, k]
        ds[k] = base[2, k] + s * step[2, k]
        vals[k] = val


@numba.njit(cache=True, nogil=True)
def _min3(a, b, c):
    m = a if a < b else b                  # (explicit: numba's min(a, b, c) is ~2× slower)
    return m if m < c else c


@numba.njit(cache=True, nogil=True)
def _max3(a, b, c):
    m = a if a > b else b
    return m if m > c else c


@numba.njit(cache=True, nogil=True)
def _pixel_box(us, vs, a, b, c, h, w, margin):
    """Pixel centres (j0..j1, i0..i1) in the frame within ``margin`` of triangle (a, b, c)'s box."""
    j0 = max(0, int(math.ceil(_min3(us[a], us[b], us[c]) - margin)))
    j1 = min(w - 1, int(math.floor(_max3(us[a], us[b], us[c]) + margin)))
    i0 = max(0, int(math.ceil(_min3(vs[a], vs[b], vs[c]) - margin)))
    i1 = min(h - 1, int(math.floor(_max3(vs[a], vs[b], vs[c]) + margin)))
    return j0, j1, i0, i1


@numba.njit(cache=True, nogil=True)
def _area(us, vs, a, b, c):
    """Twice the signed projected area of triangle (a, b, c)."""
    return (us[b] - us[a]) * (vs[c] - vs[a]) - (us[c] - us[a]) * (vs[b] - vs[a])


@numba.njit(cache=True, nogil=True)
def _barycentric(us, vs, a, b, c, inv_area, i, j):
    """Barycentric weights of pixel centre (j, i) in triangle (a, b, c); 1/area given."""
    wa = ((us[b] - j) * (vs[c] - i) - (us[c] - j) * (vs[b] - i)) * inv_area
    wb = ((us[c] - j) * (vs[a] - i) - (us[a] - j) * (vs[c] - i)) * inv_area
    return wa, wb, 1.0 - wa - wb


@numba.njit(cache=True, nogil=True)
def _covers(wa, wb, wc):
    """The coverage test of the z-buffer: inside the triangle or within _TOL of its edges."""
    return wa >= -_TOL and wb >= -_TOL and wc >= -_TOL


@numba.njit(cache=True, nogil=True)
def _zbuffer(us, vs, ds, vals, tris, img, depth, winner, bary):
    """The reference renderer: z-buffer every triangle into ``img`` (H, W), 0 off the surface.

    A triangle takes pixel (i, j) if the pixel centre lies in its bounding box, its area is
    non-zero, :func:`_covers` holds and its depth is strictly below the best so far (so of
    equal depths the first triangle wins). ``winner`` and ``bary`` receive the visible
    triangle (−1 off the surface) and its barycentric weights.
    """
    h, w = img.shape
    img[:, :] = 0.0
    depth[:, :] = np.inf
    winner[:, :] = -1
    for f in range(tris.shape[0]):
        a, b, c = tris[f, 0], tris[f, 1], tris[f, 2]
        j0, j1, i0, i1 = _pixel_box(us, vs, a, b, c, h, w, 0.0)
        if j0 > j1 or i0 > i1:
            continue
        area = _area(us, vs, a, b, c)
        if area == 0.0:
            continue
        inv_area = 1.0 / area
        for i in range(i0, i1 + 1):
            for j in range(j0, j1 + 1):
                wa, wb, wc = _barycentric(us, vs, a, b, c, inv_area, i, j)
                if not _covers(wa, wb, wc):
                    continue
                d = wa * ds[a] + wb * ds[b] + wc * ds[c]
                if d < depth[i, j]:
                    depth[i, j] = d
                    img[i, j] = wa * vals[a] + wb * vals[b] + wc * vals[c]
                    winner[i, j] = f
                    bary[i, j, 0] = wa
                    bary[i, j, 1] = wb
                    bary[i, j, 2] = wc


@numba.njit(cache=True, nogil=True)
def _zbuffer_pixel(us, vs, ds, vals, tris, i, j):
    """:func:`_zbuffer`'s value at the single pixel (i, j): the same tests in the same order.
    (For an integer j, ceil(min u) ≤ j ≤ floor(max u) is min u ≤ j ≤ max u.)"""
    best = np.inf
    value = 0.0
    for f in range(tris.shape[0]):
        a, b, c = tris[f, 0], tris[f, 1], tris[f, 2]
        if (_min3(us[a], us[b], us[c]) > j or _max3(us[a], us[b], us[c]) < j
                or _min3(vs[a], vs[b], vs[c]) > i or _max3(vs[a], vs[b], vs[c]) < i):
            continue
        area = _area(us, vs, a, b, c)
        if area == 0.0:
            continue
        wa, wb, wc = _barycentric(us, vs, a, b, c, 1.0 / area, i, j)
        if not _covers(wa, wb, wc):
            continue
        d = wa * ds[a] + wb * ds[b] + wc * ds[c]
        if d < best:
            best = d
            value = wa * vals[a] + wb * vals[b] + wc * vals[c]
    return value


@numba.njit(cache=True, nogil=True)
def _near_segment(j, i, ua, va, ub, vb):
    """Whether the point (j, i) is within _NEAR of the segment (ua, va)–(ub, vb)."""
    du, dv = ub - ua, vb - va
    length2 = du * du + dv * dv
    cross = du * (i - va) - dv * (j - ua)
    if cross * cross > _NEAR * _NEAR * length2:          # farther than _NEAR from the line
        return False
    s = 0.0 if length2 == 0.0 else min(1.0, max(0.0, ((j - ua) * du + (i - va) * dv) / length2))
    eu, ev = ua + s * du - j, va + s * dv - i
    return eu * eu + ev * ev <= _NEAR * _NEAR


@numba.njit(cache=True, nogil=True)
def _mark_near(us, vs, a, b, c, slow, slow_px, n_slow):
    """Append to ``slow_px`` the pixel centres within _NEAR of the closed triangle (a, b, c)
    (the segment a–b if c == b), once each (``slow`` flags them). Returns the new count."""
    h, w = slow.shape
    j0, j1, i0, i1 = _pixel_box(us, vs, a, b, c, h, w, _NEAR)
    if i0 > i1 or j0 > j1:
        return n_slow
    for i in range(i0, i1 + 1):
        for j in range(j0, j1 + 1):
            if slow[i, j]:
                continue
            near = _near_segment(j, i, us[a], vs[a], us[b], vs[b])
            if c != b:
                # Inside: the three edge functions do not disagree in sign (any orientation).
                e0 = (us[b] - us[a]) * (i - vs[a]) - (vs[b] - vs[a]) * (j - us[a])
                e1 = (us[c] - us[b]) * (i - vs[b]) - (vs[c] - vs[b]) * (j - us[b])
                e2 = (us[a] - us[c]) * (i - vs[c]) - (vs[a] - vs[c]) * (j - us[c])
                near = (near or (e0 >= 0 and e1 >= 0 and e2 >= 0) or (e0 <= 0 and e1 <= 0 and e2 <= 0)
                        or _near_segment(j, i, us[b], vs[b], us[c], vs[c])
                        or _near_segment(j, i, us[c], vs[c], us[a], vs[a]))
            if near:
                slow[i, j] = True
                slow_px[n_slow, 0] = i
                slow_px[n_slow, 1] = j
                n_slow += 1
    return n_slow


@numba.njit(cache=True, nogil=True)
def _walk(us, vs, vals, tris, neighbours, f, i, j):
    """Walk from triangle ``f`` towards pixel (i, j): while the z-buffer's coverage test fails,
    cross the edge opposite the most negative barycentric weight. Returns (found, triangle,
    value); not found if the walk leaves the mesh, meets a degenerate triangle or runs long."""
    for _ in range(_MAX_STEPS):            # (no `break` here: numba compiles it ~10× slower)
        a, b, c = tris[f, 0], tris[f, 1], tris[f, 2]
        area = _area(us, vs, a, b, c)
        if area == 0.0:
            return False, f, 0.0
        wa, wb, wc = _barycentric(us, vs, a, b, c, 1.0 / area, i, j)
        if _covers(wa, wb, wc):
            return True, f, wa * vals[a] + wb * vals[b] + wc * vals[c]
        g = neighbours[f, 0 if wa <= wb and wa <= wc else (1 if wb <= wc else 2)]
        if g == _NONE:
            return False, f, 0.0
        f = g
    return False, f, 0.0


@numba.njit(cache=True, nogil=True)
def _mark_flipped(us, vs, tris, orientation, slow, slow_px):
    """Step 1 of :func:`_fast_frame` for the triangles: mark the pixels near every triangle
    whose projected area is not of the sign ``orientation``. Returns the number marked."""
    n_slow = 0
    for f in range(tris.shape[0]):
        a, b, c = tris[f, 0], tris[f, 1], tris[f, 2]
        if _area(us, vs, a, b, c) * orientation <= 0.0:
            n_slow = _mark_near(us, vs, a, b, c, slow, slow_px, n_slow)
    return n_slow


@numba.njit(cache=True, nogil=True)
def _boundary_pass(us, vs, boundary, slow, slow_px, n_slow, cross_u, cross_d, n_cross):
    """Steps 1–2 of :func:`_fast_frame` for the boundary edges: mark the pixels near them and
    list each row's crossings (row i in [min v, max v) of the edge). Returns (slow pixels,
    False if a row has more crossings than ``cross_u`` holds)."""
    h = cross_u.shape[0]
    n_cross[:] = 0
    ok = True
    for e in range(boundary.shape[0]):
        p, q = boundary[e, 0], boundary[e, 1]
        up, vp, uq, vq = us[p], vs[p], us[q], vs[q]
        lo, hi = (vp, vq) if vp < vq else (vq, vp)
        if math.floor(hi + _NEAR) >= math.ceil(lo - _NEAR):      # a pixel row within reach
            n_slow = _mark_near(us, vs, p, q, q, slow, slow_px, n_slow)
        if vp == vq:
            continue
        direction = 1 if vq > vp else -1
        slope = (uq - up) / (vq - vp)
        for i in range(max(0, int(math.ceil(lo))), min(h, int(math.ceil(hi)))):
            k = n_cross[i]
            if k < cross_u.shape[1]:
                cross_u[i, k] = up + (i - vp) * slope
                cross_d[i, k] = direction
                n_cross[i] = k + 1
            else:
                ok = False
    return n_slow, ok


@numba.njit(cache=True, nogil=True)
def _sweep_row(us, vs, vals, tris, neighbours, cache, img, slow, slow_px, n_slow, cross_u, cross_d, n, i):
    """Steps 2–3 of :func:`_fast_frame` for pixel row i with its n boundary crossings
    ``cross_u`` (columns) and ``cross_d`` (±1). Returns the new number of slow pixels.
    (Pixel indices are unsigned: numba then skips negative-index wraparound checks.)"""
    w = img.shape[1]
    i = np.uint64(i)
    for k in range(1, n):                                                  # insertion sort
        cu, cd = cross_u[k], cross_d[k]
        m = k - 1
        while m >= 0 and cross_u[m] > cu:
            cross_u[m + 1] = cross_u[m]
            cross_d[m + 1] = cross_d[m]
            m -= 1
        cross_u[m + 1] = cu
        cross_d[m + 1] = cd
    # Run k: the columns j with exactly k crossings left of them (cross_u < j).
    winding = 0
    j_lo = 0
    for k in range(n + 1):
        j_hi = w - 1 if k == n else min(w - 1, int(math.floor(cross_u[k])))
        for jj in range(j_lo, j_hi + 1):
            j = np.uint64(jj)
            if winding == 0:
                img[i, j] = 0.0
                continue
            found = False
            if winding == 1 or winding == -1:
                found, f, value = _walk(us, vs, vals, tris, neighbours, cache[i, j], i, j)
                if found:
                    cache[i, j] = f
                    img[i, j] = value
            if not found and not slow[i, j]:
                slow[i, j] = True
                slow_px[n_slow, 0] = i
                slow_px[n_slow, 1] = j
                n_slow += 1
        if k < n:
            winding += cross_d[k]
            j_lo = max(j_lo, j_hi + 1)
    return n_slow


@numba.njit(cache=True, nogil=True)
def _fast_frame(us, vs, ds, vals, tris, neighbours, boundary, orientation, cache, img,
                slow, cross_u, cross_d, n_cross, slow_px):
    """Render one frame like :func:`_zbuffer` without a depth buffer. Returns the number of
    pixels it z-tested one by one, or −1 if it declined (then run :func:`_zbuffer`).

    Why it is exact. Give the view's triangles the orientation they have at rest
    (``orientation``; the mesh is consistently oriented, so interior edges cancel and the
    chain's boundary is the view's boundary edges). For a point y on no edge, the triangles
    containing y, counted with the sign of their projected area, sum to the winding number
    of the projected boundary around y (the degree of the projection). So if every
    triangle that could contain y keeps its orientation, the number of triangles containing
    y *equals* |winding(y)|: 0 → y is off the surface, 1 → exactly one triangle contains y,
    and it is the visible one whatever the depths; ≥ 2 → the surface overlaps itself at y.

    Per frame:
    1. Pixel centres within _NEAR px of a triangle whose projected area lost its sign or
       vanished (where the displaced surface folds), or of a boundary edge (where the
       z-buffer's edge tolerance decides), are "slow": the argument is not used there.
       (:func:`_covers` accepts points up to ~3·_TOL·diameter ≈ 1e-8 px outside a
       triangle, far inside _NEAR, so a pixel that is not slow is covered by the z-buffer
       exactly when it is inside the outline.)
    2. The boundary edges' crossings of each pixel row (half-open in v), sorted, split the
       row into runs of constant winding number.
    3. Winding 0 → 0. Winding ±1 → :func:`_walk` from the pixel's triangle in the previous
       frame to the triangle that passes the z-buffer's own coverage test; its
       interpolated value is the pixel. A walk that fails (non-convex outline, long walk)
       and winding ≥ 2 make the pixel slow.
    4. Slow pixels get :func:`_zbuffer_pixel`, the z-buffer restricted to one pixel.
    Too many slow pixels (> _MAX_SLOW_PIXELS) or crossings in a row → decline.

    Pixels on an edge shared by two triangles may be taken from either of them (the
    z-buffer takes the nearer by rounding); both interpolate the edge's two vertices, so
    the values agree to rounding.
    """
    h, w = img.shape
    n_slow = _mark_flipped(us, vs, tris, orientation, slow, slow_px)                 # 1.
    n_slow, ok = _boundary_pass(us, vs, boundary, slow, slow_px, n_slow, cross_u, cross_d, n_cross)
    for i in range(h):
        if ok and n_slow <= _MAX_SLOW_PIXELS:
            n_slow = _sweep_row(us, vs, vals, tris, neighbours, cache, img, slow, slow_px, n_slow,
                                cross_u[i], cross_d[i], n_cross[i], i)
    ok = ok and n_slow <= _MAX_SLOW_PIXELS
    for k in range(n_slow):                                                # 4.
        i, j = slow_px[k, 0], slow_px[k, 1]
        slow[i, j] = False
        if ok:
            img[i, j] = _zbuffer_pixel(us, vs, ds, vals, tris, i, j)
    return n_slow if ok else -1


@numba.njit(cache=True, nogil=True)
def _interpolate(activation, view_weights, out):
    """``out[t, k] = Σ_c activation[t, c]·view_weights[c, k]``, summed in taxel order.

    Every row is computed on its own with the same arithmetic, so a frame's vertex values
    do not depend on the other frames computed with it (a BLAS product's blocking, and
    so its rounding, depends on the number of rows): a frame rendered alone, as
    :mod:`tactile.online` does, is bit-identical to the same frame rendered in a chunk.
    Four taxels per pass over the row, (((row + a0·w0) + a1·w1) + a2·w2) + a3·w3: the
    order of one taxel per pass, with a quarter of the row's loads and stores (≈ 30 %
    faster)."""
    n_c, n_k = view_weights.shape
    for t in range(activation.shape[0]):
        row = out[t]
        row[:] = 0.0
        c = 0
        while c + 4 <= n_c:
            a0, a1, a2, a3 = activation[t, c], activation[t, c + 1], activation[t, c + 2], activation[t, c + 3]
            w0, w1, w2, w3 = view_weights[c], view_weights[c + 1], view_weights[c + 2], view_weights[c + 3]
            for k in range(n_k):
                row[k] = row[k] + a0 * w0[k] + a1 * w1[k] + a2 * w2[k] + a3 * w3[k]
            c += 4
        for c in range(c, n_c):
            a = activation[t, c]
            w = view_weights[c]
            for k in range(n_k):
                row[k] += a * w[k]


@numba.njit(cache=True, nogil=True)
def _render_frame(base, step, scale, tris, neighbours, boundary, orientation, fast, vertex_values, cache,
                  us, vs, ds, vals, img, depth, winner, bary, slow, slow_px, cross_u, cross_d, n_cross):
    """Render one frame of (K,) vertex values into ``img`` (H, W) float64: through
    :func:`_fast_frame` if ``fast``, else (or when it declines) through :func:`_zbuffer`.
    Arguments: :func:`frame_geometry`, the values, ``cache`` (:func:`frame_cache`, updated)
    and :func:`frame_scratch`. Returns the pixels z-tested one by one, or −1 if the frame
    was z-buffered in full."""
    _project(base, step, vertex_values, scale, us, vs, ds, vals)
    n_slow = -1
    if fast:
        n_slow = _fast_frame(us, vs, ds, vals, tris, neighbours, boundary, orientation, cache,
                             img, slow, cross_u, cross_d, n_cross, slow_px)
    if n_slow < 0:
        _zbuffer(us, vs, ds, vals, tris, img, depth, winner, bary)
    return n_slow


@numba.njit(cache=True, nogil=True)
def _store_u8(img, low, gain, out):
    """``out`` (H, W) uint8 ← ``img``: (value − low)·gain in float32, rounded half to even,
    clipped to 0..255: exactly :func:`to_uint8`."""
    h, w = img.shape
    for i in range(h):
        for j in range(w):
            x = np.rint((np.float32(img[i, j]) - low) * gain)
            out[i, j] = 0 if x < 0 else (255 if x > 255 else np.uint8(x))


@numba.njit(cache=True, nogil=True)
def _render_activation_u8(activation, view_weights, base, step, scale, tris, neighbours, boundary,
                          orientation, fast, cache, low, gain, out, vertex_values, us, vs, ds, vals, img,
                          depth, winner, bary, slow, slow_px, cross_u, cross_d, n_cross):
    """One 8-bit frame (H, W) into ``out`` from one sample of (C,) taxel ``activation``,
    allocating nothing: :func:`_interpolate` into ``vertex_values`` (K,), :func:`_render_frame`,
    :func:`_store_u8`. Bit-identical to that frame of :func:`render_activation` given the
    same ``cache`` state. Returns as :func:`_render_frame`."""
    _interpolate(activation.reshape(1, -1), view_weights, vertex_values.reshape(1, -1))
    n_slow = _render_frame(base, step, scale, tris, neighbours, boundary, orientation, fast, vertex_values,
                           cache, us, vs, ds, vals, img, depth, winner, bary, slow, slow_px, cross_u,
                           cross_d, n_cross)
    _store_u8(img, low, gain, out)
    return n_slow


@numba.njit(cache=True, nogil=True)
def _render_frames(base, step, scale, tris, neighbours, boundary, orientation, fast, activation, view_weights,
                   vertex_values, cache, to_u8, low, gain, out_f, out_u):
    """Render T frames into ``out_f`` (T, H, W) float32, or into ``out_u`` as 8-bit frames
    (:func:`_store_u8`), one :func:`_render_frame` each; ``cache`` (H, W) holds each pixel's
    triangle to start its walk from and is updated. The frames' vertex values: if
    ``view_weights`` (C, K) has columns, :func:`_interpolate` of ``activation`` (T, C), one
    frame at a time just before it is rendered (the values stay in cache; the arithmetic of
    :func:`_render_activation_u8`), else ``vertex_values`` (T, K). Returns (frames
    z-buffered in full, pixels z-tested one by one by the fast path)."""
    h, w = cache.shape
    k = base.shape[1]
    interpolate = view_weights.shape[1] > 0
    n_frames = activation.shape[0] if interpolate else vertex_values.shape[0]
    row = np.empty((1, k))
    us, vs, ds, vals = np.empty(k), np.empty(k), np.empty(k), np.empty(k)
    img, depth = np.zeros((h, w)), np.empty((h, w))
    winner, bary = np.empty((h, w), np.int32), np.empty((h, w, 3))
    slow, slow_px = np.zeros((h, w), np.bool_), np.empty((h * w, 2), np.int64)
    cross_u, cross_d = np.empty((h, _MAX_CROSSINGS)), np.empty((h, _MAX_CROSSINGS), np.int64)
    n_cross = np.zeros(h, np.int64)
    stats = np.zeros(2, np.int64)             # frames z-buffered in full, pixels z-tested alone
    for t in range(n_frames):
        if interpolate:
            _interpolate(activation[t:t + 1], view_weights, row)
            values = row[0]
        else:
            values = vertex_values[t]
        n_slow = _render_frame(base, step, scale, tris, neighbours, boundary, orientation, fast,
                               values, cache, us, vs, ds, vals, img, depth, winner, bary, slow,
                               slow_px, cross_u, cross_d, n_cross)
        if n_slow < 0:
            stats[0] += 1
        else:
            stats[1] += n_slow
        if to_u8:
            _store_u8(img, low, gain, out_u[t])
        else:
            for i in range(h):
                for j in range(w):
                    out_f[t, i, j] = img[i, j]
    return stats


@numba.njit(cache=True, nogil=True)
def _rasterise(base, step, vidx, values, scale, tris, out, winner, bary):
    """Z-buffer every frame of (T, M) ``values`` into ``out`` (T, H, W); vertex k of the view is
    mesh vertex vidx[k]. ``winner``, ``bary``: visible triangle and weights of the last frame."""
    h, w = winner.shape
    k = base.shape[1]
    us, vs, ds, vals = np.empty(k), np.empty(k), np.empty(k), np.empty(k)
    img, depth = np.zeros((h, w)), np.empty((h, w))
    for t in range(values.shape[0]):
        _project(base, step, values[t][vidx], scale, us, vs, ds, vals)
        _zbuffer(us, vs, ds, vals, tris, img, depth, winner, bary)
        for i in range(h):
            for j in range(w):
                out[t, i, j] = img[i, j]

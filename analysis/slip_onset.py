"""When a contact began to slip: a knee in how far its pattern has moved, with its uncertainty.

A still finger on an object that starts to move first carries its skin along (the stuck skin
stretches, and the pattern moves with the object), until the skin breaks away and slides: from
then on the pattern moves far more slowly than before — it stays where the kinetic friction
holds it, or on a curved object keeps turning with the object's shape without the skin's
stretch. So the motion signal ``y(t)`` of a slipping contact (the centre of pressure's travel
along the slip for a translation, the pattern's turn for a rotation) is, to the resolution of
the smoothed record, three straight pieces: still before the object moved (slope 0), a ramp
while the skin follows it (slope s₁), and after gross slip a slope |s₂| well below |s₁|.

:func:`knee` fits that shape by least squares over every pair of knots ``a < b`` (frames; the
levels and slopes are linear in the knots): ``a`` is the *motion onset*, ``b`` the *slip
onset* (gross slip, the skin broken away). When the best fit has no slowing down
(|s₂| ≥ ``SLOWER`` |s₁|: the contact slid at once, or the record ends while the skin still
follows), the slip onset is the motion onset.

Uncertainty: the knots whose fit is within one standard error of the best —
``SSE(b) ≤ SSE_min + σ²·L``, σ² the residual variance and L the residuals' correlation length
in frames (the smoothing makes neighbouring residuals alike, so L frames carry one
independent sample) — spread over ``[b_lo, b_hi]``; the uncertainty is half that width, at
least half a frame. The knots within two standard errors (``SSE(b) ≤ SSE_min + 4σ²·L``) spread
over ``[wide_lo, wide_hi]``: where the slip onset may lie at all (a release dated before
``wide_lo`` contradicts the fit: the signal went on at its ramp's pace after it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SLOWER = 0.5
"""After gross slip the pattern moves at most this fraction of its speed while the skin stuck."""


@dataclass(frozen=True)
class Knee:
    """The fit of :func:`knee`, frames relative to the signal's start.

    Attributes:
        motion: first frame of the ramp (the motion onset).
        slip: the slip onset (gross slip; = ``motion`` without a slowing down).
        slip_lo, slip_hi: the frames the slip onset may lie between (module docstring).
        ramp_slope, after_slope: the signal's slope on the ramp and after the knee (units/frame).
        rise: the ramp's height ``s₁·(b − a)`` (signal units).
        slowed: the fit slowed down after the ramp (``|s₂| < SLOWER·|s₁|``).
        wide_lo, wide_hi: the frames the slip onset may lie between at two standard errors.
    """

    motion: int
    slip: int
    slip_lo: int
    slip_hi: int
    ramp_slope: float
    after_slope: float
    rise: float
    slowed: bool
    wide_lo: int = 0
    wide_hi: int = 0


def correlation_length(r) -> float:
    """1 + 2 Σ ρ_k of ``r`` up to the first lag with ρ ≤ 0.05: how many neighbouring samples carry
    one independent one (frames, ≥ 1)."""
    r = np.asarray(r, float) - np.mean(r)
    v = float(r @ r)
    if v <= 0 or len(r) < 4:
        return 1.0
    total = 1.0
    for k in range(1, len(r) // 2):
        rho = float(r[:-k] @ r[k:]) / v
        if rho <= 0.05:
            break
        total += 2.0 * rho
    return total


def _fits(y: np.ndarray, a: np.ndarray, b: np.ndarray):
    """Least-squares fits of still → ramp → slope for knots (a, b) (K,): ``(sse (K,), coef (K, 3))``
    with coef = level, ramp slope, slope after b. Each fit's normal equations come from prefix
    sums of ``y``, ``i·y`` and ``y²`` (the basis is piecewise linear in the frame ``i``), so a fit
    costs O(1), not O(N): a 30 s contact's knee takes milliseconds, not a minute."""
    mean = float(np.mean(y))
    y = np.asarray(y, float) - mean                           # the level absorbs it; no cancellation
    n = len(y)
    i = np.arange(n, dtype=float)
    cy, ciy = np.r_[0.0, np.cumsum(y)], np.r_[0.0, np.cumsum(i * y)]
    sum_y = lambda lo, hi: cy[hi] - cy[lo]                    # Σ y_i over lo ≤ i < hi   # noqa: E731
    sum_iy = lambda lo, hi: ciy[hi] - ciy[lo]                 # noqa: E731
    sum_i = lambda lo, hi: (hi - lo) * (lo + hi - 1) / 2.0    # noqa: E731
    sum_ii = lambda lo, hi: ((hi - 1) * hi * (2 * hi - 1) - (lo - 1) * lo * (2 * lo - 1)) / 6.0  # noqa: E731
    a, b = np.asarray(a, float), np.asarray(b, float)
    ai, bi = a.astype(np.int64), b.astype(np.int64)
    L = b - a
    lo, hi = ai, bi + 1                                       # the ramp a ≤ i ≤ b (r1 = i − a)
    tail_lo = bi + 1                                          # after the knee i > b (r1 = L, r2 = i − b)
    m_tail = n - tail_lo
    s1 = sum_i(lo, hi) - a * (hi - lo) + L * m_tail
    s11 = sum_ii(lo, hi) - 2 * a * sum_i(lo, hi) + a * a * (hi - lo) + L * L * m_tail
    s2 = sum_i(tail_lo, n) - b * m_tail
    s22 = sum_ii(tail_lo, n) - 2 * b * sum_i(tail_lo, n) + b * b * m_tail
    s12 = L * s2
    h = np.stack([np.full(len(a), cy[n]),
                  sum_iy(lo, hi) - a * sum_y(lo, hi) + L * sum_y(tail_lo, n),
                  sum_iy(tail_lo, n) - b * sum_y(tail_lo, n)], axis=1)               # (K, 3) basis·y
    gram = np.stack([np.stack([np.full(len(a), float(n)), s1, s2], 1),
                     np.stack([s1, s11, s12], 1),
                     np.stack([s2, s12, s22], 1)], axis=1)                           # (K, 3, 3)
    c = np.linalg.solve(gram + 1e-9 * np.eye(3), h[..., None])[..., 0]
    sse = float(y @ y) - 2 * np.einsum("ki,ki->k", c, h) + np.einsum("ki,kij,kj->k", c, gram, c)
    c[:, 0] += mean
    return np.maximum(sse, 0.0), c


def _fits_direct(y: np.ndarray, a: np.ndarray, b: np.ndarray):
    """:func:`_fits` frame by frame (O(N) per fit): the reference the tests hold it to."""
    n = len(y)
    i = np.arange(n, dtype=float)
    ka, kb = np.asarray(a, float)[:, None], np.asarray(b, float)[:, None]
    r1 = np.clip(i[None, :] - ka, 0.0, kb - ka)
    r2 = np.maximum(i[None, :] - kb, 0.0)
    basis = np.stack([np.ones_like(r1), r1, r2], axis=1)              # (K, 3, N)
    gram = np.einsum("kin,kjn->kij", basis, basis) + 1e-9 * np.eye(3)
    c = np.linalg.solve(gram, np.einsum("kin,n->ki", basis, y)[..., None])[..., 0]
    return ((np.einsum("ki,kin->kn", c, basis) - y[None]) ** 2).sum(axis=1), c


def _pairs(starts, stops, min_ramp: int):
    a, b = np.meshgrid(np.asarray(starts, float), np.asarray(stops, float), indexing="ij")
    keep = b - a >= min_ramp
    return a[keep], b[keep]


def knee(y, min_ramp: int = 2, coarse: int = 60) -> Knee | None:
    """Fit still → ramp → slower to the signal ``y`` (N,) (module docstring); ``None`` for fewer
    than 8 finite samples or a flat signal. The knots are searched on a grid of about ``coarse``
    points, then frame by frame around the best pair."""
    y = np.asarray(y, float)
    n = len(y)
    if n < 8 or not np.all(np.isfinite(y)) or np.ptp(y) <= 0:
        return None
    step = max(1, int(np.ceil(n / coarse)))
    a, b = _pairs(np.arange(0, n - 1, step), np.arange(0, n - 1, step), min_ramp)
    sse, coef = _fits(y, a, b)
    k = int(np.argmin(sse))
    if step > 1:
        near = lambda c: np.arange(max(0, int(c) - 2 * step), min(n - 1, int(c) + 2 * step + 1))  # noqa: E731
        fa, fb = _pairs(near(a[k]), near(b[k]), min_ramp)
        fsse, fcoef = _fits(y, fa, fb)
        a, b, sse, coef = (np.r_[a, fa], np.r_[b, fb], np.r_[sse, fsse], np.r_[coef, fcoef])
        k = int(np.argmin(sse))
    s1, s2 = coef[k, 1], coef[k, 2]
    ka, kb = int(a[k]), int(b[k])
    i = np.arange(n, dtype=float)
    fit = coef[k, 0] + s1 * np.clip(i - ka, 0.0, kb - ka) + s2 * np.maximum(i - kb, 0.0)
    sigma2 = float(sse[k]) / max(n - 5, 1)
    corr = correlation_length(y - fit)
    band = sse <= sse[k] + sigma2 * corr
    slowed = abs(s2) < SLOWER * abs(s1)
    still_ramp = abs(s1) < SLOWER * abs(s2)          # the "ramp" is still: the motion begins at b
    where = b if (slowed or still_ramp) else a
    motion = kb if still_ramp else ka
    level = sse[k] + 4.0 * sigma2 * corr
    wide_lo, wide_hi = int(where[sse <= level].min()), int(where[sse <= level].max())
    if step > 1:
        # the two-standard-error band frame by frame: the slip knot over the coarse band's span,
        # the other knot over the coarse grid and frame by frame near its best (not every frame:
        # that is O(N²) fits of N frames, minutes for a 30 s contact)
        span = np.arange(max(0, wide_lo - 2 * step), min(n - 1, wide_hi + 2 * step + 1))
        other = np.union1d(np.arange(0, n - 1, step), near(ka if where is b else kb))
        wa, wb = _pairs(other, span, min_ramp) if where is b else _pairs(span, other, min_ramp)
        wsse, _ = _fits(y, wa, wb)
        w = (wb if where is b else wa)[wsse <= level]
        if len(w):
            wide_lo, wide_hi = min(wide_lo, int(w.min())), max(wide_hi, int(w.max()))
    return Knee(motion=motion, slip=kb if (slowed or still_ramp) else ka, slip_lo=int(where[band].min()),
                slip_hi=int(where[band].max()), ramp_slope=float(s1), after_slope=float(s2),
                rise=float(s1 * (kb - ka)), slowed=bool(slowed), wide_lo=wide_lo, wide_hi=wide_hi)

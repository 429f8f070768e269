"""What tactile flow and pressure make possible to estimate: direction of motion (sensor and
world frame), feature width, relative feature height and texture angle.

Conventions: the sensor frame is the BioTac SP's (x along the finger, y lateral, z normal to
the pad). The pressure pattern on the sensor moves *opposite* to the finger's motion over the
surface, so the finger's direction of motion is minus the tactile flow. Directions are unit
3-vectors; the sensor-frame direction is projected onto the pad's tangent plane (z = 0).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tactile_flow.hardware.transforms import rotvec_to_matrix

from . import segments as seg


def unit(v) -> np.ndarray:
    v = np.asarray(v, float)
    n = np.linalg.norm(v)
    return v / n if n > 0 else np.full_like(v, np.nan)


def motion_direction_sensor(flow_sensor) -> np.ndarray:
    """Finger direction of motion (3,) unit, sensor frame, from the mean flow (3,) of the pattern."""
    d = -np.asarray(flow_sensor, float)
    d[2] = 0.0
    return unit(d)


def sensor_to_world(tcp_rotvec, tip_rotvec) -> np.ndarray:
    """(3, 3) rotation sensor → world (robot base) = R(TCP in base) · R(sensor in TCP)."""
    return rotvec_to_matrix(tcp_rotvec) @ rotvec_to_matrix(tip_rotvec)


def pose_at(arm_time, tcp_pose, t: float) -> np.ndarray:
    """TCP pose (6,) at time ``t`` (nearest arm sample)."""
    i = int(np.clip(np.searchsorted(arm_time, t), 0, len(arm_time) - 1))
    return np.asarray(tcp_pose[i], float)


def speed_mm_s(arm_time, tcp_speed, t) -> np.ndarray:
    """Translational TCP speed (mm/s) interpolated at times ``t``."""
    v = np.linalg.norm(np.asarray(tcp_speed, float)[:, :3], axis=1) * 1e3
    return np.interp(np.asarray(t, float), arm_time, v)


def feature_width(signal, bump: seg.Bump, t, speed, level: float, min_speed: float):
    """Width (mm) = plateau duration (s) × mean TCP speed over the plateau (mm/s).

    ``signal``: (T,) the width signal; ``bump``: the bump found on the pressure (its extent is
    reused; the peak is taken on ``signal``); ``speed``: (T,) mm/s. Returns (width, duration, speed)
    or (nan, duration, speed) if the finger moved slower than ``min_speed``.
    """
    s = np.asarray(signal, float)
    k = bump.start + int(np.argmax(s[bump.start:bump.stop]))
    b = seg.Bump(bump.start, bump.stop, k, bump.plateau, float(s[k]))
    rate = 1.0 / float(np.median(np.diff(t))) if len(t) > 1 else 100.0
    lo, hi, dur = seg.plateau_duration(s, b, rate, level)
    i0, i1 = int(np.floor(lo * rate)), int(np.ceil(hi * rate)) + 1
    v = float(np.mean(speed[max(i0, 0):max(i1, i0 + 1)]))
    if not v >= min_speed:
        return float("nan"), dur, v
    return dur * v, dur, v


@dataclass(frozen=True)
class TaxelPlateaus:
    """Where a crossed feature was under each electrode that felt it (:func:`taxel_plateaus`).

    Attributes:
        used: (M,) indices of those electrodes (columns of the activation).
        start_mm, end_mm: (M,) distance the finger had travelled since the crossing's first frame
            when each electrode's activation rose above / fell below its level, mm.
        duration_s: (M,) how long each stayed above it, s.
        rise_fraction: (M,) each one's rise as a fraction of the largest rise (1 for the largest).
    """
    used: np.ndarray
    start_mm: np.ndarray
    end_mm: np.ndarray
    duration_s: np.ndarray
    rise_fraction: np.ndarray

    @property
    def width_mm(self) -> np.ndarray:
        return self.end_mm - self.start_mm

    @property
    def passing_mm(self) -> np.ndarray:
        """(M,) distance travelled when the feature's middle was under each electrode, mm."""
        return 0.5 * (self.start_mm + self.end_mm)

    def strong(self, fraction: float) -> "TaxelPlateaus":
        """The electrodes whose rise is at least ``fraction`` of the largest (never empty)."""
        k = self.rise_fraction >= fraction
        return TaxelPlateaus(self.used[k], self.start_mm[k], self.end_mm[k], self.duration_s[k],
                             self.rise_fraction[k])


def remove_load_share(activation, load_fraction: float) -> np.ndarray:
    """The activation (n, N) less each electrode's share of the contact's load: ``a − L·c``.

    Why: dragging the skin over a feature stretches it for as long as the contact carries load,
    not only while the feature is under an electrode: the electrodes ahead of the contact's
    centre stay raised after the feature has passed them (the skin dragged along behind it), those
    behind it dip before it arrives. That share follows the load on the whole pad, ``L(t)`` = the
    sum over the electrodes, with one factor per electrode ``c`` (positive ahead, negative behind):
    on the classic BioTac at shear gain 12 it stretched the front electrode's plateau over a 6 mm
    straw to 8.5 mm (5.4 mm at gain 3). ``c`` is each electrode's smallest ratio ``a / L`` over
    the frames where ``L`` is at least ``load_fraction`` of its largest value: where the feature is
    away from the electrode, its own pressure adds nothing, so that ratio is the share alone
    (the feature's pressure only ever adds). Nothing depends on the signal's scale (ratios of the
    activation to its own sum). ``load_fraction`` 0: the activation unchanged.
    """
    a = np.asarray(activation, float)
    if not load_fraction > 0 or a.ndim != 2 or len(a) == 0:
        return a
    load = a.sum(axis=1)
    if not load.max() > 0:
        return a
    loaded = load >= load_fraction * load.max()
    share = (a[loaded] / load[loaded, None]).min(axis=0)
    return a - load[:, None] * share[None, :]


def taxel_plateaus(activation, t, speed, level: float, strong: float,
                   load_fraction: float = 0.0) -> TaxelPlateaus | None:
    """The plateau of every electrode that feels a crossed feature.

    ``activation``: (n, N) smoothed activation of one finger's electrodes over the crossing (any
    unit: only each electrode's own shape is read); ``t``: (n,) s; ``speed``: (n,) TCP speed,
    mm/s. An electrode feels the feature when its rise over the crossing (peak above the lower of
    its first value, last value and 0) is at least ``strong`` × the largest rise; its plateau is
    where its activation stays above ``level`` of its own rise. ``None`` if nothing rose.
    Nothing depends on the signal's scale: both thresholds are fractions of the signal's own rise.
    ``load_fraction`` > 0: each electrode's share of the pad's load is taken off first
    (:func:`remove_load_share`), the skin's stretch that outlasts the feature.
    """
    a = remove_load_share(activation, load_fraction)
    tt = np.asarray(t, float)
    v = np.asarray(speed, float)
    if a.ndim != 2 or len(a) < 3:
        return None
    floor = np.minimum(np.minimum(a[0], a[-1]), 0.0)
    rise = a.max(axis=0) - floor
    if not rise.max() > 0:
        return None
    used = np.flatnonzero(rise >= strong * rise.max())
    idx = np.arange(len(a), dtype=float)
    dist = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(tt))])   # mm since frame 0
    edges = []
    for e in used:
        s = a[:, e]
        k = int(np.argmax(s))
        lev = floor[e] + level * rise[e]
        edges.append((seg._crossing(s, k, lev, -1), seg._crossing(s, k, lev, +1)))
    lo, hi = np.asarray(edges, float).T
    return TaxelPlateaus(used, np.interp(lo, idx, dist), np.interp(hi, idx, dist),
                         np.interp(hi, idx, tt) - np.interp(lo, idx, tt), rise[used] / rise.max())


def feature_width_per_taxel(activation, t, speed, level: float, min_speed: float, strong: float = 0.3,
                            load_fraction: float = 0.0):
    """Width (mm) of a crossed feature read on each electrode that feels it, not on their sum.

    Arguments as :func:`taxel_plateaus`; the width is the median over those electrodes of the
    distance the finger travelled (∫ speed dt) while the electrode's activation stayed above
    ``level`` of its own rise. Returns (width, duration, speed, electrodes used): duration the
    median time above the level (s), speed the mean over it (mm/s); width ``nan`` if the finger
    moved slower than ``min_speed`` mm/s or no electrode rose.

    Why per electrode: a sum over the pad adds the pad's own extent to every feature, so a round
    6 mm straw and a flat 10 mm stick give bumps of nearly one shape (half-height widths 1.23×
    apart on the pad sum, 1.67× in truth), and the skin-stretch (shear) share of the sum changes
    that shape with the sensor's shear gain. One electrode sees the feature through its own
    footprint only.
    """
    return width_from_plateaus(taxel_plateaus(activation, t, speed, level, strong, load_fraction), speed, min_speed)


def width_from_plateaus(plateaus: TaxelPlateaus | None, speed, min_speed: float):
    """(width, duration, speed, electrodes used) of :func:`feature_width_per_taxel` from the
    plateaus of the electrodes that feel the feature (:meth:`TaxelPlateaus.strong` selects them);
    ``speed``: (n,) TCP speed over the crossing, mm/s (its mean when the plateaus last no time)."""
    nan = float("nan")
    p = plateaus
    if p is None:
        return nan, nan, nan, 0
    width, dur = float(np.median(p.width_mm)), float(np.median(p.duration_s))
    mean_speed = width / dur if dur > 0 else float(np.mean(speed))
    if not mean_speed >= min_speed:
        return nan, dur, mean_speed, len(p.used)
    return width, dur, mean_speed, len(p.used)


#: mm travelled per mm of electrode position across the pad below which a "crossing" passed every
#: electrode at once (a press): a crossing of the simulated fingertip gives 0.23-0.8, a press ~0.01
MIN_PASSING_GRADIENT = 0.1


def ridge_from_passing(plateaus: TaxelPlateaus, positions, max_uncertainty_deg: float):
    """Long axis of a straight feature from *where the finger was* when it passed each electrode.

    A straight ridge swept across the pad passes an electrode at ``p`` (mm, sensor x–y) when the
    finger has travelled s(p): constant along the ridge, growing across it. So the gradient of
    the passing distances (:attr:`TaxelPlateaus.passing_mm`) over the electrodes' positions is
    across the ridge, whatever the direction of motion. On a curved fingertip the contact rolls
    rather than slides over the pad, so s grows less than linearly across the ridge (the outer
    electrodes feel the feature while the contact is still near the pad's middle): the fit is
    s = s0 + q·p + a·u² + b·u³, u = p along the first (linear) estimate of q, so that this
    curvature does not count as noise. ``positions``: (N, ≥2) electrode positions, sensor frame,
    mm (rows indexed like the activation's columns).

    Returns (axis, uncertainty_deg, reason): ``axis`` (3,) unit, sensor frame (z = 0), at right
    angles to q, and the standard error of q's direction (deg) from the fit's residuals; or
    (``None``, uncertainty, reason) when the electrodes cannot fix it: fewer than 7 felt the
    feature, they lie on a line, the finger moved less than :data:`MIN_PASSING_GRADIENT` mm per
    mm across the pad between their passings (a press, not a crossing: its gradient is noise), or
    the uncertainty is above ``max_uncertainty_deg``. Read from timing only:
    the skin stretch shifts every electrode's plateau alike, and the signal's scale does not enter.
    """
    nan = float("nan")
    xy = np.asarray(positions, float)[plateaus.used, :2]
    s = plateaus.passing_mm
    n = len(s)
    if n < 7:
        return None, nan, f"{n} electrodes felt the feature (at least 7 are needed to fix a ridge's axis)"
    xy = xy - xy.mean(axis=0)
    if np.linalg.svd(xy, compute_uv=False)[-1] < 1e-6 * max(np.abs(xy).max(), 1e-12):
        return None, nan, "the electrodes that felt the feature lie on a line"
    q = np.linalg.lstsq(np.c_[np.ones(n), xy], s, rcond=None)[0][1:]
    if not np.linalg.norm(q) >= MIN_PASSING_GRADIENT:
        return None, nan, (f"the feature passed the electrodes all at once (the finger moved "
                           f"{np.linalg.norm(q):.2f} mm per mm across the pad between their passings, "
                           f"a crossing: ≥ {MIN_PASSING_GRADIENT})")
    u = xy @ (q / np.linalg.norm(q))
    X = np.c_[np.ones(n), xy, u ** 2, u ** 3]
    coef = np.linalg.lstsq(X, s, rcond=None)[0]
    q = coef[1:3]
    qn = float(np.linalg.norm(q))
    resid = s - X @ coef
    cov = float(resid @ resid) / (n - X.shape[1]) * np.linalg.pinv(X.T @ X)[1:3, 1:3]
    across = np.array([-q[1], q[0]]) / qn if qn > 0 else np.array([1.0, 0.0])
    unc = float(np.degrees(np.sqrt(max(float(across @ cov @ across), 0.0)) / qn)) if qn > 0 else float("inf")
    if not unc <= max_uncertainty_deg:
        return None, unc, (f"the electrodes' passing times fix the ridge's axis to ±{unc:.0f}° only "
                           f"(above {max_uncertainty_deg:g}°)")
    return np.array([across[0], across[1], 0.0]), unc, None


def height_ranks(heights) -> np.ndarray:
    """Rank 1 = highest pressure peak (ties share the smaller rank order of appearance)."""
    h = np.asarray(heights, float)
    order = np.argsort(-h, kind="stable")
    ranks = np.empty(len(h), int)
    ranks[order] = np.arange(1, len(h) + 1)
    return ranks


def ridge_axis(frame, mask, plan) -> np.ndarray | None:
    """Long axis (3,) unit, sensor frame, of the pressed region of a tactile frame (H, W) uint8.

    The pressed region is the part of the footprint brighter than its median; its
    intensity-weighted second moments give the axis. ``None`` if nothing stands out.
    """
    f = np.asarray(frame, float)
    vals = f[mask]
    if vals.size < 4:
        return None
    w = np.where(mask, np.clip(f - np.median(vals), 0, None), 0.0)
    if w.sum() <= 0:
        return None
    rows, cols = np.mgrid[0:f.shape[0], 0:f.shape[1]]
    c0, r0 = (w * cols).sum() / w.sum(), (w * rows).sum() / w.sum()
    dc, dr = cols - c0, rows - r0
    cov = np.array([[(w * dc * dc).sum(), (w * dc * dr).sum()], [(w * dc * dr).sum(), (w * dr * dr).sum()]])
    evals, evecs = np.linalg.eigh(cov / w.sum())
    if evals[1] <= 1.05 * evals[0]:
        return None                                       # round blob: no orientation
    axis = plan.image_to_sensor(evecs[:, 1])
    return unit(axis)


def texture_angle_deg(ridge, direction) -> float:
    """Angle (deg, 0..90) between a ridge axis and the direction of motion (both (3,))."""
    if ridge is None or not np.all(np.isfinite(direction)):
        return float("nan")
    r, d = unit(np.asarray(ridge)[:2]), unit(np.asarray(direction)[:2])
    return float(np.degrees(np.arccos(np.clip(abs(r @ d), 0.0, 1.0))))


def angle_deg(a, b) -> float:
    """Angle (deg) between two vectors."""
    a, b = unit(a), unit(b)
    return float(np.degrees(np.arccos(np.clip(a @ b, -1.0, 1.0))))

"""What tactile flow and pressure make possible to estimate: direction of motion (sensor and
world frame), feature width, relative feature height and texture angle.

Conventions: the sensor frame is the BioTac SP's (x along the finger, y lateral, z normal to
the pad). The pressure pattern on the sensor moves *opposite* to the finger's motion over the
surface, so the finger's direction of motion is minus the tactile flow. Directions are unit
3-vectors; the sensor-frame direction is projected onto the pad's tangent plane (z = 0).
"""

from __future__ import annotations

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

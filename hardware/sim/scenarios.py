"""Small scripted scenarios on a simulated lab, for tests, the benchmark and the docs.

Not protocols (those are declared in ``conf/protocol`` and run by the run engine): just
enough motion to exercise the simulator directly, returning the recorded streams.
"""

from __future__ import annotations

import math

import numpy as np

from . import Lab


def pad_height_pose(lab: Lab, x: float, y: float, depth_m: float, finger: str = "ff") -> np.ndarray:
    """TCP pose (TCP pointing down) putting ``finger``'s pad ``depth_m`` below the
    highest point of the surface (positive: pressing into the tallest features)."""
    w = lab.world
    T = w.T_tcp_sensor[finger]
    rv = np.asarray(lab.world.cfg.arm.home_pose[3:], float)
    from ..transforms import rotvec_to_matrix
    R = rotvec_to_matrix(rv)
    pole_w = R @ (T[:3, :3] @ (w.tip.pole * 1e-3) + T[:3, 3])
    z = lab.surface.max_z - depth_m - pole_w[2]
    return np.array([x - pole_w[0], y - pole_w[1], z, *rv])


def record(lab: Lab, frames: dict) -> None:
    """Drain every device's buffer into ``frames`` (lists by stream)."""
    frames.setdefault("biotac", []).extend(lab.biotac.read())
    frames.setdefault("arm", []).extend(lab.arm.read_states())
    frames.setdefault("hand", []).extend(lab.hand.read_states())
    frames.setdefault("pump", []).extend(lab.pump.read_states())
    frames.setdefault("scale", []).extend(lab.scale.read())


def biotac_arrays(frames) -> dict[str, np.ndarray]:
    """Stack BioTac frames: time (T,) host s, seq (T,), electrodes (T, F, 24), pdc/tdc/tac (T, F), pac (T·22, F)."""
    return {"time": np.array([f.host_time for f in frames]),
            "device_time": np.array([f.device_time for f in frames]),
            "seq": np.array([f.seq for f in frames]),
            "electrodes": np.array([f.electrodes for f in frames]),
            "pdc": np.array([f.pdc for f in frames]),
            "tdc": np.array([f.tdc for f in frames]),
            "tac": np.array([f.tac for f in frames]),
            "pac": np.concatenate([f.pac.T for f in frames]) if frames else np.zeros((0, 0))}


def straws_sweep(lab: Lab, speed: float = 0.01, direction: int = +1, depth_m: float = 0.0015,
                 margin_m: float = 0.015, finger: str = "ff", poll_s: float = 0.05) -> dict:
    """Sweep ``finger`` across every feature along the board's local x at ``speed`` m/s.

    ``direction`` +1 sweeps towards +x (feature_0 first), -1 the other way. Starts
    ``margin_m`` before the first feature, lowered to the hold depth clear of the features,
    and ends ``margin_m`` past the last. Returns the recorded streams (see :func:`record`).
    """
    s = lab.surface
    fs = s.features
    u0 = fs[0].u - fs[0].width / 2 - margin_m
    u1 = fs[-1].u + fs[-1].width / 2 + margin_m
    if direction < 0:
        u0, u1 = u1, u0
    o, a = s.origin, s.across
    start = pad_height_pose(lab, *(o[:2] + u0 * a[:2]), depth_m, finger)
    end = pad_height_pose(lab, *(o[:2] + u1 * a[:2]), depth_m, finger)
    above = start.copy()
    above[2] += 0.02
    lab.arm.move_linear(above, 0.1, 1.0)
    lab.arm.move_linear(start, 0.02, 0.5)
    lab.clock.sleep(0.2)
    frames: dict = {}
    record(lab, frames)
    frames = {}
    lab.arm.move_linear(end, speed, 0.5, asynchronous=True)
    while lab.arm.is_moving():
        lab.clock.sleep(poll_s)
        record(lab, frames)
    lab.clock.sleep(0.2)
    record(lab, frames)
    lab.arm.move_linear(end + np.array([0, 0, 0.02, 0, 0, 0]), 0.05, 0.5)
    return frames


def press(lab: Lab, force_n: float, xy=None, finger: str = "ff", speed_m_s: float = 0.0005,
          hold_s: float = 0.5, poll_s: float = 0.01) -> dict:
    """Lower ``finger`` onto the surface at ``xy`` (base frame m; default the board's centre)
    until its normal force reaches ``force_n`` (N), stop, and hold ``hold_s``.

    Returns the streams recorded during the hold (see :func:`record`); the finger stays pressed.
    """
    x, y = lab.surface.origin[:2] if xy is None else xy
    above = pad_height_pose(lab, x, y, -0.003, finger)
    lab.arm.move_linear(above, 0.05, 0.5)
    lab.arm.move_linear(pad_height_pose(lab, x, y, 0.008, finger), speed_m_s, 0.5, asynchronous=True)
    while lab.world.contacts[finger].force < force_n:
        if not lab.arm.is_moving():
            raise RuntimeError(f"press: {finger} reached {lab.world.contacts[finger].force:.2f} N, not {force_n} N")
        lab.clock.sleep(poll_s)
    lab.arm.stop(2.0)
    lab.clock.sleep(0.1)
    frames: dict = {}
    record(lab, frames)
    frames = {}
    lab.clock.sleep(hold_s)
    record(lab, frames)
    return frames


def close_grasp(lab: Lab, flexion_rad: float, duration: float = 1.0) -> None:
    """Close the pour grasp fingers to a total flexion (two joints) of ``flexion_rad``."""
    from .grasp import FLEX_JOINTS
    targets = {}
    for f in lab.world.cfg.pour.grasp_fingers:
        for j in FLEX_JOINTS[f]:
            targets[j] = flexion_rad / 2
    lab.hand.move_to(targets, duration)


def pour_until_slip(lab: Lab, rate_ml_min: float, flexion_rad: float, timeout_s: float = 300.0,
                    poll_s: float = 0.1) -> dict:
    """Grasp, pump at ``rate_ml_min`` until full slip (or ``timeout_s``), stop the pump."""
    close_grasp(lab, flexion_rad)
    lab.clock.sleep(0.5)
    frames: dict = {}
    record(lab, frames)
    lab.pump.set_rate(rate_ml_min)
    t_end = lab.clock.now() + timeout_s
    while lab.clock.now() < t_end and math.isnan(lab.truth.pour["full_slip"]):
        lab.clock.sleep(poll_s)
        record(lab, frames)
    lab.pump.stop()
    lab.clock.sleep(0.5)
    record(lab, frames)
    return frames

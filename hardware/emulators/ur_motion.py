"""Simple Cartesian kinematics of the emulated UR controller (no joints, no dynamics).

The TCP is a point with an orientation that moves the way URScript's ``movel``,
``speedl``, ``stopl``, ``servol`` and ``force_mode`` describe it, integrated in fixed
control periods ``dt`` (s). Poses are ``[x, y, z, rx, ry, rz]`` (m, axis-angle rad),
speeds ``[vx, vy, vz, wx, wy, wz]`` (m/s, rad/s), accelerations m/s².

Contact is a horizontal plane at ``surface_z`` (m) with a linear stiffness (N/m): below
it the environment pushes the tool up with ``k · depth``. That is all the "world" the
emulator has; it is enough to exercise force mode and force-triggered protective stops.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..transforms import matrix_to_rotvec, rotvec_to_matrix



def _step_toward(v, target, dv_max):
    """Move vector ``v`` toward ``target`` by at most ``dv_max`` (Euclidean)."""
    d = target - v
    n = float(np.linalg.norm(d))
    return target.copy() if n <= dv_max else v + d * (dv_max / n)


@dataclass
class Contact:
    """A horizontal surface the tool can press on (base frame)."""

    surface_z: float | None = None          # m; None: free space
    stiffness_n_m: float = 5000.0           # N/m

    def wrench(self, pose) -> np.ndarray:
        """(6,) force the environment exerts on the tool (N, N·m)."""
        w = np.zeros(6)
        if self.surface_z is not None and pose[2] < self.surface_z:
            w[2] = self.stiffness_n_m * (self.surface_z - pose[2])
        return w


@dataclass
class _Linear:
    """A ``movel``: straight line, trapezoidal speed along the path, slerped orientation."""

    start: np.ndarray
    target: np.ndarray
    speed: float
    accel: float
    s: float = 0.0                          # distance travelled along the path (m)
    s_dot: float = 0.0                      # m/s
    length: float = 0.0
    _R0: np.ndarray = field(default=None, repr=False)
    _w: np.ndarray = field(default=None, repr=False)

    def __post_init__(self):
        self.length = float(np.linalg.norm(self.target[:3] - self.start[:3]))
        self._R0 = rotvec_to_matrix(self.start[3:])
        self._w = matrix_to_rotvec(self._R0.T @ rotvec_to_matrix(self.target[3:]))
        if self.length < 1e-6:              # pure reorientation: path length is the angle (rad)
            self.length = float(np.linalg.norm(self._w))

    def pose_at(self, s: float) -> np.ndarray:
        f = 1.0 if self.length < 1e-9 else s / self.length
        p = self.start[:3] + f * (self.target[:3] - self.start[:3])
        r = matrix_to_rotvec(self._R0 @ rotvec_to_matrix(f * self._w))
        return np.concatenate([p, r])

    def step(self, dt: float) -> bool:
        """Advance one period; return True when the target is reached."""
        remaining = self.length - self.s
        if remaining <= 1e-9:
            self.s, self.s_dot = self.length, 0.0
            return True
        # accelerate, cruise, and brake so as to arrive at rest: v ≤ √(2·a·remaining)
        v_brake = math.sqrt(2 * self.accel * remaining)
        self.s_dot = max(min(self.speed, self.s_dot + self.accel * dt, v_brake), min(1e-3, self.speed))
        self.s = min(self.length, self.s + self.s_dot * dt)
        if self.length - self.s <= 1e-7:
            self.s, self.s_dot = self.length, 0.0
            return True
        return False

    def velocity(self) -> np.ndarray:
        if self.length < 1e-9 or self.s_dot == 0.0:
            return np.zeros(6)
        p_dir = (self.target[:3] - self.start[:3]) / self.length
        return np.concatenate([p_dir * self.s_dot, self._w / self.length * self.s_dot])


class Kinematics:
    """The TCP state and the motion currently commanded.

    ``mode`` is one of ``idle``, ``linear``, ``speed``, ``stopping``, ``servo``;
    force mode (``force`` not None) overrides the compliant axes of any of them.
    """

    def __init__(self, pose, contact: Contact | None = None, max_speed: float = 3.0):
        self.pose = np.asarray(pose, float).copy()
        self.velocity = np.zeros(6)
        self.mode = "idle"
        self.contact = contact or Contact()
        self.max_speed = max_speed
        self.ft_offset = np.zeros(6)
        self.force = None                   # (task_frame, selection, wrench, limits) in force mode
        self.force_gain = 0.005             # m/s per N of force error (admittance)
        self._linear: _Linear | None = None
        self._speed_target = np.zeros(6)
        self._accel = 1.0
        self._servo_target = None
        self._servo_lookahead = 0.1

    # -- commands ------------------------------------------------------------------
    def move_linear(self, target, speed: float, accel: float) -> None:
        self._linear = _Linear(self.pose.copy(), np.asarray(target, float), max(speed, 1e-6), max(accel, 1e-6))
        # keep the current speed along the new path so that a replaced move does not jerk to rest
        if self._linear.length > 1e-9:
            self._linear.s_dot = min(float(np.linalg.norm(self.velocity[:3])), speed)
        self.mode = "linear"

    def speed_linear(self, velocity, accel: float) -> None:
        self._speed_target = np.asarray(velocity, float)
        self._accel = max(accel, 1e-6)
        self.mode = "speed"

    def stop(self, decel: float) -> None:
        if self.mode != "idle":
            self._accel = max(decel, 1e-6)
            self.mode = "stopping"
            self._linear = None

    def servo(self, target, lookahead: float) -> None:
        self._servo_target = np.asarray(target, float)
        self._servo_lookahead = max(lookahead, 0.03)
        self.mode = "servo"

    def halt(self) -> None:
        """Immediate stop (protective stop): no deceleration ramp."""
        self.mode, self._linear, self.velocity = "idle", None, np.zeros(6)

    def zero_ft(self) -> None:
        self.ft_offset = self.contact.wrench(self.pose)

    def measured_wrench(self) -> np.ndarray:
        return self.contact.wrench(self.pose) - self.ft_offset

    # -- integration ---------------------------------------------------------------
    def step(self, dt: float) -> bool:
        """Advance one control period ``dt`` (s); return True when a linear move arrived."""
        arrived, path_pose = False, None
        if self.mode == "linear":
            lin = self._linear
            arrived = lin.step(dt)
            nominal, path_pose = lin.velocity(), lin.pose_at(lin.s)
            if arrived:
                self.mode, self._linear = "idle", None
        elif self.mode == "speed":
            nominal = _step_toward(self.velocity, self._speed_target, self._accel * dt)
        elif self.mode == "stopping":
            nominal = _step_toward(self.velocity, np.zeros(6), self._accel * dt)
            if not np.any(nominal):
                self.mode = "idle"
        elif self.mode == "servo":
            nominal = (self._servo_target - self.pose) / self._servo_lookahead
            nominal[3:] = 0.0
        else:
            nominal = np.zeros(6)
        if self.force is not None:
            nominal = self._force_velocity(nominal)
            path_pose = None
        self.velocity = nominal
        if path_pose is not None:
            self.pose = path_pose
        else:
            self._integrate(nominal, dt)
        return arrived

    def _integrate(self, v, dt):
        self.pose[:3] += v[:3] * dt
        if np.any(v[3:]):
            R = rotvec_to_matrix(v[3:] * dt) @ rotvec_to_matrix(self.pose[3:])
            self.pose[3:] = matrix_to_rotvec(R)

    def _force_velocity(self, nominal):
        """Replace the compliant axes of ``nominal`` by an admittance law on the force error."""
        frame, selection, wrench, limits = self.force
        R = rotvec_to_matrix(frame[3:])
        applied = -self.contact.wrench(self.pose)             # force the tool applies on the world
        err_lin = R.T @ (wrench[:3] - applied[:3])
        v_task = R.T @ nominal[:3]
        for i in range(3):
            if selection[i]:
                v_task[i] = float(np.clip(self.force_gain * err_lin[i], -limits[i], limits[i]))
        out = nominal.copy()
        out[:3] = R @ v_task
        return out

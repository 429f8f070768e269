"""TCP motion profiles: piecewise-constant 6-D acceleration, evaluated in closed form.

A :class:`Motion` starts at time ``t0`` from position ``p0`` (m) and orientation ``R0``
and is a list of phases, each with a constant acceleration (m/s², rad/s²) applied to the
6-D velocity ``[vx, vy, vz, wx, wy, wz]`` (base frame). The orientation is
``exp(φ(t)) · R0`` with ``φ`` the integral of the angular velocity, exact whenever the
rotation axis is constant (every ``moveL``; ``speedL`` ramps between different axes are
approximated). After the last phase the TCP keeps its final velocity (zero for every
profile built here, except an endless ``speedL``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..transforms import matrix_to_rotvec, rotvec_to_matrix


@dataclass
class Motion:
    t0: float
    p0: np.ndarray               # (3,) m
    R0: np.ndarray               # (3, 3)
    v0: np.ndarray = field(default_factory=lambda: np.zeros(6))
    phases: list = field(default_factory=list)   # [(duration s, acc (6,))]

    def __post_init__(self):
        # state (x (6: position + accumulated rotation vector), v (6,)) at each phase start
        self._starts, x, v, t = [], np.zeros(6), np.asarray(self.v0, float).copy(), self.t0
        for dur, acc in self.phases:
            self._starts.append((t, x.copy(), v.copy(), np.asarray(acc, float)))
            x = x + v * dur + 0.5 * acc * dur * dur
            v = v + acc * dur
            t += dur
        v[np.abs(v) < 1e-12] = 0.0      # a ramp to rest ends at rest, not at ±1e-18 (rounding)
        self.t_end = t
        self._final = (t, x, v)
        self.rotates = bool(np.any(np.asarray(self.v0)[3:]) or
                            any(np.any(np.asarray(a)[3:]) for _, a in self.phases))
        self._rv0 = matrix_to_rotvec(self.R0)
        self.moves_forever = bool(np.any(v != 0))       # an endless speedL: never at rest
        self._last: tuple | None = None                 # (t, state) of the latest call of state()
        self._at_rest: tuple | None = None              # the state after t_end when it ends at rest

    def state(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position (3,) m, rotation matrix (3, 3), velocity (6,) at time ``t`` (s).

        The arrays are shared (do not modify them): the state at the latest time asked for is
        kept (the world, the interlocks and the devices ask for the same instant), and so is
        the constant state after a motion that ends at rest."""
        if self._last is not None and self._last[0] == t:
            return self._last[1]
        if t >= self.t_end and self._at_rest is not None:
            return self._at_rest
        out = self._state(t)
        if t >= self.t_end and not self.moves_forever:
            self._at_rest = out
        self._last = (t, out)
        return out

    def _state(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`state` evaluated in closed form."""
        t = max(t, self.t0)
        if t >= self.t_end:
            (ts, x, v), acc = self._final, np.zeros(6)
        else:
            for ts, x, v, acc in reversed(self._starts):
                if t >= ts:
                    break
        dt = t - ts
        xt = x + v * dt + 0.5 * acc * dt * dt
        vt = v + acc * dt
        R = rotvec_to_matrix(xt[3:]) @ self.R0 if self.rotates and np.any(xt[3:]) else self.R0
        return self.p0 + xt[:3], R, vt

    def pose(self, t: float) -> np.ndarray:
        p, R, _ = self.state(t)
        return self.pose_of(p, R)

    def pose_of(self, p, R) -> np.ndarray:
        """(6,) pose from a position and rotation of this motion (cheap when not rotating)."""
        return np.concatenate([p, matrix_to_rotvec(R) if self.rotates else self._rv0])

    def is_moving(self, t: float) -> bool:
        return t < self.t_end or self.moves_forever


def hold(t0, p0, R0) -> Motion:
    """At rest."""
    return Motion(t0, np.asarray(p0, float), np.asarray(R0, float))


def linear(t0, p0, R0, target_pose, speed: float, accel: float) -> Motion:
    """Trapezoidal straight-line move (``moveL``) from rest to ``target_pose`` (6,).

    Position and rotation follow the same normalised profile; ``speed``/``accel`` apply to
    the position (to the rotation angle, in rad/s and rad/s², for a pure rotation).
    """
    p0 = np.asarray(p0, float)
    d = np.asarray(target_pose[:3], float) - p0
    rel = matrix_to_rotvec(rotvec_to_matrix(target_pose[3:6]) @ np.asarray(R0).T)
    L = float(np.linalg.norm(d))
    ang = float(np.linalg.norm(rel))
    dist = L if L > 1e-9 else ang
    if dist < 1e-12:
        return hold(t0, p0, R0)
    u = np.concatenate([d, rel]) / dist
    if dist < speed * speed / accel:
        vpk = math.sqrt(dist * accel)
        ta, tc = vpk / accel, 0.0
    else:
        vpk, ta = speed, speed / accel
        tc = (dist - speed * speed / accel) / speed
    phases = [(ta, accel * u)]
    if tc > 0:
        phases.append((tc, np.zeros(6)))
    phases.append((ta, -accel * u))
    return Motion(t0, p0, np.asarray(R0, float), np.zeros(6), phases)


def velocity(t0, p0, R0, v_start, v_target, accel: float, duration: float) -> Motion:
    """``speedL``: ramp from ``v_start`` to ``v_target`` (6,) at ``accel``, hold for
    ``duration`` s from ``t0`` (0: forever), then ramp down to rest."""
    v_start, v_target = np.asarray(v_start, float), np.asarray(v_target, float)
    dv = v_target - v_start
    n = max(float(np.linalg.norm(dv[:3])), float(np.linalg.norm(dv[3:])))
    t_ramp = n / accel if n > 0 else 0.0
    phases = []
    if t_ramp > 0:
        phases.append((t_ramp, dv / t_ramp))
    if duration > 0:
        hold_t = max(duration - t_ramp, 0.0)
        if hold_t > 0:
            phases.append((hold_t, np.zeros(6)))
        n2 = max(float(np.linalg.norm(v_target[:3])), float(np.linalg.norm(v_target[3:])))
        if n2 > 0:
            t_down = n2 / accel
            phases.append((t_down, -v_target / t_down))
    m = Motion(t0, np.asarray(p0, float), np.asarray(R0, float), v_start, phases)
    return m


def stopping(t0, p0, R0, v_start, accel: float) -> Motion:
    """Decelerate from ``v_start`` to rest at ``accel`` (``stopL`` / protective stop)."""
    return velocity(t0, p0, R0, v_start, np.zeros(6), accel, 0.0)

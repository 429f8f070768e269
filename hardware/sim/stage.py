"""Where the object on the simulated stage is: its commanded motion and its tremor.

:class:`StageMotion` is the object's pose in time: trapezoidal rest-to-rest translations and
rotations commanded by :class:`~hardware.sim.stage_device.SimStage` (the
:class:`hardware.stage.ObjectStage` interface),
plus the small tremor of a held object (an AR(1) jitter of the position, the height — the
normal-force fluctuation — and the angle). The world asks it where a base-frame point lies
on the object (:meth:`StageMotion.to_object`) and how the object moved at a point since the
previous frame (:meth:`StageMotion.moved`).

Pose ``[x, y, rz]``: the XY stage's translation from home (m) and the rotary stage's angle
(rad, about +z: counter-clockwise seen from above). The rotation axis passes through
``axis_m`` at home and travels with the XY stage.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .config import StageConfig


@dataclass(frozen=True)
class Trapezoid:
    """Rest-to-rest move of ``distance`` (signed) from ``x0`` starting at ``t0``: accelerate at
    ``accel`` to at most ``speed``, cruise, decelerate (all magnitudes > 0)."""

    t0: float
    x0: float
    distance: float
    speed: float
    accel: float

    @property
    def ramp(self) -> float:
        d = abs(self.distance)
        return math.sqrt(d / self.accel) if d < self.speed ** 2 / self.accel else self.speed / self.accel

    @property
    def duration(self) -> float:
        d, ta = abs(self.distance), self.ramp
        return 2 * ta if d < self.speed ** 2 / self.accel else d / self.speed + ta

    def at(self, t: float) -> tuple[float, float]:
        """Position and velocity at ``t`` (s)."""
        sign, a, ta, T = math.copysign(1.0, self.distance), self.accel, self.ramp, self.duration
        tau = min(max(t - self.t0, 0.0), T)
        vmax = a * ta
        if tau < ta:
            s, v = 0.5 * a * tau * tau, a * tau
        elif tau <= T - ta:
            s, v = 0.5 * a * ta * ta + vmax * (tau - ta), vmax
        else:
            r = T - tau
            s, v = abs(self.distance) - 0.5 * a * r * r, a * r
        return self.x0 + sign * s, (sign * v if tau < T else 0.0)


class StageMotion:
    """The object's pose over time (commanded motion + tremor), advanced once per frame."""

    def __init__(self, cfg: StageConfig, rng: np.random.Generator):
        self.cfg, self.rng = cfg, rng
        self.axis = np.asarray(cfg.axis_m, float)
        self.xy = np.zeros(2)
        self.theta = 0.0
        self.move: tuple | None = None          # ("translate", Trapezoid, unit (2,), start xy) | ("rotate", Trapezoid)
        self._jitter = np.zeros(4)             # x, y, z (m), angle (rad) of the tremor
        self._std = np.array([cfg.tremor_mm * 1e-3, cfg.tremor_mm * 1e-3, cfg.tremor_normal_mm * 1e-3,
                              math.radians(cfg.tremor_deg)])
        self.now = self._pose_tremor()
        self.prev = self.now

    # -- commands ------------------------------------------------------------------
    def command(self, t: float, kind: str, amount, speed: float) -> float:
        """Start a translation (``amount`` (dx, dy) m) or rotation (``amount`` rad) from where the
        object is, at rest (a motion under way is replaced, as the arm's); returns the end time."""
        self._settle(t)
        if kind == "translate":
            d = np.asarray(amount, float)
            dist = float(np.hypot(*d))
            prof = Trapezoid(t, 0.0, dist, speed, self.cfg.accel_m_s2)
            self.move = ("translate", prof, d / dist if dist > 0 else np.zeros(2), self.xy.copy())
        else:
            prof = Trapezoid(t, self.theta, float(amount), speed, self.cfg.angular_accel_rad_s2)
            self.move = ("rotate", prof)
        return prof.t0 + prof.duration

    def stop(self, t: float) -> None:
        """Decelerate from the current velocity to rest at the configured rate: the second half
        of a triangular profile whose peak is now."""
        if not self.moving(t):
            return
        kind, prof = self.move[0], self.move[1]
        x, v = prof.at(t)
        accel = prof.accel
        half = math.copysign(v * v / (2 * accel), v)
        stop = Trapezoid(t - abs(v) / accel, x - half, 2 * half, abs(v), accel)
        self.move = (kind, stop, *self.move[2:])

    def _settle(self, t: float) -> None:
        """Fold the commanded motion up to ``t`` into the pose."""
        self.xy, self.theta = self.commanded(t)

    def commanded(self, t: float) -> tuple[np.ndarray, float]:
        """Commanded ``(xy (2,) m, theta rad)`` at ``t``."""
        if self.move is None:
            return self.xy.copy(), self.theta
        if self.move[0] == "translate":
            _, prof, unit, start = self.move
            return start + unit * prof.at(t)[0], self.theta
        return self.xy.copy(), self.move[1].at(t)[0]

    def velocity(self, t: float) -> np.ndarray:
        """(3,) ``[vx, vy, wz]`` commanded at ``t``."""
        if self.move is None:
            return np.zeros(3)
        v = self.move[1].at(t)[1]
        return np.r_[self.move[2] * v, 0.0] if self.move[0] == "translate" else np.array([0.0, 0.0, v])

    def moving(self, t: float) -> bool:
        return self.move is not None and t < self.move[1].t0 + self.move[1].duration

    # -- per frame -----------------------------------------------------------------
    def step(self, t: float, dt: float) -> None:
        """Advance the tremor by ``dt`` and take the pose at ``t`` (the previous one is kept)."""
        if np.any(self._std > 0):
            phi = math.exp(-dt / self.cfg.tremor_tau_s)
            self._jitter = phi * self._jitter + math.sqrt(1 - phi * phi) * self._std * self.rng.standard_normal(4)
        self.prev = self.now
        xy, theta = self.commanded(t)
        self.now = self._pose_tremor(xy, theta)

    def _pose_tremor(self, xy=None, theta=None) -> tuple[np.ndarray, float, float]:
        xy = self.xy if xy is None else xy
        theta = self.theta if theta is None else theta
        return xy + self._jitter[:2], theta + self._jitter[3], self._jitter[2]

    @property
    def lift(self) -> float:
        """Vertical offset of the object (m): the tremor's normal component."""
        return self.now[2]

    def to_object(self, x, y, pose=None):
        """Base-frame (x, y) m → where they lie on the object (its home placement)."""
        (t, theta, _) = self.now if pose is None else pose
        c, s = math.cos(theta), math.sin(theta)
        dx, dy = np.asarray(x) - self.axis[0] - t[0], np.asarray(y) - self.axis[1] - t[1]
        return self.axis[0] + c * dx + s * dy, self.axis[1] - s * dx + c * dy

    def from_object(self, qx, qy, pose=None):
        (t, theta, _) = self.now if pose is None else pose
        c, s = math.cos(theta), math.sin(theta)
        dx, dy = np.asarray(qx) - self.axis[0], np.asarray(qy) - self.axis[1]
        return self.axis[0] + t[0] + c * dx - s * dy, self.axis[1] + t[1] + s * dx + c * dy

    def moved(self, xy) -> tuple[np.ndarray, float]:
        """How the object moved since the previous frame: the displacement (2,) m of its material
        point now at base-frame ``xy``, and its turn (rad about +z)."""
        q = self.to_object(xy[0], xy[1], self.now)
        before = np.array(self.from_object(q[0], q[1], self.prev))
        return np.asarray(xy, float) - before, self.now[1] - self.prev[1]

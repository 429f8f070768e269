"""Steps that press the finger on an object and move the object under it (slip in place).

- ``press``: put the protocol's finger on the object with a given force;
- ``slide``: the object stage pulls the object under the still finger, in a direction of the
  finger's sensor x–y plane (the object's motion relative to the finger: 0° = +x, 90° = +y);
- ``twist``: the stage turns the object about its vertical axis (+ = counter-clockwise seen
  from outside the pad, i.e. about the sensor's −z);
- ``move_object``: ``slide``, ``twist`` or a still touch, as ``protocol.motion`` says.

Units are the protocol's: mm, mm/s, deg, deg/s, N, s. ``slide`` and ``twist`` need an object
stage (``hardware.stage``, :class:`hardware.stage.ObjectStage`); without one the plan check
refuses them. Registered in :data:`protocols.steps.STEP_KINDS` on import (``protocols.steps``
imports this module).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from .steps import Criterion, ProtocolError, Step, _positive, _still, step

MOTIONS = ("translate", "rotate", "none")


@step
@dataclass
class Press(Step):
    """Put the finger on the object: move to ``height`` mm above the surface top over ``at`` (a
    surface reference, or ``stage``: the object stage's rotation axis), then lower it at
    ``speed`` mm/s until the TCP force reaches ``force`` N (default ``protocol.press_force``),
    at most ``depth`` mm below the top. With ``protocol.tare: false`` this step and those before
    it run before the recording starts: the record begins in contact."""

    kind: ClassVar[str] = "press"
    at: str = "stage"
    force: float | None = None
    height: float = 2.0
    depth: float = 5.0
    speed: float = 1.0

    def resolve(self, ctx) -> dict:
        return {"force": ctx.params.press_force if self.force is None else self.force,
                "travel_speed": ctx.params.travel_speed}

    def targets(self, ctx) -> tuple[np.ndarray, np.ndarray]:
        above = ctx.pose_above(self.at, self.height, f"{self.key}.at")
        return above, ctx.pose_at_depth(above, self.depth)

    def plan(self, ctx):
        force, travel_speed = self.resolve(ctx).values()
        if not 0 < force <= ctx.limits.max_force:
            raise ProtocolError(f"{self.key}.force", f"expected a force in (0, {ctx.limits.max_force}] N "
                                                     f"(hardware.arm.max_contact_force_n), got {force}")
        _positive(self.height, f"{self.key}.height")
        _positive(self.depth, f"{self.key}.depth")
        above, bottom = self.targets(ctx)
        w1, d1 = ctx.linear(above, travel_speed, self.key)
        w2, d2 = ctx.linear(bottom, self.speed, self.key)
        return w1 + w2, d1 + d2

    def run(self, ctx):
        force, travel_speed = self.resolve(ctx).values()
        above, bottom = self.targets(ctx)
        ctx.move(above, travel_speed)
        if not ctx.move(bottom, self.speed, until=Criterion(force=force)):
            raise RuntimeError(f"{self.key}: the force never reached {force} N, {self.depth} mm below the "
                               f"surface top (is the object there?)")
        ctx.event("press", self.key, {"force_n": force, "reached_n": round(ctx.tcp_force(), 3)})


@step
@dataclass
class Slide(Step):
    """The object stage pulls the object ``distance`` mm at ``speed`` mm/s in ``direction_deg``
    of the finger's sensor x–y plane (the object's motion relative to the finger; defaults:
    ``protocol.direction_deg``, ``distance_mm``, ``speed_mm_s``)."""

    kind: ClassVar[str] = "slide"
    direction_deg: float | None = None
    distance: float | None = None
    speed: float | None = None

    def values(self, ctx) -> tuple[float, float, float]:
        return tuple(_value(self, ctx, f, k)[0] for f, k in SLIDE_KEYS)

    def displacement(self, ctx, direction_deg: float, distance_mm: float, R_sensor) -> np.ndarray:
        """(2,) base-frame x, y (m) of the object's motion; the sensor plane must face the stage."""
        d = R_sensor @ np.array([math.cos(math.radians(direction_deg)), math.sin(math.radians(direction_deg)), 0.0])
        if abs(R_sensor[2, 2]) < 0.9:
            raise ProtocolError(self.key, "the finger's sensor x–y plane is not horizontal: a horizontal stage "
                                          "cannot move the object in it")
        return d[:2] / np.hypot(*d[:2]) * distance_mm * 1e-3

    def plan(self, ctx):
        ctx.require_stage(self.key)
        (direction, k_dir), (distance, k_dist), (speed, k_speed) = (_value(self, ctx, f, k) for f, k in SLIDE_KEYS)
        if not math.isfinite(direction):
            raise ProtocolError(k_dir, f"expected a finite angle (deg), got {direction}")
        _positive(distance, k_dist)
        _stage_speed(speed * 1e-3, ctx.stage_cfg.max_speed_m_s, k_speed, "mm/s", 1e3, "max_speed_m_s")
        ctx.stage_pose[:2] += self.displacement(ctx, direction, distance, ctx.sensor_rotation())
        limit = ctx.stage_cfg.max_travel_m
        if np.any(np.abs(ctx.stage_pose[:2]) > limit + 1e-12):
            where = np.round(ctx.stage_pose[:2] * 1e3, 2).tolist()
            raise ProtocolError(k_dist, f"takes the object stage to {where} mm from home, beyond "
                                                        f"hardware.stage.max_travel_m = {limit}")
        from .plan import trapezoid_time          # (plan imports the step registry: import here)
        return _still(ctx, trapezoid_time(distance * 1e-3, speed * 1e-3, ctx.stage_cfg.accel_m_s2), self.key)

    def run(self, ctx):
        direction, distance, speed = self.values(ctx)
        dx, dy = self.displacement(ctx, direction, distance, ctx.sensor_rotation(ctx.pose))
        ctx.event("slide", self.key, {"direction_deg": direction, "distance_mm": distance, "speed_mm_s": speed,
                                      "world_mm": [round(dx * 1e3, 4), round(dy * 1e3, 4)]})
        ctx.stage_move(lambda: ctx.lab.stage.translate(dx, dy, speed * 1e-3, asynchronous=True))


@step
@dataclass
class Twist(Step):
    """The object stage turns the object by ``angle`` deg (+ = counter-clockwise seen from outside
    the pad, i.e. about the sensor's −z) at ``speed`` deg/s about its vertical axis (defaults:
    ``protocol.rotation_deg``, ``rotation_speed_deg_s``)."""

    kind: ClassVar[str] = "twist"
    angle: float | None = None
    speed: float | None = None

    def values(self, ctx) -> tuple[float, float]:
        return tuple(_value(self, ctx, f, k)[0] for f, k in TWIST_KEYS)

    def stage_angle(self, angle_deg: float, R_sensor) -> float:
        """The stage's turn (rad about the base +z) for ``angle_deg`` about the sensor's −z."""
        if abs(R_sensor[2, 2]) < 0.9:
            raise ProtocolError(self.key, "the finger's sensor z axis is not vertical: the stage's vertical "
                                          "axis cannot turn the object about it")
        return -math.radians(angle_deg) * float(np.sign(R_sensor[2, 2]))

    def plan(self, ctx):
        ctx.require_stage(self.key)
        (angle, k_angle), (speed, k_speed) = (_value(self, ctx, f, k) for f, k in TWIST_KEYS)
        if not (math.isfinite(angle) and angle != 0):
            raise ProtocolError(k_angle, f"expected a non-zero angle (deg), got {angle}")
        _stage_speed(math.radians(speed), ctx.stage_cfg.max_angular_speed_rad_s, k_speed, "deg/s",
                     math.degrees(1), "max_angular_speed_rad_s")
        ctx.stage_pose[2] += self.stage_angle(angle, ctx.sensor_rotation())
        limit = ctx.stage_cfg.max_rotation_rad
        if abs(ctx.stage_pose[2]) > limit + 1e-12:
            raise ProtocolError(k_angle, f"turns the object stage {math.degrees(ctx.stage_pose[2]):.1f} "
                                                     f"deg from home, beyond hardware.stage.max_rotation_rad = {limit}")
        from .plan import trapezoid_time          # (plan imports the step registry: import here)
        return _still(ctx, trapezoid_time(math.radians(abs(angle)), math.radians(speed),
                                          ctx.stage_cfg.angular_accel_rad_s2), self.key)

    def run(self, ctx):
        angle, speed = self.values(ctx)
        turn = self.stage_angle(angle, ctx.sensor_rotation(ctx.pose))
        ctx.event("twist", self.key, {"rotation_deg": angle, "rotation_speed_deg_s": speed})
        ctx.stage_move(lambda: ctx.lab.stage.rotate(turn, math.radians(speed), asynchronous=True))


@step
@dataclass
class MoveObject(Step):
    """Move the object as ``motion`` says (default ``protocol.motion``): ``translate`` is a
    ``slide``, ``rotate`` a ``twist`` (both from the protocol's keys); ``none`` keeps the touch
    still for ``duration`` s (default: as long as the slide would take, distance / speed)."""

    kind: ClassVar[str] = "move_object"
    motion: str | None = None
    duration: float | None = None

    def delegate(self, ctx) -> Step | None:
        motion = ctx.params.motion if self.motion is None else self.motion
        if motion not in MOTIONS:
            raise ProtocolError(f"{self.key}.motion", f"expected one of {', '.join(MOTIONS)}, got {motion!r}")
        if motion == "translate":
            return Slide(key=self.key)
        if motion == "rotate":
            return Twist(key=self.key)
        return None

    def touch_s(self, ctx) -> float:
        if self.duration is not None:
            return self.duration
        _positive(ctx.params.speed_mm_s, "protocol.speed_mm_s")
        return ctx.params.distance_mm / ctx.params.speed_mm_s

    def plan(self, ctx):
        inner = self.delegate(ctx)
        return inner.plan(ctx) if inner is not None else _still(ctx, self.touch_s(ctx), f"{self.key}.duration")

    def run(self, ctx):
        inner = self.delegate(ctx)
        if inner is not None:
            return inner.run(ctx)
        start = ctx.clock.now()
        ctx.event("touch", self.key, {"duration_s": self.touch_s(ctx)})
        ctx.wait(self.touch_s(ctx))
        if getattr(ctx.lab, "truth", None) is not None:
            ctx.lab.truth.touch(start, ctx.clock.now())


SLIDE_KEYS = (("direction_deg", "direction_deg"), ("distance", "distance_mm"), ("speed", "speed_mm_s"))
TWIST_KEYS = (("angle", "rotation_deg"), ("speed", "rotation_speed_deg_s"))


def _value(s: Step, ctx, name: str, protocol_key: str) -> tuple[float, str]:
    """The step's ``name`` parameter and its YAML key, or the protocol's default and its key."""
    v = getattr(s, name)
    return (getattr(ctx.params, protocol_key), f"protocol.{protocol_key}") if v is None else (v, f"{s.key}.{name}")


def _stage_speed(value: float, limit: float, key: str, unit: str, scale: float, limit_key: str) -> None:
    """``value`` (SI) must be in (0, ``limit``]; the message gives it in the protocol's ``unit``."""
    if not (math.isfinite(value) and 0 < value <= limit + 1e-12):
        raise ProtocolError(key, f"expected a speed in (0, {limit * scale:g}] {unit} "
                                 f"(hardware.stage.{limit_key} = {limit}), got {value * scale:g}")

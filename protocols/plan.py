"""Expand a protocol into a timeline and check it before anything moves.

:func:`make_plan` parses the steps, expands ``repeat``, and walks the whole protocol with a
planned TCP pose and clock, checking every waypoint against the workspace envelope and
the arm's reach, every speed, acceleration and force threshold against the hardware's
limits, and every surface reference against the surface. :func:`format_timeline` prints
what ``tactile-run plan_only=true`` shows.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from tactile_flow.hardware.arm import trapezoid_time
from tactile_flow.hardware.errors import brief
from tactile_flow.hardware.transforms import rotvec_to_matrix
from tactile_flow.hardware.surfaces import Surface, load_surface
from tactile_flow.tactile.geometry import cached_fit_ellipsoid, load_taxels

from .settings import run_settings
from .steps import Criterion, ProtocolError, Repeat, Step

UR10_REACH_M = 1.3          # UR10 working radius from the base axis
MAX_STEPS = 10_000          # expanded steps: far beyond any lab protocol, short of a runaway repeat
JOINT_RANGE_RAD = math.pi / 2   # no Shadow Hand joint moves beyond ±π/2 rad
DEFAULT_MAX_DURATION_S = 7200.0


@dataclass(frozen=True)
class Limits:
    """Motion limits from the hardware config (SI units)."""

    workspace_min: np.ndarray
    workspace_max: np.ndarray
    max_speed: float                 # m/s
    max_accel: float                 # m/s²
    max_force: float                 # N
    max_pump_rate: float             # ml/min
    max_hand_velocity: float = math.inf   # rad/s
    reach: float = UR10_REACH_M      # m

    @classmethod
    def from_hardware(cls, hw) -> "Limits":
        """From a typed hardware config (:class:`~hardware.config.SimConfig`, :class:`~hardware.lab.LabConfig`)."""
        return cls(workspace_min=np.asarray(hw.workspace.min_m, float),
                   workspace_max=np.asarray(hw.workspace.max_m, float),
                   max_speed=float(hw.arm.max_speed_m_s), max_accel=float(hw.arm.max_accel_m_s2),
                   max_force=float(hw.arm.max_contact_force_n), max_pump_rate=float(hw.pump.max_rate_ml_min),
                   max_hand_velocity=float(hw.hand.max_velocity_rad_s))


class Geometry:
    """Where the TCP must be for the protocol's finger to touch a given place.

    ``hw.fingertips[finger]`` is the sensor's pose in the TCP frame (m, rad); the pad's
    lowest point in the sensor frame is the pole of the BioTac ellipsoid fitted to the
    taxels (:mod:`tactile.geometry`). The TCP keeps the orientation of the home pose.
    """

    def __init__(self, hw, surface: Surface | None, finger: str):
        if finger not in hw.fingertips:
            raise ProtocolError("protocol.finger", f"expected one of {sorted(hw.fingertips)}, got {finger!r}")
        self.surface = surface
        self.home = np.asarray(hw.arm.home_pose, float)
        self.R_tcp = rotvec_to_matrix(self.home[3:])
        self.stage_cfg = hw.stage                 # the object stage's settings; None: the lab has none
        tip = np.asarray(hw.fingertips[finger], float)
        self.R_tip = rotvec_to_matrix(tip[3:])
        fit = cached_fit_ellipsoid(load_taxels())
        pole_sensor = (fit.centre + np.array([0.0, 0.0, -fit.axes[2]])) * 1e-3
        self.pad_offset = self.R_tip @ pole_sensor + tip[:3]                     # TCP frame, m

    def tcp_for_pad(self, pad_world) -> np.ndarray:
        """TCP pose putting the pad's lowest point at ``pad_world`` (3,) m."""
        return np.r_[np.asarray(pad_world, float) - self.R_tcp @ self.pad_offset, self.home[3:]]

    def pad_of(self, pose) -> np.ndarray:
        return np.asarray(pose[:3], float) + self.R_tcp @ self.pad_offset

    def _surface(self, key: str) -> Surface:
        if self.surface is None:
            raise ProtocolError(key, "refers to the surface, but this run has none (set surface=...)")
        return self.surface

    def board_position(self, ref: str, margin_mm: float, key: str) -> float:
        """Position along the board's sweep axis (m) of ``before:/after:<feature>`` or a centre."""
        s = self._surface(key)
        side, _, name = ref.rpartition(":")
        if side not in ("", "before", "after"):
            raise ProtocolError(key, f"expected before:<feature>, after:<feature> or <feature>, got {ref!r}")
        names = {"first": 0, "last": len(s.features) - 1}
        try:
            feature = s.feature(names.get(name, name))
        except (KeyError, IndexError, ValueError):
            valid = [f.name for f in s.features] + ["first", "last"]
            raise ProtocolError(key, f"the surface has no feature {name!r}; it has {valid}") from None
        half = feature.width / 2 + margin_mm * 1e-3
        return feature.u + {"": 0.0, "before": -half, "after": half}[side]

    def pose_over(self, ref: str, margin_mm: float, height_mm: float, key: str) -> np.ndarray:
        """TCP pose with the pad ``height_mm`` above the surface top at reference ``ref``."""
        s = self._surface(key)
        u = self.board_position(ref, margin_mm, key)
        xy = s.origin[:2] + u * s.across[:2]
        return self.tcp_for_pad([xy[0], xy[1], s.max_z + height_mm * 1e-3])

    def pose_above(self, ref: str, height_mm: float, key: str) -> np.ndarray:
        """TCP pose with the pad ``height_mm`` above the surface top, over ``ref``: a surface
        reference, or ``stage`` (the object stage's rotation axis)."""
        if ref != "stage":
            return self.pose_over(ref, 0.0, height_mm, key)
        self.require_stage(key)
        s = self._surface(key)
        x, y = (float(v) for v in self.stage_cfg.axis_m)
        return self.tcp_for_pad([x, y, s.max_z + height_mm * 1e-3])

    def require_stage(self, key: str) -> None:
        if self.stage_cfg is None:
            raise ProtocolError(key, "needs an object stage, but this lab has none (hardware.stage is not "
                                     "configured)")

    def sensor_rotation(self, pose=None) -> np.ndarray:
        """(3, 3) the protocol finger's sensor frame in the base frame, at TCP ``pose`` (default home)."""
        R = self.R_tcp if pose is None else rotvec_to_matrix(np.asarray(pose, float)[3:6])
        return R @ self.R_tip

    def pose_at_depth(self, pose, depth_mm: float) -> np.ndarray:
        """``pose`` lowered or raised so the pad is ``depth_mm`` below the surface top."""
        s = self._surface("approach")
        pad = self.pad_of(pose)
        pad[2] = s.max_z - depth_mm * 1e-3
        return self.tcp_for_pad(pad)


@dataclass
class PlannedStep:
    """One step of the timeline: where it starts (s), how long it is expected to take (s),
    and the TCP waypoints it commands."""

    index: int
    step: Step
    start: float
    duration: float
    waypoints: list[np.ndarray] = field(default_factory=list)

    @property
    def name(self) -> str:
        return f"{self.index:02d}_{self.step.kind}"


class PlanContext(Geometry):
    """The planner's running state: planned pose, time and hand targets, parameters, limits."""

    def __init__(self, hw, surface, params, limits: Limits, max_duration: float = DEFAULT_MAX_DURATION_S):
        super().__init__(hw, surface, params.finger)
        self.params, self.limits, self.max_duration = params, limits, max_duration
        self.pose = self.home.copy()
        self.time = 0.0
        self.pour_until = None
        self.stage_pose = np.zeros(3)      # planned object stage pose [x, y] m, [rz] rad from home
        self.hand_targets: dict[str, float] = {}          # joint angles commanded so far (rad)

    def linear(self, target, speed_mm_s: float, key: str):
        """Plan a straight move at ``speed_mm_s``; check the target, speed and acceleration."""
        speed = speed_mm_s * 1e-3
        accel = self.params.accel * 1e-3
        if not speed > 0:
            raise ProtocolError(f"{key}.speed", f"expected a speed > 0 mm/s, got {brief(speed_mm_s)}")
        if speed > self.limits.max_speed:
            raise ProtocolError(f"{key}.speed", f"{brief(speed_mm_s)} mm/s exceeds the arm's limit "
                                                f"hardware.arm.max_speed_m_s={self.limits.max_speed}")
        self.check_reachable(target, key)
        distance = float(np.linalg.norm(np.asarray(target[:3]) - self.pose[:3]))
        duration = trapezoid_time(distance, speed, accel)
        self.pose = np.asarray(target, float).copy()
        self.time += duration
        return [self.pose.copy()], duration

    def check_parameters(self) -> None:
        """The protocol-level parameters, whichever steps use them (finite already:
        :func:`protocols.settings.run_settings`): ``accel`` within the arm's limit."""
        if not 0 < self.params.accel * 1e-3 <= self.limits.max_accel:
            raise ProtocolError("protocol.accel", f"expected an acceleration in (0, {self.limits.max_accel * 1e3:g}] "
                                                  f"mm/s² (hardware.arm.max_accel_m_s2), "
                                                  f"got {brief(self.params.accel)}")

    def check_reachable(self, pose, key: str) -> None:
        if not np.all(np.isfinite(np.asarray(pose, float))):
            raise ProtocolError(key, f"waypoint {_point(pose)} is not finite "
                                     f"(a NaN or infinite parameter?)")
        p = np.asarray(pose[:3], float)
        lo, hi = self.limits.workspace_min, self.limits.workspace_max
        for axis, name in enumerate("xyz"):
            if p[axis] < lo[axis] or p[axis] > hi[axis]:
                bound = ("min_m", lo[axis]) if p[axis] < lo[axis] else ("max_m", hi[axis])
                raise ProtocolError(key, f"waypoint {_point(p)} m leaves the workspace envelope: {name} = "
                                         f"{brief(round(float(p[axis]), 4))} m is beyond "
                                         f"hardware.workspace.{bound[0]}[{axis}] = {bound[1]} m")
        if np.hypot(p[0], p[1]) > self.limits.reach:
            raise ProtocolError(key, f"waypoint {_point(p)} m is out of the arm's reach "
                                     f"({self.limits.reach} m from the base axis)")

    def hand(self, targets: dict[str, float], duration: float, key: str, commit: bool = True) -> None:
        """Check hand joint targets (rad) reached in ``duration`` s from the planned ones: every
        angle within ±:data:`JOINT_RANGE_RAD`, no joint faster than the hand's limit
        (``hardware.hand.max_velocity_rad_s``); with ``commit`` they become the planned ones."""
        for name, value in targets.items():
            if not abs(value) <= JOINT_RANGE_RAD:
                raise ProtocolError(key, f"{name} target {brief(value)} rad is beyond the hand's range "
                                         f"±{JOINT_RANGE_RAD:.4g} rad")
        change = max((abs(v - self.hand_targets.get(n, 0.0)) for n, v in targets.items()), default=0.0)
        if change > self.limits.max_hand_velocity * duration:
            raise ProtocolError(key, f"moves a joint {change:.3g} rad in {brief(duration)} s, faster than "
                                     f"hardware.hand.max_velocity_rad_s={self.limits.max_hand_velocity:g}; "
                                     f"give it a longer duration")
        if commit:
            self.hand_targets.update(targets)

    def check_criterion(self, crit: Criterion | None, key: str) -> None:
        if crit is None:
            return
        for name in ("pdc_rise", "contact_lost"):
            if getattr(crit, name) is not None and not self.params.tare:
                raise ProtocolError(f"{key}.{name}", "counts PDC from the tare, but protocol.tare=false starts the "
                                                     "run in contact without one; use force instead")
        if crit.force is not None and not 0 < crit.force <= self.limits.max_force:
            raise ProtocolError(f"{key}.force", f"expected a force in (0, {self.limits.max_force}] N "
                                                f"(hardware.arm.max_contact_force_n), got {crit.force}")
        for name in ("pdc_rise", "contact_lost"):
            value = getattr(crit, name)
            if value is not None and not value > 0:
                raise ProtocolError(f"{key}.{name}", f"expected a threshold > 0 counts, got {value}")


def _point(p) -> str:
    """A position (m) for a message, to 0.1 mm."""
    return "[" + ", ".join(brief(round(float(v), 4)) for v in p) + "]"


@dataclass
class Plan:
    """The checked timeline. ``setup``: how many leading steps run before the recording starts
    (``protocol.tare: false``: the steps up to the first ``press`` make the contact unrecorded)."""

    protocol: str
    steps: list[PlannedStep]
    labels: list[str]
    setup: int = 0

    @property
    def duration(self) -> float:
        return self.steps[-1].start + self.steps[-1].duration if self.steps else 0.0

    def slip_steps(self) -> list[str]:
        """YAML keys of the steps that react to slip (``until: slip`` or ``on_slip``)."""
        def reacts(step):
            until = getattr(step, "until", None)
            return bool(getattr(step, "on_slip", None)) or (until is not None and bool(until.slip))
        return [p.step.key for p in self.steps if reacts(p.step)]


def make_plan(cfg) -> Plan:
    """Check the protocol's steps against the hardware and the surface, and its expected
    duration against ``safety.max_duration_s``; ``cfg``: :class:`~protocols.settings.RunSettings`
    (or the composed config, checked first by :func:`~protocols.settings.run_settings`).

    Raises :class:`ProtocolError` (or the hardware's ``ConfigError``) naming the key at
    fault; never touches hardware.
    """
    settings = run_settings(cfg)
    params, hardware = settings.protocol, settings.hardware
    surface = load_surface(settings.surface) if settings.surface is not None else None
    max_duration = settings.safety.max_duration_s
    ctx = PlanContext(hardware, surface, params, Limits.from_hardware(hardware), max_duration)
    ctx.check_parameters()
    if params.finger not in hardware.fingers:
        raise ProtocolError("protocol.finger", f"{params.finger!r} has no sensor in hardware.fingers "
                                               f"{list(hardware.fingers)}")
    planned: list[PlannedStep] = []

    def walk(items):
        for s in items:
            if len(planned) > MAX_STEPS:
                raise ProtocolError(s.key, f"the protocol expands to more than {MAX_STEPS} steps; "
                                           f"is a repeat count too large?")
            if isinstance(s, Repeat):
                s.plan(ctx)
                for _ in range(s.times):
                    walk(s.steps)
                continue
            start = ctx.time
            waypoints, duration = s.plan(ctx)
            if not ctx.time <= max_duration:
                raise ProtocolError(s.key, f"the protocol would run {brief(ctx.time)} s by the end of this step, "
                                           f"longer than safety.max_duration_s={max_duration:g} s")
            planned.append(PlannedStep(len(planned), s, start, duration, waypoints))

    walk(params.steps)
    return Plan(protocol=params.name, steps=planned, labels=list(params.labels), setup=_setup_steps(params, planned))


def _setup_steps(params, planned: list[PlannedStep]) -> int:
    """Steps before the recording: none with a tare; without, the steps up to the first press."""
    if params.tare:
        return 0
    presses = [p.index for p in planned if p.step.kind == "press"]
    if not presses:
        raise ProtocolError("protocol.tare", "false starts the run in contact, but no step makes the contact: "
                                             "add a `press` step (it and the steps before it run before the "
                                             "recording starts)")
    return presses[0] + 1


def format_timeline(plan: Plan) -> str:
    """The plan as a table: step, start, expected duration, parameters, waypoints."""
    lines = [f"protocol {plan.protocol}: {len(plan.steps)} steps, expected {plan.duration:.1f} s; "
             f"analysis labels: {', '.join(plan.labels) or '-'}"
             + (f"; the first {plan.setup} step(s) make the contact before the recording (no tare)"
                if plan.setup else ""),
             f"{'#':>3}  {'step':<10} {'start s':>8} {'dur s':>7}  parameters / TCP waypoints (m)"]
    for p in plan.steps:
        lines.append(f"{p.index:>3}  {p.step.kind:<10} {p.start:>8.2f} {p.duration:>7.2f}  {p.step.describe()}")
        for w in p.waypoints:
            lines.append(f"{'':>33}→ [{w[0]:.4f}, {w[1]:.4f}, {w[2]:.4f}]")
    return "\n".join(lines)

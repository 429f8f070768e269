"""The step vocabulary of protocols: one small dataclass per step kind.

A protocol's ``steps`` is a YAML list of one-key mappings, ``- sweep: {speed: 10}``.
:func:`parse_steps` turns it into step objects, checking every key and type and naming
the YAML key at fault (``protocol.steps[2].sweep.speed``). Each step class knows how to

- ``plan(ctx)``: advance the planned TCP pose and time, returning its waypoints and
  expected duration, so the whole protocol can be checked before anything moves;
- ``run(ctx)``: execute against the hardware interfaces (see :mod:`protocols.engine`).

Adding a step kind is one class here with its fields, ``plan`` and ``run``, decorated
with :func:`step`; the protocol's defaults it takes (``speed`` from ``protocol.sweep_speed``...)
are filled in by its ``resolve``, which both ``plan`` and ``run`` call. ``hold`` and ``pour`` may react to slip (``until: slip``, ``on_slip:
[...]``, see ``docs/live.md``); reactions are :class:`Reaction` steps, which act at once. Units are the protocol's: mm, mm/s, s, N, ml, ml/min, rad.

Surface references (``at``/``to``): ``before:<feature>``, ``after:<feature>``, or
``<feature>`` (its centre), where ``<feature>`` is ``feature_<i>``, ``first`` or ``last``;
"before" and "after" are along the board's sweep axis (its local x, across the features),
``margin`` mm outside the feature's edge. ``home`` is the arm's home pose.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from tactile_flow.hardware.hand import JOINT_NAMES
from tactile_flow.validation import ConfigError, brief, unknown_key


class ProtocolError(ConfigError):
    """A protocol that cannot run as written; ``key`` is the YAML key at fault."""


STEP_KINDS: dict[str, type[Step]] = {}


def step(cls):
    """Register a step class under its ``kind``."""
    STEP_KINDS[cls.kind] = cls
    return cls


@dataclass
class Criterion:
    """When a waiting step ends early. Any key that is set must hold.

    ``pdc_rise``: PDC of the protocol's finger this many counts above its tare value.
    ``contact_lost``: every grasp finger's PDC back within this many counts of its tare.
    ``force``: TCP force magnitude above this many newtons.
    ``slip``: the live slip detector fired (:mod:`protocols.live`); ``until: slip`` is
    short for ``until: {slip: true}``.
    """

    pdc_rise: float | None = None
    contact_lost: float | None = None
    force: float | None = None
    slip: bool | None = None

    def describe(self) -> str:
        return ", ".join(f"{k}={v}" for k, v in dataclasses.asdict(self).items() if v is not None) or "none"


@dataclass
class Step:
    """Base class. ``key`` is this step's YAML key, for messages."""

    kind: ClassVar[str] = ""
    key: str = field(default="", repr=False)

    def resolve(self, ctx) -> dict:
        """The step's parameters with the protocol's defaults (``ctx.params``) filled in: the
        one place a default is chosen, used by both ``plan`` and ``run``."""
        return {}

    def plan(self, ctx) -> tuple[list[np.ndarray], float]:
        """Advance ``ctx`` (a :class:`protocols.plan.PlanContext`); return (waypoints, seconds)."""
        return [], 0.0

    def run(self, ctx) -> None:  # pragma: no cover - every step overrides it
        raise NotImplementedError

    def react(self, ctx) -> None:
        """Act at once, without waiting (a reaction in ``on_slip``); only :data:`REACTIONS` can."""
        raise NotImplementedError(f"{self.kind} cannot be a reaction")

    def describe(self) -> str:
        fields = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name != "key"}
        return ", ".join(f"{k}={_short(v)}" for k, v in fields.items() if v is not None)


def _short(v):
    if isinstance(v, Criterion):
        return "{" + v.describe() + "}"
    if isinstance(v, list) and v and isinstance(v[0], Step) and all(x.kind in REACTIONS for x in v):
        return "[" + ", ".join(x.kind for x in v) + "]"
    if isinstance(v, list) and v and isinstance(v[0], Step):
        return f"[{len(v)} steps]"
    return v


# ----------------------------------------------------------------------------- motion


@step
@dataclass
class MoveTo(Step):
    """Move the TCP in a straight line to a surface reference or a pose, out of contact.

    ``at``: a surface reference (see the module docstring) or ``home``; ``height``: mm of
    the finger's pad above the top of the tallest feature; ``pose``: an explicit TCP pose
    ``[x, y, z, rx, ry, rz]`` (m, rad, as ur_rtde) instead of ``at``.
    """

    kind: ClassVar[str] = "move_to"
    at: str | None = None
    pose: list[float] | None = None
    height: float = 10.0
    margin: float = 15.0
    speed: float | None = None

    def target(self, ctx) -> np.ndarray:
        if self.pose is not None and self.at is not None:
            raise ProtocolError(self.key, f"give either `at` ({self.at!r}) or `pose`, not both")
        if self.pose is not None:
            if len(self.pose) != 6:
                raise ProtocolError(f"{self.key}.pose", f"expected 6 numbers [x,y,z,rx,ry,rz], got {self.pose}")
            return np.asarray(self.pose, float)
        if self.at is None:
            raise ProtocolError(self.key, "expected `at` (a surface reference or home) or `pose`")
        if self.at == "home":
            return ctx.home.copy()
        return ctx.pose_over(self.at, self.margin, self.height, f"{self.key}.at")

    def resolve(self, ctx) -> dict:
        return {"speed": self.speed or ctx.params.travel_speed}

    def plan(self, ctx):
        return ctx.linear(self.target(ctx), self.resolve(ctx)["speed"], self.key)

    def run(self, ctx):
        ctx.move(self.target(ctx), self.resolve(ctx)["speed"])


@step
@dataclass
class Approach(Step):
    """Lower the finger to ``depth`` mm below the tallest feature's top at ``speed``,
    stopping early when ``until`` holds (e.g. a PDC rise: the first contact)."""

    kind: ClassVar[str] = "approach"
    depth: float = 1.5
    speed: float | None = None
    until: Criterion | None = None

    def target(self, ctx) -> np.ndarray:
        return ctx.pose_at_depth(ctx.pose, self.depth)

    def resolve(self, ctx) -> dict:
        return {"speed": self.speed or ctx.params.approach_speed}

    def plan(self, ctx):
        ctx.check_criterion(self.until, f"{self.key}.until")
        return ctx.linear(self.target(ctx), self.resolve(ctx)["speed"], self.key)

    def run(self, ctx):
        ctx.move(self.target(ctx), self.resolve(ctx)["speed"], until=self.until)


@step
@dataclass
class Sweep(Step):
    """Slide the finger at constant ``speed`` and height to a surface reference ``to``."""

    kind: ClassVar[str] = "sweep"
    to: str = "after:last"
    speed: float | None = None
    margin: float = 15.0

    def target(self, ctx) -> np.ndarray:
        goal = ctx.pose_over(self.to, self.margin, 0.0, f"{self.key}.to")
        goal[2] = ctx.pose[2]                              # keep the hold depth
        return goal

    def resolve(self, ctx) -> dict:
        return {"speed": self.speed or ctx.params.sweep_speed}

    def plan(self, ctx):
        return ctx.linear(self.target(ctx), self.resolve(ctx)["speed"], self.key)

    def run(self, ctx):
        speed = self.resolve(ctx)["speed"]
        ctx.event("sweep", self.key, {"speed_mm_s": speed, "to": self.to})
        ctx.move(self.target(ctx), speed)


@step
@dataclass
class Lift(Step):
    """Raise the TCP straight up by ``height`` mm."""

    kind: ClassVar[str] = "lift"
    height: float = 20.0
    speed: float | None = None

    def target(self, ctx) -> np.ndarray:
        goal = ctx.pose.copy()
        goal[2] += self.height * 1e-3
        return goal

    def resolve(self, ctx) -> dict:
        return {"speed": self.speed or ctx.params.travel_speed}

    def plan(self, ctx):
        return ctx.linear(self.target(ctx), self.resolve(ctx)["speed"], self.key)

    def run(self, ctx):
        ctx.move(self.target(ctx), self.resolve(ctx)["speed"])


# ----------------------------------------------------------------------------- hand
# The two distal flexion joints of each finger (J1 and J2 are coupled on the real hand).
FLEX_JOINTS = {"ff": ("rh_FFJ2", "rh_FFJ3"), "mf": ("rh_MFJ2", "rh_MFJ3"), "rf": ("rh_RFJ2", "rh_RFJ3"),
               "lf": ("rh_LFJ2", "rh_LFJ3"), "th": ("rh_THJ2", "rh_THJ5")}
MAX_FLEXION = math.pi           # rad, a grasp's closure: two flexion joints of at most π/2 each


@step
@dataclass
class Grasp(Step):
    """Close the hand: each of ``fingers`` flexes its two distal joints by ``flexion`` rad in
    total, over ``duration`` s; or move the named ``joints`` (rad) explicitly."""

    kind: ClassVar[str] = "grasp"
    fingers: list[str] = field(default_factory=lambda: ["ff", "mf", "th"])
    flexion: float | None = None
    joints: dict[str, float] | None = None
    duration: float = 1.0

    def targets(self, ctx) -> dict[str, float]:
        if self.joints:
            unknown = [j for j in self.joints if j not in JOINT_NAMES]
            if unknown:
                raise ProtocolError(f"{self.key}.joints", f"unknown joint(s) {unknown}; expected Shadow "
                                                          f"names such as rh_FFJ3")
            return dict(self.joints)
        flexion, key = ((ctx.params.grasp_flexion, "protocol.grasp_flexion") if self.flexion is None
                        else (self.flexion, f"{self.key}.flexion"))
        if isinstance(flexion, bool) or not isinstance(flexion, (int, float)) or not 0 < flexion <= MAX_FLEXION:
            raise ProtocolError(key, f"expected a closure in (0, {MAX_FLEXION:.4g}] rad (two joints of at most "
                                     f"π/2 each), got {brief(flexion)}")
        targets = {}
        for i, f in enumerate(self.fingers):
            if f not in FLEX_JOINTS:
                raise ProtocolError(f"{self.key}.fingers[{i}]", f"expected one of {list(FLEX_JOINTS)}, got {f!r}")
            targets.update({j: flexion / 2 for j in FLEX_JOINTS[f]})
        return targets

    def plan(self, ctx):
        _positive(self.duration, f"{self.key}.duration")
        ctx.hand(self.targets(ctx), self.duration, self.key)
        return _still(ctx, self.duration, f"{self.key}.duration")

    def run(self, ctx):
        ctx.hand_move(self.targets(ctx), self.duration)
        ctx.wait(self.duration)


@step
@dataclass
class Release(Step):
    """Open the hand: every flexion joint back to 0 over ``duration`` s."""

    kind: ClassVar[str] = "release"
    duration: float = 1.0
    OPEN: ClassVar[dict] = {j: 0.0 for joints in FLEX_JOINTS.values() for j in joints}

    def plan(self, ctx):
        _positive(self.duration, f"{self.key}.duration")
        ctx.hand(self.OPEN, self.duration, self.key)
        return _still(ctx, self.duration, f"{self.key}.duration")

    def run(self, ctx):
        ctx.lab.pump.stop()
        ctx.hand_move(dict(self.OPEN), self.duration)
        ctx.wait(self.duration)


class Reaction(Step):
    """A step that acts at once: in a protocol it acts and the next step follows, in
    ``on_slip`` it is a reaction (:data:`REACTIONS`). ``check`` validates it at plan time."""

    def check(self, ctx) -> None:
        pass

    def plan(self, ctx):
        self.check(ctx)
        return [], 0.0

    def run(self, ctx):
        self.react(ctx)


@step
@dataclass
class Tighten(Reaction):
    """Close the grasp further: each of ``fingers`` flexes its two distal joints by
    ``flexion`` rad more in total (half each), from their commanded angles, over ``duration``
    s. As a step it waits ``duration``; as a reaction (``on_slip``) it returns at once."""

    kind: ClassVar[str] = "tighten"
    fingers: list[str] = field(default_factory=lambda: ["ff", "mf", "th"])
    flexion: float = 0.2
    duration: float = 0.2

    def targets(self, ctx) -> dict[str, float]:
        out = {}
        for i, f in enumerate(self.fingers):
            if f not in FLEX_JOINTS:
                raise ProtocolError(f"{self.key}.fingers[{i}]", f"expected one of {list(FLEX_JOINTS)}, got {f!r}")
            out.update({j: ctx.hand_targets.get(j, 0.0) + self.flexion / 2 for j in FLEX_JOINTS[f]})
        return out

    def check(self, ctx, commit: bool = False) -> None:
        if not (0 < self.flexion <= MAX_TIGHTEN):
            raise ProtocolError(f"{self.key}.flexion", f"expected an increment in (0, {MAX_TIGHTEN}] rad, "
                                                       f"got {brief(self.flexion)}")
        _positive(self.duration, f"{self.key}.duration")
        ctx.hand(self.targets(ctx), self.duration, self.key, commit=commit)

    def plan(self, ctx):
        self.check(ctx, commit=True)
        return _still(ctx, self.duration, f"{self.key}.duration")

    def run(self, ctx):
        self.react(ctx)
        ctx.wait(self.duration)

    def react(self, ctx):
        ctx.hand_move(self.targets(ctx), self.duration)


@step
@dataclass
class StopPump(Reaction):
    """Stop the pump (the pour ends here)."""

    kind: ClassVar[str] = "stop_pump"

    def react(self, ctx):
        ctx.lab.pump.stop()


@step
@dataclass
class Mark(Reaction):
    """Record an event of kind ``mark`` named ``name`` (with ``note``) in the run store."""

    kind: ClassVar[str] = "mark"
    name: str = "mark"
    note: str | None = None

    def react(self, ctx):
        ctx.event("mark", self.name, {"note": self.note} if self.note else None)


REACTIONS = ("tighten", "stop_pump", "mark")
"""Step kinds allowed in ``on_slip``: they act at once, so the reaction is never held up."""
MAX_TIGHTEN = 0.5               # rad, the largest single grasp increment a protocol may ask for


def _check_reactions(ctx, on_slip, key: str) -> None:
    for r in on_slip or ():
        r.check(ctx)




# ----------------------------------------------------------------------------- pour and waiting


@step
@dataclass
class Pour(Step):
    """Start the pump at ``rate`` ml/min, to dispense at most ``volume`` ml; returns at once
    (a following ``hold`` waits). The pump is stopped on every exit path of the run."""

    kind: ClassVar[str] = "pour"
    rate: float | None = None
    volume: float | None = None
    until: Criterion | None = None
    on_slip: list[Step] | None = None

    @property
    def waits(self) -> bool:
        """With ``until`` or ``on_slip`` the step lasts as long as the pour (volume / rate)."""
        return self.until is not None or bool(self.on_slip)

    def resolve(self, ctx) -> dict:
        return {"rate": ctx.params.pour_rate if self.rate is None else self.rate,
                "volume": ctx.params.pour_volume if self.volume is None else self.volume}

    def plan(self, ctx):
        rate, volume = self.resolve(ctx).values()
        _positive(rate, f"{self.key}.rate")
        _positive(volume, f"{self.key}.volume")
        if rate > ctx.limits.max_pump_rate:
            raise ProtocolError(f"{self.key}.rate", f"{rate} ml/min exceeds the pump's limit "
                                                    f"hardware.pump.max_rate_ml_min={ctx.limits.max_pump_rate}")
        ctx.check_criterion(self.until, f"{self.key}.until")
        _check_reactions(ctx, self.on_slip, f"{self.key}.on_slip")
        if not volume / rate * 60.0 <= ctx.max_duration:         # the pump is told how long to run
            raise ProtocolError(f"{self.key}.volume", f"{brief(volume)} ml at {brief(rate)} ml/min would pour for "
                                                      f"{brief(volume / rate * 60.0)} s, longer than "
                                                      f"safety.max_duration_s={ctx.max_duration:g} s")
        ctx.pour_until = ctx.time + volume / rate * 60.0
        return _still(ctx, volume / rate * 60.0, f"{self.key}.volume") if self.waits else ([], 0.0)

    def run(self, ctx):
        rate, volume = self.resolve(ctx).values()
        ctx.event("pour", self.key, {"rate_ml_min": rate, "volume_ml": volume})
        ctx.lab.pump.dispense(volume, rate)
        if self.waits:
            _wait_reacting(ctx, volume / rate * 60.0, self)


@step
@dataclass
class Hold(Step):
    """Keep still for ``duration`` s, or until ``until`` holds (then end early)."""

    kind: ClassVar[str] = "hold"
    duration: float | None = None
    until: Criterion | None = None
    on_slip: list[Step] | None = None

    def resolve(self, ctx) -> dict:
        return {"duration": ctx.params.hold_time if self.duration is None else self.duration}

    def plan(self, ctx):
        ctx.check_criterion(self.until, f"{self.key}.until")
        _check_reactions(ctx, self.on_slip, f"{self.key}.on_slip")
        return _still(ctx, self.resolve(ctx)["duration"], f"{self.key}.duration")

    def run(self, ctx):
        _wait_reacting(ctx, self.resolve(ctx)["duration"], self)


def _wait_reacting(ctx, seconds: float, s) -> None:
    """Wait ``seconds`` or until ``s.until``; run ``s.on_slip`` the moment slip is detected."""
    met = ctx.wait(seconds, until=s.until, on_slip=s.on_slip)
    if s.until is not None:
        ctx.event("criterion" if met else "timeout", s.key, {"until": s.until.describe()})


@step
@dataclass
class Wait(Step):
    """Do nothing for ``duration`` s (streams keep recording)."""

    kind: ClassVar[str] = "wait"
    duration: float = 1.0

    def plan(self, ctx):
        return _still(ctx, self.duration, f"{self.key}.duration")

    def run(self, ctx):
        ctx.wait(self.duration)


@step
@dataclass
class Repeat(Step):
    """Run ``steps`` ``times`` times."""

    kind: ClassVar[str] = "repeat"
    times: int = 1
    steps: list[Step] = field(default_factory=list)

    def plan(self, ctx):
        if self.times < 1:
            raise ProtocolError(f"{self.key}.times", f"expected an integer ≥ 1, got {self.times}")
        return [], 0.0                                  # expanded by the planner

    def run(self, ctx):  # pragma: no cover - the engine runs the expanded steps
        raise AssertionError("repeat is expanded before running")


def _still(ctx, seconds, key: str) -> tuple[list, float]:
    """Plan ``seconds`` without arm motion: no waypoints, the planned clock moves on."""
    _positive(seconds, key)
    ctx.time += seconds
    return [], seconds


def _positive(value, key: str) -> None:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise ProtocolError(key, f"expected a number > 0, got {brief(value)}")


# ----------------------------------------------------------------------------- parsing


MAX_NESTING = 8               # repeats inside repeats


def parse_steps(items, key: str = "protocol.steps", depth: int = 0) -> list[Step]:
    """YAML list of ``{kind: {params}}`` → step objects, every key and type checked."""
    if not isinstance(items, list) or not items:
        raise ProtocolError(key, "expected a non-empty list of steps")
    if depth > MAX_NESTING:
        raise ProtocolError(key, f"repeats nested more than {MAX_NESTING} deep")
    return [parse_step(item, f"{key}[{i}]", depth) for i, item in enumerate(items)]


def parse_step(item, key: str, depth: int = 0) -> Step:
    if not isinstance(item, dict) or len(item) != 1:
        raise ProtocolError(key, f"expected one step as `- <kind>: {{params}}` with kind one of "
                                 f"{sorted(STEP_KINDS)}, got {item!r}")
    (kind, params), = item.items()
    if kind not in STEP_KINDS:
        expected = unknown_key(key, kind, STEP_KINDS, what="step kind").message.split("; ", 1)[1]
        raise ProtocolError(key, f"unknown step kind {kind!r}; {expected}")
    cls = STEP_KINDS[kind]
    key = f"{key}.{kind}"
    params = {} if params is None else params
    if not isinstance(params, dict):
        raise ProtocolError(key, f"expected a mapping of parameters, got {params!r}")
    fields = {f.name: f for f in dataclasses.fields(cls) if f.name != "key"}
    unknown = sorted(set(params) - set(fields))
    if unknown:
        raise _protocol_error(unknown_key(key, unknown[0], fields, what="parameter"))
    values = {name: _convert(value, fields[name].type, f"{key}.{name}") for name, value in params.items()}
    if kind == "repeat":
        values["steps"] = parse_steps(params.get("steps"), f"{key}.steps", depth + 1)
    if params.get("on_slip") is not None:
        values["on_slip"] = parse_reactions(params["on_slip"], f"{key}.on_slip")
    return cls(key=key, **values)


def parse_reactions(items, key: str) -> list[Step]:
    """``on_slip``: a non-empty list of steps of the :data:`REACTIONS` kinds."""
    steps = parse_steps(items, key, MAX_NESTING)
    for i, s in enumerate(steps):
        if s.kind not in REACTIONS:
            raise ProtocolError(f"{key}[{i}].{s.kind}", f"cannot react to slip (it would hold the reaction up); "
                                                        f"on_slip takes {', '.join(REACTIONS)}")
    return steps


def _protocol_error(exc: ConfigError) -> ProtocolError:
    return ProtocolError(exc.key, exc.message)


_SCALARS = {"float": (int, float), "int": (int,), "str": (str,), "bool": (bool,)}


def _convert(value, annotation: str, key: str) -> Any:
    """Check ``value`` against a field annotation written as a string (``float | None``...)."""
    options = [a.strip() for a in str(annotation).split("|")]
    if value is None:
        if "None" in options:
            return None
        raise ProtocolError(key, f"expected {annotation}, got null")
    for opt in options:
        if opt in _SCALARS and isinstance(value, _SCALARS[opt]) and not (opt != "bool" and isinstance(value, bool)):
            if opt == "float" and not math.isfinite(value):
                raise ProtocolError(key, f"expected a finite number, got {value!r}")
            return float(value) if opt == "float" else value
        if opt == "Criterion" and value == "slip":
            return Criterion(slip=True)
        if opt == "Criterion" and isinstance(value, dict):
            names = {f.name for f in dataclasses.fields(Criterion)}
            unknown = sorted(set(value) - names)
            if unknown:
                raise _protocol_error(unknown_key(key, unknown[0], names, what="criterion"))
            if not value:
                raise ProtocolError(key, f"expected at least one criterion of {sorted(names)}")
            if "pdc_rise" in value and "contact_lost" in value:
                raise ProtocolError(key, "pdc_rise (contact made) and contact_lost (contact gone) contradict "
                                         "each other; give one")
            return Criterion(**{k: _convert(v, "bool" if k == "slip" else "float", f"{key}.{k}")
                                for k, v in value.items()})
        if opt.startswith("list[") and isinstance(value, list):
            inner = opt[5:-1]
            if inner == "Step":
                return value                               # parsed by the caller (repeat)
            return [_convert(v, inner, f"{key}[{i}]") for i, v in enumerate(value)]
        if opt.startswith("dict[") and isinstance(value, dict):
            return {str(k): _convert(v, "float", f"{key}.{k}") for k, v in value.items()}
    raise ProtocolError(key, f"expected {annotation.replace('None', 'null')}, got {value!r}")


from . import object_steps  # noqa: E402,F401  (registers press, slide, twist, move_object)

"""The Shadow Dexterous Hand and its BioTacs, through rosbridge (roslibpy).

- :class:`ShadowHand`: joint targets published to ``/rh_trajectory_controller/command``
  (``trajectory_msgs/JointTrajectory``, one point reached at ``duration``), joint states
  subscribed from ``/joint_states`` (``sensor_msgs/JointState``).
- :class:`RosbridgeBiotacs`: frames from ``/rh/tactile`` (``sr_robot_msgs/BiotacAll``: a
  header and five ``Biotac`` with ``pac0``, ``pac1``, ``pac[]``, ``pdc``, ``tac``, ``tdc``,
  ``electrodes[]``, Shadow finger order). The header stamp is the frame's device time and
  ``header.seq`` its sequence number. A finger without a sensor reads ``pdc = -22072`` and
  zeros elsewhere: it is reported in :attr:`RosbridgeBiotacs.unconnected`, and ``connect()``
  refuses a configuration that asks to record one.

Messages arrive on roslibpy's thread and are buffered; nothing the recorder or the engine
calls waits on the network. A lost websocket or a silent stream becomes a typed error.
"""

from __future__ import annotations

import logging
import math
import threading
from dataclasses import dataclass, field

import numpy as np

from .biotac import FINGERS, N_TAXELS, BiotacFrame, TactileSensors, check_fingers
from .device import Clock, DeviceIdentity, SampleBuffer, WallClock
from .errors import (BUFFER_RANGE_S, RATE_RANGE_HZ, ConfigError, DeviceDisconnectedError, DeviceFaultError,
                     DeviceTimeoutError, NotConnectedError, SafetyError, require_positive, require_within)
from .hand import JOINT_INDEX, JOINT_NAMES, Hand, HandState, check_joint_names
from .rosbridge import RosbridgeConfig, RosbridgeConnection
from .wire import WireError, WireRejects, _brief, counts

log = logging.getLogger(__name__)

UNCONNECTED_PDC = -22072
"""What Shadow's driver publishes as ``pdc`` for a finger without a BioTac (other fields 0)."""


def stamp_seconds(stamp: dict) -> float:
    """ROS1 ``{secs, nsecs}`` or ROS2 ``{sec, nanosec}`` → seconds."""
    return float(stamp.get("secs", stamp.get("sec", 0))) + 1e-9 * float(stamp.get("nsecs", stamp.get("nanosec", 0)))


def ros_duration(seconds: float) -> dict:
    secs = int(math.floor(seconds))
    return {"secs": secs, "nsecs": int(round((seconds - secs) * 1e9))}


class _Stream:
    """Bounded buffer of samples with the newest kept apart, and its staleness check."""

    def __init__(self, maxlen: int):
        self.buffer = SampleBuffer(maxlen)
        self.latest = None
        self.latest_host = None
        self.first = threading.Event()

    @property
    def overflows(self) -> int:
        return self.buffer.overflows

    def push(self, sample, host_time: float) -> None:
        self.buffer.put(sample)
        self.latest, self.latest_host = sample, host_time
        self.first.set()

    def drain(self) -> list:
        return self.buffer.drain()


class _RosbridgeDevice:
    """Connection bookkeeping shared by the hand and the BioTacs (``kind`` comes from the interface)."""

    def _init_link(self, cfg: RosbridgeConfig, clock: Clock | None) -> None:
        self.rb_cfg = cfg
        self.clock = clock or WallClock()
        self.conn: RosbridgeConnection | None = None

    @property
    def is_connected(self) -> bool:
        return self.conn is not None and self.conn.is_open

    def _check_alive(self, stream: _Stream, what: str) -> None:
        if self.conn is None:
            raise NotConnectedError(f"{self.kind}: not connected (call connect() first)")
        if self.conn.lost:
            raise DeviceDisconnectedError(self.conn.lost)
        if stream.latest_host is not None:
            silent = self.clock.now() - stream.latest_host
            if silent > self.rb_cfg.stale_timeout_s:
                raise DeviceTimeoutError(f"{self.kind}: no {what} from {self.rb_cfg.url} for {silent:.2f} s "
                                         f"(> {self.rb_cfg.key}.stale_timeout_s={self.rb_cfg.stale_timeout_s})")

    def _await_first(self, stream: _Stream, timeout_s: float, what: str) -> None:
        if not stream.first.wait(timeout_s):
            if self.conn.lost:
                raise DeviceDisconnectedError(self.conn.lost)
            raise DeviceTimeoutError(f"{self.kind}: connected to {self.rb_cfg.url} but no {what} within "
                                     f"{timeout_s} s; hint: is the driver publishing it (rostopic hz {what})?")

    def close(self) -> None:
        if self.conn is not None:
            self.conn.close()
            self.conn = None


# ============================================================================ hand
@dataclass
class ShadowHandConfig:
    """Shadow Hand through rosbridge.

    Attributes:
        rosbridge: where rosbridge listens (shared with the BioTacs in ``lab.yaml``).
        command_topic, state_topic: trajectory command and joint-state topics.
        controller_joints: every joint of the trajectory controller; each command sends all
            of them (unnamed ones keep their current targets), as ros_control requires
            unless ``allow_partial_joints_goal`` is set.
        max_velocity_rad_s: the fastest joint motion ``move_to`` accepts (rad/s).
        first_state_timeout_s: ``connect()`` fails without a joint state within this (s).
        arrival_tolerance_rad, arrival_timeout_s: a waiting ``move_to`` fails if a joint is
            further than the tolerance (rad) from its target this long (s) after ``duration``.
        rate_hz, buffer_s: nominal joint-state rate (Hz) and seconds of states buffered.
    """

    rosbridge: RosbridgeConfig = field(default_factory=RosbridgeConfig)
    command_topic: str = "/rh_trajectory_controller/command"
    state_topic: str = "/joint_states"
    controller_joints: tuple[str, ...] = JOINT_NAMES
    max_velocity_rad_s: float = 2.0
    first_state_timeout_s: float = 2.0
    arrival_tolerance_rad: float = 0.05
    arrival_timeout_s: float = 1.0
    rate_hz: float = 100.0
    buffer_s: float = 120.0
    key: str = field(default="hardware.hand", repr=False)

    def __post_init__(self):
        try:
            check_joint_names(self.controller_joints, f"{self.key}.controller_joints")
        except ValueError as exc:
            raise ConfigError(f"{self.key}.controller_joints", str(exc)) from None
        require_positive(self, ("max_velocity_rad_s", "first_state_timeout_s", "arrival_tolerance_rad",
                     "arrival_timeout_s", "rate_hz", "buffer_s"), self.key)
        require_within(self, ("rate_hz",), RATE_RANGE_HZ, "Hz", self.key)
        require_within(self, ("buffer_s",), BUFFER_RANGE_S, "s", self.key)


class ShadowHand(_RosbridgeDevice, Hand):
    """Right Shadow Hand: trajectory commands out, joint states in, over rosbridge."""

    model = "Shadow Dexterous Hand (right) via rosbridge"

    def __init__(self, cfg: ShadowHandConfig, clock: Clock | None = None):
        self.cfg = cfg
        self._init_link(cfg.rosbridge, clock)
        self._states = _Stream(int(cfg.buffer_s * cfg.rate_hz))
        self._position = np.full(len(JOINT_NAMES), np.nan)
        self._target = np.full(len(JOINT_NAMES), np.nan)
        self._command = None
        self._seq = 0
        self.rejects = WireRejects()
        """Joint states refused as malformed (:mod:`hardware.wire`)."""

    @property
    def identity(self) -> DeviceIdentity:
        return DeviceIdentity(self.model, f"{self.rb_cfg.url}{self.cfg.command_topic}", "ROS (rosbridge v2)")

    def check_link(self) -> None:
        self._check_alive(self._states, self.cfg.state_topic)

    def wire_report(self) -> dict:
        return self.rejects.as_dict()

    def connect(self) -> None:
        """Open rosbridge, subscribe to joint states, advertise the command topic; wait for a state."""
        if self.conn is not None:
            return
        self.conn = RosbridgeConnection(self.rb_cfg, self.kind).open()
        try:
            self.conn.subscribe(self.cfg.state_topic, "sensor_msgs/JointState", self._on_state)
            self._command = self.conn.advertise(self.cfg.command_topic, "trajectory_msgs/JointTrajectory")
            self._await_first(self._states, self.cfg.first_state_timeout_s, self.cfg.state_topic)
        except Exception:
            self.close()
            raise
        known = ~np.isnan(self._position)
        self._target[known] = self._position[known]

    def positions(self) -> dict[str, float]:
        """Latest joint angles (rad) by name (joints never reported are absent)."""
        self._check_alive(self._states, self.cfg.state_topic)
        return {n: float(q) for n, q in zip(JOINT_NAMES, self._position) if not np.isnan(q)}

    def move_to(self, targets: dict[str, float], duration: float, wait: bool = True) -> None:
        """Move the named joints to ``targets`` (rad) in ``duration`` s along one trajectory point."""
        self._check_alive(self._states, self.cfg.state_topic)
        check_joint_names(targets, "targets")
        if not (isinstance(duration, (int, float)) and math.isfinite(duration) and duration >= 0):
            raise ValueError(f"duration: expected >= 0 s, got {duration!r}")
        goal = self._target.copy()
        for name, value in targets.items():
            if not math.isfinite(value):
                raise ValueError(f"targets[{name!r}]: expected a finite angle (rad), got {value!r}")
            goal[JOINT_INDEX[name]] = float(value)
        self._check_speed(targets, duration)
        self._publish(goal, duration)
        self._target = goal
        if wait:
            self._wait_arrival(targets, duration)

    def read_states(self) -> list[HandState]:
        self._check_alive(self._states, self.cfg.state_topic)
        return self._states.drain()

    # -- internals -----------------------------------------------------------------
    def _check_speed(self, targets: dict, duration: float) -> None:
        current = np.where(np.isnan(self._position), self._target, self._position)
        dq = max((abs(v - current[JOINT_INDEX[n]]) for n, v in targets.items() if not np.isnan(current[JOINT_INDEX[n]])),
                 default=0.0)
        vmax = self.cfg.max_velocity_rad_s
        if dq > vmax * max(duration, 1e-9):
            raise SafetyError(f"hand: moving {dq:.2f} rad in {duration} s exceeds "
                              f"{self.cfg.key}.max_velocity_rad_s={vmax}")

    def _publish(self, goal: np.ndarray, duration: float) -> None:
        import roslibpy

        joints = list(self.cfg.controller_joints)
        positions = [float(goal[JOINT_INDEX[j]]) if not np.isnan(goal[JOINT_INDEX[j]]) else 0.0 for j in joints]
        self._seq += 1
        self._command.publish(roslibpy.Message({
            "header": {"seq": self._seq, "stamp": {"secs": 0, "nsecs": 0}, "frame_id": ""},  # 0: start now
            "joint_names": joints,
            "points": [{"positions": positions, "velocities": [], "accelerations": [], "effort": [],
                        "time_from_start": ros_duration(max(duration, 0.01))}]}))

    def _wait_arrival(self, targets: dict, duration: float) -> None:
        self.clock.sleep(duration)
        idx = [JOINT_INDEX[n] for n in targets]
        want = np.array([targets[n] for n in targets])
        end = self.clock.now() + self.cfg.arrival_timeout_s
        while True:
            self._check_alive(self._states, self.cfg.state_topic)
            err = np.abs(self._position[idx] - want)
            if np.all(err <= self.cfg.arrival_tolerance_rad):
                return
            if self.clock.now() > end:
                worst = idx[int(np.nanargmax(err))]
                raise DeviceTimeoutError(f"hand: {JOINT_NAMES[worst]} is {np.nanmax(err):.3f} rad from its target "
                                         f"{self.cfg.arrival_timeout_s} s after the trajectory's end "
                                         f"({self.cfg.key}.arrival_tolerance_rad={self.cfg.arrival_tolerance_rad})")
            self.clock.sleep(0.01)

    def _on_state(self, msg) -> None:
        host = self.clock.now()
        try:
            pos, stamp = self._decode_state(msg)
        except WireError as exc:                  # refused, counted, the stream goes on (hardware.wire)
            self.rejects.add(exc)
            return
        self._position = pos
        self._states.push(HandState(host, stamp, pos, self._target.copy()), host)

    def _decode_state(self, msg) -> tuple[np.ndarray, float]:
        """A ``JointState`` → (joint positions (rad) with this message's joints updated, stamp s)."""
        names = msg.get("name") if isinstance(msg, dict) else None
        values = msg.get("position") if isinstance(msg, dict) else None
        if not isinstance(names, list) or not isinstance(values, list) or len(names) != len(values):
            raise WireError("joint state: not names and positions of one length",
                            f"joint state: name {_brief(names)}, position {_brief(values)}")
        pos = self._position.copy()
        for name, q in zip(names, values):
            i = JOINT_INDEX.get(name) if isinstance(name, str) else None
            if i is None:
                continue
            if isinstance(q, bool) or not isinstance(q, (int, float)) or not math.isfinite(q):
                raise WireError("joint state: position not a finite number", f"{name}: got {_brief(q)} rad")
            pos[i] = q
        header = msg.get("header") if isinstance(msg.get("header"), dict) else {}
        try:
            stamp = stamp_seconds(header.get("stamp") if isinstance(header.get("stamp"), dict) else {})
        except (TypeError, ValueError):
            raise WireError("header: not a stamp", f"header: got {_brief(header)}") from None
        return pos, stamp


# ============================================================================ BioTacs
@dataclass
class RosbridgeBiotacConfig:
    """BioTacs published by Shadow's driver on ``/rh/tactile`` (``sr_robot_msgs/BiotacAll``).

    Attributes:
        rosbridge: where rosbridge listens.
        topic: the BiotacAll topic.
        fingers: the fingers to record (Shadow order); each must have a connected sensor.
        rate_hz: nominal frame rate (Hz). buffer_s: seconds of frames buffered.
        first_frame_timeout_s: ``connect()`` fails without a frame within this (s).
    """

    rosbridge: RosbridgeConfig = field(default_factory=RosbridgeConfig)
    topic: str = "/rh/tactile"
    fingers: tuple[str, ...] = FINGERS
    rate_hz: float = 100.0
    buffer_s: float = 120.0
    first_frame_timeout_s: float = 2.0
    key: str = field(default="hardware.biotac", repr=False)

    def __post_init__(self):
        self.fingers = check_fingers(self.fingers, f"{self.key}.fingers")
        require_positive(self, ("rate_hz", "buffer_s", "first_frame_timeout_s"), self.key)
        require_within(self, ("rate_hz",), RATE_RANGE_HZ, "Hz", self.key)
        require_within(self, ("buffer_s",), BUFFER_RANGE_S, "s", self.key)


class RosbridgeBiotacs(_RosbridgeDevice, TactileSensors):
    """BioTac SP frames from the Shadow Hand's driver over rosbridge."""

    model = "BioTac SP via Shadow driver (rosbridge)"

    def __init__(self, cfg: RosbridgeBiotacConfig, clock: Clock | None = None):
        self.cfg = cfg
        self._init_link(cfg.rosbridge, clock)
        self._frames = _Stream(int(cfg.buffer_s * cfg.rate_hz))
        self._rows = [FINGERS.index(f) for f in cfg.fingers]
        self._count = 0
        self.unconnected: set[str] = set()
        """Fingers seen reading ``pdc = -22072`` (no sensor) in any frame so far."""
        self.rejects = WireRejects()
        """Messages refused as malformed (:mod:`hardware.wire`)."""

    @property
    def fingers(self) -> tuple[str, ...]:
        return self.cfg.fingers

    @property
    def rate_hz(self) -> float:
        return self.cfg.rate_hz

    @property
    def overflows(self) -> int:
        return self._frames.overflows

    @property
    def identity(self) -> DeviceIdentity:
        return DeviceIdentity(self.model, f"{self.rb_cfg.url}{self.cfg.topic}", "sr_robot_msgs/BiotacAll")

    def connect(self) -> None:
        """Open rosbridge, subscribe, wait for a frame; refuse configured fingers without a sensor."""
        if self.conn is not None:
            return
        self.conn = RosbridgeConnection(self.rb_cfg, self.kind).open()
        try:
            self.conn.subscribe(self.cfg.topic, "sr_robot_msgs/BiotacAll", self._on_frame)
            self._await_first(self._frames, self.cfg.first_frame_timeout_s, self.cfg.topic)
            self._check_fingers()
        except Exception:
            self.close()
            raise

    def read(self) -> list[BiotacFrame]:
        self._check_alive(self._frames, self.cfg.topic)
        return self._frames.drain()

    def latest(self) -> BiotacFrame | None:
        self._check_alive(self._frames, self.cfg.topic)
        return self._frames.latest

    def check_link(self) -> None:
        self._check_alive(self._frames, self.cfg.topic)

    def wire_report(self) -> dict:
        return self.rejects.as_dict()

    @property
    def malformed(self) -> int:
        """Messages refused so far (``rejects.total``)."""
        return self.rejects.total

    # -- internals -----------------------------------------------------------------
    def _check_fingers(self) -> None:
        asked = [f for f in self.cfg.fingers if f in self.unconnected]
        others = sorted(self.unconnected - set(asked), key=FINGERS.index)
        if others:
            log.info("biotac: no sensor on %s (pdc=%d); not configured, ignored", others, UNCONNECTED_PDC)
        if asked:
            raise DeviceFaultError(f"{self.kind}: finger(s) {asked} in {self.cfg.key}.fingers have no sensor "
                                   f"connected (pdc={UNCONNECTED_PDC}, zeros on {self.cfg.topic}); remove them "
                                   f"from {self.cfg.key}.fingers or connect the sensors")

    def _on_frame(self, msg: dict) -> None:
        host = self.clock.now()
        try:
            frame = self._decode(msg, host)
        except WireError as exc:                  # refused, counted, the stream goes on (hardware.wire)
            self.rejects.add(exc)
            return
        self._frames.push(frame, host)
        self._publish(frame)

    def _decode(self, msg, host: float) -> BiotacFrame:
        """A ``BiotacAll`` message → a frame of the configured fingers; :class:`WireError` for a
        message that is not one (a field missing or of the wrong type, a count that does not fit
        16 bits). Counts outside 0..4095 that fit are kept: the frame is then invalid."""
        tactiles = msg.get("tactiles") if isinstance(msg, dict) else None
        if not isinstance(tactiles, list) or len(tactiles) <= max(self._rows):
            raise WireError("tactiles: not a list of the fingers' readings",
                            f"tactiles: got {_brief(tactiles)}; expected a list of {len(FINGERS)} Biotac readings")
        for i, t in enumerate(tactiles[:len(FINGERS)]):
            if isinstance(t, dict) and t.get("pdc") == UNCONNECTED_PDC:
                self.unconnected.add(FINGERS[i])
        F = len(self._rows)
        electrodes = np.zeros((F, N_TAXELS), np.int16)
        channels = {name: np.zeros(F, np.int32) for name in ("pdc", "tdc", "tac")}
        pacs = []
        for k, r in enumerate(self._rows):
            t, who = tactiles[r], FINGERS[r]
            if not isinstance(t, dict):
                raise WireError("tactiles: a reading is not a mapping", f"tactiles[{r}] ({who}): got {_brief(t)}")
            e = counts(t.get("electrodes") or [], f"{who} electrodes")
            if e.ndim != 1 or len(e) > N_TAXELS:
                raise WireError("electrodes: not a list of counts",
                                f"{who} electrodes: got {len(e)} values; expected {N_TAXELS}")
            electrodes[k, :len(e)] = e
            for name in channels:
                if name not in t:
                    raise WireError(f"{name}: missing", f"{who}: no {name}")
                channels[name][k] = counts(t[name], f"{who} {name}")
            pac = t.get("pac") or [t.get("pac0"), t.get("pac1")]
            pacs.append(counts(pac, f"{who} pac"))
        n_pac = min(len(p) for p in pacs)
        header = msg.get("header") if isinstance(msg.get("header"), dict) else {}
        stamp = header.get("stamp") if isinstance(header.get("stamp"), dict) else {}
        seq = header.get("seq", self._count + 1)
        try:
            device_time, seq = stamp_seconds(stamp), int(seq)
        except (TypeError, ValueError):
            raise WireError("header: not a stamp and a sequence number", f"header: got {_brief(header)}") from None
        self._count += 1
        return BiotacFrame(seq=seq, device_time=device_time, host_time=host, electrodes=electrodes,
                           pdc=channels["pdc"], tdc=channels["tdc"], tac=channels["tac"],
                           pac=np.array([p[:n_pac] for p in pacs], np.int16))

"""UR10 arm driver over ur_rtde (RTDE control, receive and dashboard clients).

A drop-in :class:`~hardware.arm.Arm` for the run engine: same units as ur_rtde (m, m/s,
m/s², rad, N). ur_rtde reports many failures by returning ``False``; every command here
turns that into a typed error (:class:`ProtectiveStopError`, :class:`EmergencyStopError`,
:class:`DeviceDisconnectedError`, :class:`DeviceTimeoutError`, :class:`DeviceFaultError`).

Threads: a stream thread polls the receive interface once per controller period and
buffers one :class:`ArmState` per new controller timestamp (``read_states()`` drains it),
detects a lost link (connection closed, or no new sample for ``stale_timeout_s``) and
supervises speed motions (duration, workspace guard). Control-interface calls are
serialised by a lock. Blocking moves are sent asynchronously and awaited here, with a
deadline, so that a controller that dies mid-move cannot hang the caller (ur_rtde's own
blocking ``moveL`` waits up to 300 s on a stale state).
"""

from __future__ import annotations

import math
import socket
import struct
import threading
import time
from dataclasses import dataclass, field

import numpy as np

from .arm import Arm, ArmState, Workspace, trapezoid_time
from .device import DeviceIdentity, SampleBuffer, WallClock
from .errors import (ConfigError, DeviceDisconnectedError, DeviceFaultError, DeviceTimeoutError,
                     EmergencyStopError, NotConnectedError, ProtectiveStopError, SafetyError)

RECEIVE_VARIABLES = ["timestamp", "actual_TCP_pose", "actual_TCP_speed", "actual_TCP_force",
                     "safety_status_bits", "safety_mode", "runtime_state", "robot_mode", "robot_status_bits"]
HINT = ("check that the controller is powered on and booted, the address (hardware.arm.host), "
        "the network link, and (e-series) that the robot is in Remote Control")


@dataclass
class UR10Config:
    """How to reach the robot and what it may do.

    Attributes:
        host: controller IP address.
        rtde_frequency_hz: RTDE/control rate; None: from the controller (125 CB3, 500 e-series).
        connect_timeout_s: bound on reaching each port and on the RTDE handshake (s).
        stale_timeout_s: no new RTDE sample for this long means the link is lost (s).
        move_timeout_margin_s: a blocking move may take its planned duration plus this (s).
        recover_timeout_s: bound on unlock + script restart (a UR refuses unlock for 5 s).
        workspace: box the TCP must stay in (m).
        max_speed_m_s, max_accel_m_s2: limits on every commanded TCP speed and acceleration.
        max_force_n: limit on the force commanded in force mode (N).
        dashboard_port, rtde_port, script_port: checked before connecting (ur_rtde fixes them).
        buffer_s: seconds of samples kept for ``read_states()`` (oldest dropped, counted).
        key: config key quoted in errors.
    """

    host: str = "192.168.1.10"
    rtde_frequency_hz: float | None = None
    connect_timeout_s: float = 3.0
    stale_timeout_s: float = 1.0
    move_timeout_margin_s: float = 5.0
    recover_timeout_s: float = 10.0
    workspace: Workspace = field(default_factory=Workspace)
    max_speed_m_s: float = 0.25
    max_accel_m_s2: float = 1.5
    max_force_n: float = 50.0
    dashboard_port: int = 29999
    rtde_port: int = 30004
    script_port: int = 30003
    buffer_s: float = 60.0
    key: str = "hardware.arm"

    def __post_init__(self):
        for name in ("connect_timeout_s", "stale_timeout_s", "move_timeout_margin_s", "recover_timeout_s",
                     "max_speed_m_s", "max_accel_m_s2", "max_force_n", "buffer_s"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ConfigError(f"{self.key}.{name}", f"expected a positive number, got {v!r}")
        if self.rtde_frequency_hz is not None and not 0 < self.rtde_frequency_hz <= 500:
            raise ConfigError(f"{self.key}.rtde_frequency_hz", f"expected (0, 500] Hz or null, "
                                                               f"got {self.rtde_frequency_hz!r}")
        if not isinstance(self.host, str) or not self.host:
            raise ConfigError(f"{self.key}.host", f"expected an IP address, got {self.host!r}")

    @classmethod
    def from_mapping(cls, arm: dict, workspace: dict | None = None, key: str = "hardware.arm") -> "UR10Config":
        """Build from plain config mappings (e.g. Hydra's ``hardware.arm`` and ``hardware.workspace``)."""
        arm = dict(arm)
        unknown = set(arm) - set(cls.__dataclass_fields__) - {"workspace"}
        if unknown:
            from tactile_flow.validation import unknown_key
            raise unknown_key(key, sorted(unknown)[0], set(cls.__dataclass_fields__) - {"key"} | {"workspace"})
        ws = workspace if workspace is not None else arm.pop("workspace", None)
        arm.pop("workspace", None)
        if ws is not None:
            arm["workspace"] = Workspace(list(ws["min_m"]), list(ws["max_m"]), key="hardware.workspace")
        return cls(key=key, **arm)


def _recv_exact(sock, n) -> bytes:
    buf = b""
    while len(buf) < n:
        chunk = sock.recv(n - len(buf))
        if not chunk:
            raise ConnectionError("connection closed")
        buf += chunk
    return buf


class UR10Arm(Arm):
    """A UR10 (CB3 or e-series) driven through ur_rtde. See the module docstring."""

    kind = "arm"

    def __init__(self, config: UR10Config, clock=None):
        self.cfg = config
        self.clock = clock or WallClock()
        self.workspace = config.workspace
        self._c = self._r = self._dash = None
        self._lock = threading.RLock()              # serialises control-interface calls
        self._buffer = SampleBuffer(config.buffer_s * 125.0)      # resized at connect to the RTDE rate
        self._stream: threading.Thread | None = None
        self._stop_stream = threading.Event()
        self._connected = False
        self._lost: str | None = None
        self._mode = "idle"                          # idle | move | speed | servo | force
        self._speed_deadline: tuple[float, float] | None = None   # (host time, decel)
        self._last_state: ArmState | None = None
        self.controller_version: tuple = ()
        self.frequency_hz = 125.0
        self.faults: list[str] = []                  # what the supervisor did (workspace guard...)

    # ------------------------------------------------------------------ connection
    @property
    def is_connected(self) -> bool:
        return self._connected and self._lost is None

    @property
    def identity(self) -> DeviceIdentity:
        v = ".".join(str(x) for x in self.controller_version) or "unknown"
        return DeviceIdentity("UR10", self.cfg.host, f"URControl {v}; ur_rtde {_ur_rtde_version()}")

    def connect(self) -> None:
        """Check the controller answers, then open the ur_rtde interfaces and start streaming.

        Raises DeviceTimeoutError (unreachable, naming the address) within about
        ``3 × connect_timeout_s``; DeviceFaultError if ur_rtde refuses to start.
        """
        if self.is_connected:
            return
        self.close()
        self.controller_version = self._preflight()
        major = self.controller_version[0]
        self.frequency_hz = self.cfg.rtde_frequency_hz or (500.0 if major >= 5 else 125.0)
        self._buffer.maxlen = self.cfg.buffer_s * self.frequency_hz
        import dashboard_client
        import rtde_control
        import rtde_receive
        host = self.cfg.host
        try:
            self._r = rtde_receive.RTDEReceiveInterface(host, self.frequency_hz, RECEIVE_VARIABLES)
            self._c = rtde_control.RTDEControlInterface(host, self.frequency_hz)
            self._dash = dashboard_client.DashboardClient(host, self.cfg.dashboard_port)
            self._dash.connect(int(self.cfg.connect_timeout_s * 1000))
        except RuntimeError as exc:
            self.close()
            raise DeviceFaultError(f"arm: ur_rtde could not start on the UR controller at {host}: {exc}") from exc
        self._lost, self._mode, self._connected = None, "idle", True
        self._stop_stream.clear()
        self._stream = threading.Thread(target=self._stream_loop, name="ur10-stream", daemon=True)
        self._stream.start()

    def _preflight(self) -> tuple:
        """Every port reachable and the RTDE server answering, each within the connect timeout.

        ur_rtde's constructors block without a deadline (and hold the GIL) on a silent
        controller; this bounded check runs first so an unreachable robot fails fast.
        """
        c, t = self.cfg, self.cfg.connect_timeout_s
        for port, what in ((c.dashboard_port, "dashboard"), (c.rtde_port, "RTDE"), (c.script_port, "script")):
            try:
                socket.create_connection((c.host, port), timeout=t).close()
            except OSError as exc:
                reason = "timed out" if isinstance(exc, socket.timeout) else (exc.strerror or str(exc))
                raise DeviceTimeoutError(f"arm: UR controller at {c.host} not reachable on the {what} port "
                                         f"{port} ({reason}, timeout {t:g} s): {HINT}") from exc
        try:
            with socket.create_connection((c.host, c.rtde_port), timeout=t) as s:
                s.sendall(struct.pack(">HBH", 5, 86, 2))             # request protocol version 2
                size, kind = struct.unpack(">HB", _recv_exact(s, 3))
                accepted = _recv_exact(s, size - 3)
                s.sendall(struct.pack(">HB", 3, 118))                # controller version
                size, kind2 = struct.unpack(">HB", _recv_exact(s, 3))
                version = struct.unpack(">IIII", _recv_exact(s, size - 3)[:16])
        except (OSError, ConnectionError, struct.error) as exc:
            raise DeviceTimeoutError(f"arm: the RTDE server of the UR controller at {c.host}:{c.rtde_port} "
                                     f"did not answer the handshake within {t:g} s ({exc}): {HINT}") from exc
        if kind != 86 or not accepted or not accepted[0] or kind2 != 118:
            raise DeviceFaultError(f"arm: the controller at {c.host}:{c.rtde_port} refused RTDE protocol "
                                   f"version 2 (PolyScope too old?)")
        return version

    def close(self) -> None:
        """Stop the control script (the arm decelerates) and release every interface."""
        self._stop_stream.set()
        if self._stream is not None and self._stream is not threading.current_thread():
            self._stream.join(timeout=2.0)
        self._stream = None
        if self._c is not None and self._lost is None:
            try:
                with self._lock:
                    self._c.stopScript()
            except RuntimeError:
                pass
        for iface in (self._c, self._r, self._dash):
            if iface is not None:
                try:
                    iface.disconnect()
                except RuntimeError:
                    pass
        self._c = self._r = self._dash = None
        self._connected = False

    # ------------------------------------------------------------------ streaming
    def _stream_loop(self) -> None:
        period = 1.0 / self.frequency_hz
        last_ts, last_new = None, time.monotonic()
        while not self._stop_stream.is_set():
            try:
                if not self._r.isConnected():
                    self._lose("the RTDE connection was closed by the controller")
                    return
                ts = self._r.getTimestamp()
                now = time.monotonic()
                if ts != last_ts:
                    last_ts, last_new = ts, now
                    self._push(self._sample(ts))
                    self._supervise()
                elif now - last_new > self.cfg.stale_timeout_s:
                    self._lose(f"no RTDE data for {self.cfg.stale_timeout_s:g} s")
                    return
            except RuntimeError as exc:
                self._lose(f"RTDE receive failed: {exc}")
                return
            self._stop_stream.wait(period / 2)

    def _sample(self, ts: float) -> ArmState:
        r = self._r
        return ArmState(self.clock.now(), float(ts), np.array(r.getActualTCPPose()),
                        np.array(r.getActualTCPSpeed()), np.array(r.getActualTCPForce()),
                        bool(r.isProtectiveStopped()))

    def _push(self, state: ArmState) -> None:
        self._buffer.put(state)
        self._last_state = state

    def _lose(self, why: str) -> None:
        self._lost = f"arm: link to the UR controller at {self.cfg.host} lost: {why}"

    def _supervise(self) -> None:
        """Speed motions: end them after their duration; stop any motion leaving the workspace."""
        s = self._last_state
        if self._mode == "speed" and self._speed_deadline and self.clock.now() >= self._speed_deadline[0]:
            self._safe_stop(self._speed_deadline[1], "speedL duration elapsed")
        if self._mode in ("speed", "servo", "force") and not self.workspace.contains(s.tcp_pose):
            self.faults.append(f"workspace guard: TCP {np.round(s.tcp_pose[:3], 4).tolist()} left "
                               f"{self.workspace.key}; stopped")
            self._safe_stop(self.cfg.max_accel_m_s2, "workspace guard")

    def _safe_stop(self, decel: float, why: str) -> None:
        try:
            self.stop(decel)
        except Exception as exc:  # the supervisor must not die; the next call reports the fault
            self.faults.append(f"{why}: stop failed: {exc}")

    # ------------------------------------------------------------------ state
    def check_link(self) -> None:
        """The RTDE stream's verdict (a closed connection, no new sample for ``stale_timeout_s``)."""
        self._require_link()

    def _require_link(self) -> None:
        if self._lost is not None:
            raise DeviceDisconnectedError(self._lost)
        if not self._connected:
            raise NotConnectedError("arm: not connected (call connect() first)")

    def _require_ready(self) -> None:
        """Connected, streaming and free to move, else the typed reason why not."""
        self._require_link()
        if self._r.isEmergencyStopped():
            raise EmergencyStopError(f"arm: emergency stop engaged on the UR controller at {self.cfg.host}")
        if self._r.isProtectiveStopped():
            raise ProtectiveStopError("arm: protective stop active; inspect the cause, then call recover()")
        if not self._c.isProgramRunning():
            raise DeviceFaultError("arm: the ur_rtde control script is not running on the controller "
                                   "(stopped from the pendant or dashboard?); call recover()")

    def tcp_pose(self) -> np.ndarray:
        self._require_link()
        return np.array(self._r.getActualTCPPose())

    def tcp_wrench(self) -> np.ndarray:
        self._require_link()
        return np.array(self._r.getActualTCPForce())

    def tcp_speed(self) -> np.ndarray:
        """(6,) TCP velocity (m/s, rad/s)."""
        self._require_link()
        return np.array(self._r.getActualTCPSpeed())

    def controller_time(self) -> float:
        self._require_link()
        return float(self._r.getTimestamp())

    def safety_mode(self) -> int:
        """The controller's safety mode (1 normal, 3 protective stop, 7 robot e-stop...)."""
        self._require_link()
        return int(self._r.getSafetyMode())

    def is_protective_stopped(self) -> bool:
        self._require_link()
        return bool(self._r.isProtectiveStopped())

    def is_emergency_stopped(self) -> bool:
        self._require_link()
        return bool(self._r.isEmergencyStopped())

    def is_moving(self) -> bool:
        """An async operation is running, or the TCP moves faster than 0.1 mm/s."""
        self._require_link()
        if self._r.isProtectiveStopped():
            return False
        with self._lock:
            running = self._c.isProgramRunning() and self._c.getAsyncOperationProgressEx().isAsyncOperationRunning()
        return running or float(np.linalg.norm(self._r.getActualTCPSpeed()[:3])) > 1e-4

    @property
    def overflows(self) -> int:
        """Samples lost to a full buffer (a consumer that did not drain for ``buffer_s``)."""
        return self._buffer.overflows

    def read_states(self) -> list[ArmState]:
        self._require_link()
        return self._buffer.drain()

    # ------------------------------------------------------------------ command plumbing
    def _command(self, name: str, fn, *args):
        """Call a control-interface method; ``False`` or an exception becomes a typed error."""
        with self._lock:
            try:
                ok = fn(*args)
            except RuntimeError as exc:
                self._lose(f"{name}: {exc}")
                raise DeviceDisconnectedError(self._lost) from exc
        if ok is False:
            self._raise_refused(name)
        return ok

    def _raise_refused(self, name: str) -> None:
        if not self._r.isConnected() or not self._c.isConnected():
            self._lose(f"{name} failed and the RTDE connection is down")
            raise DeviceDisconnectedError(self._lost)
        if self._r.isEmergencyStopped():
            raise EmergencyStopError(f"arm: {name} refused: emergency stop engaged")
        if self._r.isProtectiveStopped():
            raise ProtectiveStopError(f"arm: {name} refused: protective stop; inspect the cause, then recover()")
        if not self._c.isProgramRunning():
            raise DeviceFaultError(f"arm: {name} refused: the control script is not running; call recover()")
        raise DeviceFaultError(f"arm: {name} returned False (controller not ready for a command within 3 s)")

    def check_pose(self, pose) -> None:
        """Raise WorkspaceError (naming the config key) if ``pose`` is outside the workspace."""
        self.workspace.check(pose, "pose")

    def _checked_pose(self, pose, what="pose") -> np.ndarray:
        p = np.asarray(pose, float)
        self.workspace.check(p, what)
        return p

    def _check_motion(self, speed: float, accel: float) -> None:
        c = self.cfg
        if not 0 < speed <= c.max_speed_m_s:
            raise SafetyError(f"arm: speed {speed} m/s outside (0, {c.key}.max_speed_m_s={c.max_speed_m_s}]")
        if not 0 < accel <= c.max_accel_m_s2:
            raise SafetyError(f"arm: accel {accel} m/s² outside (0, {c.key}.max_accel_m_s2={c.max_accel_m_s2}]")

    # ------------------------------------------------------------------ motion
    def move_linear(self, pose, speed: float = 0.05, accel: float = 0.5, asynchronous: bool = False) -> None:
        """``moveL`` to ``pose`` (m, rad) at ``speed`` m/s, ``accel`` m/s².

        Blocking: returns on arrival; raises ProtectiveStopError if the arm stops on the
        way, DeviceTimeoutError (after stopping it) if it has not arrived within the
        planned duration + ``move_timeout_margin_s``.
        """
        target = self._checked_pose(pose, "moveL target")
        self._check_motion(speed, accel)
        self._require_ready()
        self._end_continuous_mode()
        start = self.tcp_pose()
        self._command("moveL", self._c.moveL, target.tolist(), float(speed), float(accel), True)
        self._mode = "move"
        if not asynchronous:
            dist = float(np.linalg.norm(target[:3] - start[:3]))
            self.wait_until_stopped(trapezoid_time(dist, speed, accel) + self.cfg.move_timeout_margin_s)

    def wait_until_stopped(self, timeout_s: float | None = None) -> None:
        """Block until the current motion ends (typed errors on a stop or a lost link)."""
        deadline = time.monotonic() + (timeout_s if timeout_s is not None else 3600.0)
        period = 1.0 / self.frequency_hz
        while True:
            self._require_link()
            if self._r.isProtectiveStopped():
                raise ProtectiveStopError(f"arm: protective stop during a move at "
                                          f"{np.round(self.tcp_pose()[:3], 4).tolist()} m")
            if not self.is_moving():
                self._mode = "idle" if self._mode == "move" else self._mode
                return
            if time.monotonic() > deadline:
                self._safe_stop(self.cfg.max_accel_m_s2, "move timeout")
                raise DeviceTimeoutError(f"arm: move not finished within {timeout_s:.2f} s; stopped")
            time.sleep(period)

    def speed_linear(self, velocity, accel: float = 0.5, duration: float = 0.0) -> None:
        """``speedL``: TCP ``velocity`` (6,) m/s, rad/s; for ``duration`` s (0: until stop()).

        The stream thread stops the arm after ``duration`` and if it leaves the workspace.
        """
        vel = np.asarray(velocity, float)
        if vel.shape != (6,) or not np.all(np.isfinite(vel)):
            raise ValueError(f"velocity: expected 6 finite numbers (m/s, rad/s), got {velocity!r}")
        if not duration >= 0:
            raise ValueError(f"duration: expected >= 0 s, got {duration}")
        speed = float(np.linalg.norm(vel[:3]))
        self._check_motion(max(speed, 1e-9), accel)
        self._require_ready()
        if duration > 0:                                  # where it comes to rest must be allowed
            end = self.tcp_pose().copy()
            end[:3] += vel[:3] * (duration + speed / (2 * accel) + speed / (2 * self.cfg.max_accel_m_s2))
            self.workspace.check(end, "speedL end point")
        if self._mode not in ("speed", "idle", "move"):
            self._end_continuous_mode()
        self._command("speedL", self._c.speedL, vel.tolist(), float(accel), 0.0)
        self._mode = "speed"
        self._speed_deadline = (self.clock.now() + duration, float(accel)) if duration > 0 else None

    def servo_linear(self, pose, time_s: float, lookahead_s: float = 0.1, gain: float = 300.0) -> None:
        """``servoL`` one set point (m, rad) to be reached in ``time_s`` s; call once per period."""
        target = self._checked_pose(pose, "servoL target")
        self._require_link()
        self._command("servoL", self._c.servoL, target.tolist(), 0.0, 0.0, float(time_s),
                      float(lookahead_s), float(gain))
        self._mode = "servo"

    def servo_sweep(self, target, speed: float, lookahead_s: float = 0.1) -> None:
        """Constant-speed straight sweep to ``target`` by ``servoL`` set points, one per period.

        Blocks; ends with ``servoStop``. Raises like :meth:`move_linear`.
        """
        goal = self._checked_pose(target, "servo sweep target")
        self._check_motion(speed, self.cfg.max_accel_m_s2)
        self._require_ready()
        self._end_continuous_mode()
        start = self.tcp_pose()
        dt = 1.0 / self.frequency_hz
        duration = float(np.linalg.norm(goal[:3] - start[:3])) / speed
        settle = 4 * lookahead_s                     # hold the goal while the servo catches up
        t0 = time.monotonic()

        def step(k):
            # set points follow the host clock, so a late cycle does not slow the sweep down
            t = time.monotonic() - t0
            self.servo_linear(start + (goal - start) * min(1.0, t / duration), dt, lookahead_s)
            return t < duration + settle

        try:
            self.control_loop(step)
        finally:
            self.stop(self.cfg.max_accel_m_s2)

    def control_loop(self, step, max_cycles: int | None = None) -> int:
        """Call ``step(k)`` once per controller period (``initPeriod``/``waitPeriod``).

        Stops when ``step`` returns a false value or after ``max_cycles``; checks the
        protective stop and the link every cycle. Returns the number of cycles run.
        """
        k = 0
        while max_cycles is None or k < max_cycles:
            t0 = self._c.initPeriod()
            if self._r.isProtectiveStopped():
                raise ProtectiveStopError("arm: protective stop during a control loop")
            self._require_link()
            more = step(k)
            k += 1
            if not more:
                break
            self._c.waitPeriod(t0)
        return k

    def force_mode(self, task_frame, selection, wrench, limits, mode_type: int = 2) -> None:
        """``forceMode``: compliant along ``selection`` axes of ``task_frame`` (pose, m, rad).

        ``wrench`` (6,) N, N·m the tool applies to the environment on compliant axes;
        ``limits`` (6,) max TCP speed (m/s, rad/s) on compliant axes, deviation (m, rad)
        on the others. Refuses forces above ``max_force_n`` and speeds above ``max_speed_m_s``.
        """
        frame = self._checked_pose(task_frame, "force task frame") if np.any(task_frame) else \
            np.asarray(task_frame, float)
        sel, w, lim = (np.asarray(x, dtype) for x, dtype in ((selection, int), (wrench, float), (limits, float)))
        if sel.shape != (6,) or w.shape != (6,) or lim.shape != (6,) or not np.all(np.isfinite(w)):
            raise ValueError("force_mode: selection, wrench and limits need 6 values each")
        if np.linalg.norm(w[:3]) > self.cfg.max_force_n:
            raise SafetyError(f"arm: force {np.linalg.norm(w[:3]):.1f} N above {self.cfg.key}.max_force_n="
                              f"{self.cfg.max_force_n}")
        if np.any(lim[:3][sel[:3] == 1] > self.cfg.max_speed_m_s):
            raise SafetyError(f"arm: force-mode speed limit above {self.cfg.key}.max_speed_m_s")
        self._require_ready()
        self._command("forceMode", self._c.forceMode, frame.tolist(), sel.tolist(), w.tolist(), int(mode_type),
                      lim.tolist())
        self._mode = "force"

    def force_mode_stop(self) -> None:
        self._require_link()
        self._command("forceModeStop", self._c.forceModeStop)
        self._mode = "idle"

    def zero_ft_sensor(self) -> None:
        """Zero the force/torque reading (``zeroFtSensor``): do it out of contact."""
        self._require_ready()
        self._command("zeroFtSensor", self._c.zeroFtSensor)

    def stop(self, accel: float = 2.0) -> None:
        """Decelerate at ``accel`` m/s²: ``speedStop``/``servoStop`` after those modes, else async ``stopL``."""
        self._require_link()
        if self._r.isProtectiveStopped() or not self._c.isProgramRunning():
            return                                        # already at rest; the script cannot take commands
        accel = float(min(max(accel, 1e-3), self.cfg.max_accel_m_s2 * 10))
        mode, self._speed_deadline = self._mode, None
        if mode == "speed":
            self._command("speedStop", self._c.speedStop, accel)
        elif mode == "servo":
            self._command("servoStop", self._c.servoStop, accel)
        elif mode == "force":
            self._command("forceModeStop", self._c.forceModeStop)
        else:
            with self._lock:
                try:
                    self._c.stopL(accel, True)
                except RuntimeError as exc:
                    self._lose(f"stopL: {exc}")
                    raise DeviceDisconnectedError(self._lost) from exc
        self._mode = "idle"

    def _end_continuous_mode(self) -> None:
        if self._mode in ("speed", "servo", "force"):
            self.stop(self.cfg.max_accel_m_s2)

    # ------------------------------------------------------------------ recovery
    def recover(self) -> None:
        """Clear a protective stop: close the popup, unlock (retried until the controller's
        5 s wait is over), re-upload the control script and wait until it runs.

        Raises DeviceTimeoutError if this takes longer than ``recover_timeout_s``.
        """
        self._require_link()
        deadline = time.monotonic() + self.cfg.recover_timeout_s
        if self._r.isProtectiveStopped():
            self._dashboard("close safety popup", self._dash.closeSafetyPopup)
            refusal = ""
            while self._r.isProtectiveStopped():
                try:
                    self._dash.unlockProtectiveStop()
                except RuntimeError as exc:           # "Cannot unlock ... until 5s after occurrence": retry
                    refusal = str(exc)
                    if "cannot unlock" not in refusal.lower():
                        raise DeviceFaultError(f"arm: dashboard at {self.cfg.host}:{self.cfg.dashboard_port} "
                                               f"refused to unlock the protective stop: {exc}") from exc
                self._wait_for(lambda: not self._r.isProtectiveStopped(), min(0.25, self._left(deadline)))
                if time.monotonic() > deadline:
                    raise DeviceTimeoutError(f"arm: protective stop not released within "
                                             f"{self.cfg.recover_timeout_s:g} s ({refusal or 'no refusal'})")
        with self._lock:
            if not self._c.isProgramRunning():
                if not self._c.reuploadScript():
                    raise DeviceFaultError("arm: could not re-upload the ur_rtde control script")
        if not self._wait_for(self._c.isProgramRunning, self._left(deadline)):
            raise DeviceTimeoutError(f"arm: control script not running within {self.cfg.recover_timeout_s:g} s "
                                     f"after re-upload (dashboard: {self._dash.programState()!r})")
        self._mode = "idle"

    def _dashboard(self, what: str, fn):
        try:
            return fn()
        except RuntimeError as exc:
            raise DeviceFaultError(f"arm: dashboard command {what!r} failed at {self.cfg.host}:"
                                   f"{self.cfg.dashboard_port}: {exc}") from exc

    @staticmethod
    def _left(deadline: float) -> float:
        return max(0.0, deadline - time.monotonic())

    def _wait_for(self, predicate, timeout_s: float) -> bool:
        end = time.monotonic() + timeout_s
        while True:
            self._require_link()
            if predicate():
                return True
            if time.monotonic() >= end:
                return False
            time.sleep(0.01)


def _ur_rtde_version() -> str:
    try:
        from importlib.metadata import version
        return version("ur_rtde")
    except Exception:
        return "unknown"

"""Emulator of a UR controller (CB3 UR10 by default) for ur_rtde, on loopback.

What ur_rtde talks to on a real robot, rebuilt from the protocols (no ur_rtde code):

- **RTDE** on 30004 (:mod:`hardware.emulators.ur_wire`): protocol version, controller
  version, output and input recipe setup (``NOT_FOUND`` for unknown variables, ``IN_USE``
  for an input another client owns), start/pause, data packages at the recipe frequency
  (one per control period of ``1/frequency_hz`` s), input packages written into the
  controller's input registers.
- **Dashboard server** on 29999: the text commands ur_rtde's ``DashboardClient`` and a
  recovery use (``unlock protective stop``, ``close safety popup``, ``play``, ``stop``,
  ``programState``, ``robotmode``, ``safetymode``, ``safetystatus``, ``PolyscopeVersion``...),
  answered with the real controller's strings.
- **Script port** 30003: accepts URScript programs. The ``rtde_control`` program that
  ur_rtde uploads is not interpreted as text: its register handshake is emulated in Python
  (:class:`_ControlScript`): the client writes a command id into ``input_int_register_0``
  (arguments in the other input registers), the script answers 1 (ready) / 2 (done) in
  ``output_int_register_0``, async progress in ``output_int_register_2``.
- Motion: :class:`hardware.emulators.ur_motion.Kinematics` (Cartesian only, no joints).
- Faults: a protective stop at a given time, on demand (:meth:`trigger_protective_stop`,
  SIGUSR1 to the process, or ur_rtde's ``triggerProtectiveStop``) or when the contact force
  exceeds ``force_limit_n``; :meth:`kill` closes every socket abruptly (RST).

Run it as a process (ur_rtde's constructors hold the GIL, so an emulator thread in the
client's process would deadlock)::

    python -m hardware.emulators.ur_controller --host 127.0.0.2

It prints ``READY ur_controller ...`` once listening and stops on SIGTERM/SIGINT.
:class:`URControllerProcess` does that from Python (tests, ``tactile-emulate``).
"""

from __future__ import annotations

import argparse
import math
import os
import select
import signal
import socket
import struct
import subprocess
import sys
import threading
import time
from dataclasses import dataclass

import numpy as np

from . import ur_wire as wire
from .ur_motion import Contact, Kinematics

DASHBOARD_PORT, SCRIPT_PORT, RTDE_PORT = 29999, 30003, 30004

# runtime_state, robot_mode, safety_mode values (UR RTDE guide)
STOPPED, PLAYING = 1, 2
ROBOT_MODE_RUNNING = 7
SAFETY_NORMAL, SAFETY_PROTECTIVE_STOP = 1, 3
# safety_status_bits
BIT_NORMAL, BIT_PROTECTIVE, BIT_STOPPED_DUE_TO_SAFETY = 1 << 0, 1 << 2, 1 << 10
# robot_status_bits
BIT_POWER_ON, BIT_PROGRAM_RUNNING = 1 << 0, 1 << 1

READY_FOR_CMD, DONE_WITH_CMD = 1, 2
#: commands the control script processes without waiting for the client to clear them
REALTIME_CMDS = {6, 9, 10, 11, 24, 25, 26, 27, 38, 58, 66, 67, 68, 69, 70, 71}


@dataclass
class URControllerConfig:
    """What the emulated controller is and how it behaves.

    Attributes:
        host: loopback address to bind (127.0.0.x; the ports are fixed like a robot's).
        model: robot model answered by the dashboard.
        controller_version: (major, minor, bugfix, build); major 3 = CB3, 5 = e-series.
        frequency_hz: control/RTDE rate (125 on CB3, 500 on e-series).
        initial_pose: TCP pose at start ``[x,y,z,rx,ry,rz]`` (m, rad).
        surface_z: height (m) of a contact plane, None for free space.
        stiffness_n_m: contact stiffness (N/m).
        force_limit_n: protective stop when the contact force exceeds this (N); None: never.
        protective_stop_at_s: protective stop this long after start (s); None: never.
        unlock_delay_s: the dashboard refuses to unlock a protective stop earlier (5 s on a UR).
        serial_number: answered by ``get serial number`` (e-series).
        pose_file: publish the TCP pose here every period (:class:`~.touch.PoseFile`), for the
            BioTac emulators to press with it; None: not published.
    """

    host: str = "127.0.0.1"
    model: str = "UR10"
    controller_version: tuple = (3, 15, 7, 106331)
    frequency_hz: float = 125.0
    initial_pose: tuple = (0.5, -0.2, 0.3, 0.0, math.pi, 0.0)
    surface_z: float | None = None
    stiffness_n_m: float = 5000.0
    force_limit_n: float | None = None
    protective_stop_at_s: float | None = None
    unlock_delay_s: float = 5.0
    serial_number: str = "2017350001"
    rtde_port: int = RTDE_PORT
    dashboard_port: int = DASHBOARD_PORT
    script_port: int = SCRIPT_PORT
    log: bool = False
    pose_file: str | None = None


def _log(cfg, *msg):
    if cfg.log:
        print("ur_controller:", *msg, file=sys.stderr, flush=True)


# ============================================================================ script
class _ControlScript:
    """The semantics of ur_rtde's ``rtde_control`` URScript program, one control period at a time.

    Holds the registers it reads and writes; the controller calls :meth:`step` once per
    period while the program runs. A blocking command (sync ``moveL``, ``stopL``...) keeps
    the script busy until the motion ends, then it signals "done".
    """

    def __init__(self, ctrl: "URControllerEmulator", reg_offset: int = 0):
        self.ctrl, self.kin, self.off = ctrl, ctrl.kin, reg_offset
        self.executing = False
        self.busy_until = None              # predicate: the blocking command has finished
        self.async_kind = None              # "move" | "stop" while an async operation runs
        self.wr_count = 0
        self.op_id = 0
        self.keep_running = True
        self.speeding = None                # (velocity, accel) while the speed thread runs
        self._async_register(-1)
        self._ready()

    # -- registers -------------------------------------------------------------------
    def _in_int(self, i):
        return self.ctrl.in_int[i + self.off]

    def _in_double(self, i):
        return self.ctrl.in_double[i + self.off]

    def _pose(self, first=0):
        return np.array([self._in_double(first + k) for k in range(6)])

    def _out_int(self, i, v):
        self.ctrl.out_int[i + self.off] = int(v)

    def _ready(self):
        self._out_int(0, READY_FOR_CMD)

    def _done(self):
        self._out_int(0, DONE_WITH_CMD)

    def _async_register(self, value):
        """Progress word: change count bits 16-23, operation id bits 24-30, running bit 15."""
        self.wr_count = (self.wr_count + 1) % 128
        if value == 0:
            self.op_id = (self.op_id + 1) % 128
        reg = self.wr_count * 65536 + self.op_id * 16777216
        if value >= 0:
            reg += min(value, 32767) + 32768
        self._out_int(2, reg)

    def _async_started(self, kind):
        self.async_kind = kind
        self._async_register(0)

    def _async_finished(self):
        if self.async_kind is not None:
            self.async_kind = None
            self._async_register(-1)

    # -- one control period --------------------------------------------------------
    def step(self) -> None:
        if self.async_kind == "move" and self.kin.mode != "linear":
            self._async_finished()
        elif self.async_kind == "stop" and self.kin.mode == "idle":
            self._async_finished()
        if self.speeding is not None and self.kin.mode != "speed":
            self.kin.speed_linear(*self.speeding)        # the script's speed thread re-issues speedl
        if self.busy_until is not None:
            if not self.busy_until():
                return
            self.busy_until = None
            self._done()
            return
        cmd = self._in_int(0)
        if cmd in REALTIME_CMDS:
            self._process(cmd)
            self._ready()
        elif cmd == 0:
            self.executing = False
            self._ready()
        elif not self.executing:
            self.executing = True
            self._process(cmd)
            if cmd != 255 and self.busy_until is None:
                self._done()

    def _block_until_idle(self):
        self.busy_until = lambda: self.kin.mode == "idle"

    def _stop_async_move(self):
        if self.async_kind == "move":
            self._async_finished()

    def _process(self, cmd: int) -> None:
        kin, c = self.kin, self.ctrl
        if cmd in (2, 3):                                   # moveJ_IK, moveL (pose targets)
            pose, speed, accel, asynchronous = self._pose(0), self._in_double(6), self._in_double(7), self._in_int(1)
            self._stop_async_move()
            kin.move_linear(pose, speed, accel)
            if asynchronous == 1:
                self._async_started("move")
            else:
                self.busy_until = lambda: kin.mode != "linear"
        elif cmd == 6:                                      # forceMode
            selection = [self._in_int(2 + i) for i in range(6)]
            kin.force = (self._pose(0), selection, self._pose(6), self._pose(12))
        elif cmd == 7:                                      # forceModeStop: end_force_mode(); stopl(10)
            kin.force = None
            kin.stop(10.0)
            self._block_until_idle()
        elif cmd == 8:                                      # zeroFtSensor
            kin.zero_ft()
        elif cmd == 10:                                     # speedL (a thread repeating speedl)
            self.speeding = (self._pose(0), self._in_double(6))
            kin.speed_linear(*self.speeding)
        elif cmd == 24:                                     # servoL
            kin.servo(self._pose(0), self._in_double(9))
        elif cmd in (15, 16):                               # speedStop, servoStop
            self.speeding = None
            kin.stop(self._in_double(0))
            self._block_until_idle()
        elif cmd == 31:                                     # triggerProtectiveStop
            c.trigger_protective_stop("protective_stop() from the control script")
        elif cmd in (33, 34):                               # stopL, stopJ
            decel, asynchronous = self._in_double(0), self._in_int(1)
            if self.async_kind == "stop":
                self._async_finished()
            else:
                self._stop_async_move()
            kin.stop(decel)
            if asynchronous == 1:
                self._async_started("stop")
            else:
                self._block_until_idle()
        elif cmd == 47:                                     # isSteady
            steady = kin.mode == "idle" and not np.any(np.abs(kin.velocity) > 1e-6)
            self._out_int(1, 1 if steady else 0)
        elif cmd == 255:                                    # stopScript
            self.keep_running = False
        else:                                               # accepted, not emulated
            _log(c.cfg, f"control script: command {cmd} not emulated (acknowledged)")


# ============================================================================ sessions
class _RtdeSession:
    """One RTDE client connection: its recipes and whether it is streaming."""

    def __init__(self, sock, peer):
        self.sock, self.peer = sock, peer
        self.out_names: list[str] = []
        self.out_types: list[str] = []
        self.out_period = 0.0
        self.next_send = 0.0
        self.inputs: dict[int, tuple[list[str], list[str]]] = {}
        self.next_recipe = 1
        self.started = False
        self.send_lock = threading.Lock()
        self.closed = False

    def send(self, data: bytes) -> bool:
        with self.send_lock:
            if self.closed:
                return False
            try:
                self.sock.sendall(data)
                return True
            except OSError:
                self.closed = True
                return False


def _recv_exact(sock, n, alive) -> bytes | None:
    buf = b""
    while len(buf) < n:
        if not alive():
            return None
        try:
            chunk = sock.recv(n - len(buf))
        except socket.timeout:
            continue
        except OSError:
            return None
        if not chunk:
            return None
        buf += chunk
    return buf


def _listener(host, port) -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        s.bind((host, port))
    except OSError as exc:
        s.close()
        raise OSError(exc.errno, f"cannot bind {host}:{port} ({exc.strerror}); is another emulator "
                                 f"or robot software using this address? Use another 127.0.0.x") from exc
    s.listen(8)
    s.settimeout(0.2)
    return s


# ============================================================================ controller
class URControllerEmulator:
    """A UR controller on loopback: RTDE, dashboard and script servers around a simple arm.

    Use as a context manager or call :meth:`start` / :meth:`stop`. Thread-safe.
    """

    def __init__(self, host: str = "127.0.0.1", **options):
        self.cfg = URControllerConfig(host=host, **options)
        self.dt = 1.0 / self.cfg.frequency_hz
        self.kin = Kinematics(self.cfg.initial_pose, Contact(self.cfg.surface_z, self.cfg.stiffness_n_m))
        self.lock = threading.RLock()
        self.in_int, self.in_double = [0] * 48, [0.0] * 48
        self.out_int, self.out_double = [0] * 48, [0.0] * 48
        self.script: _ControlScript | None = None
        self._last_program: str | None = None
        self.protective_stopped = False
        self.protective_stop_time = None
        self.protective_stop_reason = ""
        self.ticks = 0
        self._pose_file = None                  # opened on the first tick (cfg.pose_file)
        self._owners: dict[str, _RtdeSession] = {}
        self._sessions: list[_RtdeSession] = []
        self._sockets: set[socket.socket] = set()
        self._listeners: list[socket.socket] = []
        self._threads: list[threading.Thread] = []
        self._running = False
        self._t0 = 0.0

    # -- lifecycle -------------------------------------------------------------------
    def start(self) -> "URControllerEmulator":
        c = self.cfg
        servers = [(c.rtde_port, self._serve_rtde), (c.dashboard_port, self._serve_dashboard),
                   (c.script_port, self._serve_script)]
        try:
            for port, _ in servers:
                self._listeners.append(_listener(c.host, port))
        except OSError:
            for s in self._listeners:
                s.close()
            self._listeners.clear()
            raise
        self._running = True
        self._t0 = time.monotonic()
        for lst, (_, handler) in zip(self._listeners, servers):
            self._spawn(self._accept_loop, lst, handler)
        self._spawn(self._tick_loop)
        return self

    def stop(self) -> None:
        """Close every connection and listener and stop the threads (graceful)."""
        self._shutdown(abrupt=False)

    def kill(self) -> None:
        """Close every socket abruptly (TCP RST), as a crashed or unplugged controller."""
        self._shutdown(abrupt=True)

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()

    def _shutdown(self, abrupt: bool) -> None:
        self._running = False
        with self.lock:
            socks = list(self._sockets) + list(self._listeners)
            self._sockets.clear()
            self._listeners.clear()
        for s in socks:
            try:
                if abrupt:
                    s.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
                else:
                    s.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            s.close()
        for t in self._threads:
            if t is not threading.current_thread():
                t.join(timeout=2.0)
        self._threads.clear()

    def _spawn(self, fn, *args):
        t = threading.Thread(target=fn, args=args, daemon=True, name=f"ur-emu-{fn.__name__}")
        t.start()
        self._threads.append(t)

    def _accept_loop(self, lst, handler):
        while self._running:
            try:
                conn, peer = lst.accept()
            except socket.timeout:
                continue
            except OSError:
                return
            conn.settimeout(0.2)
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            with self.lock:
                if not self._running:
                    conn.close()
                    return
                self._sockets.add(conn)
            self._spawn(self._session, conn, peer, handler)

    def _session(self, conn, peer, handler):
        try:
            handler(conn, peer)
        finally:
            with self.lock:
                self._sockets.discard(conn)
            try:
                conn.close()
            except OSError:
                pass

    def _alive(self):
        return self._running

    # -- state -----------------------------------------------------------------------
    @property
    def program_running(self) -> bool:
        return self.script is not None

    def controller_time(self) -> float:
        """The controller's timestamp (s): control periods elapsed since start."""
        return self.ticks * self.dt

    def trigger_protective_stop(self, reason: str = "on demand") -> None:
        """Stop the arm at once, abort the running program, raise the safety flags."""
        with self.lock:
            if self.protective_stopped:
                return
            self.protective_stopped = True
            self.protective_stop_time = time.monotonic()
            self.protective_stop_reason = reason
            self.kin.halt()
            self.kin.force = None
            self.script = None
            _log(self.cfg, f"PROTECTIVE STOP: {reason}")

    def unlock_protective_stop(self) -> str:
        """The dashboard's answer to ``unlock protective stop``."""
        with self.lock:
            if self.protective_stopped:
                waited = time.monotonic() - self.protective_stop_time
                if waited < self.cfg.unlock_delay_s:
                    return (f"Cannot unlock protective stop until {self.cfg.unlock_delay_s:g}s after occurrence. "
                            "Always inspect cause of protective stop before unlocking")
                self.protective_stopped = False
            return "Protective stop releasing"

    def snapshot(self) -> dict:
        """Current state as plain values (for tests and logs)."""
        with self.lock:
            return {"pose": self.kin.pose.copy(), "velocity": self.kin.velocity.copy(), "mode": self.kin.mode,
                    "protective_stopped": self.protective_stopped, "program_running": self.program_running,
                    "controller_time": self.controller_time(), "wrench": self.kin.measured_wrench()}

    def _outputs(self) -> dict:
        k = self.kin
        prot = self.protective_stopped
        safety_bits = (BIT_PROTECTIVE | BIT_STOPPED_DUE_TO_SAFETY) if prot else BIT_NORMAL
        return {
            "timestamp": self.controller_time(),
            "actual_TCP_pose": k.pose, "target_TCP_pose": k.pose,
            "actual_TCP_speed": k.velocity, "target_TCP_speed": k.velocity,
            "actual_TCP_force": k.measured_wrench(), "ft_raw_wrench": k.contact.wrench(k.pose),
            "robot_mode": ROBOT_MODE_RUNNING, "joint_mode": [253] * 6,
            "safety_mode": SAFETY_PROTECTIVE_STOP if prot else SAFETY_NORMAL,
            "safety_status": SAFETY_PROTECTIVE_STOP if prot else SAFETY_NORMAL,
            "safety_status_bits": safety_bits,
            "runtime_state": PLAYING if self.program_running else STOPPED,
            "robot_status_bits": BIT_POWER_ON | (BIT_PROGRAM_RUNNING if self.program_running else 0),
            "speed_scaling": 1.0, "target_speed_fraction": 1.0,
            "actual_main_voltage": 48.0, "actual_robot_voltage": 48.0,
            "joint_temperatures": [30.0] * 6,
        }

    def _value(self, name, typ, values):
        if name in values:
            return values[name]
        if name.startswith("output_int_register_"):
            return self.out_int[int(name.rsplit("_", 1)[1])]
        if name.startswith("output_double_register_"):
            return self.out_double[int(name.rsplit("_", 1)[1])]
        n = {"VECTOR3D": 3, "VECTOR6D": 6, "VECTOR6INT32": 6, "VECTOR6UINT32": 6}.get(typ)
        return [0] * n if n else 0

    # -- control loop ----------------------------------------------------------------
    def _tick_loop(self):
        next_t = time.monotonic()
        while self._running:
            with self.lock:
                self._tick()
                values = self._outputs()
                sessions = [s for s in self._sessions if s.started and not s.closed]
            now = time.monotonic()
            for s in sessions:
                if now + 1e-4 >= s.next_send:
                    s.next_send = max(s.next_send + s.out_period, now - s.out_period)
                    vals = [self._value(n, t, values) for n, t in zip(s.out_names, s.out_types)]
                    s.send(wire.message(wire.DATA_PACKAGE, bytes([1]) + wire.pack_values(s.out_types, vals)))
            next_t += self.dt
            delay = next_t - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            elif delay < -5 * self.dt:                      # fell behind (loaded host): resynchronise
                next_t = time.monotonic()

    def _tick(self):
        self.ticks += 1
        c = self.cfg
        if c.protective_stop_at_s is not None and not self.protective_stopped and \
                time.monotonic() - self._t0 >= c.protective_stop_at_s:
            c.protective_stop_at_s = None
            self.trigger_protective_stop(f"scheduled at t={self.controller_time():.3f} s")
        script = self.script
        if script is not None:
            script.step()
            if self.script is script and not script.keep_running:
                self.script = None
        self.kin.step(self.dt)
        if c.pose_file is not None:
            if self._pose_file is None:
                from .touch import PoseFile
                self._pose_file = PoseFile(c.pose_file, create=True)
            self._pose_file.write(self.controller_time(), self.kin.pose, self.kin.velocity)
        if c.force_limit_n is not None and not self.protective_stopped:
            f = float(np.linalg.norm(self.kin.contact.wrench(self.kin.pose)[:3]))
            if f > c.force_limit_n:
                self.trigger_protective_stop(f"contact force {f:.1f} N above {c.force_limit_n} N")

    # -- RTDE ------------------------------------------------------------------------
    def _serve_rtde(self, conn, peer):
        s = _RtdeSession(conn, peer)
        with self.lock:
            self._sessions.append(s)
        try:
            while self._running and not s.closed:
                head = _recv_exact(conn, 3, self._alive)
                if head is None:
                    return
                size, kind = wire.HEADER.unpack(head)
                body = _recv_exact(conn, size - 3, self._alive) if size > 3 else b""
                if body is None:
                    return
                reply = self._rtde_request(s, kind, body)
                if reply is not None and not s.send(reply):
                    return
        finally:
            with self.lock:
                s.closed = True
                self._sessions.remove(s)
                for name in [n for n, owner in self._owners.items() if owner is s]:
                    del self._owners[name]

    def _rtde_request(self, s: _RtdeSession, kind: int, body: bytes) -> bytes | None:
        c = self.cfg
        if kind == wire.REQUEST_PROTOCOL_VERSION:
            version = struct.unpack(">H", body[:2])[0] if len(body) >= 2 else 0
            return wire.message(kind, bytes([1 if version in (1, 2) else 0]))
        if kind == wire.GET_URCONTROL_VERSION:
            return wire.message(kind, struct.pack(">IIII", *c.controller_version))
        if kind == wire.SETUP_OUTPUTS:
            freq = struct.unpack(">d", body[:8])[0]
            names = wire.names(body[8:])
            types = [wire.output_type(n) for n in names]
            if 0 < freq <= c.frequency_hz and "NOT_FOUND" not in types:
                with self.lock:
                    s.out_names, s.out_types, s.out_period = names, types, 1.0 / freq
            return wire.message(kind, bytes([1]) + ",".join(types).encode())
        if kind == wire.SETUP_INPUTS:
            names = wire.names(body)
            with self.lock:
                types = [wire.input_type(n) for n in names]
                types = ["IN_USE" if not self._owned_by(n, s) else t for n, t in zip(names, types)]
                if any(t in ("NOT_FOUND", "IN_USE") for t in types):
                    return wire.message(kind, bytes([0]) + ",".join(types).encode())
                rid = s.next_recipe
                s.next_recipe += 1
                s.inputs[rid] = (names, types)
                for n in names:
                    self._owners[n] = s
            return wire.message(kind, bytes([rid]) + ",".join(types).encode())
        if kind == wire.START:
            ok = bool(s.out_names)
            with self.lock:
                s.started = ok
                s.next_send = time.monotonic()
            return wire.message(kind, bytes([1 if ok else 0]))
        if kind == wire.PAUSE:
            s.started = False
            return wire.message(kind, bytes([1]))
        if kind == wire.DATA_PACKAGE:
            self._write_inputs(s, body)
            return None
        _log(c, f"RTDE: unknown message type {kind} from {s.peer}")
        return None

    def _owned_by(self, name: str, s: _RtdeSession) -> bool:
        """True if ``name`` is free or already ``s``'s; frees it if its owner hung up."""
        owner = self._owners.get(name, s)
        if owner is s:
            return True
        try:                                    # a client that reconnects at once may race our recv
            gone = owner.sock.recv(1, socket.MSG_PEEK | socket.MSG_DONTWAIT) == b""
        except BlockingIOError:
            gone = False
        except OSError:
            gone = True
        if gone:
            owner.closed = True
            del self._owners[name]
        return gone

    def _write_inputs(self, s: _RtdeSession, body: bytes) -> None:
        recipe = s.inputs.get(body[0]) if body else None
        if recipe is None:
            return
        names, types = recipe
        try:
            values = wire.unpack_values(types, body[1:])
        except struct.error:
            _log(self.cfg, f"RTDE: malformed data package for recipe {body[0]}")
            return
        with self.lock:
            for n, v in zip(names, values):
                if n.startswith("input_int_register_"):
                    self.in_int[int(n.rsplit("_", 1)[1])] = v
                elif n.startswith("input_double_register_"):
                    self.in_double[int(n.rsplit("_", 1)[1])] = v

    # -- dashboard -------------------------------------------------------------------
    def _serve_dashboard(self, conn, peer):
        self._send_line(conn, "Connected: Universal Robots Dashboard Server")
        buf = b""
        while self._running:
            try:
                chunk = conn.recv(4096)
            except socket.timeout:
                continue
            except OSError:
                return
            if not chunk:
                return
            buf += chunk
            while b"\n" in buf:
                line, buf = buf.split(b"\n", 1)
                cmd = line.decode("utf-8", "replace").strip()
                answer = self._dashboard(cmd)
                if not self._send_line(conn, answer) or cmd.lower() == "quit":
                    return

    @staticmethod
    def _send_line(conn, text) -> bool:
        try:
            conn.sendall((text + "\n").encode())
            return True
        except OSError:
            return False

    def _polyscope_version(self) -> str:
        v = self.cfg.controller_version
        return f"URSoftware {v[0]}.{v[1]}.{v[2]}.{v[3]} (emulated)"

    def _dashboard(self, cmd: str) -> str:
        low = cmd.lower()
        with self.lock:
            prot, running = self.protective_stopped, self.program_running
            name = "rtde_control" if running or self._last_program else "<unnamed>"
            fixed = {
                "polyscopeversion": self._polyscope_version(),
                "robotmode": "Robotmode: RUNNING",
                "safetymode": "Safetymode: " + ("PROTECTIVE_STOP" if prot else "NORMAL"),
                "safetystatus": "Safetystatus: " + ("PROTECTIVE_STOP" if prot else "NORMAL"),
                "programstate": ("PLAYING " if running else "STOPPED ") + name,
                "running": f"Program running: {str(running).lower()}",
                "close safety popup": "closing safety popup",
                "close popup": "closing popup",
                "power on": "Powering on", "power off": "Powering off",
                "brake release": "Brake releasing",
                "get robot model": self.cfg.model,
                "get serial number": self.cfg.serial_number,
                "is in remote control": "true",
                "get loaded program": "No program loaded",
                "isprogramsaved": "false <unnamed>",
                "restart safety": "Restarting safety",
                "quit": "Disconnected",
                "shutdown": "Shutting down",
            }
        if low in fixed:
            return fixed[low]
        if low == "unlock protective stop":
            return self.unlock_protective_stop()
        if low == "stop":
            with self.lock:
                self.script = None
                self.kin.stop(10.0)
            return "Stopped"
        if low == "pause":
            return "Pausing program" if running else "Failed to execute: pause"
        if low == "play":
            return self._play()
        if low.startswith("popup "):
            return "showing popup"
        if low.startswith("addtolog "):
            return "Added log message"
        if low.startswith("load "):
            return f"File not found: {cmd[5:]}"
        return f"could not understand: '{cmd}'"

    def _play(self) -> str:
        with self.lock:
            if self._last_program is None or self.protective_stopped:
                return "Failed to execute: play"
            if self.script is None:
                self._start_program(self._last_program)
        return "Starting program"

    # -- script port -----------------------------------------------------------------
    def _serve_script(self, conn, peer):
        buf = ""
        while self._running:
            try:
                chunk = conn.recv(65536)
            except socket.timeout:
                continue
            except OSError:
                return
            if not chunk:
                return
            buf += chunk.decode("utf-8", "replace")
            buf = self._consume_programs(buf)

    def _consume_programs(self, buf: str) -> str:
        """Run every complete ``def name(): ... end`` program in ``buf``; return the rest."""
        while True:
            start = buf.find("def ")
            if start < 0:
                if buf.endswith("\n") and buf.strip():
                    _log(self.cfg, f"script port: statement not emulated: {buf.strip()[:60]!r}")
                    return ""
                return buf
            end = buf.find("\nend", start)
            while end >= 0 and not buf[end + 4:end + 5] in ("\n", ""):
                end = buf.find("\nend", end + 4)
            if end < 0 or len(buf) < end + 5:
                return buf
            program, buf = buf[start:end + 5], buf[end + 5:]
            with self.lock:
                self._last_program = program
                if self.protective_stopped:
                    _log(self.cfg, "script port: program refused during a protective stop")
                else:
                    self._start_program(program)

    def _start_program(self, program: str) -> None:
        header = program.split("\n", 1)[0]
        if not header.startswith("def rtde_control"):
            _log(self.cfg, f"script port: program {header!r} not emulated; stopping the current one")
            self.script = None
            return
        offset = 24 if "reg_offset_int = # int register offset\n24" in program else 0
        self.script = _ControlScript(self, offset)
        _log(self.cfg, f"control script started (register offset {offset})")


# ============================================================================ process
class URControllerProcess:
    """The emulator as a separate process (what tests and ``tactile-emulate`` should use).

    ``start()`` launches ``python -m hardware.emulators.ur_controller`` with the given
    options and waits (bounded) for its READY line; ``stop()`` terminates it by PID;
    ``kill()`` sends SIGKILL (a controller that dies); ``protective_stop()`` sends SIGUSR1.
    """

    def __init__(self, host: str = "127.0.0.1", ready_timeout_s: float = 10.0, **options):
        self.host, self.options, self.ready_timeout_s = host, options, ready_timeout_s
        self.proc: subprocess.Popen | None = None
        self.ready_line = ""

    def command(self) -> list[str]:
        args = [sys.executable, "-m", "hardware.emulators.ur_controller", "--host", self.host]
        for key, value in self.options.items():
            if value is None or value is False:
                continue
            flag = "--" + key.replace("_", "-")
            if value is True:
                args.append(flag)
            elif isinstance(value, (list, tuple)):
                args += [flag, ",".join(str(v) for v in value)]
            else:
                args += [flag, str(value)]
        return args

    def start(self) -> "URControllerProcess":
        self.proc = subprocess.Popen(self.command(), stdout=subprocess.PIPE, stderr=None, text=True,
                                     cwd=os.path.dirname(os.path.dirname(os.path.dirname(__file__))))
        deadline = time.monotonic() + self.ready_timeout_s
        while time.monotonic() < deadline:
            ready, _, _ = select.select([self.proc.stdout], [], [], 0.1)
            if ready:
                line = self.proc.stdout.readline()
                if line.startswith("READY"):
                    self.ready_line = line.strip()
                    return self
                if not line:                                # EOF: the process is exiting
                    try:
                        self.proc.wait(timeout=2)
                    except subprocess.TimeoutExpired:
                        pass
                    break
        self.stop()
        raise RuntimeError(f"UR controller emulator on {self.host} did not print READY within "
                           f"{self.ready_timeout_s} s (exit code {self.proc.returncode})")

    @property
    def pid(self) -> int | None:
        return self.proc.pid if self.proc else None

    def protective_stop(self) -> None:
        os.kill(self.proc.pid, signal.SIGUSR1)

    def kill(self) -> None:
        if self.proc and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(timeout=5)

    def stop(self) -> None:
        if self.proc is None:
            return
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=5)
        if self.proc.stdout:
            self.proc.stdout.close()

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()


def _floats(text: str) -> tuple:
    return tuple(float(v) for v in text.split(","))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m hardware.emulators.ur_controller",
                                description="Emulated UR controller (RTDE 30004, dashboard 29999, script 30003).")
    p.add_argument("--host", default="127.0.0.1", help="loopback address to bind (127.0.0.x)")
    p.add_argument("--model", default="UR10")
    p.add_argument("--controller-version", type=lambda s: tuple(int(v) for v in s.replace(",", ".").split(".")),
                   default=(3, 15, 7, 106331), help="e.g. 3.15.7.106331 (CB3) or 5.11.1.108318 (e-series)")
    p.add_argument("--frequency-hz", type=float, default=None, help="125 (CB3) / 500 (e-series) by default")
    p.add_argument("--initial-pose", type=_floats, default=None, help="x,y,z,rx,ry,rz (m, rad)")
    p.add_argument("--surface-z", type=float, default=None, help="height of a contact plane (m)")
    p.add_argument("--stiffness-n-m", type=float, default=5000.0)
    p.add_argument("--force-limit-n", type=float, default=None)
    p.add_argument("--protective-stop-at-s", type=float, default=None)
    p.add_argument("--unlock-delay-s", type=float, default=5.0)
    p.add_argument("--log", action="store_true", help="log commands and faults to stderr")
    p.add_argument("--pose-file", default=None, help="publish the TCP pose here (hardware/emulators/touch.py)")
    a = p.parse_args(argv)
    opts = dict(model=a.model, controller_version=a.controller_version,
                frequency_hz=a.frequency_hz or (500.0 if a.controller_version[0] >= 5 else 125.0),
                surface_z=a.surface_z, stiffness_n_m=a.stiffness_n_m, force_limit_n=a.force_limit_n,
                protective_stop_at_s=a.protective_stop_at_s, unlock_delay_s=a.unlock_delay_s, log=a.log,
                pose_file=a.pose_file)
    if a.initial_pose:
        opts["initial_pose"] = a.initial_pose
    try:
        emu = URControllerEmulator(a.host, **opts).start()
    except OSError as exc:
        print(f"ERROR ur_controller: {exc}", file=sys.stderr, flush=True)
        return 2
    done = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: done.set())
    signal.signal(signal.SIGINT, lambda *_: done.set())
    signal.signal(signal.SIGUSR1, lambda *_: emu.trigger_protective_stop("SIGUSR1"))
    c = emu.cfg
    print(f"READY ur_controller host={c.host} rtde={c.rtde_port} dashboard={c.dashboard_port} "
          f"script={c.script_port} frequency_hz={c.frequency_hz:g} pid={os.getpid()}", flush=True)
    while not done.wait(0.5):
        pass
    emu.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())

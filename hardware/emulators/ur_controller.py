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
  (:class:`ControlScript`): the client writes a command id into ``input_int_register_0``
  (arguments in the other input registers), the script answers 1 (ready) / 2 (done) in
  ``output_int_register_0``, async progress in ``output_int_register_2``.
- Motion: :class:`hardware.emulators.ur_motion.Kinematics` (Cartesian only, no joints).
- Faults: a protective stop at a given time, on demand (:meth:`trigger_protective_stop`,
  SIGUSR1 to the process, or ur_rtde's ``triggerProtectiveStop``) or when the contact force
  exceeds ``force_limit_n``; :meth:`kill` closes every socket abruptly (RST).

Run it as a process (ur_rtde's constructors hold the GIL, so an emulator thread in the
client's process would deadlock)::

    python -m tactile_flow.hardware.emulators.ur_controller --host 127.0.0.2

It prints ``READY ur_controller ...`` once listening and stops on SIGTERM/SIGINT.
:class:`URControllerProcess` does that from Python (tests, ``tactile-emulate``).
"""

from __future__ import annotations

import argparse
import math
import os
import signal
import socket
import struct
import sys
import threading
import time
from dataclasses import dataclass

import numpy as np

from . import ur_wire as wire
from .ur_servers import DashboardServer, RtdeServer, RtdeSession, listener
from .ur_wire import (BIT_NORMAL, BIT_POWER_ON, BIT_PROGRAM_RUNNING, BIT_PROTECTIVE, BIT_STOPPED_DUE_TO_SAFETY,
                      DASHBOARD_PORT, PLAYING, ROBOT_MODE_RUNNING, RTDE_PORT, SAFETY_NORMAL,
                      SAFETY_PROTECTIVE_STOP, SCRIPT_PORT, STOPPED)
from .process import EmulatorProcess
from .ur_script import ControlScript, log_line
from .ur_motion import Contact, Kinematics




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


# ============================================================================ controller
class URControllerEmulator(RtdeServer, DashboardServer):
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
        self.script: ControlScript | None = None
        self._last_program: str | None = None
        self.protective_stopped = False
        self.protective_stop_time = None
        self.protective_stop_reason = ""
        self.ticks = 0
        self._pose_file = None                  # opened on the first tick (cfg.pose_file)
        self._owners: dict[str, RtdeSession] = {}
        self._sessions: list[RtdeSession] = []
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
                self._listeners.append(listener(c.host, port))
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
            log_line(self.cfg, f"PROTECTIVE STOP: {reason}")

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
                    log_line(self.cfg, f"script port: statement not emulated: {buf.strip()[:60]!r}")
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
                    log_line(self.cfg, "script port: program refused during a protective stop")
                else:
                    self._start_program(program)

    def _start_program(self, program: str) -> None:
        header = program.split("\n", 1)[0]
        if not header.startswith("def rtde_control"):
            log_line(self.cfg, f"script port: program {header!r} not emulated; stopping the current one")
            self.script = None
            return
        offset = 24 if "reg_offset_int = # int register offset\n24" in program else 0
        self.script = ControlScript(self, offset)
        log_line(self.cfg, f"control script started (register offset {offset})")


# ============================================================================ process
class URControllerProcess(EmulatorProcess):
    """The emulator as a separate process (what tests and ``tactile-emulate`` should use):
    ``python -m tactile_flow.hardware.emulators.ur_controller --host HOST`` with ``options`` as flags
    (``initial_pose=(...)`` → ``--initial-pose x,y,z,...``). ``protective_stop()`` sends SIGUSR1."""

    def __init__(self, host: str = "127.0.0.1", ready_timeout_s: float = 10.0, **options):
        self.host, self.options = host, options
        super().__init__("tactile_flow.hardware.emulators.ur_controller", ["--host", host, *_flags(options)], ready_timeout_s)

    def protective_stop(self) -> None:
        os.kill(self.proc.pid, signal.SIGUSR1)


def _flags(options: dict) -> list[str]:
    """Keyword options as command-line flags (``None``/``False`` omitted, ``True`` a bare flag,
    sequences comma-separated)."""
    args = []
    for key, value in options.items():
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


def _floats(text: str) -> tuple:
    return tuple(float(v) for v in text.split(","))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m tactile_flow.hardware.emulators.ur_controller",
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

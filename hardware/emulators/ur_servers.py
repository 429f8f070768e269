"""The UR controller emulator's two text/binary servers, as parts of
:class:`~hardware.emulators.ur_controller.URControllerEmulator`: RTDE on 30004
(:class:`RtdeServer`: recipes, start/pause, input packages) and the dashboard server on 29999
(:class:`DashboardServer`: the text commands ur_rtde's ``DashboardClient`` and a recovery use,
answered with the real controller's strings). Both read and write the emulator's state.
"""

from __future__ import annotations

import socket
import struct
import threading
import time

from . import ur_wire as wire
from .ur_script import log_line


class RtdeSession:
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


def listener(host, port) -> socket.socket:
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


class RtdeServer:
    """RTDE sessions of the emulated controller (a part of ``URControllerEmulator``)."""

    def _serve_rtde(self, conn, peer):
        s = RtdeSession(conn, peer)
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

    def _rtde_request(self, s: RtdeSession, kind: int, body: bytes) -> bytes | None:
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
        log_line(c, f"RTDE: unknown message type {kind} from {s.peer}")
        return None

    def _owned_by(self, name: str, s: RtdeSession) -> bool:
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

    def _write_inputs(self, s: RtdeSession, body: bytes) -> None:
        recipe = s.inputs.get(body[0]) if body else None
        if recipe is None:
            return
        names, types = recipe
        try:
            values = wire.unpack_values(types, body[1:])
        except struct.error:
            log_line(self.cfg, f"RTDE: malformed data package for recipe {body[0]}")
            return
        with self.lock:
            for n, v in zip(names, values):
                if n.startswith("input_int_register_"):
                    self.in_int[int(n.rsplit("_", 1)[1])] = v
                elif n.startswith("input_double_register_"):
                    self.in_double[int(n.rsplit("_", 1)[1])] = v

    # -- dashboard -------------------------------------------------------------------


class DashboardServer:
    """The dashboard server of the emulated controller (a part of ``URControllerEmulator``)."""

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

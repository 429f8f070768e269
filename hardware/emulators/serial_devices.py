"""Serial-device emulators on pseudo-terminals: BioTac bridge, EZO-PMP-like pump, A&D-like scale.

Run as a process (``python -m tactile_flow.hardware.emulators.serial_devices``); it opens one pty pair
per device, prints ``READY biotac=/dev/pts/N pump=/dev/pts/M scale=/dev/pts/K`` and serves
until killed. The drivers open the pty slaves through pyserial exactly like real ports.
With ``--link-dir DIR`` it also makes stable symlinks ``DIR/biotac``, ``DIR/pump``,
``DIR/scale`` (what ``conf/hardware/lab_emulated.yaml`` points at).

Control lines on stdin (each answered by one ``OK <json>`` or ``ERR <reason>`` line):

- ``garbage N``: write N random bytes between two BioTac frames.
- ``truncate K``: cut each of the next K BioTac frames short (the next frame follows at once).
- ``corrupt K``: flip one payload byte in each of the next K frames (CRC fails).
- ``disconnect DEVICE``: close that device's pty master (a pulled USB cable).
- ``stats``: counters and the sequence numbers of the frames sent whole, truncated, corrupted
  (and, with ``--world-dir``, the emulated world's bottle: :mod:`.touch`).
- ``frames A B``: the monotonic times the BioTac frames ``A``..``B`` were sent.

Wire formats: ``docs/serial_protocol.md``. The pump moves water from the reservoir on the
scale into the bottle held in the emulated world (``--world-dir``: the pump's flow is shared
as ``<world dir>/pump``): the scale's reading falls by 1 g per ml dispensed.
"""

from __future__ import annotations

import argparse
import fcntl
import json
import os
import sys
import threading
import time
import tty
from pathlib import Path

import numpy as np

from ..biotac import FINGERS
from ..serial_biotac import encode_frame
from ..serial_pour import format_weight_line
from .process import EmulatorProcess, emulated_sensor, sensor_model_config
from .touch import frame_times

FIRMWARE = "2.4-emulated"


class Pty:
    """A pty pair: we write/read the master; clients open ``path`` (the slave)."""

    def __init__(self, name: str):
        self.name = name
        self.master, self._slave = os.openpty()
        tty.setraw(self._slave)                        # no echo, no CR/LF translation before a client opens it
        fl = fcntl.fcntl(self.master, fcntl.F_GETFL)
        fcntl.fcntl(self.master, fcntl.F_SETFL, fl | os.O_NONBLOCK)
        self.path = os.ttyname(self._slave)
        self.closed = False
        self.overruns = 0                              # writes dropped because nobody read the pty

    def write(self, data: bytes) -> bool:
        """Write all of ``data`` or, if the pty is full before a byte went out, none (returns False)."""
        sent = 0
        deadline = time.monotonic() + 0.5
        while sent < len(data) and not self.closed:
            try:
                sent += os.write(self.master, data[sent:])
            except BlockingIOError:
                if sent == 0 or time.monotonic() > deadline:
                    self.overruns += 1
                    return False
                time.sleep(0.001)
            except OSError:
                return False
        return sent == len(data)

    def read(self) -> bytes:
        try:
            return os.read(self.master, 4096)
        except (BlockingIOError, OSError):
            return b""

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            for fd in (self.master, self._slave):
                try:
                    os.close(fd)
                except OSError:
                    pass


CATCH_UP_S = 1.0      # a sampling device late by up to this (a stalled process) sends what it missed


class _Periodic(threading.Thread):
    """Calls ``tick(k, t)`` every ``period`` s on an absolute schedule, ``t`` the period's
    scheduled (monotonic) time. A late thread skips the missed periods, or with ``catch_up``
    (a device that samples on its own clock: the BioTac bridge) calls them all at once, as a
    sensor buffered behind a stalled link delivers its frames late but dated (up to
    :data:`CATCH_UP_S`; beyond, the periods are skipped)."""

    def __init__(self, period: float, tick, name: str, catch_up: bool = False):
        super().__init__(name=name, daemon=True)
        self.period, self.tick, self.catch_up = period, tick, catch_up
        self.stop = threading.Event()

    def run(self) -> None:
        t_next = time.monotonic()
        k = 0
        while not self.stop.is_set():
            self.tick(k, t_next)
            k += 1
            now = time.monotonic()
            behind = CATCH_UP_S if self.catch_up else self.period
            t_next = max(t_next + self.period, now - behind)
            self.stop.wait(max(0.0, t_next - now))


# ============================================================================ BioTac bridge
class BiotacBridge:
    """Sends BioTac frames (sim sensor model) at ``rate_hz`` with injectable faults: resting,
    or pressed by the emulated world when ``touch`` (:class:`~.touch.EmulatedWorld`) is given.
    ``sent[k]`` is the monotonic time frame ``k + 1`` was written to the pty (s)."""

    def __init__(self, fingers=FINGERS, rate_hz: float = 100.0, seed: int = 0, touch=None, sensor=None,
                 model_config=None):
        from ..sim.sensor import BiotacModel, SensorInputs

        self.pty = Pty("biotac")
        self.fingers = tuple(fingers)
        self.rate_hz = rate_hz
        self.rng = np.random.default_rng(seed)
        self.model = BiotacModel(self.fingers, model_config or sensor_model_config(), self.rng, 1.0 / rate_hz, sensor)
        F = len(self.fingers)
        self.inputs = SensorInputs(np.zeros((F, self.model.N)), np.zeros(F), np.zeros(F), np.zeros(F))
        self.touch = touch
        self.t0 = time.monotonic()
        self.seq = 0
        self.lock = threading.Lock()
        self.pending_garbage = 0
        self.truncate_left = 0
        self.corrupt_left = 0
        self.whole: list[int] = []
        self.truncated: list[int] = []
        self.corrupted: list[int] = []
        self.dropped: list[int] = []
        self.sent: list[float] = []
        self.thread = _Periodic(1.0 / rate_hz, self._tick, "biotac-bridge", catch_up=True)

    def _tick(self, k: int, now: float) -> None:
        """Sample, encode and send frame ``k``, scheduled (and dated) at monotonic ``now``."""
        if self.pty.closed:
            return
        t = now - self.t0
        if self.touch is not None:
            self.inputs = self.touch.inputs(now)
        e, pdc, tdc, tac, pac = self.model.frame(t, self.inputs)
        self.seq += 1
        frame = encode_frame(self.seq, int(t * 1e6), self.fingers, e, pdc, tdc, tac, pac)
        with self.lock:
            garbage, self.pending_garbage = self.pending_garbage, 0
            kind = "whole"
            if self.truncate_left:
                self.truncate_left -= 1
                frame, kind = frame[:int(len(frame) * self.rng.uniform(0.2, 0.8))], "truncated"
            elif self.corrupt_left:
                self.corrupt_left -= 1
                b = bytearray(frame)
                b[30 + int(self.rng.integers(0, len(b) - 40))] ^= 0x5A
                frame, kind = bytes(b), "corrupted"
        if garbage:
            self.pty.write(self.rng.integers(0, 256, garbage, dtype=np.uint8).tobytes())
        self.sent.append(time.monotonic())
        sent = self.pty.write(frame)
        log = {"whole": self.whole, "truncated": self.truncated, "corrupted": self.corrupted}[kind]
        (log if sent else self.dropped).append(self.seq)


# ============================================================================ pump and scale
class EmulatedPump:
    """Shared by the pump (which changes it) and the scale (which weighs the reservoir);
    ``shared`` (a :class:`~.touch.PumpFile`) passes the flow on to the emulated world."""

    def __init__(self, max_rate_ml_min: float, shared=None):
        self.shared = shared
        self.max_rate = max_rate_ml_min
        self.rate = 0.0
        self.total_ml = 0.0
        self.target_ml: float | None = None        # total at which a volume dispense ends
        self.t_last = time.monotonic()
        self.lock = threading.Lock()
        self.done_events = 0
        self.done_unsent = 0                        # finished dispenses the pump has not announced yet

    def advance(self) -> bool:
        """Integrate the flow up to now; True when a volume dispense just finished (whoever
        advances it, the pump announces it: :attr:`done_unsent`)."""
        now = time.monotonic()
        with self.lock:
            self.total_ml += self.rate * (now - self.t_last) / 60.0
            self.t_last = now
            done = self.target_ml is not None and self.total_ml >= self.target_ml
            if done:
                self.total_ml, self.rate, self.target_ml = self.target_ml, 0.0, None
                self.done_events += 1
                self.done_unsent += 1
            if self.shared is not None:
                self.shared.write(now, self.rate, self.total_ml)
        return done

    def set(self, rate: float, target_ml: float | None) -> None:
        """Run at ``rate`` ml/min until ``target_ml`` (total; ``None``: on) — shared at once."""
        with self.lock:
            self.rate, self.target_ml = rate, target_ml
            if self.shared is not None:
                self.shared.write(time.monotonic(), self.rate, self.total_ml)


class PumpDevice:
    """EZO-PMP-like command interpreter on a pty (commands and replies end with CR)."""

    def __init__(self, state: EmulatedPump):
        self.pty = Pty("pump")
        self.state = state
        self.commands = 0
        self.errors = 0
        self._pending = b""
        self.thread = _Periodic(0.005, self._tick, "pump")

    def _tick(self, k: int, now: float) -> None:
        if self.pty.closed:
            return
        s = self.state
        s.advance()
        with s.lock:
            done, s.done_unsent = s.done_unsent, 0
        for _ in range(done):
            self.pty.write(b"*DONE\r")
        data = self.pty.read()
        if not data:
            return
        *lines, self._pending = (self._pending + data).replace(b"\n", b"\r").split(b"\r")
        for raw in lines:
            if raw.strip():
                self.commands += 1
                reply = self.handle(raw.decode("ascii", "replace").strip())
                self.errors += reply.endswith("*ER")
                self.pty.write("".join(f"{r}\r" for r in reply.split("\n")).encode())

    def handle(self, cmd: str) -> str:
        """One command → reply lines joined by newlines (the last is ``*OK`` or ``*ER``)."""
        s = self.state
        self.state.advance()
        parts = cmd.split(",")
        head = parts[0].upper()
        try:
            if head == "I" and len(parts) == 1:
                return f"?I,PMP,{FIRMWARE}\n*OK"
            if head == "X" and len(parts) == 1:
                s.set(0.0, None)
                return "*OK"
            if head == "D" and parts[1:] == ["?"]:
                return f"?D,{s.rate:.3f},{int(s.rate > 0)}\n*OK"
            if head == "TV" and parts[1:] == ["?"]:
                return f"?TV,{s.total_ml:.3f}\n*OK"
            if head == "CLEAR" and len(parts) == 1:
                with s.lock:
                    s.total_ml = 0.0
                return "*OK"
            if head == "DC" and len(parts) == 3:
                return self._dispense(parts[1], parts[2])
        except (ValueError, IndexError):
            pass
        return "*ER"

    def _dispense(self, first: str, second: str) -> str:
        s = self.state
        if second == "*":                                   # DC,<rate>,*: continuous
            rate, target = float(first), None
        else:                                               # DC,<volume>,<minutes>
            volume, minutes = float(first), float(second)
            if not (volume > 0 and minutes > 0):
                return "*ER"
            rate, target = volume / minutes, s.total_ml + volume
        if not 0 < rate <= s.max_rate * (1 + 1e-6):
            return "*ER"
        s.set(rate, target)
        return "*OK"


class ScaleDevice:
    """A&D-like balance streaming weight lines at ``rate_hz``; ``T`` tares (ACK reply)."""

    def __init__(self, state: EmulatedPump, reservoir_g: float = 1500.0, rate_hz: float = 10.0,
                 noise_g: float = 0.05, seed: int = 0):
        self.pty = Pty("scale")
        self.state, self.reservoir_g, self.noise_g = state, reservoir_g, noise_g
        self.rng = np.random.default_rng(seed + 1)
        self.tare_g: float | None = None
        self.history: list[float] = []
        self.lines = 0
        self.thread = _Periodic(1.0 / rate_hz, self._tick, "scale")

    def gross_g(self) -> float:
        self.state.advance()
        return self.reservoir_g - self.state.total_ml

    def _tick(self, k: int, now: float) -> None:
        if self.pty.closed:
            return
        if b"T" in self.pty.read().upper():
            self.tare_g = self.gross_g()
            self.pty.write(b"\x06\r\n")
        gross = self.gross_g()
        self.history = (self.history + [gross])[-5:]
        stable = max(self.history) - min(self.history) < 0.02
        net = gross - (self.tare_g or 0.0) + float(self.rng.normal(0, self.noise_g))
        line = format_weight_line(net, stable, net=self.tare_g is not None)
        if self.pty.write(line.encode() + b"\r\n"):
            self.lines += 1


# ============================================================================ the process
class SerialLab:
    """The three devices of one emulator process."""

    def __init__(self, fingers=FINGERS, rate_hz: float = 100.0, seed: int = 0,
                 pump_max_rate_ml_min: float = 150.0, reservoir_g: float = 1500.0, touch=None, sensor=None,
                 model_config=None):
        self.biotac = BiotacBridge(fingers, rate_hz, seed, touch, sensor, model_config)
        self.world = touch
        self.pump_state = EmulatedPump(pump_max_rate_ml_min, None if touch is None else touch.pump_writer())
        self.pump = PumpDevice(self.pump_state)
        self.scale = ScaleDevice(self.pump_state, reservoir_g, seed=seed)
        self.devices = {"biotac": self.biotac, "pump": self.pump, "scale": self.scale}

    def start(self) -> None:
        for d in self.devices.values():
            d.thread.start()

    def ports(self) -> dict[str, str]:
        return {name: d.pty.path for name, d in self.devices.items()}

    def control(self, line: str) -> str:
        """One stdin control line → its reply line."""
        words = line.split()
        if not words:
            return "ERR empty command"
        cmd, args = words[0], words[1:]
        b = self.biotac
        if cmd in ("garbage", "truncate", "corrupt") and len(args) == 1 and args[0].isdigit():
            with b.lock:
                attr = {"garbage": "pending_garbage", "truncate": "truncate_left", "corrupt": "corrupt_left"}[cmd]
                setattr(b, attr, getattr(b, attr) + int(args[0]))
                return f"OK {json.dumps({'after_seq': b.seq})}"
        if cmd == "disconnect" and len(args) == 1 and args[0] in self.devices:
            self.devices[args[0]].pty.close()
            return f"OK {json.dumps({'disconnected': args[0], 'time': time.monotonic()})}"
        if cmd == "stats":
            return "OK " + json.dumps({"seq": b.seq, "whole": b.whole, "truncated": b.truncated,
                                       "corrupted": b.corrupted, "dropped": b.dropped,
                                       "overruns": {n: d.pty.overruns for n, d in self.devices.items()},
                                       "pump": {"rate": self.pump_state.rate, "total_ml": self.pump_state.total_ml,
                                                "commands": self.pump.commands, "errors": self.pump.errors},
                                       "scale": {"lines": self.scale.lines, "tare_g": self.scale.tare_g},
                                       "world": None if self.world is None else self.world.state()})
        if cmd == "frames" and len(args) == 2 and all(a.isdigit() for a in args):
            return "OK " + json.dumps(frame_times(b.sent, int(args[0]), int(args[1])))
        return (f"ERR unknown command {line!r}; expected garbage N, truncate K, corrupt K, disconnect DEVICE, "
                f"stats, frames A B")


def link_ports(ports: dict[str, str], link_dir: str) -> None:
    """Stable symlinks ``link_dir/<device>`` → the pty paths (replacing old ones)."""
    d = Path(link_dir)
    d.mkdir(parents=True, exist_ok=True)
    for name, path in ports.items():
        link = d / name
        if link.is_symlink() or link.exists():
            link.unlink()
        link.symlink_to(path)


class SerialDevicesEmulator(EmulatorProcess):
    """The serial emulator as a child process; ``ports`` maps device → pty path.

        with SerialDevicesEmulator() as emu:
            SerialPump(SerialPumpConfig(port=emu.ports["pump"]))
            emu.command("garbage 200")
    """

    def __init__(self, fingers=FINGERS, rate_hz: float = 100.0, seed: int = 0, link_dir: str | None = None,
                 pump_max_rate_ml_min: float = 150.0, world_dir: str | None = None, surface: str = "straws",
                 sensor: str = "biotac_sp", shear_kohm_per_n: float | None = None):
        args = ["--fingers", ",".join(fingers), "--rate", rate_hz, "--seed", seed,
                "--pump-max-rate", pump_max_rate_ml_min, "--sensor", sensor]
        if shear_kohm_per_n is not None:
            args += ["--shear-kohm-per-n", shear_kohm_per_n]
        if link_dir:
            args += ["--link-dir", link_dir]
        if world_dir:
            args += ["--world-dir", world_dir, "--surface", surface]
        super().__init__("tactile_flow.hardware.emulators.serial_devices", args)

    @property
    def ports(self) -> dict[str, str]:
        return {k: self.ready[k] for k in ("biotac", "pump", "scale")}

    @property
    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def stats(self) -> dict:
        return json.loads(self.command("stats"))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description="BioTac bridge, pump and scale emulators on ptys")
    p.add_argument("--fingers", default=",".join(FINGERS))
    p.add_argument("--rate", type=float, default=100.0, help="BioTac frame rate (Hz)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--pump-max-rate", type=float, default=150.0, help="ml/min")
    p.add_argument("--link-dir", default=None)
    p.add_argument("--world-dir", default=None,
                   help="the emulated world's shared files (touch.py): the BioTacs press on the board under the "
                        "emulated arm and hold the bottle the pump fills")
    p.add_argument("--surface", default="straws", help="the board pressed on (conf/surface/NAME.yaml; none: no board)")
    p.add_argument("--sensor", default="biotac_sp", help="the BioTacs' sensor model: a name (conf/sensor/) or a .yaml")
    p.add_argument("--shear-kohm-per-n", type=float, default=None,
                   help="the BioTacs' shear response, kΩ per N (hardware.sensor.shear_kohm_per_n; default: the simulator's)")
    a = p.parse_args(argv)
    fingers = [f for f in a.fingers.split(",") if f]
    bad = [f for f in fingers if f not in FINGERS]
    if bad:
        p.error(f"--fingers: unknown {bad}; expected names of {FINGERS}")
    sensor = emulated_sensor(a.sensor, p)
    touch = None
    sensor = emulated_sensor(a.sensor, p)
    touch = None
    if a.world_dir:
        from .touch import EmulatedWorld
        touch = EmulatedWorld(a.world_dir, None if a.surface == "none" else a.surface, fingers, sensor)
    lab = SerialLab(fingers, a.rate, a.seed, a.pump_max_rate, touch=touch, sensor=sensor,
                    model_config=sensor_model_config(a.shear_kohm_per_n, p))
    if a.link_dir:
        link_ports(lab.ports(), a.link_dir)
    lab.start()
    print("READY " + " ".join(f"{k}={v}" for k, v in lab.ports().items()), flush=True)
    for line in sys.stdin:                     # control channel; EOF (parent gone) ends the process
        print(lab.control(line.strip()), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())

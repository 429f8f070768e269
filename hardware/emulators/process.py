"""An emulator as a child process: ``python -m <module> <args>`` prints one ``READY key=value ...``
line once it listens, takes control commands on its stdin (``OK ...`` / ``ERR ...`` replies) and
stops on SIGTERM. Emulators run as processes because ur_rtde's constructors hold the GIL: an
emulator thread inside the client's process can deadlock. Every emulator's wrapper is an
:class:`EmulatorProcess`.
"""

from __future__ import annotations

import math
import os
import queue
import signal
import subprocess
import sys
import threading
import time


class EmulatorError(RuntimeError):
    """An emulator process did not start, or did not answer a control command."""


class EmulatorProcess:
    """A ``python -m <module> <args>`` child: waits for its READY line, sends control commands
    on its stdin, stops it by PID.

    ``ready`` holds the READY line's ``key=value`` fields (addresses, ports, pty paths).
    """

    def __init__(self, module: str, args=(), ready_timeout_s: float = 20.0):
        self.module, self.args = module, [str(a) for a in args]
        self.ready_timeout_s = ready_timeout_s
        self.proc: subprocess.Popen | None = None
        self.ready: dict[str, str] = {}
        self._lines: queue.Queue[str | None] = queue.Queue()

    @property
    def pid(self) -> int:
        return self.proc.pid

    def start(self) -> "EmulatorProcess":
        env = {**os.environ, "PYTHONUNBUFFERED": "1"}
        self.proc = subprocess.Popen([sys.executable, "-m", self.module, *self.args], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
        threading.Thread(target=self._pump_stdout, daemon=True).start()
        line = self._expect("READY", self.ready_timeout_s)
        self.ready = dict(f.split("=", 1) for f in line.split()[1:] if "=" in f)
        return self

    def command(self, text: str, timeout_s: float = 5.0) -> str:
        """Send one control line; return the emulator's ``OK ...`` reply (``ERR ...`` raises)."""
        try:
            self.proc.stdin.write(text + "\n")
            self.proc.stdin.flush()
        except (BrokenPipeError, OSError) as exc:
            raise EmulatorError(f"{self.module}: cannot send {text!r}: {exc}") from exc
        line = self._expect(("OK", "ERR"), timeout_s)
        if line.startswith("ERR"):
            raise EmulatorError(f"{self.module}: {text!r} → {line}")
        return line[2:].strip()

    def kill(self) -> None:
        """SIGKILL, as a crash would (no goodbye on any socket or pty)."""
        if self.proc and self.proc.poll() is None:
            os.kill(self.proc.pid, signal.SIGKILL)
            self.proc.wait(timeout=5)

    def stop(self) -> None:
        """SIGTERM, then SIGKILL after 3 s."""
        if self.proc is None or self.proc.poll() is not None:
            return
        os.kill(self.proc.pid, signal.SIGTERM)
        try:
            self.proc.wait(timeout=3)
        except subprocess.TimeoutExpired:
            self.kill()

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()

    def _pump_stdout(self) -> None:
        for line in self.proc.stdout:
            self._lines.put(line.rstrip("\n"))
        self._lines.put(None)

    def _expect(self, prefixes, timeout_s: float) -> str:
        prefixes = (prefixes,) if isinstance(prefixes, str) else tuple(prefixes)
        end, seen = time.monotonic() + timeout_s, []
        while True:
            try:
                line = self._lines.get(timeout=max(0.0, end - time.monotonic()))
            except queue.Empty:
                raise EmulatorError(f"{self.module}: no {'/'.join(prefixes)} line within {timeout_s} s; "
                                    f"output: {seen[-10:]}") from None
            if line is None:
                raise EmulatorError(f"{self.module}: exited (code {self.proc.wait()}); output: {seen[-10:]}")
            if line.startswith(prefixes):
                return line
            seen.append(line)


def emulated_sensor(value: str, parser):
    """The :class:`tactile.sensor.SensorModel` an emulator's ``--sensor`` names: a built-in
    model (``biotac_sp``, ``biotac``) or a sensor ``.yaml`` file; ``parser.error`` (one line,
    exit 2) otherwise."""
    from tactile_flow.tactile.sensor import SensorModelError, builtin_sensor, load_sensor_file
    try:
        return load_sensor_file(value) if value.endswith((".yaml", ".yml")) else builtin_sensor(value)
    except SensorModelError as exc:
        parser.error(f"--sensor: {exc}")


def sensor_model_config(shear_kohm_per_n: float | None = None, parser=None):
    """The emulated BioTacs' :class:`hardware.config.SensorModelConfig`: the simulator's
    defaults, with ``--shear-kohm-per-n`` (``hardware.sensor.shear_kohm_per_n`` of a run) when
    given, so an emulated lab can be run at the shear gain a simulated run is. A value that is
    not a number ≥ 0 is ``parser.error`` (one line, exit 2), or ValueError without a parser."""
    from ..config import SensorModelConfig
    if shear_kohm_per_n is None:
        return SensorModelConfig()
    if not (math.isfinite(shear_kohm_per_n) and shear_kohm_per_n >= 0):
        msg = f"--shear-kohm-per-n: expected a number of kΩ per N >= 0, got {shear_kohm_per_n}"
        if parser is not None:
            parser.error(msg)
        raise ValueError(msg)
    return SensorModelConfig(shear_kohm_per_n=float(shear_kohm_per_n))


def free_loopback(subnet: int, port: int = 30004, tries: int = 50) -> str | None:
    """A loopback address ``127.0.<subnet>.<n>`` on which TCP ``port`` is free, or None after
    ``tries``: the UR controller emulator's ports are fixed (RTDE 30004, dashboard 29999), so
    emulated labs running side by side (test workers, benchmarks) need an address each."""
    import random
    import socket
    for _ in range(tries):
        host = f"127.0.{subnet}.{random.randint(2, 250)}"
        with socket.socket() as s:
            try:
                s.bind((host, port))
                return host
            except OSError:
                continue
    return None

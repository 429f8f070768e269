"""Pour devices on serial lines (pyserial): a peristaltic pump and a streaming scale.

Both speak ASCII line protocols specified in ``docs/serial_protocol.md``:

- :class:`SerialPump`: modelled on the Atlas Scientific EZO-PMP UART commands
  (``DC,<ml/min>,*`` pump at a rate, ``DC,<ml>,<min>`` dispense a volume, ``X`` stop,
  ``D,?``/``TV,?`` status, ``*OK``/``*ER`` replies, ``*DONE`` when a volume is dispensed).
- :class:`SerialScale`: an A&D-style balance streaming ``ST,GS,+  4.876kg`` lines
  (``ST`` stable, ``US`` unstable, ``OL`` overload; ``GS`` gross, ``NT`` net), ``T`` tares.

Neither device has a clock of its own, so every sample's ``device_time`` is its host
receipt time. A reader thread per port parses lines as they arrive; nothing the recorder
calls blocks on the wire.
"""

from __future__ import annotations

import math
import queue
import re
import threading
from dataclasses import dataclass, field

from .device import Clock, DeviceIdentity, SampleBuffer, WallClock, batch_times
from .errors import (BUFFER_RANGE_S, RATE_RANGE_HZ, DeviceDisconnectedError, DeviceFaultError, DeviceTimeoutError,
                     NotConnectedError, require_positive, require_within)
from .pour import Pump, PumpState, Scale, ScaleReading
from .serial_biotac import open_serial


class LinePort:
    """A serial port read line by line on a thread; lines go to ``on_line(text, host_time)``.

    Lines read together get receipt times spread back from the read, ``line_period_s``
    apart (the device's line rate) but never back to the line before: strictly increasing.

    ``lost`` holds the reason once the port fails (the device vanished, the pty closed).
    """

    def __init__(self, port: str, baudrate: int, who: str, key: str, on_line, clock: Clock,
                 eol: bytes = b"\r", line_period_s: float = 0.0):
        self.port, self.who, self.on_line, self.clock, self.eol = port, who, on_line, clock, eol
        self.line_period_s = line_period_s
        self._last_time: float | None = None
        self.serial = open_serial(port, baudrate, who, key)
        self.serial.reset_input_buffer()
        self.lost: str | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name=f"serial-{who}", daemon=True)
        self._thread.start()

    def write_line(self, text: str) -> None:
        """Send ``text`` + EOL; a failure marks the port lost and raises DeviceDisconnectedError."""
        import serial

        try:
            self.serial.write(text.encode("ascii") + self.eol)
        except (serial.SerialException, OSError) as exc:
            self.lost = self.lost or f"{self.who}: serial link {self.port} lost ({exc})"
            raise DeviceDisconnectedError(self.lost) from exc

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=1.0)
        try:
            self.serial.close()
        except Exception:  # the device may already be gone; the port is closed either way
            pass

    def _loop(self) -> None:
        import serial

        pending = bytearray()
        while not self._stop.is_set():
            try:
                data = self.serial.read(self.serial.in_waiting or 1)
            except (serial.SerialException, OSError, TypeError, AttributeError) as exc:
                if not self._stop.is_set():
                    self.lost = f"{self.who}: serial link {self.port} lost ({exc})"
                return
            if not data:
                continue
            pending += data.replace(b"\n", b"\r")
            *lines, rest = pending.split(b"\r")
            pending = bytearray(rest)
            lines = [raw for raw in lines if raw]
            if not lines:
                continue
            # lines read together arrived over the time since the previous ones: spread them
            # back from now, so no two get the same receipt time
            times = batch_times([self.clock.now()], [len(lines)], self.line_period_s, self._last_time)
            self._last_time = float(times[-1])
            for raw, t in zip(lines, times):
                self.on_line(raw.decode("ascii", "replace").strip(), float(t))


# ============================================================================ pump
@dataclass
class SerialPumpConfig:
    """EZO-PMP-like peristaltic pump.

    Attributes:
        port: pyserial URL. baudrate: bits/s (EZO default 9600).
        max_rate_ml_min: the largest rate (ml/min) the driver will command.
        poll_hz: status samples per second recorded by :meth:`SerialPump.read_states`.
        timeout_s: the longest wait (s) for a reply to one command.
        buffer_s: seconds of samples kept before the oldest are dropped.
    """

    port: str = "/dev/ttyUSB0"
    baudrate: int = 9600
    max_rate_ml_min: float = 105.0
    poll_hz: float = 10.0
    timeout_s: float = 1.0
    buffer_s: float = 600.0
    key: str = field(default="hardware.pump", repr=False)

    def __post_init__(self):
        require_positive(self, ("max_rate_ml_min", "poll_hz", "timeout_s", "buffer_s"), self.key)
        require_within(self, ("poll_hz",), RATE_RANGE_HZ, "Hz", self.key)
        require_within(self, ("buffer_s",), BUFFER_RANGE_S, "s", self.key)


class SerialPump(Pump):
    """Peristaltic pump over an ASCII line protocol; a poll thread records its status."""

    model = "peristaltic pump (EZO-PMP protocol)"

    def __init__(self, cfg: SerialPumpConfig, clock: Clock | None = None):
        self.cfg = cfg
        self.clock = clock or WallClock()
        self._port: LinePort | None = None
        self._lock = threading.Lock()                  # one command/reply exchange at a time
        self._replies: queue.Queue[str] = queue.Queue()
        self._buffer = SampleBuffer(cfg.buffer_s * cfg.poll_hz)
        self._stop = threading.Event()
        self._poller: threading.Thread | None = None
        self._firmware = "?"
        self.done_count = 0                            # ``*DONE`` messages seen (volume dispensed)
        self.poll_errors = 0
        self._last_poll_error: str | None = None
        self._last_status: float | None = None         # host time of the last status reply

    @property
    def identity(self) -> DeviceIdentity:
        return DeviceIdentity(self.model, self.cfg.port, self._firmware)

    @property
    def is_connected(self) -> bool:
        return self._port is not None and self._port.lost is None

    def connect(self) -> None:
        """Open the port, identify the pump (``i``), start polling its status."""
        if self._port is not None:
            return
        self._port = LinePort(self.cfg.port, self.cfg.baudrate, self.kind, f"{self.cfg.key}.port",
                              self._on_line, self.clock)
        try:
            reply = self._command("i", query=True, hint="is the pump powered, in UART mode, at this baud rate?")
            self._firmware = reply.split(",", 2)[-1] if reply.startswith("?I,PMP") else reply
            if not reply.startswith("?I,PMP"):
                raise DeviceFaultError(f"{self.kind}: {self.cfg.port} answered {reply!r} to 'i', not a pump "
                                       f"(expected ?I,PMP,<firmware>); check {self.cfg.key}.port")
        except Exception:
            self.close()
            raise
        self._stop.clear()
        self._last_status = self.clock.now()
        self._poller = threading.Thread(target=self._poll_loop, name="pump-poll", daemon=True)
        self._poller.start()

    def close(self) -> None:
        self._stop.set()
        if self._poller is not None:
            self._poller.join(timeout=2.0)
            self._poller = None
        if self._port is not None:
            self._port.close()
            self._port = None

    def set_rate(self, ml_per_min: float) -> None:
        """Pump continuously at ``ml_per_min`` (ml/min); 0 stops."""
        rate = self._check_rate(ml_per_min, "ml_per_min")
        self._command("X" if rate == 0 else f"DC,{rate:.3f},*")

    def dispense(self, volume_ml: float, ml_per_min: float | None = None) -> None:
        """Dispense ``volume_ml`` (ml) at ``ml_per_min`` (default the maximum); returns at once."""
        if not (isinstance(volume_ml, (int, float)) and math.isfinite(volume_ml) and volume_ml > 0):
            raise ValueError(f"volume_ml: expected a volume > 0 ml, got {volume_ml!r}")
        rate = self._check_rate(self.cfg.max_rate_ml_min if ml_per_min is None else ml_per_min, "ml_per_min")
        if rate == 0:
            raise ValueError("ml_per_min: a volume cannot be dispensed at 0 ml/min")
        self._command(f"DC,{volume_ml:.3f},{volume_ml / rate:.5f}")

    def stop(self) -> None:
        self._command("X")

    def status(self) -> PumpState:
        """Query rate (``D,?``) and total volume (``TV,?``)."""
        d = self._command("D,?", query=True)
        tv = self._command("TV,?", query=True)
        try:
            _, rate, running = d.split(",")
            dispensed = float(tv.split(",")[1])
            now = self.clock.now()
            return PumpState(now, now, float(rate), dispensed, running.strip() == "1")
        except (ValueError, IndexError) as exc:
            raise DeviceFaultError(f"{self.kind}: malformed status replies {d!r}, {tv!r}") from exc

    def read_states(self) -> list[PumpState]:
        self._require_alive()
        return self._buffer.drain()

    def check_link(self) -> None:
        """A lost port, or (while polling) no status reply for ``timeout_s`` + two poll periods:
        a pump that stopped answering may still be pumping."""
        self._require_alive()
        last, limit = self._last_status, self.cfg.timeout_s + 2.0 / self.cfg.poll_hz
        if self._poller is not None and last is not None and self.clock.now() - last > limit:
            raise DeviceTimeoutError(f"{self.kind}: no status reply on {self.cfg.port} for "
                                     f"{self.clock.now() - last:.2f} s (> {self.cfg.key}.timeout_s + 2 poll periods "
                                     f"= {limit:g} s)")

    def wire_report(self) -> dict:
        return {"refused": self.poll_errors, "reasons": {"status poll failed": self.poll_errors} if self.poll_errors
                else {}, "last": self._last_poll_error}

    # -- internals -----------------------------------------------------------------
    def _check_rate(self, rate, name: str) -> float:
        mx = self.cfg.max_rate_ml_min
        if not (isinstance(rate, (int, float)) and math.isfinite(rate) and 0 <= rate <= mx):
            raise ValueError(f"{name}: pump rate {rate!r} ml/min outside [0, {self.cfg.key}.max_rate_ml_min={mx}]")
        return float(rate)

    def _require_alive(self) -> None:
        if self._port is None:
            raise NotConnectedError(f"{self.kind}: not connected (call connect() first)")
        if self._port.lost:
            raise DeviceDisconnectedError(self._port.lost)

    def _on_line(self, line: str, host_time: float) -> None:
        if line.startswith("*DONE"):
            self.done_count += 1
        else:
            self._replies.put(line)

    def _command(self, cmd: str, query: bool = False, hint: str = "") -> str:
        """Send ``cmd``; return the ``?...`` reply of a query (else ``*OK``). ``*ER`` → DeviceFaultError."""
        self._require_alive()
        with self._lock:
            while not self._replies.empty():
                self._replies.get_nowait()
            self._port.write_line(cmd)
            answer = None
            while True:
                line = self._reply(cmd, hint)
                if line == "*ER":
                    raise DeviceFaultError(f"{self.kind}: the pump refused {cmd!r} (*ER)")
                if line == "*OK":
                    return answer if query and answer is not None else line
                answer = line

    def _reply(self, cmd: str, hint: str) -> str:
        try:
            return self._replies.get(timeout=self.cfg.timeout_s)
        except queue.Empty:
            self._require_alive()
            raise DeviceTimeoutError(f"{self.kind}: no reply to {cmd!r} on {self.cfg.port} within "
                                     f"{self.cfg.key}.timeout_s={self.cfg.timeout_s} s"
                                     + (f"; hint: {hint}" if hint else "")) from None

    def _poll_loop(self) -> None:
        period = 1.0 / self.cfg.poll_hz
        while not self._stop.wait(period):
            try:
                state = self.status()
            except (DeviceDisconnectedError, NotConnectedError):
                return
            except Exception as exc:  # one missed sample; the recorder sees the gap
                self.poll_errors += 1
                self._last_poll_error = f"{type(exc).__name__}: {exc}"
                continue
            self._last_status = state.host_time
            self._buffer.put(state)


# ============================================================================ scale
LINE = re.compile(r"^(ST|US|OL),(GS|NT),([+-])\s*([0-9]*\.?[0-9]+)\s*(kg|g)$")
ACK = "\x06"
GRAMS = {"g": 1.0, "kg": 1000.0}


@dataclass
class SerialScaleConfig:
    """A&D-style streaming balance.

    Attributes:
        port: pyserial URL. baudrate: bits/s (A&D default 2400; 9600 common).
        rate_hz: nominal reading rate (Hz), sizes the buffer.
        first_reading_timeout_s: ``connect()`` fails without a reading within this (s).
        stale_timeout_s: after the first reading, a silence this long (s) is a timeout error.
        timeout_s: the longest wait (s) for the tare acknowledgement.
        buffer_s: seconds of readings kept before the oldest are dropped.
    """

    port: str = "/dev/ttyUSB1"
    baudrate: int = 9600
    rate_hz: float = 10.0
    first_reading_timeout_s: float = 2.0
    stale_timeout_s: float = 2.0
    timeout_s: float = 1.0
    buffer_s: float = 600.0
    key: str = field(default="hardware.scale", repr=False)

    def __post_init__(self):
        require_positive(self, ("rate_hz", "first_reading_timeout_s", "stale_timeout_s", "timeout_s", "buffer_s"), self.key)
        require_within(self, ("rate_hz",), RATE_RANGE_HZ, "Hz", self.key)
        require_within(self, ("buffer_s",), BUFFER_RANGE_S, "s", self.key)


class SerialScale(Scale):
    """Streaming balance; readings parsed on the port's reader thread."""

    model = "balance (A&D-style stream)"

    def __init__(self, cfg: SerialScaleConfig, clock: Clock | None = None):
        self.cfg = cfg
        self.clock = clock or WallClock()
        self._port: LinePort | None = None
        self._buffer = SampleBuffer(cfg.buffer_s * cfg.rate_hz)
        self._last: ScaleReading | None = None
        self._first = threading.Event()
        self._ack = threading.Event()
        self.overloaded = False
        self.unparsed = 0                             # lines that were neither a reading nor an ACK
        self._last_unparsed: str | None = None

    @property
    def identity(self) -> DeviceIdentity:
        return DeviceIdentity(self.model, self.cfg.port, "unknown")

    @property
    def is_connected(self) -> bool:
        return self._port is not None and self._port.lost is None

    def connect(self) -> None:
        """Open the port and wait for the first weight line."""
        if self._port is not None:
            return
        self._first.clear()
        self._port = LinePort(self.cfg.port, self.cfg.baudrate, self.kind, f"{self.cfg.key}.port",
                              self._on_line, self.clock, eol=b"\r\n", line_period_s=1.0 / self.cfg.rate_hz)
        if not self._first.wait(self.cfg.first_reading_timeout_s):
            lost = self._port.lost
            self.close()
            if lost:
                raise DeviceDisconnectedError(lost)
            raise DeviceTimeoutError(f"{self.kind}: no weight line on {self.cfg.port} within "
                                     f"{self.cfg.first_reading_timeout_s} s; hint: set the balance to stream "
                                     f"(A&D: prt 'stream' mode) at {self.cfg.baudrate} baud")

    def close(self) -> None:
        if self._port is not None:
            self._port.close()
            self._port = None

    def mass(self) -> float:
        """Latest mass (g), net of the last tare."""
        self._require_alive()
        if self.overloaded:
            raise DeviceFaultError(f"{self.kind}: overload (OL) on {self.cfg.port}")
        return self._last.mass_g

    @property
    def stable(self) -> bool:
        self._require_alive()
        return self._last.stable

    def tare(self) -> None:
        """Send ``T`` and wait for the balance's ACK (0x06)."""
        self._require_alive()
        self._ack.clear()
        self._port.write_line("T")
        if not self._ack.wait(self.cfg.timeout_s):
            self._require_alive()
            raise DeviceTimeoutError(f"{self.kind}: no ACK to tare within {self.cfg.key}.timeout_s="
                                     f"{self.cfg.timeout_s} s")

    def read(self) -> list[ScaleReading]:
        self._require_alive()
        return self._buffer.drain()

    def check_link(self) -> None:
        self._require_alive()

    def wire_report(self) -> dict:
        return {"refused": self.unparsed, "reasons": {"not a weight line": self.unparsed} if self.unparsed else {},
                "last": self._last_unparsed}

    # -- internals -----------------------------------------------------------------
    def _require_alive(self) -> None:
        if self._port is None:
            raise NotConnectedError(f"{self.kind}: not connected (call connect() first)")
        if self._port.lost:
            raise DeviceDisconnectedError(self._port.lost)
        last = self._last
        if last is not None and self.clock.now() - last.host_time > self.cfg.stale_timeout_s:
            raise DeviceTimeoutError(f"{self.kind}: no weight line on {self.cfg.port} for "
                                     f"{self.clock.now() - last.host_time:.2f} s "
                                     f"(> {self.cfg.key}.stale_timeout_s={self.cfg.stale_timeout_s})")

    def _on_line(self, line: str, host_time: float) -> None:
        if line == ACK:
            self._ack.set()
            return
        reading = parse_weight_line(line, host_time)
        if reading is None:
            self.unparsed += 1
            self._last_unparsed = f"scale: {line[:40]!r} is not a weight line"
            return
        self.overloaded = line.startswith("OL")
        if self.overloaded:
            return
        self._buffer.put(reading)
        self._last = reading
        self._first.set()


def parse_weight_line(line: str, host_time: float = 0.0) -> ScaleReading | None:
    """``ST,GS,+  4.876kg`` → ScaleReading(mass_g=4876.0, stable=True); None if malformed."""
    m = LINE.match(line.strip())
    if m is None:
        return None
    stab, _kind, sign, number, unit = m.groups()
    grams = float(number) * GRAMS[unit] * (-1.0 if sign == "-" else 1.0)
    return ScaleReading(host_time, host_time, grams, stab == "ST")


def format_weight_line(grams: float, stable: bool, net: bool, unit: str = "g") -> str:
    """The line a balance sends for ``grams``: ``ST,NT,+  123.45 g`` (sign, 7-char value, unit)."""
    value = abs(grams) / GRAMS[unit]
    digits = 3 if unit == "kg" else 2
    return (f"{'ST' if stable else 'US'},{'NT' if net else 'GS'},{'-' if grams < 0 else '+'}"
            f"{value:>7.{digits}f}{unit:>2}")

"""BioTac SP sensors read from a microcontroller bridge over a serial line (pyserial).

The bridge samples up to five BioTacs and sends one binary frame per 100 Hz period; the
format (sync bytes, header with length and sequence number, per-finger payload, CRC-16)
is specified in ``docs/serial_protocol.md`` and implemented by :func:`encode_frame` and
:class:`FrameParser`. :class:`SerialBiotacs` opens the port (any pyserial URL: a device
path, a pty, ``loop://``, ``socket://host:port``), reads it on its own thread, and buffers
decoded frames, so :meth:`~SerialBiotacs.read` and :meth:`~SerialBiotacs.latest` never
block the recorder or the run engine.

    with SerialBiotacs(SerialBiotacConfig(port="/dev/ttyACM0", fingers=("ff", "mf", "th"))) as bt:
        frames = bt.read()
        print(bt.stats)        # frames, dropped, corrupt, truncated, garbage_bytes, ...
"""

from __future__ import annotations

import binascii
import struct
import threading
from dataclasses import dataclass, field

import numpy as np

from .biotac import FINGERS, N_TAXELS, BiotacFrame, TactileSensors, check_fingers
from .device import Clock, DeviceIdentity, SampleBuffer, WallClock
from .errors import (BUFFER_RANGE_S, RATE_RANGE_HZ, ConfigError, DeviceDisconnectedError, DeviceFaultError,
                     DeviceTimeoutError, NotConnectedError, require_positive, require_within)

SYNC = b"\xA5\x5A"
VERSION = 1
HEADER = struct.Struct("<2sBBBBHIQ")      # sync, version, finger mask, n_pac, flags, payload len, seq, time µs
HEADER_SIZE = HEADER.size                 # 20 bytes
CRC_SIZE = 2
MAX_PAC = 44                              # PAC samples per finger and frame (2 frame periods of 2.2 kHz)
CHANNELS = N_TAXELS + 3                   # electrodes, pdc, tdc, tac (before the PAC samples)


def crc16(data: bytes) -> int:
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no final xor)."""
    return binascii.crc_hqx(data, 0xFFFF)


def mask_of(fingers) -> int:
    """Finger mask byte: bit i set for finger ``FINGERS[i]`` (ff=bit 0 ... th=bit 4)."""
    return sum(1 << FINGERS.index(f) for f in fingers)


def fingers_of(mask: int) -> tuple[str, ...]:
    return tuple(f for i, f in enumerate(FINGERS) if mask >> i & 1)


def encode_frame(seq: int, device_time_us: int, fingers, electrodes, pdc, tdc, tac, pac) -> bytes:
    """One wire frame (see ``docs/serial_protocol.md``).

    ``fingers``: names in Shadow order (F of them); ``electrodes`` (F, 24), ``pdc``/``tdc``/
    ``tac`` (F,), ``pac`` (F, n_pac) counts as int16; ``seq`` uint32 (wraps);
    ``device_time_us`` the bridge clock (µs, uint64).
    """
    F = len(fingers)
    pac = np.asarray(pac, np.int16).reshape(F, -1)
    block = np.concatenate([np.asarray(electrodes, np.int16).reshape(F, N_TAXELS),
                            np.stack([np.asarray(a, np.int16).reshape(F) for a in (pdc, tdc, tac)], 1),
                            pac], axis=1).astype("<i2").tobytes()
    head = HEADER.pack(SYNC, VERSION, mask_of(fingers), pac.shape[1], 0, len(block),
                       seq & 0xFFFFFFFF, int(device_time_us))
    body = head[2:] + block
    return SYNC + body + struct.pack("<H", crc16(body))


@dataclass(frozen=True)
class WireFrame:
    """A decoded, CRC-checked frame: counts for the fingers of ``fingers``."""

    seq: int
    device_time_us: int
    fingers: tuple[str, ...]
    electrodes: np.ndarray     # (F, 24) int16
    pdc: np.ndarray            # (F,) int16
    tdc: np.ndarray
    tac: np.ndarray
    pac: np.ndarray            # (F, n_pac) int16


@dataclass
class ParserStats:
    """Counters of a :class:`FrameParser` (all since creation).

    frames: good frames decoded. dropped: frames missing from the sequence numbers.
    corrupt: frames whose CRC failed. truncated: frames cut short by the start of the next
    one (their CRC failed and a new sync began within their length). garbage_bytes: bytes
    skipped while hunting for a sync (including headers that failed validation).
    """

    frames: int = 0
    dropped: int = 0
    corrupt: int = 0
    truncated: int = 0
    garbage_bytes: int = 0

    def as_dict(self) -> dict[str, int]:
        return dict(self.__dict__)


class FrameParser:
    """Byte stream → frames, resynchronising after garbage without losing a valid frame.

    On a CRC failure the parser advances past the failed sync only (not the whole claimed
    length), so a good frame that starts inside a truncated or corrupt one is still found.
    """

    def __init__(self):
        self.buf = bytearray()
        self.stats = ParserStats()
        self._last_seq: int | None = None

    def feed(self, data: bytes) -> list[WireFrame]:
        """Append ``data``; return every complete, valid frame it finishes (oldest first)."""
        self.buf += data
        out = []
        while True:
            frame, progressed = self._next()
            if frame is not None:
                out.append(frame)
            if not progressed:
                return out

    def _next(self) -> tuple[WireFrame | None, bool]:
        buf = self.buf
        i = buf.find(SYNC)
        if i < 0:
            keep = 1 if buf[-1:] == SYNC[:1] else 0          # a sync may straddle two reads
            self.stats.garbage_bytes += len(buf) - keep
            del buf[:len(buf) - keep]
            return None, False
        if i:
            self.stats.garbage_bytes += i
            del buf[:i]
        if len(buf) < HEADER_SIZE:
            return None, False
        _, version, mask, n_pac, _flags, length, seq, t_us = HEADER.unpack_from(buf)
        F = bin(mask).count("1")
        if version != VERSION or not 0 < mask < 32 or n_pac > MAX_PAC or length != F * (CHANNELS + n_pac) * 2:
            self.stats.garbage_bytes += 1                     # a false sync inside garbage
            del buf[:1]
            return None, True
        total = HEADER_SIZE + length + CRC_SIZE
        if len(buf) < total:
            return None, False
        (crc,) = struct.unpack_from("<H", buf, total - CRC_SIZE)
        if crc != crc16(bytes(buf[2:total - CRC_SIZE])):
            if buf.find(SYNC, 2, total) >= 0:
                self.stats.truncated += 1
            else:
                self.stats.corrupt += 1
            del buf[:2]
            return None, True
        block = np.frombuffer(bytes(buf[HEADER_SIZE:HEADER_SIZE + length]), "<i2").reshape(F, CHANNELS + n_pac)
        del buf[:total]
        self._count_seq(seq)
        block = block.astype(np.int16)
        return WireFrame(seq, t_us, fingers_of(mask), block[:, :N_TAXELS], block[:, N_TAXELS],
                         block[:, N_TAXELS + 1], block[:, N_TAXELS + 2], block[:, CHANNELS:]), True

    def _count_seq(self, seq: int) -> None:
        self.stats.frames += 1
        if self._last_seq is not None:
            gap = (seq - self._last_seq - 1) & 0xFFFFFFFF
            if gap < 1 << 31:                                  # a backwards jump is a bridge reset, not a gap
                self.stats.dropped += gap
        self._last_seq = seq


@dataclass
class SerialBiotacConfig:
    """Serial BioTac bridge.

    Attributes:
        port: pyserial URL: ``/dev/ttyACM0``, a pty path, ``loop://``, ``socket://host:port``.
        baudrate: bits/s (five fingers at 100 Hz need ≥ 520 kbit/s on a real UART; USB CDC ignores it).
        fingers: the fingers to record, Shadow order; each must be in the bridge's finger mask.
        rate_hz: nominal frame rate (Hz).
        buffer_s: seconds of frames kept for :meth:`SerialBiotacs.read` before the oldest are dropped.
        first_frame_timeout_s: ``connect()`` fails if no valid frame arrives within this (s).
        stale_timeout_s: after the first frame, a silence this long (s) is a timeout error.
    """

    port: str = "/dev/ttyACM0"
    baudrate: int = 1_000_000
    fingers: tuple[str, ...] = FINGERS
    rate_hz: float = 100.0
    buffer_s: float = 120.0
    first_frame_timeout_s: float = 2.0
    stale_timeout_s: float = 0.5
    key: str = field(default="hardware.biotac", repr=False)

    def __post_init__(self):
        self.fingers = check_fingers(self.fingers, f"{self.key}.fingers")
        require_positive(self, ("rate_hz", "buffer_s", "first_frame_timeout_s", "stale_timeout_s"), self.key)
        require_within(self, ("rate_hz",), RATE_RANGE_HZ, "Hz", self.key)
        require_within(self, ("buffer_s",), BUFFER_RANGE_S, "s", self.key)
        if not isinstance(self.port, str) or not self.port:
            raise ConfigError(f"{self.key}.port", f"expected a pyserial port or URL, got {self.port!r}")


def open_serial(port: str, baudrate: int, who: str, key: str, timeout: float = 0.02):
    """``serial.serial_for_url`` with a typed error naming the device, the port and a hint."""
    import serial

    try:
        return serial.serial_for_url(port, baudrate=baudrate, timeout=timeout, write_timeout=1.0)
    except (serial.SerialException, OSError, ValueError) as exc:
        raise NotConnectedError(f"{who}: cannot open serial port {port!r} ({exc}); hint: check {key} "
                                f"(ls /dev/serial/by-id/; for the emulated lab start tactile-emulate and "
                                f"use the ports it prints)") from exc


class SerialBiotacs(TactileSensors):
    """BioTacs on a serial bridge: a reader thread decodes frames into a bounded buffer."""

    model = "BioTac SP via serial bridge"

    def __init__(self, cfg: SerialBiotacConfig, clock: Clock | None = None):
        self.cfg = cfg
        self.clock = clock or WallClock()
        self.parser = FrameParser()
        self._serial = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._buffer = SampleBuffer(cfg.buffer_s * cfg.rate_hz)
        self._latest: BiotacFrame | None = None
        self._first = threading.Event()
        self._lost: str | None = None
        self._bridge_fingers: tuple[str, ...] = ()
        self.mismatched = 0

    # -- interface -----------------------------------------------------------------
    @property
    def overflows(self) -> int:
        """Samples lost to a full buffer (a consumer that did not drain for ``buffer_s``)."""
        return self._buffer.overflows

    @property
    def fingers(self) -> tuple[str, ...]:
        return self.cfg.fingers

    @property
    def rate_hz(self) -> float:
        return self.cfg.rate_hz

    @property
    def identity(self) -> DeviceIdentity:
        return DeviceIdentity(self.model, self.cfg.port, f"frame format v{VERSION}")

    @property
    def is_connected(self) -> bool:
        return self._serial is not None and self._lost is None

    @property
    def stats(self) -> dict[str, int]:
        """Parser counters plus ``overflows`` (frames lost to a full buffer) and ``mismatched``
        (frames lacking a configured finger)."""
        return {**self.parser.stats.as_dict(), "overflows": self.overflows, "mismatched": self.mismatched}

    def connect(self) -> None:
        """Open the port, start the reader, wait for a first valid frame carrying every configured finger."""
        if self._serial is not None:
            return
        self._serial = open_serial(self.cfg.port, self.cfg.baudrate, self.kind, f"{self.cfg.key}.port")
        self._serial.reset_input_buffer()                 # bytes queued before we opened are stale
        self._lost = None
        self._stop.clear()
        self._thread = threading.Thread(target=self._read_loop, name="serial-biotac", daemon=True)
        self._thread.start()
        try:
            self._await_first_frame()
        except Exception:
            self.close()
            raise

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=1.0)
            self._thread = None
        if self._serial is not None:
            try:
                self._serial.close()
            except Exception:  # closing a port whose device vanished may fail; it is closed either way
                pass
            self._serial = None

    def read(self) -> list[BiotacFrame]:
        self._check_alive()
        return self._buffer.drain()

    def latest(self) -> BiotacFrame | None:
        self._check_alive()
        return self._latest

    def check_link(self) -> None:
        self._check_alive()

    def wire_report(self) -> dict:
        """Frames refused on the wire: failed CRC, cut short, or lacking a configured finger."""
        st = self.parser.stats
        reasons = {"crc failed": st.corrupt, "truncated": st.truncated, "fingers missing": self.mismatched}
        reasons = {k: v for k, v in reasons.items() if v}
        return {"refused": sum(reasons.values()), "reasons": reasons, "last": None,
                "garbage_bytes": st.garbage_bytes}

    @property
    def malformed(self) -> int:
        """Frames refused so far (CRC, truncation, fingers missing)."""
        return self.parser.stats.corrupt + self.parser.stats.truncated + self.mismatched

    # -- internals -----------------------------------------------------------------
    def _await_first_frame(self) -> None:
        if not self._first.wait(self.cfg.first_frame_timeout_s):
            if self._lost:
                raise DeviceDisconnectedError(self._lost)
            raise DeviceTimeoutError(
                f"{self.kind}: no valid frame on {self.cfg.port} within {self.cfg.first_frame_timeout_s} s "
                f"(stats {self.stats}); hint: is the bridge powered and streaming, at {self.cfg.baudrate} baud?")
        missing = [f for f in self.cfg.fingers if f not in self._bridge_fingers]
        if missing:
            raise DeviceFaultError(f"{self.kind}: the bridge on {self.cfg.port} sends fingers "
                                   f"{list(self._bridge_fingers)}, not {missing}; remove them from "
                                   f"{self.cfg.key}.fingers or connect those sensors")

    def _check_alive(self) -> None:
        if self._lost is not None:
            raise DeviceDisconnectedError(self._lost)
        if self._serial is None:
            raise NotConnectedError(f"{self.kind}: not connected (call connect() first)")
        latest = self._latest
        if latest is not None and self.clock.now() - latest.host_time > self.cfg.stale_timeout_s:
            raise DeviceTimeoutError(f"{self.kind}: no valid frame on {self.cfg.port} for "
                                     f"{self.clock.now() - latest.host_time:.2f} s "
                                     f"(> {self.cfg.key}.stale_timeout_s={self.cfg.stale_timeout_s})")

    def _read_loop(self) -> None:
        import serial

        ser = self._serial
        while not self._stop.is_set():
            try:
                data = ser.read(ser.in_waiting or 1)
            except (serial.SerialException, OSError, TypeError, AttributeError) as exc:
                # TypeError/AttributeError: pyserial's fd is gone after a concurrent close()
                if not self._stop.is_set():
                    self._lost = f"{self.kind}: serial link {self.cfg.port} lost ({exc})"
                return
            if data:
                for wf in self.parser.feed(data):
                    self._accept(wf, self.clock.now())

    def _accept(self, wf: WireFrame, host_time: float) -> None:
        self._bridge_fingers = wf.fingers
        try:
            rows = [wf.fingers.index(f) for f in self.cfg.fingers]
        except ValueError:
            self.mismatched += 1
            self._first.set()
            return
        frame = BiotacFrame(seq=wf.seq, device_time=wf.device_time_us * 1e-6, host_time=host_time,
                            electrodes=wf.electrodes[rows], pdc=wf.pdc[rows].astype(np.int32),
                            tdc=wf.tdc[rows].astype(np.int32), tac=wf.tac[rows].astype(np.int32),
                            pac=wf.pac[rows])
        self._buffer.put(frame)
        self._latest = frame
        self._publish(frame)
        self._first.set()


"""What every device has in common: identity, connect/close, context manager, a clock.

A device is created unconnected; ``connect()`` opens the link (idempotent) and
``close()`` releases it (idempotent, never raises for an already closed device).
``with device:`` connects on entry and closes on exit. Every other call on an unconnected
device raises :class:`~hardware.errors.NotConnectedError`.
"""

from __future__ import annotations

import threading
import time
from abc import ABC, abstractmethod
from collections import deque
from dataclasses import dataclass
from typing import ClassVar, Protocol, runtime_checkable

import numpy as np

from .errors import NotConnectedError


@dataclass(frozen=True)
class DeviceIdentity:
    """Provenance of a device: what it is, which one, and what it runs.

    Attributes:
        model: e.g. ``"UR10"``, ``"BioTac SP"``, ``"SimArm"``.
        serial_or_address: serial number, IP address, port or ``sim://`` URL.
        firmware: firmware / controller / simulator version string.
    """

    model: str
    serial_or_address: str
    firmware: str

    def to_dict(self) -> dict[str, str]:
        return {"model": self.model, "serial_or_address": self.serial_or_address,
                "firmware": self.firmware}


@runtime_checkable
class Clock(Protocol):
    """Time source shared by the devices and the run engine (never call ``time.sleep``).

    ``now()`` returns seconds on a monotonic time base; ``sleep(dt)`` waits ``dt`` seconds
    of *that* time base (simulated time for :class:`hardware.sim.SimClock`).
    """

    def now(self) -> float: ...

    def sleep(self, dt: float) -> None: ...


class WallClock:
    """The host's monotonic clock (``time.monotonic``), for real hardware."""

    def now(self) -> float:
        return time.monotonic()

    def sleep(self, dt: float) -> None:
        if dt > 0:
            time.sleep(dt)


def batch_times(ends, counts, period: float, previous: float | None = None) -> np.ndarray:
    """Times (s) of samples that arrive in batches: the ``counts[k]`` samples of batch k end
    at ``ends[k]`` (its timestamp), ``period`` s apart — closer when that would reach back
    to the end of the batch before it (``previous`` for the first batch: the last sample
    before these; ``None``: no bound), so the times increase strictly whenever the ends do.

    Batches are a BioTac frame's PAC samples (22 at 2.2 kHz per 100 Hz frame, but frame
    stamps jitter: one frame's 10 ms of samples can be longer than the time since the frame
    before) or serial lines read together. ``ends``, ``counts``: (N,); returns (sum(counts),).
    """
    ends = np.asarray(ends, float)
    counts = np.asarray(counts, np.int64)
    before = np.r_[np.nan if previous is None else float(previous), ends[:-1]]
    with np.errstate(invalid="ignore"):
        room = (ends - before) / np.maximum(counts, 1)
        spacing = np.where(np.isfinite(room), np.minimum(period, room), period)
    total = int(counts.sum())
    first = np.repeat(np.cumsum(counts) - counts, counts)
    back = np.repeat(counts, counts) - 1 - (np.arange(total) - first)        # samples after this one
    return np.repeat(ends, counts) - back * np.repeat(spacing, counts)


class SampleBuffer:
    """The newest ``maxlen`` samples a device received and has not handed out yet; thread-safe.

    Bounded, so a consumer that stalls can never grow memory: a full buffer drops its oldest
    sample and counts it in ``overflows``. ``maxlen`` can change (a rate known only once the
    device is connected); the samples kept are the newest.
    """

    def __init__(self, maxlen: int):
        self._items: deque = deque(maxlen=max(1, int(maxlen)))
        self._lock = threading.Lock()
        self.overflows = 0

    @property
    def maxlen(self) -> int:
        return self._items.maxlen

    @maxlen.setter
    def maxlen(self, n: int) -> None:
        with self._lock:
            self._items = deque(self._items, maxlen=max(1, int(n)))

    def put(self, sample) -> None:
        with self._lock:
            if len(self._items) == self._items.maxlen:
                self.overflows += 1
            self._items.append(sample)

    def drain(self) -> list:
        """Every sample put since the last call, oldest first."""
        with self._lock:
            out = list(self._items)
            self._items.clear()
        return out

    def clear(self) -> None:
        with self._lock:
            self._items.clear()

    def __len__(self) -> int:
        return len(self._items)


class Device(ABC):
    """Base of every device interface: connect/close, identity, context manager."""

    #: short name used in error messages and fault configs ("arm", "hand", "biotac", ...)
    kind: str = "device"
    #: the type of the samples it records, whose ``describe()`` declares their columns
    sample_type: ClassVar[type | None] = None

    def describe(self) -> tuple:
        """The streams this device records (:class:`hardware.streams.Stream`), as its sample
        type declares them; none for a device that records nothing."""
        return self.sample_type.describe() if self.sample_type is not None else ()

    def read_samples(self) -> list:
        """Every sample received since the last call; never blocks (the recorder's source)."""
        return self.read_states()

    @abstractmethod
    def connect(self) -> None:
        """Open the link to the device (idempotent)."""

    @abstractmethod
    def close(self) -> None:
        """Release the device (idempotent; safe after a failure)."""

    @property
    @abstractmethod
    def is_connected(self) -> bool:
        """True between a successful ``connect()`` and ``close()`` (or a lost link)."""

    @property
    @abstractmethod
    def identity(self) -> DeviceIdentity:
        """Model, serial number or address, firmware of the device."""

    def check_link(self) -> None:
        """Raise the device's typed error (:class:`~hardware.errors.DeviceError`) if its link is
        down now: lost (a closed socket, a vanished port, a killed bridge) or silent longer than
        its stale timeout. Cheap and non-blocking: the run engine asks every device every period
        (the link interlock, :mod:`protocols.interlocks`). By default nothing to check."""

    def wire_report(self) -> dict | None:
        """What the driver refused on the wire (:class:`hardware.wire.WireRejects`, as a dict),
        or None for a device that has nothing to report."""
        return None

    def _require_connected(self) -> None:
        if not self.is_connected:
            raise NotConnectedError(f"{self.kind}: not connected (call connect() first)")

    def __enter__(self):
        self.connect()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

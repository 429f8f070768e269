"""Tactile sensor interface (SynTouch BioTacs or another taxel array, up to five, Shadow finger order).

Every channel is a raw count as the sensor reports it (12-bit, 0..4095, on the BioTacs): the
electrodes (24 on a BioTac SP, 19 on a classic BioTac: the sensor model says,
:mod:`tactile.sensor`; impedance sensing: the count falls as the skin is pressed over the
electrode), PDC (static fluid pressure), TDC (temperature), TAC (temperature change), all at
~100 Hz, and PAC (dynamic pressure, vibration) at 2.2 kHz, delivered in batches with each
frame. What a run store records of them follows the model (:meth:`BiotacFrame.describe`):
a sensor without a pressure channel records none.
"""

from __future__ import annotations

import threading
from abc import abstractmethod
from dataclasses import dataclass
from functools import cached_property, partial

import numpy as np

from tactile_flow.tactile import FINGERS, N_TAXELS  # noqa: F401  (Shadow finger order; taxels per sensor)

from .device import Device, SampleBuffer, batch_times
from .streams import Column, Coord, Stream, as_dtype, device_time
from .errors import ConfigError

COUNTS_MAX = 4095
PAC_RATE_HZ = 2200.0


def check_fingers(fingers, key: str = "hardware.fingers") -> tuple[str, ...]:
    """Validate a finger subset and return it in Shadow order.

    Raises :class:`~hardware.errors.ConfigError` naming ``key`` for an unknown or
    duplicated name or an empty list.
    """
    if isinstance(fingers, str):
        raise ConfigError(key, f"expected a list of finger names, got the string {fingers!r}")
    fingers = list(fingers)
    if not fingers:
        raise ConfigError(key, "expected at least one finger of ff, mf, rf, lf, th")
    for i, f in enumerate(fingers):
        if f not in FINGERS:
            raise ConfigError(f"{key}[{i}]", f"{f!r} is not a finger; expected one of "
                                             f"{', '.join(FINGERS)}")
    if len(set(fingers)) != len(fingers):
        raise ConfigError(key, f"duplicated finger name in {fingers}")
    return tuple(f for f in FINGERS if f in fingers)


@dataclass(frozen=True)
class BiotacFrame:
    """One frame of all connected sensors.

    Attributes:
        seq: device sequence number (increments by one per frame produced; a jump means
            frames were lost).
        device_time: the sensor bridge's timestamp (s, its own clock).
        host_time: host clock time of receipt (s).
        electrodes: (F, N) int16 counts, F = len(fingers), N the sensor model's taxels in its order.
        pdc, tdc, tac: (F,) int32 counts.
        pac: (F, n_pac) int16 counts, the 2.2 kHz samples since the previous frame.
        counts_max: full scale of the sensor's ADC (4095 on the BioTacs).

    A corrupted frame is delivered as received: values outside 0..counts_max mark it
    (see :meth:`is_valid`).
    """

    seq: int
    device_time: float
    host_time: float
    electrodes: np.ndarray
    pdc: np.ndarray
    tdc: np.ndarray
    tac: np.ndarray
    pac: np.ndarray
    counts_max: int = COUNTS_MAX

    def is_valid(self) -> bool:
        """False if any channel lies outside 0..counts_max (checked once per frame:
        the engine, the interlocks and the recorder all ask)."""
        return self._valid

    @cached_property
    def _valid(self) -> bool:
        return all(a.size == 0 or (a.min() >= 0 and a.max() <= self.counts_max)
                   for a in map(np.asarray, (self.electrodes, self.pdc, self.tdc, self.tac, self.pac)))

    @classmethod
    def describe(cls, fingers=FINGERS, sensor=None) -> tuple[Stream, ...]:
        """The ``biotac`` stream (one row per frame) and the ``biotac_pac`` stream derived from
        it (one row per PAC sample, :func:`pac_columns`), :mod:`hardware.streams`, for the
        sensor model ``sensor`` (:class:`tactile.sensor.SensorModel`; default the BioTac SP):
        its taxels along ``taxel``, and of the pressure (``pdc``), temperature (``tdc``),
        temperature-change (``tac``) and vibration (``pac``) channels the ones it has, stored
        under the model's names for them."""
        if sensor is None:
            from tactile_flow.tactile.sensor import builtin_sensor
            sensor = builtin_sensor()
        T, TF = ("time",), ("time", "finger")
        finger = Coord("finger", tuple(fingers), "", "finger (Shadow order)")
        top = sensor.counts_max
        scalars = [Column(c.name, TF, "i2", "count", f"{what}, raw counts", attr)
                   for role, attr, what in (("pressure", "pdc", "static pressure (PDC)"),
                                            ("temperature", "tdc", "temperature (TDC)"),
                                            ("temperature_change", "tac", "temperature change (TAC)"))
                   if (c := sensor.channel(role)) is not None]
        frames = Stream("biotac", "biotac", "time", "BioTac frame", rate_hz=float(sensor.electrodes.rate_hz),
                        device_time=device_time("device_time", "time",
                                                "sensor bridge timestamp of the frame (device clock)"),
                        columns=(
            Column("seq", T, "i8", "1", "frame sequence number (one per frame, all fingers)"),
            Column("valid", T, "bool", "1", f"every channel of the frame within 0..{top}", "is_valid"),
            Column("electrodes", (*TF, "taxel"), "i2", "count", "electrode impedance reading, raw counts"),
            *scalars),
                        coords=(finger, Coord("taxel", np.arange(1, sensor.n_taxels + 1, dtype=np.int16), "1",
                                              f"taxel number ({sensor.name}: {', '.join(sensor.taxel_names[:3])}, ...)")))
        if sensor.vibration is None:
            return (frames,)
        rate = float(sensor.vibration.rate_hz)
        pac = Stream("biotac_pac", "biotac_pac", "time_pac", "PAC", rate_hz=rate, source="biotac",
                     device_time=device_time("device_time", "time_pac",
                                             f"device time of the PAC sample (its frame's timestamp minus the later "
                                             f"samples of the frame at {rate:g} Hz)"),
                     columns=(Column(sensor.vibration.name, ("time_pac", "finger"), "i2", "count",
                                     f"dynamic pressure (PAC) at {rate:g} Hz, raw counts", "pac"),),
                     coords=(finger,), rows=partial(pac_columns, rate_hz=rate, name=sensor.vibration.name))
        return frames, pac


def pac_columns(frames, previous: float | None = None, rate_hz: float = PAC_RATE_HZ,
                name: str = "pac") -> dict[str, np.ndarray]:
    """PAC samples of ``frames`` → (M, F) ``name`` (int16 counts), (M,) device_time, host_time (s, raw).

    A frame's n PAC samples end at the frame's timestamp, 1/rate apart — closer when a
    frame follows the one before sooner than its samples span (stamps jitter), so the times
    increase strictly (:func:`hardware.device.batch_times`; ``previous``: the device time of
    the last PAC sample before these frames); host_time is the frame's.
    """
    pac = [np.asarray(f.pac).T for f in frames]                       # (n, F) each
    counts = [len(p) for p in pac]
    F = pac[0].shape[1] if pac else 0
    return {name: as_dtype(np.concatenate(pac), np.int16) if pac else np.zeros((0, F), np.int16),
            "device_time": batch_times([f.device_time for f in frames], counts, 1.0 / rate_hz, previous),
            "host_time": np.repeat(np.array([f.host_time for f in frames], float), counts)}


class FrameTap(SampleBuffer):
    """A second, independent copy of a sensor's frame stream (see :meth:`TactileSensors.tap`):
    the newest ``maxlen`` frames, the ones it had to drop counted in ``overflows``.
    :meth:`wait` lets a consumer on the wall clock wake the moment a frame arrives."""

    def __init__(self, maxlen: int):
        super().__init__(maxlen)
        self._arrived = threading.Event()

    def put(self, sample) -> None:
        super().put(sample)
        self._arrived.set()

    def drain(self) -> list:
        self._arrived.clear()                 # before draining: a frame put meanwhile sets it again
        return super().drain()

    def wait(self, timeout_s: float) -> bool:
        """Block until a frame has arrived since the last :meth:`drain` (True), or ``timeout_s``
        s of wall time have passed (False)."""
        return self._arrived.wait(timeout_s)


class TactileSensors(Device):
    """The set of BioTacs on the hand, read as a stream of frames."""

    kind = "biotac"
    sample_type = BiotacFrame

    def describe(self) -> tuple[Stream, ...]:
        return BiotacFrame.describe(self.fingers, self.sensor_model)

    @property
    def sensor_model(self):
        """The :class:`tactile.sensor.SensorModel` of these sensors (set by the driver from the
        run's ``sensor`` config; the BioTac SP's when a driver is built without one)."""
        model = self.__dict__.get("_sensor_model")
        if model is None:
            from tactile_flow.tactile.sensor import builtin_sensor
            model = builtin_sensor()
        return model

    @sensor_model.setter
    def sensor_model(self, model) -> None:
        self.__dict__["_sensor_model"] = model

    @property
    def n_taxels(self) -> int:
        """Electrodes per sensor (the F × N of every frame)."""
        return self.sensor_model.n_taxels

    def read_samples(self) -> list[BiotacFrame]:
        return self.read()

    @property
    @abstractmethod
    def fingers(self) -> tuple[str, ...]:
        """Connected fingers, in Shadow order (the F axis of every frame)."""

    @property
    @abstractmethod
    def rate_hz(self) -> float:
        """Nominal frame rate (Hz)."""

    @abstractmethod
    def read(self) -> list[BiotacFrame]:
        """Every frame received since the last call (oldest first); never blocks long."""

    @abstractmethod
    def latest(self) -> BiotacFrame | None:
        """The newest frame received, without consuming the stream (``None`` before the
        first). The run engine watches contact criteria with it while the recorder alone
        drains :meth:`read`."""

    @property
    def malformed(self) -> int:
        """Frames this driver received and refused so far (:mod:`hardware.wire`); 0 for a source
        that cannot receive a malformed one."""
        return 0

    def tap(self, maxlen: int = 1000) -> FrameTap:
        """A copy of every frame received from now on, for a consumer other than the
        recorder (the live tactile-flow monitor): :meth:`read` still gets every frame.
        Drivers hand each frame to :meth:`_publish` as they receive it."""
        tap = FrameTap(maxlen)
        self.__dict__.setdefault("_taps", []).append(tap)
        return tap

    def untap(self, tap: FrameTap) -> None:
        taps = self.__dict__.get("_taps", [])
        if tap in taps:
            taps.remove(tap)

    def _publish(self, frame: BiotacFrame) -> None:
        for tap in self.__dict__.get("_taps", ()):
            tap.put(frame)

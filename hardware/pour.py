"""Pour devices: a peristaltic pump (ml/min, ml) and a scale (g)."""

from __future__ import annotations

from abc import abstractmethod
from dataclasses import dataclass

from .device import Device
from .streams import Column, Stream, device_time


@dataclass(frozen=True)
class PumpState:
    """One pump sample.

    Attributes:
        host_time: host clock time of receipt (s). device_time: pump clock (s).
        rate_ml_min: current flow rate (ml/min). dispensed_ml: total since connect (ml).
        running: True while pumping.
    """

    host_time: float
    device_time: float
    rate_ml_min: float
    dispensed_ml: float
    running: bool

    @classmethod
    def describe(cls) -> tuple[Stream, ...]:
        """The ``pump`` stream, in the ``pour`` group (:mod:`hardware.streams`)."""
        T = ("time_pump",)
        return (Stream("pump", "pour", "time_pump", "pump", rate_hz=10.0, host_time="pump_host_time",
                       device_time=device_time("pump_device_time", "time_pump", "pump timestamp (device clock)"),
                       columns=(Column("pump_rate", T, "f8", "ml min-1", "pump flow rate", "rate_ml_min"),
                                Column("dispensed", T, "f8", "ml", "volume dispensed since the pump connected",
                                       "dispensed_ml"),
                                Column("pump_running", T, "bool", "1", "pump running", "running"))),)


@dataclass(frozen=True)
class ScaleReading:
    """One scale reading: ``mass_g`` (g, net of the last tare) and the ``stable`` flag."""

    host_time: float
    device_time: float
    mass_g: float
    stable: bool

    @classmethod
    def describe(cls) -> tuple[Stream, ...]:
        """The ``scale`` stream, in the ``pour`` group (:mod:`hardware.streams`)."""
        T = ("time_scale",)
        return (Stream("scale", "pour", "time_scale", "scale", rate_hz=10.0, host_time="scale_host_time",
                       device_time=device_time("scale_device_time", "time_scale", "scale timestamp (device clock)"),
                       columns=(Column("mass", T, "f8", "g", "net mass on the scale (since the last tare)", "mass_g"),
                                Column("stable", T, "bool", "1", "scale stability flag"))),)


class Pump(Device):
    """A pump commanded by flow rate or by volume."""

    kind = "pump"
    sample_type = PumpState

    @abstractmethod
    def set_rate(self, ml_per_min: float) -> None:
        """Pump continuously at ``ml_per_min`` (0 stops). Above the pump's maximum: ValueError."""

    @abstractmethod
    def dispense(self, volume_ml: float, ml_per_min: float | None = None) -> None:
        """Dispense ``volume_ml`` at ``ml_per_min`` (default: the maximum rate); returns at once."""

    @abstractmethod
    def stop(self) -> None: ...

    @abstractmethod
    def status(self) -> PumpState: ...

    @abstractmethod
    def read_states(self) -> list[PumpState]:
        """Every sample since the last call; never blocks."""


class Scale(Device):
    """A streaming scale."""

    kind = "scale"
    sample_type = ScaleReading

    def read_samples(self) -> list[ScaleReading]:
        return self.read()

    @abstractmethod
    def mass(self) -> float:
        """Latest net mass (g)."""

    @property
    @abstractmethod
    def stable(self) -> bool:
        """The scale's stability flag for the latest reading."""

    @abstractmethod
    def tare(self) -> None:
        """Zero the scale at the current load."""

    @abstractmethod
    def read(self) -> list[ScaleReading]:
        """Every reading since the last call; never blocks."""

"""Pour devices: a peristaltic pump (ml/min, ml) and a scale (g)."""

from __future__ import annotations

from abc import abstractmethod
from dataclasses import dataclass

from .device import Device


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


@dataclass(frozen=True)
class ScaleReading:
    """One scale reading: ``mass_g`` (g, net of the last tare) and the ``stable`` flag."""

    host_time: float
    device_time: float
    mass_g: float
    stable: bool


class Pump(Device):
    """A pump commanded by flow rate or by volume."""

    kind = "pump"

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

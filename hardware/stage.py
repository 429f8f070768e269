"""Object stage: moves the object under a still finger (slip-in-place experiments).

An XY translation stage with a rotary stage on top, its axes those of the robot base (x, y
horizontal, rotation about the vertical +z, counter-clockwise seen from above). The object
sits on the rotary stage, whose axis passes through ``axis_m`` (base frame, m) at the stage's
home and travels with the XY stage. Units are SI, as the arm's: m, m/s, rad, rad/s.
"""

from __future__ import annotations

from abc import abstractmethod
from dataclasses import dataclass

import numpy as np

from .device import Device
from .streams import Column, Coord, Stream, device_time

#: the stage's pose / velocity components: x, y (m, m s-1) and rz (rad, rad s-1)
STAGE_AXES = ("x", "y", "rz")


@dataclass(frozen=True)
class StageState:
    """One stage sample.

    Attributes:
        host_time: host clock time of receipt (s). device_time: stage controller clock (s).
        pose: (3,) ``[x, y, rz]``: translation from home (m) and rotation about +z (rad).
        velocity: (3,) ``[vx, vy, wz]`` (m/s, rad/s).
        moving: True while a commanded motion is under way.
    """

    host_time: float
    device_time: float
    pose: np.ndarray
    velocity: np.ndarray
    moving: bool

    @classmethod
    def describe(cls) -> tuple[Stream, ...]:
        """The ``stage`` stream (:mod:`hardware.streams`)."""
        A = ("time_stage", "stage_axis")
        return (Stream("stage", "stage", "time_stage", "object stage", rate_hz=100.0,
                       device_time=device_time("device_time", "time_stage", "stage controller timestamp (device clock)"),
                       columns=(
            Column("pose", A, "f8", "m, rad", "object stage pose [x, y] m from home (robot base axes) and rotation rz "
                   "rad about +z (counter-clockwise seen from above)"),
            Column("velocity", A, "f8", "m s-1, rad s-1", "object stage velocity"),
            Column("moving", ("time_stage",), "bool", "1", "a commanded stage motion is under way")),
                       coords=(Coord("stage_axis", STAGE_AXES, "", "object stage pose / velocity component"),)),)


class ObjectStage(Device):
    """Moves the object: relative translations and rotations, rest to rest (trapezoidal)."""

    kind = "stage"
    sample_type = StageState

    @property
    @abstractmethod
    def axis_m(self) -> np.ndarray:
        """(2,) base-frame x, y (m) of the rotation axis at the stage's home."""

    @abstractmethod
    def translate(self, dx: float, dy: float, speed: float, asynchronous: bool = False) -> None:
        """Move the object by ``(dx, dy)`` m (base axes) at ``speed`` m/s. Beyond the stage's
        travel or speed limits: :class:`~hardware.errors.SafetyError`, before moving."""

    @abstractmethod
    def rotate(self, angle: float, speed: float, asynchronous: bool = False) -> None:
        """Turn the object by ``angle`` rad about the vertical axis (+ counter-clockwise seen
        from above) at ``speed`` rad/s; beyond the limits: ``SafetyError`` before moving."""

    @abstractmethod
    def stop(self) -> None:
        """Decelerate to rest."""

    @abstractmethod
    def is_moving(self) -> bool: ...

    @abstractmethod
    def pose(self) -> np.ndarray:
        """(3,) current ``[x, y, rz]`` (m, m, rad) from home."""

    @abstractmethod
    def read_states(self) -> list[StageState]:
        """Every sample since the last call; never blocks."""

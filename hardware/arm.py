"""Arm interface (UR10-like, units and conventions of ur_rtde).

Poses are ``[x, y, z, rx, ry, rz]``: position of the TCP in the robot base frame (m) and
its orientation as an axis-angle rotation vector (rad), exactly as ``getActualTCPPose``.
Wrenches are ``[Fx, Fy, Fz, Tx, Ty, Tz]`` in N and N·m in the base frame, the force the
environment exerts on the tool (as ``getActualTCPForce``). Speeds in m/s, accelerations
in m/s².
"""

from __future__ import annotations

import math
from abc import abstractmethod
from dataclasses import dataclass, field

import numpy as np

from .device import Device
from .streams import Column, Coord, Stream, device_time

#: the components of a pose, twist or wrench (m or N, then rad or N m)
AXIS6 = ("x", "y", "z", "rx", "ry", "rz")
from .errors import ConfigError, WorkspaceError


@dataclass(frozen=True)
class ArmState:
    """One controller sample, as a recorder stores it.

    Attributes:
        host_time: host clock time of receipt (s).
        controller_time: the controller's own timestamp (s since controller start).
        tcp_pose: (6,) ``[x, y, z, rx, ry, rz]`` m, rad (axis-angle).
        tcp_speed: (6,) linear (m/s) and angular (rad/s) TCP velocity.
        tcp_wrench: (6,) N, N·m.
        protective_stopped: the controller's protective-stop flag at this sample.
    """

    host_time: float
    controller_time: float
    tcp_pose: np.ndarray
    tcp_speed: np.ndarray
    tcp_wrench: np.ndarray
    protective_stopped: bool = False

    @classmethod
    def describe(cls) -> tuple[Stream, ...]:
        """The ``arm`` stream (:mod:`hardware.streams`)."""
        A = ("time_arm", "axis6")
        return (Stream("arm", "arm", "time_arm", "arm state", rate_hz=500.0,
                       device_time=device_time("controller_time", "time_arm",
                                               "controller timestamp (s since controller start)", "controller_time"),
                       columns=(
            Column("tcp_pose", A, "f8", "m, rad", "TCP pose [x, y, z] m and axis-angle [rx, ry, rz] rad, robot base frame"),
            Column("tcp_speed", A, "f8", "m s-1, rad s-1", "TCP linear and angular velocity"),
            Column("tcp_wrench", A, "f8", "N, N m",
                   "force [Fx, Fy, Fz] N and torque [Tx, Ty, Tz] N m on the tool, base frame"),
            Column("protective_stopped", ("time_arm",), "bool", "1", "controller protective-stop flag")),
                       coords=(Coord("axis6", AXIS6, "", "pose / twist / wrench component"),)),)


def trapezoid_time(distance: float, speed: float, accel: float) -> float:
    """Duration (s) of a rest-to-rest move of ``distance`` (m or rad) at most ``speed`` (per s)
    and ``accel`` (per s²): a trapezoidal speed profile, triangular when too short to reach ``speed``.

    >>> trapezoid_time(0.1, 0.05, 0.5)           # 2 s cruising + 0.1 s ramping
    2.1
    """
    if distance <= 0:
        return 0.0
    if distance < speed ** 2 / accel:
        return 2.0 * math.sqrt(distance / accel)
    return distance / speed + speed / accel


@dataclass
class Workspace:
    """Axis-aligned box (robot base frame, m) that the TCP position must stay inside.

    ``key`` is the config key it came from, quoted in every refusal.
    """

    min_m: list[float] = field(default_factory=lambda: [-1.0, -1.0, 0.0])
    max_m: list[float] = field(default_factory=lambda: [1.0, 1.0, 1.0])
    key: str = "hardware.workspace"

    def __post_init__(self):
        lo, hi = np.asarray(self.min_m, float), np.asarray(self.max_m, float)
        if lo.shape != (3,) or hi.shape != (3,) or not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            raise ConfigError(self.key, f"expected min_m and max_m as 3 finite numbers (m), "
                                        f"got {self.min_m!r}, {self.max_m!r}")
        if np.any(lo >= hi):
            raise ConfigError(f"{self.key}.min_m", f"must be below max_m on every axis, "
                                                   f"got min {self.min_m} max {self.max_m}")

    def contains(self, position) -> bool:
        p = np.asarray(position, float)[:3]
        return bool(np.all(p >= np.asarray(self.min_m)) and np.all(p <= np.asarray(self.max_m)))

    def check(self, pose, what: str = "pose") -> None:
        """Raise :class:`WorkspaceError` naming the config key if ``pose`` is outside."""
        p = np.asarray(pose, float)
        if p.shape != (6,) or not np.all(np.isfinite(p)):
            raise ValueError(f"{what}: expected 6 finite numbers [x,y,z,rx,ry,rz] (m, rad), got {pose!r}")
        if not self.contains(p):
            axes = "xyz"
            bad = [f"{axes[i]}={p[i]:.4f} not in [{self.min_m[i]}, {self.max_m[i]}]"
                   for i in range(3) if not self.min_m[i] <= p[i] <= self.max_m[i]]
            raise WorkspaceError(f"{what} outside the workspace {self.key} "
                                 f"(min_m={list(self.min_m)}, max_m={list(self.max_m)}): {', '.join(bad)}")


class Arm(Device):
    """A 6-axis arm with a TCP, moved in Cartesian space."""

    kind = "arm"
    sample_type = ArmState

    @abstractmethod
    def tcp_pose(self) -> np.ndarray:
        """(6,) current TCP pose ``[x,y,z,rx,ry,rz]`` (m, rad)."""

    @abstractmethod
    def tcp_wrench(self) -> np.ndarray:
        """(6,) current TCP wrench ``[Fx,Fy,Fz,Tx,Ty,Tz]`` (N, N·m)."""

    @abstractmethod
    def tcp_speed(self) -> np.ndarray:
        """(6,) current TCP velocity ``[vx, vy, vz, wx, wy, wz]`` (m/s, rad/s), as the
        controller reports it (``getActualTCPSpeed``)."""

    @abstractmethod
    def controller_time(self) -> float:
        """The controller's timestamp (s)."""

    @abstractmethod
    def check_pose(self, pose) -> None:
        """Raise :class:`~hardware.errors.WorkspaceError` if ``pose`` is not allowed."""

    @abstractmethod
    def move_linear(self, pose, speed: float = 0.05, accel: float = 0.5,
                    asynchronous: bool = False) -> None:
        """Move the TCP in a straight line to ``pose`` (``moveL``).

        ``speed`` m/s, ``accel`` m/s². Blocks until arrival unless ``asynchronous``.
        Raises ProtectiveStopError if the arm is (or becomes) protectively stopped.
        """

    @abstractmethod
    def speed_linear(self, velocity, accel: float = 0.5, duration: float = 0.0) -> None:
        """Move at TCP ``velocity`` (6,) m/s, rad/s (``speedL``); returns at once.

        ``duration`` > 0: decelerate after that many seconds; 0: until ``stop()``.
        """

    @abstractmethod
    def stop(self, accel: float = 2.0) -> None:
        """Decelerate to rest at ``accel`` m/s² (``stopL``); returns at once."""

    @abstractmethod
    def is_moving(self) -> bool:
        """True while a motion is in progress."""

    @abstractmethod
    def is_protective_stopped(self) -> bool: ...

    @abstractmethod
    def is_emergency_stopped(self) -> bool: ...

    @abstractmethod
    def recover(self) -> None:
        """Clear a protective stop (unlock, restart the control script)."""

    @abstractmethod
    def read_states(self) -> list[ArmState]:
        """Every controller sample received since the last call (oldest first); never blocks."""

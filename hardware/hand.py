"""Hand interface (Shadow Dexterous Hand, right hand, joint names as its ROS stack)."""

from __future__ import annotations

from abc import abstractmethod
from dataclasses import dataclass

import numpy as np

from .device import Device
from .streams import Column, Coord, Stream, device_time

JOINT_NAMES: tuple[str, ...] = (
    "rh_FFJ1", "rh_FFJ2", "rh_FFJ3", "rh_FFJ4",
    "rh_MFJ1", "rh_MFJ2", "rh_MFJ3", "rh_MFJ4",
    "rh_RFJ1", "rh_RFJ2", "rh_RFJ3", "rh_RFJ4",
    "rh_LFJ1", "rh_LFJ2", "rh_LFJ3", "rh_LFJ4", "rh_LFJ5",
    "rh_THJ1", "rh_THJ2", "rh_THJ3", "rh_THJ4", "rh_THJ5",
    "rh_WRJ1", "rh_WRJ2",
)
"""The 24 joints, in the order of every position/target array (rad)."""

JOINT_INDEX = {name: i for i, name in enumerate(JOINT_NAMES)}


def check_joint_names(names, key: str = "targets") -> None:
    """ValueError naming ``key`` and the unknown joint(s)."""
    bad = [n for n in names if n not in JOINT_INDEX]
    if bad:
        raise ValueError(f"{key}: unknown joint name(s) {bad}; expected names from "
                         f"rh_FFJ1..rh_WRJ2 (hardware.hand.JOINT_NAMES)")


@dataclass(frozen=True)
class HandState:
    """One joint-state sample.

    Attributes:
        host_time: host clock time of receipt (s).
        device_time: the hand's own timestamp (ROS header stamp), s.
        position: (24,) joint angles, rad, order :data:`JOINT_NAMES`.
        target: (24,) current commanded angles, rad.
    """

    host_time: float
    device_time: float
    position: np.ndarray
    target: np.ndarray

    @classmethod
    def describe(cls) -> tuple[Stream, ...]:
        """The ``hand`` stream (:mod:`hardware.streams`)."""
        J = ("time_hand", "joint")
        return (Stream("hand", "hand", "time_hand", "hand joint state", rate_hz=100.0,
                       device_time=device_time("device_time", "time_hand", "hand joint-state stamp (device clock)"),
                       columns=(Column("position", J, "f8", "rad", "measured joint angle"),
                                Column("target", J, "f8", "rad", "commanded joint angle")),
                       coords=(Coord("joint", JOINT_NAMES, "", "Shadow Hand joint name"),)),)


#: s, the trajectory that holds the hand where it is (:meth:`Hand.stop`)
STOP_S = 0.05


class Hand(Device):
    """A multi-joint hand commanded with joint targets."""

    kind = "hand"
    sample_type = HandState

    @abstractmethod
    def positions(self) -> dict[str, float]:
        """Current joint angles (rad) by joint name."""

    @abstractmethod
    def move_to(self, targets: dict[str, float], duration: float, wait: bool = True) -> None:
        """Move the named joints to ``targets`` (rad) in ``duration`` s (others keep theirs).

        Blocks until the trajectory ends when ``wait``. Unknown names: ValueError.
        """

    @abstractmethod
    def read_states(self) -> list[HandState]:
        """Every joint-state sample received since the last call; never blocks."""

    def stop(self) -> None:
        """Hold every joint where it is now: a trajectory under way ends within
        :data:`STOP_S` (joints whose angle is unknown keep their targets). Does not open the
        hand, so a grasped object stays held."""
        here = {name: q for name, q in self.positions().items() if q == q}     # NaN: unknown
        if here:
            self.move_to(here, STOP_S, wait=False)

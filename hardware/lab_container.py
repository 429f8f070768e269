"""The lab container: every device of one lab, simulated or real, behind the device
interfaces (:class:`~hardware.arm.Arm`, :class:`~hardware.hand.Hand`, ...), so the run
engine never knows which backend it drives.

    with lab:                    # connects every device; closes them all on exit
        lab.arm.move_linear(pose, speed=0.01)

The backends build it: :func:`hardware.sim.make_sim_lab` (with a world and ground truth)
and :func:`hardware.lab.make_real_lab`.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from .arm import Arm
from .biotac import TactileSensors
from .device import Clock
from .hand import Hand
from .pour import Pump, Scale
from .stage import ObjectStage

if TYPE_CHECKING:                  # (hardware.surfaces still builds on the simulator's config loader)
    from .surfaces import Surface

log = logging.getLogger(__name__)


@dataclass
class Lab:
    """Every device of a lab (``stage`` only where an object stage is configured) plus, for a
    simulated one, its world and ground truth (``None`` for the real lab).

    ``with lab:`` connects every device and closes them all on exit.
    """

    arm: Arm
    hand: Hand
    biotac: TactileSensors
    pump: Pump
    scale: Scale
    clock: Clock
    world: Any = None                          # the simulated world (hardware.sim.SimWorld)
    truth: Any = None                          # its ground truth (hardware.sim.GroundTruth)
    surface: Surface | None = None
    stage: ObjectStage | None = None           # the object stage, if the lab has one

    @property
    def devices(self) -> dict:
        out = {"arm": self.arm, "hand": self.hand, "biotac": self.biotac, "pump": self.pump, "scale": self.scale}
        return out | ({"stage": self.stage} if self.stage is not None else {})

    def connect(self) -> None:
        """Connect every device. Each is tried, so every failure is reported, not only the
        first: each is logged, and if any fails every device is closed again and the first
        device's error is raised (its type kept for the caller), its message extended with
        every other failure and ``failures`` mapping each failed device to its error."""
        failures = {}
        try:
            for name, device in self.devices.items():
                try:
                    device.connect()
                except Exception as exc:       # noqa: BLE001 - every device gets its turn
                    log.error("%s: connect failed: %s: %s", name, type(exc).__name__, exc)
                    failures[name] = exc
        except BaseException:                  # Ctrl-C while connecting: leave nothing open
            self.close()
            raise
        if failures:
            self.close()
            first = next(iter(failures.values()))
            if len(failures) > 1:
                others = "; ".join(f"{name}: {type(e).__name__}: {e}" for name, e in list(failures.items())[1:])
                first.args = (f"{first}; also failed to connect: {others}",)
            first.failures = failures
            raise first

    def close(self) -> None:
        for name, device in self.devices.items():
            try:
                device.close()
            except Exception as exc:           # noqa: BLE001 - closing must never mask the error that got us here
                log.warning("%s: close failed: %s: %s", name, type(exc).__name__, exc)

    def streams(self) -> dict:
        """What the lab records: every device's streams by name (:mod:`hardware.streams`)."""
        return {s.name: s for d in self.devices.values() for s in d.describe()}

    def sources(self) -> dict:
        """The recorder's sources: every recording device's non-blocking drain, by name."""
        return {name: d.read_samples for name, d in self.devices.items() if d.describe()}

    def identities(self) -> dict[str, dict]:
        return {k: d.identity.to_dict() for k, d in self.devices.items()}

    def __enter__(self):
        self.connect()
        return self

    def __exit__(self, *exc):
        self.close()

"""The emulated lab presses: the emulated BioTacs follow the emulated arm onto a board.

The UR controller emulator publishes its TCP pose and speed to a small shared file
(:class:`PoseFile`, written every control period); the BioTac emulators (rosbridge and
serial) read it each frame and ask the simulator's own contact model
(:meth:`hardware.sim.world.SimWorld.touch`: fingertip ellipsoids, the board's features,
Hertz-like pressure, friction and shear) for each finger's load, so a rehearsal with
``tactile-emulate`` and ``hardware=lab_emulated`` finds contacts and segments like a
simulated run. The board is a ``conf/surface/<name>.yaml`` (``tactile-emulate --surface``),
the fingertips the simulator's defaults (the same as ``conf/hardware/lab.yaml``).

The file holds 12 float64: a sequence number (odd while being written), the controller time
(s), the pose ``[x, y, z, rx, ry, rz]`` (m, rad) and the TCP velocity ``[vx, vy, vz]`` (m/s);
a reader retries while the number is odd or changed under it.
"""

from __future__ import annotations

import mmap
import os
from pathlib import Path

import numpy as np

from tactile_flow.conf import DIR as CONF_DIR

N_VALUES = 12
SURFACES_DIR = CONF_DIR / "surface"


class PoseFile:
    """The shared TCP pose: ``write`` (the arm emulator) and ``read`` (the BioTac emulators)."""

    def __init__(self, path, create: bool = False):
        self.path = Path(path)
        if create and not self.path.exists():     # never truncated under a reader's map
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self.path.write_bytes(bytes(8 * N_VALUES))
        fd = os.open(self.path, os.O_RDWR)
        try:
            self.map = mmap.mmap(fd, 8 * N_VALUES)
        finally:
            os.close(fd)
        self.values = np.frombuffer(self.map, dtype=np.float64, count=N_VALUES)

    def write(self, t: float, pose, velocity) -> None:
        v = self.values
        seq = v[0]
        v[0] = seq + 1                            # odd: being written
        v[1] = t
        v[2:8] = pose
        v[8:11] = velocity[:3]
        v[0] = seq + 2

    def read(self) -> tuple[float, np.ndarray, np.ndarray] | None:
        """(time s, pose (6,), velocity (3,)), or None before the first write."""
        for _ in range(100):
            seq = self.values[0]
            data = self.values[1:11].copy()
            if seq % 2 == 0 and self.values[0] == seq:
                return (float(data[0]), data[1:7], data[7:10]) if seq > 0 else None
        return None

    def close(self) -> None:
        del self.values
        self.map.close()


class EmulatedTouch:
    """Sensor inputs of ``fingers`` for the pose in ``pose_file``, on the board ``surface``
    (``sensor``: the fingertips' :class:`tactile.sensor.SensorModel`, default the BioTac SP)."""

    def __init__(self, pose_file, surface: str, fingers, sensor=None):
        from omegaconf import OmegaConf

        from ..config import load_config
        from ..sim.world import SimWorld
        from ..surfaces import load_surface

        path = SURFACES_DIR / f"{surface}.yaml"
        if not path.is_file():
            raise ValueError(f"--surface {surface}: no conf/surface/{surface}.yaml; expected one of "
                             f"{sorted(p.stem for p in SURFACES_DIR.glob('*.yaml'))}")
        cfg = load_config({"fingers": list(fingers), "stage": None, "pour": {"bottle_in_hand": False}})
        self.world = SimWorld(cfg, load_surface(OmegaConf.to_container(OmegaConf.load(path), resolve=True)), sensor)
        self.fingers = tuple(fingers)
        self.pose = PoseFile(pose_file)

    def inputs(self, t: float):
        """:class:`~hardware.sim.sensor.SensorInputs` of the fingers at the arm's latest pose
        (no contact before the arm emulator has written one)."""
        from ..sim.sensor import SensorInputs
        state = self.pose.read()
        if state is not None:
            _, pose, velocity = state
            self.world.touch(t, pose, velocity)
        c = [self.world.contacts[f] for f in self.fingers]
        return SensorInputs(np.array([x.load for x in c]), np.array([x.force for x in c]),
                            np.array([self.world.force_rate[f] for f in self.fingers]),
                            np.array([x.friction for x in c]), np.array([x.shear_load for x in c]))

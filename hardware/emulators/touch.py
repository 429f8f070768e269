"""The simulated world behind the emulated lab: the BioTacs feel what the other emulators do.

The emulated devices are separate processes (:mod:`hardware.emulators.process`), so the
world they share is assembled from small shared files in the link directory, each written
by one emulator and read by the others (:class:`SharedValues`, a seqlock on a memory map):

============  ==========================================  ======================================
file          written by                                  holds
============  ==========================================  ======================================
``tcp_pose``  the UR controller emulator, every period    :class:`PoseFile`: the TCP pose, speed
``hand``      the rosbridge emulator, on every command    :class:`HandFile`: the joint trajectory
``pump``      the pump emulator, every 5 ms               :class:`PumpFile`: flow, volume pumped
============  ==========================================  ======================================

Each BioTac emulator (rosbridge and serial) runs an :class:`EmulatedWorld`: the simulated
lab's own :class:`~hardware.sim.world.SimWorld`, stepped every BioTac frame from those
files (:meth:`~hardware.sim.world.SimWorld.follow`): the fingertips on the board of
``--surface`` following the arm, and the bottle held between ``ff``, ``mf`` and ``th`` as
in the simulated lab — its grip from the hand's commanded closure, filled by the pump, its
slip stages — so a rehearsal of ``pour_grasp_reactive`` slips, and is caught, through
rosbridge and the serial links. The world's times are the host's monotonic clock
(``time.monotonic``), which every emulator process shares: the slip onset compares directly
with the time the hand emulator received a command (``stats``).

Each file holds float64 values; the first is a sequence number, odd while being written; a
reader retries while it is odd or changed under it.
"""

from __future__ import annotations

import math
import mmap
import os
from pathlib import Path

import numpy as np

from tactile_flow.conf import DIR as CONF_DIR

from ..hand import JOINT_NAMES

SURFACES_DIR = CONF_DIR / "surface"
N_JOINTS = len(JOINT_NAMES)
MAX_SUBSTEPS = 100             # frames a late frame is stepped in at most (a stalled emulator: 1 s)
POSE_FILE, HAND_FILE, PUMP_FILE = "tcp_pose", "hand", "pump"
WORLD_FILES = (POSE_FILE, HAND_FILE, PUMP_FILE)
"""The shared files of the emulated world, in the link directory (``tactile-emulate --link-dir``)."""


class SharedValues:
    """``n`` float64 in a shared file: one writer (:meth:`put`), any number of readers
    (:meth:`get`), each process with its own map. The file is created (zeros) by whoever
    opens it first and only ever grown, never truncated under another process's map."""

    n = 0

    def __init__(self, path, create: bool = False):
        self.path = Path(path)
        size = 8 * (self.n + 1)
        if create:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(self.path, os.O_RDWR | (os.O_CREAT if create else 0), 0o644)
        try:
            if os.fstat(fd).st_size < size:
                os.ftruncate(fd, size)
            self.map = mmap.mmap(fd, size)
        finally:
            os.close(fd)
        self.values = np.frombuffer(self.map, dtype=np.float64, count=self.n + 1)

    def put(self, data) -> None:
        v = self.values
        seq = v[0]
        v[0] = seq + 1                            # odd: being written
        v[1:] = data
        v[0] = seq + 2

    def get(self) -> np.ndarray | None:
        """A consistent copy of the ``n`` values, or None before the first write."""
        for _ in range(100):
            seq = self.values[0]
            data = self.values[1:].copy()
            if seq % 2 == 0 and self.values[0] == seq:
                return data if seq > 0 else None
        return None

    def close(self) -> None:
        del self.values
        self.map.close()


class PoseFile(SharedValues):
    """The TCP pose: the controller time (s), the pose ``[x, y, z, rx, ry, rz]`` (m, rad) and
    the TCP velocity ``[vx, vy, vz]`` (m/s); 96 bytes with the sequence number and a spare."""

    n = 11

    def write(self, t: float, pose, velocity) -> None:
        self.put(np.r_[t, np.asarray(pose, float)[:6], np.asarray(velocity, float)[:3], 0.0])

    def read(self) -> tuple[float, np.ndarray, np.ndarray] | None:
        """(time s, pose (6,), velocity (3,)), or None before the first write."""
        d = self.get()
        return None if d is None else (float(d[0]), d[1:7], d[7:10])


def trajectory_positions(start_q, goal_q, t_start, t_end, t: float) -> np.ndarray:
    """(24,) rad: each joint linear in time from ``start_q`` at ``t_start`` to ``goal_q`` at
    ``t_end`` (s), held before and after — the emulated hand's commanded angles at ``t``."""
    span = np.maximum(t_end - t_start, 1e-9)
    s = np.clip((t - t_start) / span, 0.0, 1.0)
    return start_q + s * (goal_q - start_q)


class HandFile(SharedValues):
    """The hand's joint trajectory: per joint its start and goal angle (rad) and the
    (monotonic) times it leaves the one and reaches the other (s)."""

    n = 4 * N_JOINTS

    def write(self, start_q, goal_q, t_start, t_end) -> None:
        self.put(np.concatenate([start_q, goal_q, t_start, t_end]))

    def read(self) -> tuple[np.ndarray, ...] | None:
        """(start_q, goal_q, t_start, t_end), each (24,), or None before the first write."""
        d = self.get()
        return None if d is None else tuple(d.reshape(4, N_JOINTS))


class PumpFile(SharedValues):
    """The pump: the (monotonic) time (s), its flow (ml/min) and the volume pumped (ml)."""

    n = 3

    def write(self, t: float, rate_ml_min: float, total_ml: float) -> None:
        self.put([t, rate_ml_min, total_ml])

    def read(self) -> tuple[float, float, float] | None:
        d = self.get()
        return None if d is None else (float(d[0]), float(d[1]), float(d[2]))


def frame_times(sent: list[float], first: int, last: int) -> dict:
    """``{seq: monotonic time sent}`` of the frames numbered ``first``..``last`` (1-based),
    for an emulator's ``frames A B`` control command."""
    lo, hi = max(first, 1), min(last, len(sent))
    return {str(k): sent[k - 1] for k in range(lo, hi + 1)}


class EmulatedWorld:
    """The simulated world of ``fingers``, stepped from the shared files in ``world_dir`` (see
    the module docstring), with the board ``surface`` (a ``conf/surface`` name, or ``None``:
    no board) and a bottle between the grasp fingers (``bottle``); ``sensor``: the fingertips'
    :class:`tactile.sensor.SensorModel` (default the BioTac SP)."""

    def __init__(self, world_dir, surface: str | None, fingers, sensor=None, bottle: bool = True):
        from omegaconf import OmegaConf

        from ..config import load_config
        from ..sim.world import SimWorld
        from ..surfaces import load_surface

        board = None
        if surface is not None:
            path = SURFACES_DIR / f"{surface}.yaml"
            if not path.is_file():
                raise ValueError(f"--surface {surface}: no conf/surface/{surface}.yaml; expected one of "
                                 f"{sorted(p.stem for p in SURFACES_DIR.glob('*.yaml'))}")
            board = load_surface(OmegaConf.to_container(OmegaConf.load(path), resolve=True))
        cfg = load_config({"fingers": list(fingers), "stage": None, "pour": {"bottle_in_hand": bool(bottle)}})
        self.world = SimWorld(cfg, board, sensor)
        self.fingers = tuple(fingers)
        d = Path(world_dir)
        self.pose = PoseFile(d / POSE_FILE, create=True)
        self.hand = HandFile(d / HAND_FILE, create=True)
        self.pump = PumpFile(d / PUMP_FILE, create=True)
        self._last_t: float | None = None
        self._last_pumped: float | None = None
        self.frames = 0
        self.bottles: list[dict] = []           # the bottles taken away (:meth:`_bottle` of each), oldest first

    def hand_writer(self) -> HandFile:
        """The hand's shared trajectory, for the emulator that owns the hand to write."""
        return self.hand

    def pump_writer(self) -> PumpFile:
        """The pump's shared state, for the emulator that owns the pump to write."""
        return self.pump

    def step(self, now: float) -> None:
        """Advance the world to ``now`` (monotonic s) from the devices' latest states.

        The water poured is the pump's own count (the volume pumped since the last frame), so a
        frame late on a loaded host loses none; a gap longer than a frame is stepped in frames.
        When the hand has let go of a bottle it carried (or that fell), the bottle is taken away
        and a new, empty one stands between the fingers, as the operator places it between runs."""
        w = self.world
        dt = w.frame_dt if self._last_t is None else max(now - self._last_t, 1e-4)
        self._last_t = now
        pose, hand, pump = self.pose.read(), self.hand.read(), self.pump.read()
        q_hand = None
        if hand is not None:
            start_q, goal_q, t_start, t_end = hand
            q_hand = (trajectory_positions(start_q, goal_q, t_start, t_end, now), float(t_end.max()))
        pumped = 0.0
        if pump is not None:
            pumped = 0.0 if self._last_pumped is None else max(pump[2] - self._last_pumped, 0.0)
            self._last_pumped = pump[2]
        n = min(max(1, math.ceil(dt / w.frame_dt - 1e-6)), MAX_SUBSTEPS)
        flow = pumped / dt * 60.0                 # ml/min over this frame
        with w.lock:
            for k in range(n):
                w.follow(now - dt * (n - 1 - k) / n, dt / n, None if pose is None else pose[1],
                         None if pose is None else pose[2], q_hand, flow)
            if (w.carried or w.grasp.fallen) and self._hand_open(now):
                self.bottles.append(self._bottle())
                self._new_bottle()
        self.frames += 1

    def inputs(self, now: float):
        """:class:`~hardware.sim.sensor.SensorInputs` of the fingers after stepping the world to
        ``now`` (monotonic s)."""
        from ..sim.sensor import SensorInputs
        self.step(now)
        w = self.world
        c = [w.contacts[f] for f in self.fingers]
        return SensorInputs(np.array([x.load for x in c]), np.array([x.force for x in c]),
                            np.array([w.force_rate[f] for f in self.fingers]),
                            np.array([x.friction for x in c]), np.array([x.shear_load for x in c]))

    def measured_positions(self, q) -> np.ndarray:
        """The hand's measured angles (24,) rad for the commanded ``q``: the grasp fingers stop
        on the bottle while it is held, as in the simulated lab."""
        from ..sim import grasp
        w = self.world
        pc = w.cfg.pour
        with w.lock:
            if pc.bottle_in_hand and not w.grasp.fallen:
                return grasp.clamp_to_contact(np.asarray(q, float), pc.grasp_fingers, pc)
        return np.asarray(q, float)

    def state(self) -> dict:
        """The bottle between the fingers now and those taken away, with the pour's stages
        (monotonic s; ``None``: not yet), for ``stats``: what a rehearsal is judged by."""
        with self.world.lock:
            return {"frames": self.frames, "bottle_in_hand": bool(self.world.cfg.pour.bottle_in_hand),
                    "bottle": self._bottle(), "bottles": list(self.bottles)}

    def close(self) -> None:
        for f in (self.pose, self.hand, self.pump):
            f.close()

    # -- internals -----------------------------------------------------------------------
    def _hand_open(self, now: float) -> bool:
        """No grasp finger is commanded to close on the bottle (none would grip it)."""
        from ..sim import grasp
        w = self.world
        pc = w.cfg.pour
        return not any(grasp.grip_forces(w.hand_desired(now), pc.grasp_fingers, pc).values())

    def _new_bottle(self) -> None:
        from ..sim import grasp
        w = self.world
        w.grasp = grasp.GraspState()
        w.carried = False

    def _bottle(self) -> dict:
        """The bottle's state: held (not fallen), carried, water (ml), grip (N per finger),
        slide (mm), rotation (rad) and the pour's stage times (monotonic s or None)."""
        w = self.world
        g = w.grasp
        times = {k: (None if math.isnan(v) else round(v, 6)) for k, v in g.times.items()}
        return {"held": not g.fallen, "carried": bool(w.carried), "water_ml": round(g.water_ml, 3),
                "grip_n": {f: round(v, 4) for f, v in w.grip.items()}, "slide_mm": round(g.slide_mm, 4),
                "rotation_rad": round(g.rotation_rad, 5), **times}


EmulatedTouch = EmulatedWorld     # the name before the world held the bottle

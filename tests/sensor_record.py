"""A press recorded by the simulator's fingertip of any sensor model, as a lab would publish it:
for the import tests of the classic BioTac (19 electrodes) and other models.

The fingertip of ``ff`` (the TCP) rests 1 s above a flat board, presses 1 mm into it and
slides 8 mm along +x, then lifts and rests; the sensor model's simulated electrodes
(:class:`hardware.sim.sensor.BiotacModel`, the contact model of :mod:`hardware.sim.world`)
turn the contact into counts at 100 Hz. ``th`` rests throughout (a second connected finger).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

RATE_HZ = 100.0


@dataclass
class Record:
    """``time`` (T,) s; ``electrodes`` (T, 2, N) counts of ff and th; ``pdc``, ``tdc``, ``tac``
    (T, 2); ``pac`` (T, 2, 22); ``contact`` (T,) bool, the truth (ff touches the board)."""

    time: np.ndarray
    electrodes: np.ndarray
    pdc: np.ndarray
    tdc: np.ndarray
    tac: np.ndarray
    pac: np.ndarray
    contact: np.ndarray
    fingers: tuple = ("ff", "th")


def press_record(sensor, seconds: float = 6.0, seed: int = 0) -> Record:
    """The press of the module docstring with the model ``sensor``."""
    from tactile_flow.hardware.config import SensorModelConfig, load_config
    from tactile_flow.hardware.sim.sensor import BiotacModel, SensorInputs
    from tactile_flow.hardware.sim.world import SimWorld
    from tactile_flow.hardware.surfaces import load_surface

    fingers = ("ff", "th")
    cfg = load_config({"fingers": list(fingers), "stage": None, "pour": {"bottle_in_hand": False}})
    world = SimWorld(cfg, load_surface({"kind": "flat", "name": "flat"}), sensor)
    model = BiotacModel(fingers, SensorModelConfig(), np.random.default_rng(seed), 1.0 / RATE_HZ, sensor)
    pole = sensor.shape.pole * 1e-3          # the sensor frame is the base frame at this pose (TCP and tip rx = π)
    top = world.surface.max_z
    n = int(seconds * RATE_HZ)
    out = {k: [] for k in ("e", "pdc", "tdc", "tac", "pac", "contact")}
    for i in range(n):
        t = i / RATE_HZ
        s = np.clip((t - 1.0) / 0.5, 0, 1) * np.clip((4.5 - t) / 0.5, 0, 1)       # in 1.0-1.5 s, out 4.0-4.5 s
        slide = np.clip((t - 1.5) / 2.5, 0, 1) * 8e-3
        depth = 1.0e-3 * s - 2e-3 * (s == 0)
        pose = np.r_[0.3 + slide, 0.0, top - depth - pole[2], np.pi, 0.0, 0.0]
        moving = 1.5 <= t <= 4.0
        world.follow(t, 1.0 / RATE_HZ, pose, np.r_[8e-3 / 2.5 if moving else 0.0, 0.0, 0.0])
        c = [world.contacts[f] for f in fingers]
        inputs = SensorInputs(np.array([x.load for x in c]), np.array([x.force for x in c]),
                              np.array([world.force_rate[f] for f in fingers]), np.array([x.friction for x in c]),
                              np.array([x.shear_load for x in c]))
        e, pdc, tdc, tac, pac = model.frame(t, inputs)
        for k, v in zip(out, (e, pdc, tdc, tac, pac, c[0].force > 0)):
            out[k].append(v)
    arr = {k: np.array(v) for k, v in out.items()}
    return Record(np.arange(n) / RATE_HZ, arr["e"].astype(np.int64), arr["pdc"].astype(np.int64),
                  arr["tdc"].astype(np.int64), arr["tac"].astype(np.int64), arr["pac"].astype(np.int64),
                  arr["contact"])


def write_csv(path, rec: Record, names, *, time_name="time", time_scale=1.0, pac=False, finger_prefix=False,
              relative_to=None):
    """``rec`` as a CSV: the electrodes under ``names(i)`` (i = 1..N), ``pdc``, a time column
    ``time_name`` (× ``time_scale``), optionally ``pac1..pac22``; one sensor (ff) unless
    ``finger_prefix`` (ff and th, ``<finger>_``); values minus ``relative_to`` (counts) if given."""
    fingers = rec.fingers if finger_prefix else rec.fingers[:1]
    n = rec.electrodes.shape[2]
    header, cols = [time_name], [rec.time[:, None] * time_scale]
    for k, f in enumerate(fingers):
        p = f"{f}_" if finger_prefix else ""
        e = rec.electrodes[:, k] - (0 if relative_to is None else relative_to[k])
        header += [p + names(i) for i in range(1, n + 1)] + [p + "pdc"]
        cols += [e, rec.pdc[:, k:k + 1]]
        if pac:
            header += [f"{p}pac{i}" for i in range(1, rec.pac.shape[2] + 1)]
            cols.append(rec.pac[:, k])
    data = np.hstack([np.asarray(c, float) for c in cols])
    fmt = "%.0f" if time_scale > 1e3 else "%.6f"
    lines = [",".join([fmt % row[0], *(f"{v:.0f}" for v in row[1:])]) for row in data]
    path.write_text(",".join(header) + "\n" + "\n".join(lines) + "\n")
    return path


def write_ros1_bag(path, rec: Record, t0: float = 1_700_000_000.0):
    """``rec`` as a ROS1 bag of ``sr_robot_msgs/BiotacAll`` on ``/rh/tactile`` (Shadow's message,
    the newer form with ``pac[]``): ff and th connected, mf, rf, lf empty ports (pdc −22072,
    zero electrodes), as many electrodes per sensor as the record's model has."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    from tactile_flow.importers.bag import BIOTAC_MSGS

    ts = get_typestore(Stores.ROS1_NOETIC)
    types = {}
    for name, text in BIOTAC_MSGS.items():
        types.update(get_types_from_msg(text.replace("std_msgs/Header", "std_msgs/msg/Header"), name))
    ts.register(types)
    T = ts.types
    Biotac, BiotacAll = T["sr_robot_msgs/msg/Biotac"], T["sr_robot_msgs/msg/BiotacAll"]
    Header, Time = T["std_msgs/msg/Header"], T["builtin_interfaces/msg/Time"]
    n = rec.electrodes.shape[2]
    with Writer(path) as w:
        conn = w.add_connection("/rh/tactile", "sr_robot_msgs/msg/BiotacAll", typestore=ts)
        for i, t in enumerate(rec.time):
            stamp = t0 + t
            tact = []
            for f in ("ff", "mf", "rf", "lf", "th"):
                if f in rec.fingers:
                    k = rec.fingers.index(f)
                    pac = rec.pac[i, k].astype(np.int16)
                    tact.append(Biotac(pac0=int(pac[0]), pac1=int(pac[1]), pdc=int(rec.pdc[i, k]),
                                       tac=int(rec.tac[i, k]), tdc=int(rec.tdc[i, k]),
                                       electrodes=rec.electrodes[i, k].astype(np.int16), pac=pac))
                else:
                    tact.append(Biotac(pac0=0, pac1=0, pdc=-22072, tac=32570, tdc=0,
                                       electrodes=np.zeros(n, np.int16), pac=np.zeros(rec.pac.shape[2], np.int16)))
            sec = int(stamp)
            msg = BiotacAll(header=Header(seq=i, stamp=Time(sec=sec, nanosec=int(round((stamp - sec) * 1e9))),
                                          frame_id="rh_distal"), tactiles=tact)
            w.write(conn, int(round((stamp + 0.0015) * 1e9)), ts.serialize_ros1(msg, "sr_robot_msgs/msg/BiotacAll"))
    return path

"""Slip-in-place runs from Python, for benchmarks: the grid of ``+experiment=slip_in_place_grid``
without the command line.

    from tactile_flow.protocols.slip_grid import conditions, run_slip_in_place
    for c in conditions():                       # 72 conditions, as the Hydra grid
        result = run_slip_in_place(out / c.name, c, noise=1.0)
        result.store                             # run.zarr, truth/object_motions inside

Each run goes through :func:`protocols.run.run_protocol` with the config ``tactile-run`` composes
(``conf/``, protocol ``slip_in_place``), so the stores are the ones the CLI writes. ``noise``
scales the sensor noise (``hardware.sensor.noise_scale``) and the held object's tremor together:
0 is a noiseless sensor on a still object, 1 the calibrated lab.

:func:`varied_conditions` is a second, larger grid for calibrating and checking the slip estimate
on slips that look more like a researcher's (``python benchmarks/bench_slip_direction.py
--grid varied``): each condition draws, from a seeded generator, where on the pad the object
touches (the finger tilted up to 15°, so the contact sits off the pad's pole and
off the stage's rotation axis: a twist then also drags the contact sideways), how fast and far
the object is pulled or turned, and how steadily it is held (a hand's slow wander of the
press, up to 0.15 mm normal with 0.3–0.8 s correlation, as well as its tremor).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from tactile_flow.conf import DIR as CONF_DIR
from tactile_flow.hardware.sim.contact_check import PRESS_FORCES

DIRECTIONS_DEG = (0.0, 60.0, 120.0, 180.0, 240.0, 300.0)
ROTATIONS_DEG = (30.0, -30.0)
OBJECTS = ("flat", "cylinder")
#: the held object's tremor at noise = 1 (conf/protocol/slip_in_place.yaml)
TREMOR = {"tremor_mm": 0.01, "tremor_normal_mm": 0.005, "tremor_deg": 0.03}


@dataclass(frozen=True)
class Condition:
    """One slip-in-place run: the motion (``translate`` with ``direction_deg``, ``rotate`` with
    ``rotation_deg``, or ``none``), the press force (N), the object and whether it tares; and
    how it looks (defaults: the classic grid's): ``tilt_deg`` (pitch about the sensor's y, roll
    about its x: the contact off the pad's pole), ``speed_mm_s``/``distance_mm`` of a pull,
    ``rotation_speed_deg_s`` of a twist, ``tremor`` (the holder's tremor × this) with its
    correlation time ``tremor_tau_s``, and ``wander_mm``: the normal wander of a hand-held
    object's press (std, mm, with ``tremor_tau_s``) added to the tremor."""

    motion: str
    direction_deg: float = 0.0
    rotation_deg: float = 0.0
    press_force: float = PRESS_FORCES["light"]
    surface: str = "flat"
    tare: bool = True
    tilt_deg: tuple[float, float] = (0.0, 0.0)
    speed_mm_s: float = 5.0
    distance_mm: float = 4.0
    rotation_speed_deg_s: float = 40.0
    tremor: float = 1.0
    tremor_tau_s: float = 0.03
    wander_mm: float = 0.0

    @property
    def varied(self) -> bool:
        """Does it differ from a classic grid condition in anything but motion, force, object, tare?"""
        return self != replace(self, **{k: getattr(Condition, k) for k in VARIED_KEYS})

    @property
    def name(self) -> str:
        what = {"translate": f"translate_{self.direction_deg % 360:03.0f}", "none": "touch",
                "rotate": f"rotate_{'ccw' if self.rotation_deg > 0 else 'cw'}"}[self.motion]
        name = f"{what}_{self.press_force:g}N_{self.surface}_{'tare' if self.tare else 'notare'}"
        if self.varied:
            name += (f"_tilt{self.tilt_deg[0]:+.0f}{self.tilt_deg[1]:+.0f}_v{self.speed_mm_s:g}d{self.distance_mm:g}"
                     f"w{self.rotation_speed_deg_s:g}a{abs(self.rotation_deg):g}_t{self.tremor:g}"
                     f"_{self.tremor_tau_s:g}s_n{self.wander_mm:g}")
        return name

    def overrides(self) -> list[str]:
        o = [f"protocol.motion={self.motion}", f"protocol.press_force={self.press_force}",
             f"surface={self.surface}", f"protocol.tare={str(self.tare).lower()}"]
        if self.motion == "translate":
            o.append(f"protocol.direction_deg={self.direction_deg}")
        if self.motion == "rotate":
            o.append(f"protocol.rotation_deg={self.rotation_deg}")
        if self.varied:
            o += [f"protocol.speed_mm_s={self.speed_mm_s}", f"protocol.distance_mm={self.distance_mm}",
                  f"protocol.rotation_speed_deg_s={self.rotation_speed_deg_s}",
                  f"hardware.stage.tremor_tau_s={self.tremor_tau_s}"]
            if any(self.tilt_deg):
                tip = ",".join(f"{v:.9f}" for v in tilted_tip(*self.tilt_deg))
                o.append(f"hardware.fingertips.ff=[0.0,0.0,0.0,{tip}]")
        return o

    def tremor_overrides(self, noise: float) -> list[str]:
        """The holder's tremor (``TREMOR`` × ``tremor`` × ``noise``) and the press's wander."""
        t = {k: v * self.tremor * noise for k, v in TREMOR.items()}
        t["tremor_normal_mm"] = math.hypot(t["tremor_normal_mm"], self.wander_mm)
        return [f"protocol.{k}={v:.6g}" for k, v in t.items()]


VARIED_KEYS = ("tilt_deg", "speed_mm_s", "distance_mm", "rotation_speed_deg_s", "tremor", "tremor_tau_s",
               "wander_mm")


def tilted_tip(pitch_deg: float, roll_deg: float) -> list[float]:
    """Rotation vector of the fingertip in the TCP (``hardware.fingertips.ff[3:]``) pitched by
    ``pitch_deg`` about the sensor's y and rolled by ``roll_deg`` about its x (the default,
    π about x, turns the pad down)."""
    from tactile_flow.hardware.transforms import matrix_to_rotvec, rotvec_to_matrix
    pitch = rotvec_to_matrix([0.0, math.radians(pitch_deg), 0.0])
    roll = rotvec_to_matrix([math.radians(roll_deg), 0.0, 0.0])
    return matrix_to_rotvec(rotvec_to_matrix([math.pi, 0.0, 0.0]) @ roll @ pitch).tolist()


def conditions(directions=DIRECTIONS_DEG, rotations=ROTATIONS_DEG, forces=tuple(PRESS_FORCES.values()),
               objects=OBJECTS, tares=(True, False)) -> list[Condition]:
    """Every motion (translations, rotations, one touch) × force × object × tare."""
    motions = ([("translate", d, 0.0) for d in directions] + [("rotate", 0.0, r) for r in rotations]
               + [("none", 0.0, 0.0)])
    return [Condition(m, d, r, f, s, t) for (m, d, r), f, s, t in itertools.product(motions, forces, objects, tares)]


def varied_conditions(n: int = 120, seed: int = 33, tares=(True, False)) -> list[Condition]:
    """``n`` conditions drawn deterministically (``seed``) for slips that look like a researcher's
    (module docstring): motions in the classic grid's proportions (6 directions, now anywhere on
    the circle; both senses; touches), forces 1–4.5 N (firmer presses of a tilted finger bottom its
    electrodes out: the interlock stops them), both objects, with and without tare,
    the contact up to 15° off the pole, pulls of 1.5–6 mm at 2–15 mm/s, twists of 15–45° at
    15–90 deg/s, the holder's tremor ×0.5–3 and, for a third of the runs, a slow wander of the
    press."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        kind = ("translate",) * 6 + ("rotate",) * 2 + ("none",)
        motion = kind[i % len(kind)]
        sense = 1.0 if i % len(kind) == 6 else -1.0
        out.append(Condition(
            motion=motion, direction_deg=float(np.round(rng.uniform(0, 360), 1)),
            rotation_deg=float(sense * np.round(rng.uniform(15, 45), 1)),
            press_force=float(np.round(rng.uniform(1.0, 4.5), 2)), surface=str(rng.choice(OBJECTS)),
            tare=bool(tares[i % len(tares)]), tilt_deg=_tilt(rng),
            speed_mm_s=float(np.round(rng.uniform(2, 15), 1)), distance_mm=float(np.round(rng.uniform(1.5, 6), 1)),
            rotation_speed_deg_s=float(np.round(rng.uniform(15, 90), 0)),
            tremor=float(np.round(rng.uniform(0.5, 3), 2)),
            tremor_tau_s=float(np.round(rng.uniform(0.03, 0.8), 2)),
            wander_mm=float(np.round(rng.uniform(0.03, 0.15), 3)) if i % 3 == 0 else 0.0))
    return out


def _tilt(rng) -> tuple[float, float]:
    """(pitch, roll) deg: a tilt of up to ``MAX_TILT_DEG`` in any direction."""
    size, towards = rng.uniform(0, MAX_TILT_DEG), rng.uniform(0, 2 * math.pi)
    return float(np.round(size * math.cos(towards), 1)), float(np.round(size * math.sin(towards), 1))


MAX_TILT_DEG = 15.0
"""The finger's largest tilt in the varied grid: the pad's contact moves ~4 mm off its pole, and
the press still starts clear of the object (``press.height``)."""


def compose(condition: Condition, noise: float = 1.0, seed: int = 0, baseline: str | None = "simulated",
            overrides=()):
    """The run config ``tactile-run protocol=slip_in_place ...`` would compose for ``condition``."""
    from hydra import compose as hydra_compose
    from hydra import initialize_config_dir

    from .schema import register

    register()
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base=None):
        return hydra_compose("config", overrides=[
            "protocol=slip_in_place", "progress=false", *condition.overrides(), *condition.tremor_overrides(noise),
            f"hardware.sensor.noise_scale={noise}", f"hardware.seed={seed}",
            f"hardware.biotac_calibration={'null' if baseline is None else baseline}", *overrides])


def run_slip_in_place(run_dir, condition: Condition, noise: float = 1.0, seed: int = 0,
                      baseline: str | None = "simulated", analyze: bool = False, overrides=()):
    """Run ``condition`` into ``run_dir`` (must not hold a run yet); returns the
    :class:`protocols.run.RunResult` (``analyze``: also hand it to the analysis, as tactile-run)."""
    from .run import hand_off, run_protocol

    cfg = compose(condition, noise, seed, baseline, overrides)
    result = run_protocol(cfg, Path(run_dir), console=lambda *a: None)
    if analyze and result.status == "success":
        result.analysis = hand_off(result, cfg.analysis, console=lambda *a: None)
    return result

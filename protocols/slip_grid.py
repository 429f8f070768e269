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
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from pathlib import Path

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
    ``rotation_deg``, or ``none``), the press force (N), the object and whether it tares."""

    motion: str
    direction_deg: float = 0.0
    rotation_deg: float = 0.0
    press_force: float = PRESS_FORCES["light"]
    surface: str = "flat"
    tare: bool = True

    @property
    def name(self) -> str:
        what = {"translate": f"translate_{self.direction_deg:03.0f}", "none": "touch",
                "rotate": f"rotate_{'ccw' if self.rotation_deg > 0 else 'cw'}"}[self.motion]
        return f"{what}_{self.press_force:g}N_{self.surface}_{'tare' if self.tare else 'notare'}"

    def overrides(self) -> list[str]:
        o = [f"protocol.motion={self.motion}", f"protocol.press_force={self.press_force}",
             f"surface={self.surface}", f"protocol.tare={str(self.tare).lower()}"]
        if self.motion == "translate":
            o.append(f"protocol.direction_deg={self.direction_deg}")
        if self.motion == "rotate":
            o.append(f"protocol.rotation_deg={self.rotation_deg}")
        return o


def conditions(directions=DIRECTIONS_DEG, rotations=ROTATIONS_DEG, forces=tuple(PRESS_FORCES.values()),
               objects=OBJECTS, tares=(True, False)) -> list[Condition]:
    """Every motion (translations, rotations, one touch) × force × object × tare."""
    motions = ([("translate", d, 0.0) for d in directions] + [("rotate", 0.0, r) for r in rotations]
               + [("none", 0.0, 0.0)])
    return [Condition(m, d, r, f, s, t) for (m, d, r), f, s, t in itertools.product(motions, forces, objects, tares)]


def compose(condition: Condition, noise: float = 1.0, seed: int = 0, baseline: str | None = "simulated",
            overrides=()):
    """The run config ``tactile-run protocol=slip_in_place ...`` would compose for ``condition``."""
    from hydra import compose as hydra_compose
    from hydra import initialize_config_dir

    from .schema import register

    register()
    tremor = [f"protocol.{k}={v * noise}" for k, v in TREMOR.items()]
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base=None):
        return hydra_compose("config", overrides=[
            "protocol=slip_in_place", "progress=false", *condition.overrides(), *tremor,
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

"""The simulated lab (``hardware=sim``): one world, one clock, five devices, ground truth.

    from tactile_flow.hardware.sim import make_sim_lab
    with make_sim_lab({"seed": 1}, {"kind": "straws"}) as lab:
        lab.arm.move_linear(pose, speed=0.01)
        frames = lab.biotac.read()
        truth = lab.truth.to_dict()

See ``docs/simulator.md``.
"""

from __future__ import annotations

from ..lab_container import Lab
from .clock import SimClock
from .config import SimConfig, load_config
from .devices import SimArm, SimBiotac, SimHand, SimPump, SimScale
from .stage_device import SimStage
from ..surfaces import Surface, SurfaceConfig, load_surface
from .truth import GroundTruth
from .world import SimWorld

__all__ = ["Lab", "make_sim_lab", "SimConfig", "SurfaceConfig", "load_config", "load_surface",
           "SimWorld", "SimClock", "SimArm", "SimHand", "SimBiotac", "SimPump", "SimScale", "SimStage",
           "Surface", "GroundTruth"]


def make_sim_lab(cfg=None, surface=None, *, hardware_key: str = "hardware",
                 surface_key: str = "surface", sensor=None) -> Lab:
    """Build the simulated lab; devices are returned unconnected.

    ``cfg``: dict / OmegaConf node / :class:`SimConfig` mirroring ``conf/hardware/sim.yaml``
    (None: defaults). ``surface``: dict / OmegaConf / :class:`SurfaceConfig` as in
    ``conf/surface/*.yaml`` (None: no board). ``sensor``: the fingertips' model, a
    :class:`tactile.sensor.SensorModel` (None: the BioTac SP). Every value is validated
    first; a bad one raises :class:`~hardware.errors.ConfigError` (a ValueError) naming its key.
    """
    c = load_config(cfg, hardware_key)
    surf = load_surface(surface, surface_key) if surface is not None else None
    world = SimWorld(c, surf, sensor)
    clock = SimClock(world, realtime=c.realtime)
    return Lab(arm=SimArm(world, clock), hand=SimHand(world, clock), biotac=SimBiotac(world, clock),
               pump=SimPump(world, clock), scale=SimScale(world, clock), clock=clock, world=world,
               truth=world.truth, surface=surf, stage=SimStage(world, clock) if c.stage is not None else None)

"""Configuration of the simulated lab (``hardware=sim``, mirrors ``conf/hardware/sim.yaml``),
and the parts the real lab shares with it (:class:`WorkspaceConfig`).

Dataclasses of the project's one validation layer (:mod:`validation`): field types and
:func:`~validation.spec` bounds are checked by :func:`~validation.build`; :func:`validate`
adds the checks that relate several values (rates that divide the world step, kinetic
below static friction, fault times). :func:`load_config` does both, raising
:class:`~hardware.errors.ConfigError` naming the dotted key, e.g. ``hardware.fingers[2]``.
Units are in the key names (``_m``, ``_mm``, ``_s``, ``_hz``, ``_n``, ``_g``, ...).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional

from tactile_flow.validation import build, spec

from .biotac import FINGERS, check_fingers
from .errors import BUFFER_RANGE_S, RATE_RANGE_HZ, ConfigError, brief, require_within

DEVICES = ("arm", "hand", "biotac", "pump", "scale", "stage")
#: the world step (s): the arm controller's period is 2 ms; much finer makes a run crawl,
#: coarser no longer resolves a contact
STEP_RANGE_S = (1e-4, 0.01)
SEED_MAX = 2**63 - 1


def _default_fingertips() -> dict[str, list[float]]:
    # Sensor frame relative to the TCP frame: [x, y, z] m, [rx, ry, rz] rad. Rotating π
    # about x turns the sensor's contact side (-z) to the tool direction (+z of the TCP):
    # with the TCP pointing down ([π, 0, 0]) the sensor axes align with the base axes.
    # ff is the TCP; the others sit beside it and 30 mm higher, clear of a sweep.
    pi = math.pi
    return {"ff": [0.0, 0.0, 0.0, pi, 0.0, 0.0],
            "mf": [0.0, 0.022, -0.03, pi, 0.0, 0.0],
            "rf": [0.0, 0.044, -0.03, pi, 0.0, 0.0],
            "lf": [0.0, 0.066, -0.03, pi, 0.0, 0.0],
            "th": [0.03, -0.04, -0.03, pi, 0.0, 0.0]}


@dataclass
class WorkspaceConfig:
    """Box in the robot base frame (m) the TCP must stay in (the simulated table's reach)."""
    min_m: list[float] = field(default_factory=lambda: [-0.2, -0.4, 0.0])
    max_m: list[float] = field(default_factory=lambda: [0.8, 0.4, 0.6])


@dataclass
class ArmConfig:
    home_pose: list[float] = spec(factory=lambda: [0.3, 0.0, 0.2, math.pi, 0.0, 0.0], length=6)
    max_speed_m_s: float = spec(0.25, gt=0)
    max_accel_m_s2: float = spec(2.0, gt=0)
    stop_accel_m_s2: float = spec(4.0, gt=0)          # deceleration of a protective stop
    max_contact_force_n: float = spec(40.0, gt=0)     # above it the controller stops protectively
    wrench_noise_n: float = spec(0.05, ge=0)


@dataclass
class ContactConfig:
    """Fingertip skin and friction."""
    stiffness_n_mm2: float = spec(0.08, gt=0)         # local pressure = k · indentation^exponent (N/mm², mm)
    exponent: float = spec(1.5, gt=0)                 # Hertz-like
    friction: float = spec(0.6, ge=0)                 # sliding (kinetic) friction coefficient
    friction_static: float = spec(0.8, gt=0)          # static friction: the skin sticks to a moved object up to μs·F
    slip_speed_m_s: float = spec(0.001, gt=0)         # speed at which sliding friction is fully developed
    skin_shear_modulus_n_mm2: float = spec(0.08, gt=0)  # G*: tangential stiffness 8G*a, torsional (16/3)G*a³ (Mindlin)
    stick_slip: bool = True               # after a slip the skin sticks again (stick-slip of a pulled object)
    mesh_theta: int = spec(28, gt=0)                  # ellipsoid sampling (contact half): rings
    mesh_phi: int = spec(56, gt=0)                    # points per ring


@dataclass
class SensorModelConfig:
    """BioTac model; resting statistics come from ``calibration`` (a file in hardware/sim)."""
    calibration: str = "biotac_rest_calibration.json"
    noise_scale: float = spec(1.0, ge=0)
    drift_scale: float = spec(1.0, ge=0)
    drift_tau_s: float = spec(600.0, gt=0)            # warm-up drift settles with this time constant
    baseline_jitter_counts: float = spec(40.0, ge=0)  # per-taxel spread added to the real baselines
    # contact response, calibrated on real contact frames (biotac_contact_calibration.json)
    kernel_sigma_mm: float = spec(2.5, gt=0)          # width of a taxel's footprint (Gaussian, mm)
    saturation_load_n: float = spec(3.0, gt=0)        # footprint load (N) at which an electrode bottoms out
    far_rise_per_n: float = spec(0.023, ge=0)         # relative impedance drop of all electrodes per N of force
    contact_noise_fraction: float = spec(0.005, ge=0) # extra noise: this share of the load's impedance change
    shear_kohm_per_n: float = spec(12.0, ge=0)        # kΩ of electrode impedance per N-equivalent of shear load
    shear_gain: float = spec(0.3, ge=0)               # shear load per N of traction (leading +, trailing -)
    shear_length_mm: float = spec(6.0, gt=0)
    pdc_counts_per_n: float = spec(140.0, gt=0)
    pdc_saturation_n: float = spec(20.0, gt=0)
    pac_gain_per_n_s: float = spec(15.0, ge=0)        # PAC counts per N/s of force change
    pac_slip_gain: float = spec(15.0, ge=0)           # PAC noise std (counts) per N of sliding friction
    tac_counts_per_n: float = spec(4.0, ge=0)         # heat flow into a touched object cools TAC
    # the lab's per-sensor calibration (unloaded counts measured at the session's start) as
    # simulated for hardware.biotac_calibration=simulated: the mean of a rest this long, off the
    # sensor's unloaded counts at the run by a drift per electrode and one shared by all (std)
    calibration_rest_s: float = spec(1.0, gt=0)
    calibration_drift_counts: float = spec(10.0, ge=0)
    calibration_common_drift_counts: float = spec(64.0, ge=0)
    latency_s: float = spec(0.0015, ge=0)             # host receipt after device time
    clock_drift_ppm: float = spec(20.0, ge=0)


@dataclass
class StageConfig:
    """Object stage under the board (``hardware/stage.py``): XY translation + rotary stage.

    The surface sits on it; its rotation axis passes through ``axis_m`` (base frame x, y, m)
    at home. ``tremor_*``: the jitter of the object it holds (std of an AR(1) with
    ``tremor_tau_s``): tangential (mm), normal (mm: the force fluctuation) and angular (deg);
    0 for a board resting on a still stage, the hand's or robot's tremor for a held object
    (``conf/hardware/sim.yaml`` takes them from the protocol's ``tremor_*`` keys)."""
    axis_m: list[float] = field(default_factory=lambda: [0.3, 0.0])
    max_travel_m: float = spec(0.05, gt=0)            # each axis, from home
    max_speed_m_s: float = spec(0.05, gt=0)
    accel_m_s2: float = spec(0.5, gt=0)
    max_rotation_rad: float = spec(3.2, gt=0)         # from home, either way
    max_angular_speed_rad_s: float = spec(3.0, gt=0)
    angular_accel_rad_s2: float = spec(30.0, gt=0)
    rate_hz: float = spec(100.0, gt=0)
    tremor_mm: float = spec(0.0, ge=0)
    tremor_normal_mm: float = spec(0.0, ge=0)
    tremor_deg: float = spec(0.0, ge=0)
    tremor_tau_s: float = spec(0.03, gt=0)


@dataclass
class HandConfig:
    default_positions: dict[str, float] = field(default_factory=dict)
    max_velocity_rad_s: float = 2.0


@dataclass
class PourConfig:
    """Bottle held in the grasp while the pump fills it."""
    bottle_in_hand: bool = True
    grasp_fingers: list[str] = field(default_factory=lambda: ["ff", "mf", "th"])
    contact_flexion_rad: float = spec(1.0, ge=0)      # J2+J3 (thumb J1+J2) at which the finger meets the bottle
    grip_n_per_rad: float = spec(8.0, gt=0)           # normal force per rad of commanded closure beyond contact
    bottle_empty_g: float = spec(60.0, ge=0)
    friction_static: float = spec(0.8, gt=0)
    partial_slip_ratio: float = spec(0.6, gt=0)       # weight / (μs·N) at which the contact edge starts to slip
    com_offset_m: float = spec(0.03, ge=0)            # grasp to centre of mass: gravity's lever arm
    torsion_arm_m: float = spec(0.024, gt=0)          # torque the grip resists per N of friction
    rotation_damping_n_m_s: float = spec(0.01, gt=0)
    max_rotation_rad: float = spec(0.5, gt=0)
    slide_damping_n_s_m: float = spec(150.0, gt=0)    # viscous creep of the downward slide
    full_slip_mm: float = spec(12.0, gt=0)            # slide distance at which the bottle leaves the fingers
    stretch_mm_per_n: float = spec(0.4, ge=0)         # skin stretch under shear (static flow)
    max_stretch_mm: float = spec(2.0, ge=0)
    kinetic_ratio: float = spec(0.85, gt=0, le=1)           # kinetic / static friction (torsional and linear breakaway)
    slip_release: float = spec(0.4, ge=0, lt=1)             # fraction of the stored skin stretch released when the bottle first gives
    slip_normal_dip: float = spec(0.12, ge=0, lt=1)         # fraction of the grip's normal load lost in the skin's recoil
    recoil_tau_s: float = spec(0.3, gt=0)             # the released strain and load recover with this time constant
    gravity_sensor: list[float] = field(default_factory=lambda: [0.0, 1.0, 0.0])


@dataclass
class PumpConfig:
    max_rate_ml_min: float = spec(150.0, gt=0)
    rate_hz: float = spec(10.0, gt=0)


@dataclass
class ScaleConfig:
    reservoir_g: float = spec(1500.0, ge=0)           # the scale weighs the reservoir the pump draws from
    noise_g: float = spec(0.05, ge=0)
    resolution_g: float = spec(0.01, gt=0)
    rate_hz: float = spec(10.0, gt=0)
    settle_s: float = spec(0.5, gt=0)                 # unstable while the reading changed within this window


@dataclass
class FaultsConfig:
    """Faults injected at given simulated times (s)."""
    biotac_dropout: list[list[float]] = field(default_factory=list)  # [[t0, t1], ...] no frames
    biotac_corrupt: list[float] = field(default_factory=list)        # frames at these times garbled
    protective_stop_s: Optional[float] = None
    disconnect: dict[str, float] = field(default_factory=dict)       # device -> time


@dataclass
class SimConfig:
    """The simulated lab (``hardware=sim``)."""
    backend: str = "sim"
    seed: int = 0
    realtime: bool = False
    fingers: list[str] = field(default_factory=lambda: list(FINGERS))
    step_s: float = 0.002                 # world step = arm controller period (500 Hz)
    biotac_rate_hz: float = 100.0
    hand_rate_hz: float = 100.0
    buffer_s: float = 120.0               # device buffers hold this much unread data
    workspace: WorkspaceConfig = field(default_factory=WorkspaceConfig)
    arm: ArmConfig = field(default_factory=ArmConfig)
    fingertips: dict[str, list[float]] = field(default_factory=_default_fingertips)
    contact: ContactConfig = field(default_factory=ContactConfig)
    sensor: SensorModelConfig = field(default_factory=SensorModelConfig)
    hand: HandConfig = field(default_factory=HandConfig)
    pour: PourConfig = field(default_factory=PourConfig)
    pump: PumpConfig = field(default_factory=PumpConfig)
    scale: ScaleConfig = field(default_factory=ScaleConfig)
    stage: Optional[StageConfig] = field(default_factory=StageConfig)   # null: no object stage
    biotac_calibration: Optional[str] = "simulated"   # stored unloaded baseline: "simulated", a JSON file, null
    faults: FaultsConfig = field(default_factory=FaultsConfig)


# --------------------------------------------------------------------------- checking

def validate(cfg: SimConfig, key: str = "hardware") -> SimConfig:
    """Check values; raises ConfigError naming the key. Returns ``cfg`` (fingers in Shadow order)."""
    if cfg.backend != "sim":
        raise ConfigError(f"{key}.backend", f"expected 'sim', got {cfg.backend!r}")
    cfg.fingers = list(check_fingers(cfg.fingers, f"{key}.fingers"))
    if not 0 <= cfg.seed <= SEED_MAX:
        raise ConfigError(f"{key}.seed", f"expected a whole number in [0, 2**63 - 1], got {brief(cfg.seed)}")
    require_within(cfg, ["step_s"], STEP_RANGE_S, "s", key)
    require_within(cfg, ["biotac_rate_hz", "hand_rate_hz"], RATE_RANGE_HZ, "Hz", key)
    require_within(cfg.pump, ["rate_hz"], RATE_RANGE_HZ, "Hz", f"{key}.pump")
    require_within(cfg.scale, ["rate_hz"], RATE_RANGE_HZ, "Hz", f"{key}.scale")
    require_within(cfg, ["buffer_s"], BUFFER_RANGE_S, "s", key)
    for n in ("biotac_rate_hz", "hand_rate_hz"):
        ticks = 1.0 / (getattr(cfg, n) * cfg.step_s)
        if abs(ticks - round(ticks)) > 1e-9 or round(ticks) < 1:
            raise ConfigError(f"{key}.{n}", f"the period must be a whole number of step_s "
                                            f"({cfg.step_s} s), got {getattr(cfg, n)} Hz")
    for n in ("pump", "scale"):
        ticks = 1.0 / (getattr(cfg, n).rate_hz * cfg.step_s)
        if abs(ticks - round(ticks)) > 1e-9 or round(ticks) < 1:
            raise ConfigError(f"{key}.{n}.rate_hz", "the period must be a whole number of step_s")
    for f in cfg.fingers:
        if f not in cfg.fingertips:
            raise ConfigError(f"{key}.fingertips", f"no pose for finger {f!r}")
    for f, pose in cfg.fingertips.items():
        if f not in FINGERS:
            raise ConfigError(f"{key}.fingertips.{f}", f"{f!r} is not a finger; expected one of {', '.join(FINGERS)}")
        if len(pose) != 6:
            raise ConfigError(f"{key}.fingertips.{f}", f"expected [x,y,z,rx,ry,rz] (m, rad), got {pose}")
    if cfg.contact.friction > cfg.contact.friction_static:
        raise ConfigError(f"{key}.contact.friction", f"the kinetic friction ({cfg.contact.friction}) cannot exceed "
                                                     f"the static one (contact.friction_static = "
                                                     f"{cfg.contact.friction_static})")
    if cfg.stage is not None:
        st = cfg.stage
        if len(st.axis_m) != 2:
            raise ConfigError(f"{key}.stage.axis_m", f"expected [x, y] (m), got {st.axis_m}")
        ticks = 1.0 / (st.rate_hz * cfg.step_s)
        if abs(ticks - round(ticks)) > 1e-9 or round(ticks) < 1:
            raise ConfigError(f"{key}.stage.rate_hz", "the period must be a whole number of step_s")
    p = cfg.pour
    check_fingers(p.grasp_fingers, f"{key}.pour.grasp_fingers")
    if len(p.gravity_sensor) != 3 or math.hypot(*p.gravity_sensor) == 0:
        raise ConfigError(f"{key}.pour.gravity_sensor", "expected a non-zero 3-vector in the sensor frame")
    fk = f"{key}.faults"
    for i, w in enumerate(cfg.faults.biotac_dropout):
        if len(w) != 2 or not 0 <= w[0] < w[1]:
            raise ConfigError(f"{fk}.biotac_dropout[{i}]", f"expected [t0, t1] with 0 <= t0 < t1 (s), got {w}")
    for i, t in enumerate(cfg.faults.biotac_corrupt):
        if t < 0:
            raise ConfigError(f"{fk}.biotac_corrupt[{i}]", f"expected a time >= 0 (s), got {t}")
    if cfg.faults.protective_stop_s is not None and cfg.faults.protective_stop_s < 0:
        raise ConfigError(f"{fk}.protective_stop_s", "expected a time >= 0 (s)")
    for dev, t in cfg.faults.disconnect.items():
        if dev not in DEVICES:
            raise ConfigError(f"{fk}.disconnect.{dev}", f"unknown device; expected one of {', '.join(DEVICES)}")
        if t < 0:
            raise ConfigError(f"{fk}.disconnect.{dev}", "expected a time >= 0 (s)")
    return cfg


def load_config(data=None, key: str = "hardware") -> SimConfig:
    """A validated :class:`SimConfig` from a dict / OmegaConf node / SimConfig / None (defaults)."""
    cfg = build(SimConfig, data, key)
    return validate(cfg, key)

"""The real lab (``hardware=lab`` / ``hardware=lab_emulated``): one driver per device.

    from tactile_flow.hardware.lab import make_real_lab
    lab = make_real_lab(OmegaConf.load("conf/hardware/lab.yaml"), OmegaConf.load("conf/surface/straws.yaml"))
    with lab:                       # connects arm, hand, biotac, pump, scale (all closed if one fails)
        lab.arm.move_linear(pose, speed=0.01)

============  =========================================  ===========================
device        driver                                     link
============  =========================================  ===========================
arm           :class:`hardware.ur10.UR10Arm`             ur_rtde (RTDE, dashboard)
hand          :class:`hardware.shadow.ShadowHand`        rosbridge (roslibpy)
biotac        :class:`hardware.shadow.RosbridgeBiotacs`  rosbridge ``/rh/tactile``
              or :class:`hardware.serial_biotac.SerialBiotacs`  serial bridge (pyserial)
pump          :class:`hardware.serial_pour.SerialPump`   serial, EZO-PMP-like lines
scale         :class:`hardware.serial_pour.SerialScale`  serial, A&D-like stream
============  =========================================  ===========================

Every key of ``conf/hardware/lab.yaml`` is validated before any device is built; a bad
one raises :class:`~hardware.errors.ConfigError` naming it (``hardware.pump.poll_hz``).
The planner reads the same keys as for the simulator (``workspace``, ``arm.*`` limits and
``home_pose``, ``fingertips``, ``fingers``, ``pump.max_rate_ml_min``).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from .biotac import FINGERS, check_fingers
from .device import WallClock
from .errors import ConfigError
from .serial_biotac import SerialBiotacConfig, SerialBiotacs
from .serial_pour import SerialPump, SerialPumpConfig, SerialScale, SerialScaleConfig
from .shadow import RosbridgeBiotacConfig, RosbridgeBiotacs, ShadowHand, ShadowHandConfig
from .rosbridge import RosbridgeConfig
from tactile_flow.validation import build, to_plain, unknown_key

from .config import WorkspaceConfig
from .lab_container import Lab
from .surfaces import load_surface

TOP_KEYS = ("backend", "fingers", "workspace", "arm", "fingertips", "rosbridge", "hand", "biotac", "pump", "scale",
            "biotac_calibration", "emulator")
#: in an emulated lab's folder (``emulator``): what ``tactile-emulate`` emulates (its board), as JSON
EMULATOR_FILE = "emulator.json"
BIOTAC_SOURCES = ("rosbridge", "serial")
#: arm keys the planner and the engine read; the rest go to the UR10 driver's config
ARM_PLAN_KEYS = ("home_pose", "max_speed_m_s", "max_accel_m_s2", "stop_accel_m_s2", "max_contact_force_n")


@dataclass
class LabArmConfig:
    """``hardware.arm`` of the real lab: the limits the planner and the engine read (as the
    simulator's :class:`~hardware.config.ArmConfig`) and the UR10 driver's own settings."""
    home_pose: list[float]
    max_speed_m_s: float
    max_accel_m_s2: float
    stop_accel_m_s2: float
    max_contact_force_n: float
    driver: object                      # hardware.ur10.UR10Config


@dataclass
class LabConfig:
    """The real lab (``conf/hardware/lab.yaml``), every key checked: what :func:`make_real_lab`
    builds the drivers from, and what the planner reads (as from a
    :class:`~hardware.config.SimConfig`: ``workspace``, ``arm``, ``fingertips``, ``fingers``,
    ``pump.max_rate_ml_min``, ``hand.max_velocity_rad_s``, ``stage``)."""
    backend: str
    fingers: list[str]
    workspace: WorkspaceConfig
    arm: LabArmConfig
    fingertips: dict
    rosbridge: RosbridgeConfig
    hand: ShadowHandConfig
    biotac: RosbridgeBiotacConfig | SerialBiotacConfig
    pump: SerialPumpConfig
    scale: SerialScaleConfig
    biotac_calibration: str | None = None
    emulator: str | None = None         # the folder of a tactile-emulate lab (hardware=lab_emulated), else None
    stage: None = None                  # the real lab has no object stage


def load_lab_config(hw_cfg, key: str = "hardware") -> LabConfig:
    """Check every key of ``conf/hardware/lab.yaml`` (a dict, OmegaConf node or
    :class:`LabConfig`) without building a driver; raises :class:`ConfigError` naming the key."""
    if isinstance(hw_cfg, LabConfig):
        return hw_cfg
    hw = to_plain(hw_cfg) or {}
    if not isinstance(hw, dict):
        raise ConfigError(key, f"expected a mapping, got {type(hw).__name__}")
    unknown = sorted(set(hw) - set(TOP_KEYS))
    if unknown:
        raise unknown_key(key, unknown[0], TOP_KEYS)
    if hw.get("backend", "lab") != "lab":
        raise ConfigError(f"{key}.backend", f"expected 'lab', got {hw.get('backend')!r}")
    fingers = list(check_fingers(hw.get("fingers", FINGERS), f"{key}.fingers"))
    workspace = build(WorkspaceConfig, hw.get("workspace"), f"{key}.workspace")
    _check_fingertips(hw.get("fingertips"), fingers, f"{key}.fingertips")
    calibration = hw.get("biotac_calibration")
    if calibration is not None and not isinstance(calibration, str):
        raise ConfigError(f"{key}.biotac_calibration", f"expected a file name or null, got {calibration!r}")
    emulator = hw.get("emulator")
    if emulator is not None and not isinstance(emulator, str):
        raise ConfigError(f"{key}.emulator", f"got {emulator!r}; expected the emulated lab's folder or null")
    rosbridge = _make(RosbridgeConfig, hw.get("rosbridge"), f"{key}.rosbridge")
    return LabConfig(backend="lab", fingers=fingers, workspace=workspace,
                     arm=_arm_config(hw.get("arm"), workspace, f"{key}.arm"),
                     fingertips=dict(hw["fingertips"]), rosbridge=rosbridge,
                     hand=_make(ShadowHandConfig, hw.get("hand"), f"{key}.hand", rosbridge=rosbridge),
                     biotac=biotac_config(hw.get("biotac"), fingers, rosbridge, f"{key}.biotac"),
                     pump=_make(SerialPumpConfig, hw.get("pump"), f"{key}.pump"),
                     scale=_make(SerialScaleConfig, hw.get("scale"), f"{key}.scale"),
                     biotac_calibration=calibration, emulator=emulator)


def emulated_board(cfg: LabConfig) -> dict | None:
    """What an emulated lab (``cfg.emulator``) says about its board: ``{"surface_name": NAME,
    "surface": {...}}`` (``surface`` None: the BioTacs rest), or None (not emulated, or no
    ``tactile-emulate`` running there)."""
    import json
    from pathlib import Path
    if cfg.emulator is None:
        return None
    try:
        return json.loads((Path(cfg.emulator) / EMULATOR_FILE).read_text())
    except (OSError, ValueError):
        return None


def make_real_lab(hw_cfg, surface_cfg=None, *, key: str = "hardware") -> Lab:
    """Build the lab of ``conf/hardware/lab.yaml``; devices are returned unconnected.

    ``hw_cfg``: a :class:`LabConfig`, or a dict or OmegaConf node (checked by
    :func:`load_lab_config`); ``surface_cfg``: as ``conf/surface/*.yaml`` (geometry shared with
    the simulator), or None.
    """
    from .ur10 import UR10Arm

    cfg = load_lab_config(hw_cfg, key)
    clock = WallClock()
    surface = load_surface(surface_cfg) if surface_cfg is not None else None
    biotac = (SerialBiotacs(cfg.biotac, clock) if isinstance(cfg.biotac, SerialBiotacConfig)
              else RosbridgeBiotacs(cfg.biotac, clock))
    return Lab(arm=UR10Arm(cfg.arm.driver), hand=ShadowHand(cfg.hand, clock), biotac=biotac,
               pump=SerialPump(cfg.pump, clock), scale=SerialScale(cfg.scale, clock),
               clock=clock, surface=surface)


def biotac_config(data, fingers, rosbridge: RosbridgeConfig, key: str):
    """The config of the BioTac driver ``biotac.source`` names (:class:`RosbridgeBiotacConfig` or
    :class:`SerialBiotacConfig`); the keys of the other source (``topic`` for serial,
    ``port``/``baudrate`` for rosbridge) are accepted and ignored, so one ``lab.yaml`` can hold both."""
    data = dict(to_plain(data) or {})
    source = data.pop("source", "rosbridge")
    if source not in BIOTAC_SOURCES:
        raise ConfigError(f"{key}.source", f"expected one of {', '.join(BIOTAC_SOURCES)}, got {source!r}")
    if source == "serial":
        data.pop("topic", None)
        return _make(SerialBiotacConfig, data, key, fingers=tuple(fingers))
    data.pop("port", None)
    data.pop("baudrate", None)
    return _make(RosbridgeBiotacConfig, data, key, rosbridge=rosbridge, fingers=tuple(fingers))


def _arm_config(data, workspace: WorkspaceConfig, key: str) -> LabArmConfig:
    """``arm.*``: the planner's keys (:data:`ARM_PLAN_KEYS`, bounded as the simulator's) and
    every other key a :class:`hardware.ur10.UR10Config` setting."""
    from .config import ArmConfig
    from .ur10 import UR10Config

    data = dict(to_plain(data) or {})
    if not isinstance(data, dict):
        raise ConfigError(key, f"expected a mapping, got {data!r}")
    plan = build(ArmConfig, {k: data[k] for k in ARM_PLAN_KEYS if k in data}, key)
    driver = dict(data)
    for k in set(ARM_PLAN_KEYS) - {f.name for f in dataclasses.fields(UR10Config)}:
        driver.pop(k, None)
    ws = {"min_m": list(workspace.min_m), "max_m": list(workspace.max_m)}
    return LabArmConfig(**{k: getattr(plan, k) for k in ARM_PLAN_KEYS},
                        driver=UR10Config.from_mapping(driver, ws, key=key))


def _make(cls, data, key: str, **fixed):
    """``cls`` from a mapping: unknown keys and wrong types are ConfigErrors naming ``key.<name>``;
    ``fixed`` values (built elsewhere) are passed as they are."""
    data = dict(to_plain(data) or {})
    names = {f.name for f in dataclasses.fields(cls)}
    for k in data:
        if k not in names or k == "key" or k in fixed:
            raise unknown_key(key, k, names - set(fixed) - {"key"})
    try:
        obj = build(cls, data, key)               # type checks, naming the key
    except TypeError as exc:                      # a required field missing
        raise ConfigError(key, str(exc)) from None
    values = {f.name: getattr(obj, f.name) for f in dataclasses.fields(cls) if f.init}
    if "key" in names:
        values["key"] = key
    for k in ("fingers", "controller_joints"):
        if k in values and isinstance(values[k], list):
            values[k] = tuple(values[k])
    values.update(fixed)
    return cls(**values)


def _check_fingertips(tips, fingers, key: str) -> None:
    if not isinstance(tips, dict):
        raise ConfigError(key, f"expected a mapping finger → [x, y, z, rx, ry, rz] (m, rad), got {tips!r}")
    for f in fingers:
        pose = tips.get(f)
        if not (isinstance(pose, (list, tuple)) and len(pose) == 6
                and all(isinstance(v, (int, float)) and math.isfinite(v) for v in pose)):
            raise ConfigError(f"{key}.{f}", f"expected 6 finite numbers [x, y, z, rx, ry, rz] (m, rad), got {pose!r}")

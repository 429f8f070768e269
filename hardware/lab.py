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
            "biotac_calibration")
BIOTAC_SOURCES = ("rosbridge", "serial")
#: arm keys the planner and the engine read; the rest go to the UR10 driver's config
ARM_PLAN_KEYS = ("home_pose", "max_speed_m_s", "max_accel_m_s2", "stop_accel_m_s2", "max_contact_force_n")


def make_real_lab(hw_cfg, surface_cfg=None, *, key: str = "hardware", sensor=None) -> Lab:
    """Build the lab of ``conf/hardware/lab.yaml``; devices are returned unconnected.

    ``hw_cfg``: dict or OmegaConf node; ``surface_cfg``: as ``conf/surface/*.yaml`` (geometry
    shared with the simulator), or None; ``sensor``: the fingertips'
    :class:`tactile.sensor.SensorModel` (None: the BioTac SP).
    """
    hw = to_plain(hw_cfg) or {}
    if not isinstance(hw, dict):
        raise ConfigError(key, f"expected a mapping, got {type(hw).__name__}")
    unknown = sorted(set(hw) - set(TOP_KEYS))
    if unknown:
        raise unknown_key(key, unknown[0], TOP_KEYS)
    fingers = check_fingers(hw.get("fingers", FINGERS), f"{key}.fingers")
    workspace = build(WorkspaceConfig, hw.get("workspace"), f"{key}.workspace")
    _check_fingertips(hw.get("fingertips"), fingers, f"{key}.fingertips")
    clock = WallClock()
    rosbridge = _make(RosbridgeConfig, hw.get("rosbridge"), f"{key}.rosbridge")
    hand_cfg = _make(ShadowHandConfig, hw.get("hand"), f"{key}.hand", rosbridge=rosbridge)
    surface = load_surface(surface_cfg) if surface_cfg is not None else None
    return Lab(arm=make_arm(hw.get("arm"), workspace, f"{key}.arm"),
                   hand=ShadowHand(hand_cfg, clock),
                   biotac=make_biotacs(hw.get("biotac"), fingers, rosbridge, f"{key}.biotac", clock, sensor),
                   pump=SerialPump(_make(SerialPumpConfig, hw.get("pump"), f"{key}.pump"), clock),
                   scale=SerialScale(_make(SerialScaleConfig, hw.get("scale"), f"{key}.scale"), clock),
                   clock=clock, surface=surface)


def make_biotacs(data, fingers, rosbridge: RosbridgeConfig, key: str, clock=None, sensor=None):
    """RosbridgeBiotacs or SerialBiotacs, as ``biotac.source`` says; the keys of the other source
    (``topic`` for serial, ``port``/``baudrate`` for rosbridge) are accepted and ignored, so one
    ``lab.yaml`` can hold both."""
    data = dict(to_plain(data) or {})
    source = data.pop("source", "rosbridge")
    if source not in BIOTAC_SOURCES:
        raise ConfigError(f"{key}.source", f"expected one of {', '.join(BIOTAC_SOURCES)}, got {source!r}")
    if source == "serial":
        data.pop("topic", None)
        return SerialBiotacs(_make(SerialBiotacConfig, data, key, fingers=tuple(fingers)), clock, sensor)
    data.pop("port", None)
    data.pop("baudrate", None)
    return RosbridgeBiotacs(_make(RosbridgeBiotacConfig, data, key, rosbridge=rosbridge, fingers=tuple(fingers)),
                            clock, sensor)


def make_arm(data, workspace: WorkspaceConfig, key: str):
    """The UR10 driver from ``arm.*``: the planner's keys (:data:`ARM_PLAN_KEYS`) stay with the
    planner and the engine; every other key is a :class:`hardware.ur10.UR10Config` setting."""
    from .ur10 import UR10Arm, UR10Config

    data = dict(to_plain(data) or {})
    for k in set(ARM_PLAN_KEYS) - {f.name for f in dataclasses.fields(UR10Config)}:
        data.pop(k, None)
    ws = {"min_m": list(workspace.min_m), "max_m": list(workspace.max_m)}
    return UR10Arm(UR10Config.from_mapping(data, ws, key=key))


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

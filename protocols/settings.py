"""The run's config, checked in one pass before anything is written or moves.

:func:`run_settings` takes the config Hydra composed (``conf/config.yaml``, its groups and the
command line) and returns a :class:`RunSettings`: every group typed and checked, or a
:class:`validation.ConfigError` naming the key at fault (the command line's error line adds the
file and line it came from, :mod:`cliapp.runner`). The rest of ``protocols`` takes the
RunSettings; nothing reads the composed node again. What the pass checks, group by group
(:data:`GROUPS`; a new group is one entry there and one field of :class:`RunSettings`):

- the top-level keys, and every key of the run's own nodes (also those added with ``+``,
  which Hydra lets through), against :class:`~protocols.schema.RunConfig`;
- ``protocol``: its parameters (finite numbers) and its steps, parsed
  (:func:`protocols.steps.parse_steps`), and its segment labels against the analysis's label
  schemes (an entry point: ``protocols`` does not import ``analysis``), so that a misspelt
  label cannot switch the analysis to another scheme;
- ``hardware``: a tagged union on ``hardware.backend`` (:func:`protocols.backends.hardware_config`),
  and the calibration file it names;
- ``sensor``: the fingertips' sensor model file (:func:`tactile.sensor.load_sensor`: taxels,
  surface, views, channels), read once into a :class:`~tactile.sensor.SensorModel`;
- ``surface``, ``safety`` (finite limits within their bounds, also with ``plan_only``),
  ``live`` (its viewer, fingers and views: the sensor's), ``analysis`` (the analysis's own
  schema for this sensor, through the :data:`ANALYSIS_CHECK` entry point).

What relates the groups to the steps — every waypoint against the workspace, every speed and
force against the hardware's limits, every surface reference — is checked by the plan
(:func:`protocols.plan.make_plan`), which follows at once, also before anything moves.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from importlib.metadata import entry_points
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

from tactile_flow.hardware.surfaces import SurfaceConfig, load_surface
from tactile_flow.tactile.frames import DEFAULT_VIEWS
from tactile_flow.validation import ConfigError, build, check_keys, to_plain, unknown_key

from .backends import backend_of, hardware_config
from .interlocks import SafetyConfig
from .live import LiveConfig, viewer_names
from .schema import ProtocolConfig, RunConfig, check_targets
from .steps import parse_steps

ANALYSIS_CHECK = "tactile_flow.analysis_config"    # entry point: the ``analysis`` node → its typed config
LABELS_CHECK = "tactile_flow.analysis_labels"      # entry point: check a protocol's segment labels


@dataclass(frozen=True)
class RunSettings:
    """One run's whole config, checked (:func:`run_settings`).

    Attributes:
        protocol: the protocol's parameters; ``steps`` holds the parsed steps
            (:class:`protocols.steps.Step`).
        hardware: the backend's config: :class:`hardware.config.SimConfig` or
            :class:`hardware.lab.LabConfig`.
        surface: the board (None: none).
        sensor: the fingertips' :class:`tactile.sensor.SensorModel`.
        safety, live: the interlocks' limits and the live monitor's settings.
        analysis: the analysis's typed config (``analysis.config.AnalysisConfig``), handed to
            the analysis after the run; None when no analysis is installed.
        plan_only, analyze, verbose, progress, resume: the run's options.
        config_yaml: the composed config, resolved, as YAML (provenance, resume).
    """

    protocol: ProtocolConfig
    hardware: Any
    surface: SurfaceConfig | None
    sensor: Any
    safety: SafetyConfig
    live: LiveConfig
    analysis: Any = None
    plan_only: bool = False
    analyze: bool = True
    verbose: bool = False
    progress: bool = True
    resume: bool = False
    config_yaml: str = ""

    @property
    def backend(self) -> str:
        return self.hardware.backend


def run_settings(cfg) -> RunSettings:
    """The composed config (an OmegaConf node or a mapping) checked and typed; a
    :class:`RunSettings` is returned as it is. Raises :class:`validation.ConfigError` (a
    ``ValueError``) naming the key at fault; touches no hardware, writes nothing."""
    if isinstance(cfg, RunSettings):
        return cfg
    node = cfg if isinstance(cfg, DictConfig) else OmegaConf.create(to_plain(cfg))
    check_targets(node)
    check_keys(node, RunConfig, "")
    try:
        plain = OmegaConf.to_container(node, resolve=True, throw_on_missing=True)
    except Exception as exc:                     # an interpolation that cannot be resolved, a missing value
        key = getattr(exc, "full_key", None) or "config"
        raise ConfigError(str(key), f"{' '.join(str(getattr(exc, 'msg', exc)).split())}") from None
    values: dict = {}
    for name, check in GROUPS.items():               # in order: a later group's check may read an earlier one's
        values[name] = check(plain.get(name), plain, values)
    options = {f.name: getattr(build(_Options, {k: plain[k] for k in _OPTION_KEYS if k in plain}, ""), f.name)
               for f in dataclasses.fields(_Options)}
    return RunSettings(**values, **options, config_yaml=OmegaConf.to_yaml(node, resolve=True))


@dataclass
class _Options:
    plan_only: bool = False
    analyze: bool = True
    verbose: bool = False
    progress: bool = True
    resume: bool = False


_OPTION_KEYS = tuple(f.name for f in dataclasses.fields(_Options))


# ----------------------------------------------------------------------------- the groups
def _protocol(node, whole: dict, typed: dict) -> ProtocolConfig:
    node = dict(node or {})
    steps = node.pop("steps", None)
    protocol = build(ProtocolConfig, node, "protocol")
    if protocol.name in ("", "???"):
        raise ConfigError("protocol.name", "missing; expected the protocol's name (protocol=NAME chooses a protocol)")
    protocol.steps = parse_steps(steps)
    _check_labels(protocol.labels)
    return protocol


def _check_labels(labels: list[str]) -> None:
    for ep in entry_points(group=LABELS_CHECK):
        ep.load()(labels, "protocol.labels")


def _hardware(node, whole: dict, typed: dict):
    if node is None:
        raise ConfigError("hardware", "missing; expected hardware=sim, lab or lab_emulated")
    hardware = hardware_config(node)
    _check_calibration(hardware)
    return hardware


def _check_calibration(hardware) -> None:
    """``hardware.biotac_calibration``: ``simulated`` (the simulator only), a JSON file that
    exists, or null. (Its content is read when the run starts: :mod:`protocols.calibration`.)"""
    what, key = hardware.biotac_calibration, "hardware.biotac_calibration"
    if what is None:
        return
    if what == "simulated":
        if backend_of(hardware) != "sim":
            raise ConfigError(key, "'simulated' is only for hardware=sim; give the lab's calibration JSON file "
                                   "(or null)")
        return
    path = Path(str(what)).expanduser()
    if not path.is_file():
        raise ConfigError(key, f"no such file {path}; expected a calibration JSON (docs/import.md), "
                               f"'simulated' (hardware=sim) or null")


def _surface(node, whole: dict, typed: dict) -> SurfaceConfig | None:
    return None if node is None else load_surface(node).cfg


def _sensor(node, whole: dict, typed: dict):
    from tactile_flow.cliapp.sensors import composed_sensor
    return composed_sensor({"sensor": node})


def _safety(node, whole: dict, typed: dict) -> SafetyConfig:
    return build(SafetyConfig, node, "safety")


def _live(node, whole: dict, typed: dict) -> LiveConfig:
    try:
        live = build(LiveConfig, node, "live")
    except ConfigError:
        raise
    except ValueError as exc:                        # tactile.slip.SlipConfig's own checks: "slip.x: ..."
        key, _, message = str(exc).partition(": ")
        raise ConfigError(f"live.{key}", message) from None
    if live.viewer is not None and live.viewer not in viewer_names():
        raise ConfigError("live.viewer", f"got {live.viewer!r}; expected one of {', '.join(viewer_names()) or '(none installed)'} "
                                         f"or null")
    if live.enabled is False and live.viewer:
        raise ConfigError("live.viewer", "shows the live monitor, which live.enabled=false turns off")
    hardware_fingers = (whole.get("hardware") or {}).get("fingers") or []
    unknown = [f for f in live.fingers or () if f not in hardware_fingers]
    if unknown:
        raise ConfigError("live.fingers", f"{unknown} have no sensor in hardware.fingers {list(hardware_fingers)}")
    sensor = typed["sensor"]
    known = sensor.views if sensor is not None else tuple(DEFAULT_VIEWS)
    if not live.views:
        raise ConfigError("live.views", "got none; expected one or more of " + ", ".join(sorted(known)))
    for i, view in enumerate(live.views):
        if view not in known:
            raise ConfigError(f"live.views[{i}]", unknown_key("live.views", view, known, what=(
                f"view of sensor {sensor.name}" if sensor is not None else "view")).message)
    return live


def _analysis(node, whole: dict, typed: dict):
    found = list(entry_points(group=ANALYSIS_CHECK))
    return found[0].load()(node or {}, sensor=typed["sensor"]) if found else None


#: every group of the run config and its check, in order: ``check(node, whole, typed) -> typed``,
#: ``whole`` the plain composed config, ``typed`` the groups checked before it
GROUPS = {"protocol": _protocol, "hardware": _hardware, "surface": _surface, "sensor": _sensor, "safety": _safety,
          "live": _live, "analysis": _analysis}

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
- ``surface``, ``safety`` (finite limits within their bounds, also with ``plan_only``),
  ``live`` (its viewer, fingers and views), ``analysis`` (the analysis's own schema, through
  the :data:`ANALYSIS_CHECK` entry point).

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
        safety, live: the interlocks' limits and the live monitor's settings.
        analysis: the analysis's typed config (``analysis.config.AnalysisConfig``), handed to
            the analysis after the run; None when no analysis is installed.
        plan_only, analyze, verbose, progress, resume: the run's options.
        config_yaml: the composed config, resolved, as YAML (provenance, resume).
    """

    protocol: ProtocolConfig
    hardware: Any
    surface: SurfaceConfig | None
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
    values = {name: check(plain.get(name), plain) for name, check in GROUPS.items()}
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
def _protocol(node, whole: dict) -> ProtocolConfig:
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


def _hardware(node, whole: dict):
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


def _surface(node, whole: dict) -> SurfaceConfig | None:
    return None if node is None else load_surface(node).cfg


def _safety(node, whole: dict) -> SafetyConfig:
    return build(SafetyConfig, node, "safety")


def _live(node, whole: dict) -> LiveConfig:
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
    if not live.views:
        raise ConfigError("live.views", "got none; expected one or more of " + ", ".join(sorted(DEFAULT_VIEWS)))
    for i, view in enumerate(live.views):
        if view not in DEFAULT_VIEWS:
            raise ConfigError(f"live.views[{i}]", unknown_key("live.views", view, DEFAULT_VIEWS, what="view").message)
    return live


def _analysis(node, whole: dict):
    found = list(entry_points(group=ANALYSIS_CHECK))
    return found[0].load()(node or {}) if found else None


#: every group of the run config and its check: ``check(node, whole) -> typed``, ``whole`` the
#: plain composed config (for checks that read another group)
GROUPS = {"protocol": _protocol, "hardware": _hardware, "surface": _surface, "safety": _safety,
          "live": _live, "analysis": _analysis}

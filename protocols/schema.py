"""Typed configuration schemas, registered in Hydra's ConfigStore.

``conf/config.yaml`` starts its defaults list with ``run_schema`` (:class:`RunConfig`), so
Hydra fills in the protocol's defaults and checks the keys it types while composing (its
refusals become the same one-line errors: :func:`cliapp.runner.error_line`). Once it has
composed, :func:`protocols.settings.run_settings` checks the whole tree in one pass and
returns the typed :class:`~protocols.settings.RunSettings` the rest of the code takes.

Protocol units are the ones a researcher writes: mm, mm/s, mm/s², s, N, ml, ml/min, rad.
They are converted to the robot's SI units (m, m/s) at the hardware boundary.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from hydra.core.config_store import ConfigStore
from omegaconf import MISSING

from tactile_flow.validation import ConfigError

from .interlocks import SafetyConfig
from .live import LiveConfig


@dataclass
class ProtocolConfig:
    """A protocol: its parameters (referenced by the steps as ``${protocol.<name>}``),
    the segment labels its analysis should produce, and its steps."""

    name: str = MISSING
    description: str = ""
    labels: list[str] = field(default_factory=list)
    finger: str = "ff"                 # the finger that touches the surface in sweeps
    sweep_speed: float = 10.0          # mm/s
    sweep_depth: float = 1.5           # mm, pad below the top of the tallest feature
    approach_speed: float = 5.0        # mm/s
    travel_speed: float = 50.0         # mm/s, moves out of contact
    accel: float = 500.0               # mm/s², linear moves
    pour_rate: float = 60.0            # ml/min
    pour_volume: float = 400.0         # ml, the most the pour step may dispense
    grasp_flexion: float = 1.2         # rad, summed over the two flexion joints of each finger
    tighten_flexion: float = 0.2       # rad, added to each finger's closure by a `tighten` reaction
    hold_time: float = 1.0             # s
    tare: bool = True                  # false: the run starts in contact, without a tare (see `press`)
    # slip in place (conf/protocol/slip_in_place.yaml): the object moved under the still finger
    press_force: float = 1.3           # N, the `press` step's force
    motion: str = "none"               # translate | rotate | none (`move_object`)
    direction_deg: float = 0.0         # the object's motion relative to the finger, sensor x–y plane (0° = +x)
    distance_mm: float = 4.0           # mm
    speed_mm_s: float = 5.0            # mm/s
    rotation_deg: float = 30.0         # deg, + = counter-clockwise seen from outside the pad (about sensor −z)
    rotation_speed_deg_s: float = 40.0 # deg/s
    tremor_mm: float = 0.0             # the held object's jitter (std): tangential, mm (simulated stage)
    tremor_normal_mm: float = 0.0      # ... normal, mm: the force fluctuation
    tremor_deg: float = 0.0            # ... about the vertical, deg
    steps: list[Any] = field(default_factory=list)


@dataclass
class RunConfig:
    """The whole run: protocol, hardware, surface, analysis and run options."""

    protocol: ProtocolConfig = field(default_factory=ProtocolConfig)
    hardware: Any = MISSING
    surface: Any = None
    sensor: Any = None                 # the fingertip sensor model (conf/sensor/; tactile.sensor.load_sensor checks it)
    analysis: Any = field(default_factory=dict)
    safety: SafetyConfig = field(default_factory=SafetyConfig)
    live: LiveConfig = field(default_factory=LiveConfig)
    plan_only: bool = False            # expand and check the plan, print it, touch no hardware
    analyze: bool = True               # hand the run to the analysis pipeline when it ends
    verbose: bool = False              # tracebacks on errors
    progress: bool = True              # progress bars on the console
    resume: bool = False               # (multirun) skip jobs whose runs already succeeded


# Classes a config may name with ``_target_`` (Hydra instantiates them); nothing else.
ALLOWED_TARGETS = ("tactile_flow.protocols.cli.SweepSummary", "tactile_flow.protocols.cli.RunDirLock")


def check_targets(node, key: str = "") -> None:
    """Refuse any ``_target_`` outside :data:`ALLOWED_TARGETS` (:class:`validation.ConfigError`,
    as every bad value): a config must never make the framework import or call arbitrary code."""
    from omegaconf import DictConfig, ListConfig
    if isinstance(node, (DictConfig, ListConfig)) and node._is_none():
        return
    if isinstance(node, DictConfig):
        for k in node.keys():
            child = f"{key}.{k}" if key else str(k)
            if k == "_target_" and node.get(k) not in ALLOWED_TARGETS:
                raise ConfigError(child, f"{node.get(k)!r} is not allowed; configs may only name this project's "
                                         f"classes {list(ALLOWED_TARGETS)}")
            check_targets(node._get_node(k), child)
    elif isinstance(node, ListConfig):
        for i, item in enumerate(node._iter_ex(resolve=False)):
            check_targets(item, f"{key}[{i}]")


def register() -> None:
    ConfigStore.instance().store(name="run_schema", node=RunConfig)

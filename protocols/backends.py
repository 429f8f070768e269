"""Build the lab a config asks for, from an allowlist of this project's backends.

``hardware.backend`` names the backend; nothing else from a config is ever imported or
called, so a config cannot make the framework run arbitrary code. Each backend has a checker
(the ``hardware`` node → its typed config, every key checked, nothing built) and a builder
(the typed config and the surface → an unconnected :class:`~hardware.lab_container.Lab`).
"""

from __future__ import annotations

from importlib import import_module

from tactile_flow.hardware.errors import ConfigError
from tactile_flow.validation import to_plain

#: backend → (checker, builder), as ``module:function``
BACKENDS = {"sim": ("tactile_flow.hardware.config:load_config", "tactile_flow.hardware.sim:make_sim_lab"),
            "lab": ("tactile_flow.hardware.lab:load_lab_config", "tactile_flow.hardware.lab:make_real_lab")}


def _function(path: str):
    module, _, name = path.partition(":")
    return getattr(import_module(module), name)


def backend_of(node) -> str:
    """``hardware.backend`` of a hardware node (mapping or typed config), checked against :data:`BACKENDS`."""
    backend = getattr(node, "backend", None) if not hasattr(node, "get") else node.get("backend")
    if backend not in BACKENDS:
        raise ConfigError("hardware.backend", f"got {backend!r}; expected one of {', '.join(sorted(BACKENDS))}")
    return backend


def hardware_config(node):
    """The ``hardware`` node as its backend's typed config (:class:`~hardware.config.SimConfig`
    or :class:`~hardware.lab.LabConfig`), every key checked; nothing is built or connected."""
    plain = to_plain(node)
    if not isinstance(plain, dict):
        raise ConfigError("hardware", f"got {plain!r}; expected a mapping (hardware=sim, lab or lab_emulated)")
    return _function(BACKENDS[backend_of(plain)][0])(plain, "hardware")


def make_lab(settings):
    """The unconnected lab for ``settings.hardware`` (a typed hardware config) and
    ``settings.surface``."""
    hardware = settings.hardware
    return _function(BACKENDS[backend_of(hardware)][1])(hardware, settings.surface)


def board_warning(settings) -> str | None:
    """On an emulated lab (``hardware.emulator``, ``hardware=lab_emulated``), a warning when the
    board the emulated BioTacs press on is not this run's: the readings would not match the arm's
    moves (a sweep on sticks over an emulated board of straws finds the wrong features, or none)."""
    from dataclasses import asdict

    from tactile_flow.hardware.lab import LabConfig, emulated_board
    if not isinstance(settings.hardware, LabConfig):
        return None
    said = emulated_board(settings.hardware)
    if said is None:
        return None
    ours = asdict(settings.surface) if settings.surface is not None else None
    if said.get("surface") == ours:
        return None
    emulated = said.get("surface_name")
    wanted = (ours or {}).get("name") or (ours or {}).get("kind") or "none"
    return (f"warning: the emulated lab ({settings.hardware.emulator}) presses the BioTacs on the board "
            f"{emulated!r}, but this run's board is {wanted!r}"
            + (" (the same name, other values)" if emulated == wanted else "")
            + f": the readings will not follow this protocol's moves; restart it with "
              f"`tactile-emulate --surface {wanted}`")

"""Build the lab a config asks for, from an allowlist of this project's backends.

``hardware.backend`` names the backend; nothing else from a config is ever imported or
called, so a config cannot make the framework run arbitrary code.
"""

from __future__ import annotations

from importlib import import_module

from hardware.errors import ConfigError

BACKENDS = {"sim": "hardware.sim:make_sim_lab", "lab": "hardware.lab:make_real_lab"}


def make_lab(cfg):
    """The unconnected lab for ``cfg.hardware`` (and ``cfg.surface`` for the simulator)."""
    backend = cfg.hardware.get("backend")
    if backend not in BACKENDS:
        raise ConfigError("hardware.backend", f"expected one of {sorted(BACKENDS)}, got {backend!r}")
    module, _, name = BACKENDS[backend].partition(":")
    return getattr(import_module(module), name)(cfg.hardware, cfg.get("surface"))

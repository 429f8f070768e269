"""Build the lab a config asks for, from an allowlist of this project's backends.

``hardware.backend`` names the backend; nothing else from a config is ever imported or
called, so a config cannot make the framework run arbitrary code.
"""

from __future__ import annotations

from importlib import import_module

from tactile_flow.hardware.errors import ConfigError

BACKENDS = {"sim": "tactile_flow.hardware.sim:make_sim_lab", "lab": "tactile_flow.hardware.lab:make_real_lab"}


def make_lab(cfg, sensor=None):
    """The unconnected lab for ``cfg.hardware`` (and ``cfg.surface`` for the simulator), its
    tactile sensors of model ``sensor`` (a :class:`tactile.sensor.SensorModel`; None: the BioTac SP)."""
    backend = cfg.hardware.get("backend")
    if backend not in BACKENDS:
        raise ConfigError("hardware.backend", f"expected one of {sorted(BACKENDS)}, got {backend!r}")
    module, _, name = BACKENDS[backend].partition(":")
    return getattr(import_module(module), name)(cfg.hardware, cfg.get("surface"), sensor=sensor)


def check_hardware(cfg, sensor=None) -> None:
    """Check every value of ``cfg.hardware`` (a ``ConfigError`` naming the key) without
    connecting anything: what ``plan_only`` does in place of :func:`make_lab`."""
    if cfg.hardware.get("backend") == "sim":
        from tactile_flow.hardware.config import load_config
        load_config(cfg.hardware)                 # the values only: no simulated world is built
    else:
        make_lab(cfg, sensor)                     # real drivers check their configs when made, unconnected

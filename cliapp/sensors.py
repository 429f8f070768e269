"""The sensor model of a command, read once at its edge (``sensor=NAME``, docs/sensors.md).

``tactile-run`` composes ``conf/sensor/<name>.yaml`` as its ``sensor`` config group
(:func:`composed_sensor`); ``tactile-import`` and ``tactile-analyze`` take ``sensor=NAME`` or
``sensor=PATH.yaml`` (:func:`named_sensor`). Either way the file is checked once
(:func:`tactile.sensor.load_sensor`) and the typed :class:`~tactile.sensor.SensorModel` is
handed down; a bad file is one line naming it, the field and what was expected.
"""

from __future__ import annotations

import importlib.resources
from pathlib import Path

from tactile_flow.tactile.sensor import (SensorModel, SensorModelError, builtin_sensor, builtin_sensors, load_sensor,
                                         load_sensor_file)

__all__ = ["chosen_file", "composed_sensor", "named_sensor", "search_path_files"]


def _hydra():
    try:
        from hydra.core.hydra_config import HydraConfig
        return HydraConfig.get()
    except (ImportError, ValueError):               # not inside a Hydra job
        return None


def search_path_files(group: str) -> dict[str, Path]:
    """Option name → file of every option of config ``group`` on this Hydra job's search path
    (the first source that has a name wins, as Hydra chooses); empty outside a Hydra job."""
    hc = _hydra()
    found: dict[str, Path] = {}
    for src in (hc.runtime.config_sources if hc is not None else ()):
        if src.schema == "file":
            folder = Path(src.path) / group
        elif src.schema == "pkg":
            try:
                folder = Path(str(importlib.resources.files(src.path).joinpath(group)))
            except (ModuleNotFoundError, TypeError):
                continue
        else:
            continue
        for path in sorted(folder.glob("*.yaml")) if folder.is_dir() else ():
            found.setdefault(path.stem, path)
    return found


def chosen_file(group: str) -> str | None:
    """The file of the option Hydra chose for config ``group`` in this job, or None."""
    hc = _hydra()
    choice = hc.runtime.choices.get(group) if hc is not None else None
    path = search_path_files(group).get(str(choice)) if choice else None
    return str(path) if path else None


def composed_sensor(cfg, key: str = "sensor", default: str | None = "biotac_sp") -> SensorModel | None:
    """The :class:`SensorModel` of a composed config's ``sensor`` group (its file named from
    Hydra's choice); when the config has none, the built-in ``default`` (``None``: none)."""
    node = cfg.get(key) if hasattr(cfg, "get") else None
    if node is None:
        return builtin_sensor(default) if default else None
    if isinstance(node, str):                        # a name or a file given as a plain value
        return named_sensor(node, key)
    return load_sensor(node, file=chosen_file(key), key=key)


def named_sensor(value, key: str = "sensor") -> SensorModel | None:
    """``sensor=NAME`` (a model on the search path or shipped with the package) or
    ``sensor=PATH`` (a YAML file) as a :class:`SensorModel`; ``None`` for ``None``."""
    if value is None:
        return None
    if not isinstance(value, str) or not value:
        raise SensorModelError(key, f"got {value!r}; expected a sensor name ({', '.join(builtin_sensors())}) "
                                    f"or a .yaml file")
    if value.endswith((".yaml", ".yml")) or "/" in value:
        if not Path(value).is_file():
            raise SensorModelError(key, f"{value}: no such file; expected a sensor file (docs/sensors.md)")
        return load_sensor_file(value, key=key)
    files = {**builtin_sensors(), **search_path_files(key)}
    if value not in files:
        raise SensorModelError(key, f"no sensor model {value!r}; expected one of {', '.join(sorted(files))} "
                                    f"or a .yaml file")
    if files[value] == builtin_sensors().get(value):
        return builtin_sensor(value)
    return load_sensor_file(files[value], key=key)

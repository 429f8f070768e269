"""Which sensor model a run store was recorded with, and the refusal to read it with another.

Every store written since sensors became data holds the model in its root attributes:
``sensor`` (name, taxel count, checksum, the file it was read from) and ``sensor_model`` (the
whole model, as :func:`tactile.sensor.load_sensor` reads it). :func:`recorded_sensor` reads it
back — checked again, and against its checksum — so a store analyses with the geometry it
was recorded with. A store from before (no ``sensor`` attribute) is a BioTac SP's if it has
24 electrodes; another count is matched to the one shipped model that has it.
"""

from __future__ import annotations

import dataclasses

from tactile_flow.tactile.sensor import (SensorModel, SensorModelError, builtin_sensor, checksum, load_sensor,
                                         sensor_for_taxels)

__all__ = ["recorded_sensor", "require_same_sensor"]

_READ: dict[str, SensorModel] = {}
"""Recorded models already read in this process, by their checksum: reading one (its checks,
its surface's fit) is a pure function of its content, and every store of a dataset records
the same one (~10 ms a store otherwise, twice per analysis)."""
_READ_MAX = 16


def recorded_sensor(attrs: dict, n_taxels: int, where: str) -> tuple[SensorModel, str]:
    """The sensor model a store was recorded with and how it was found (``recorded`` or
    ``assumed: ...``). ``attrs``: the store's root attributes; ``n_taxels``: the length of its
    ``taxel`` dimension; ``where``: the store, for messages. Raises :class:`SensorModelError`
    when the recorded model is damaged (fails its own checks or its checksum) or does not
    have the store's electrode count."""
    summary, spec = attrs.get("sensor"), attrs.get("sensor_model")
    if isinstance(summary, dict) and isinstance(spec, dict):
        try:
            stored = checksum(spec)
        except (TypeError, ValueError):
            stored = None
        if stored != summary.get("sha256"):
            raise SensorModelError("sensor_model", f"checksum {str(stored)[:8]} is not the recorded "
                                                   f"{str(summary.get('sha256'))[:8]}; the store's attributes "
                                                   f"were altered", f"{where}")
        # read with today's schema: a field added since takes its default, and the model's
        # checksum is then that of today's form (what a model asked for is compared with)
        model = _READ.get(stored)
        if model is None:
            model = load_sensor(spec, file=f"{where} (attribute sensor_model)")
            if len(_READ) >= _READ_MAX:
                _READ.pop(next(iter(_READ)))
            _READ[stored] = model
        if model.n_taxels != n_taxels:
            raise SensorModelError("sensor_model", f"has {model.n_taxels} taxels but the store's electrodes have "
                                                   f"{n_taxels}; the store's attributes were altered", f"{where}")
        return dataclasses.replace(model, file=summary.get("file")), "recorded"
    if n_taxels == builtin_sensor().n_taxels:
        model = builtin_sensor()
        return model, f"assumed: the store records no sensor model; {n_taxels} electrodes: {model.name}"
    try:
        model = sensor_for_taxels(n_taxels)
    except SensorModelError as exc:
        raise SensorModelError("sensor", f"the store records no sensor model and {exc.message}", where) from None
    return model, f"assumed: the store records no sensor model; {n_taxels} electrodes: {model.name}"


def require_same_sensor(recorded: SensorModel, how: str, requested: SensorModel | None, where: str) -> SensorModel:
    """The model to read a store with: ``recorded`` unless ``requested`` is given. A requested
    model must be the recorded one (same checksum) — or, for a store that records none, have
    its electrode count; else :class:`SensorModelError`, one line naming both."""
    if requested is None:
        return recorded
    if requested.sha256 == recorded.sha256:
        return requested
    if how != "recorded" and requested.n_taxels == recorded.n_taxels:
        return requested
    raise SensorModelError("sensor", f"{where} was recorded with sensor model {recorded.describe()}; "
                                     f"sensor={requested.name} is {requested.describe()}: a store is read only "
                                     f"with the model it was recorded with (leave sensor= out to use it)")

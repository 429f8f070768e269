"""One validation layer for every config node: typed dataclasses, one error, one message format.

Each config the project reads (``protocol``, ``hardware``, ``surface``, ``analysis``,
``safety``, ``live``) is described by dataclasses: a field's type says what a value must be
(``float``, ``int``, ``bool``, ``str``, ``list[...]``, ``dict[str, ...]``, ``X | None``, a
nested dataclass), and :func:`spec` adds its bounds and choices as field metadata
(``spec(0.05, gt=0)``, ``spec("auto", choices=("auto", "pdc"))``). :func:`build` turns a
mapping (a plain dict or an OmegaConf node, as Hydra composed it) into the dataclass and
refuses, naming the dotted key:

- a key the dataclass does not have, with the nearest known one (``did you mean
  `sweep_speed`?``, :func:`unknown_key`);
- a value of the wrong type, a number that is not finite, out of its bounds, or not one of
  its choices.

Every refusal is a :class:`ConfigError` (a ``ValueError``) whose text is one line,
``key: what was wrong; what was expected``. Checks that relate several values (a rate
that must divide the world step, kinetic below static friction) stay with the config they
belong to, raising the same error.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import operator
import sys
import types
import typing
from typing import Any

__all__ = ["ConfigError", "brief", "build", "check_keys", "spec", "suggest", "unknown_key", "to_plain"]


class ConfigError(ValueError):
    """A bad configuration value. ``key`` is the dotted config key at fault, ``message``
    what was wrong and what was expected."""

    def __init__(self, key: str, message: str):
        self.key, self.message = key, message
        super().__init__(f"{key}: {message}")


def brief(value, limit: int = 60) -> str:
    """``value`` for a message: a number in at most 6 significant digits when written out it
    is long (a 300-digit number is not a message), anything else cut to ``limit`` characters."""
    if type(value).__module__ == "numpy" and hasattr(value, "item"):
        value = value.item()
    if isinstance(value, int) and not isinstance(value, bool) and value.bit_length() > 50:
        return f"{float(value):.6g}" if value.bit_length() <= 1000 else f"a {value.bit_length()}-bit whole number"
    text = repr(value)
    if isinstance(value, float) and len(text) > 16:
        return f"{value:.6g}"
    return text if len(text) <= limit else text[:limit] + "..."


# ----------------------------------------------------------------------------- unknown keys
MAX_LISTED = 12                 # a node with more keys is named, not listed, in a message


def suggest(name: str, known) -> str | None:
    """The known name nearest to a misspelt ``name`` (difflib), or None if none is close."""
    close = difflib.get_close_matches(str(name), [str(k) for k in known], n=1, cutoff=0.6)
    return close[0] if close else None


def unknown_key(key: str, name, known, what: str = "key") -> ConfigError:
    """The error for ``name`` under ``key`` that is not one of ``known``:
    ``key.name: unknown key; expected one of ...; did you mean `x`?``."""
    known = sorted(str(k) for k in known)
    expected = (f"expected one of {', '.join(known)}" if len(known) <= MAX_LISTED
                else f"expected one of the {len(known)} {what}s of {key or 'the config'}")
    near = suggest(name, known)
    hint = f"; did you mean `{near}`?" if near else ""
    return ConfigError(f"{key}.{name}" if key else str(name), f"unknown {what}; {expected}{hint}")


def check_keys(node, cls, key: str) -> None:
    """Refuse a key of mapping ``node`` that dataclass ``cls`` does not have, in nested
    dataclass fields too (what Hydra lets through when a key is added with ``+``)."""
    from omegaconf import DictConfig
    if not isinstance(node, (dict, DictConfig)) or (isinstance(node, DictConfig) and node._is_none()):
        return
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    hints = typing.get_type_hints(cls)
    for name in node.keys():
        if name not in fields:
            raise unknown_key(key, name, fields)
        tp = hints[name]
        args = [a for a in typing.get_args(tp) if a is not type(None)] or [tp]
        if dataclasses.is_dataclass(args[0]):
            child = node._get_node(name) if isinstance(node, DictConfig) else node[name]
            check_keys(child, args[0], f"{key}.{name}" if key else str(name))


# ----------------------------------------------------------------------------- fields
def spec(default: Any = dataclasses.MISSING, *, factory=None, gt=None, ge=None, lt=None, le=None,
         choices=None, length: int | None = None, units: str = "") -> Any:
    """A dataclass field with its bounds: ``gt``/``ge``/``lt``/``le`` for numbers (``units``
    for messages), ``choices`` for strings, ``length`` for lists (e.g. a 6-number pose)."""
    meta = {k: v for k, v in dict(gt=gt, ge=ge, lt=lt, le=le, choices=choices, length=length,
                                  units=units).items() if v not in (None, "")}
    if factory is not None:
        return dataclasses.field(default_factory=factory, metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


def check_bounds(value, meta: dict, key: str) -> None:
    """Refuse ``value`` outside the bounds of a field's :func:`spec` metadata."""
    if value is None:
        return
    if "choices" in meta and value not in meta["choices"]:
        raise ConfigError(key, f"got {brief(value)}; expected one of {', '.join(map(str, meta['choices']))}")
    if "length" in meta and len(value) != meta["length"]:
        raise ConfigError(key, f"got {len(value)} values; expected {meta['length']}")
    tests = {"gt": (operator.gt, ">"), "ge": (operator.ge, ">="), "lt": (operator.lt, "<"), "le": (operator.le, "<=")}
    if any(name in meta and not test(value, meta[name]) for name, (test, _) in tests.items()):
        bounds = " and ".join(f"{word} {meta[name]:g}" for name, (_, word) in tests.items() if name in meta)
        units = f" {meta['units']}" if "units" in meta else ""
        raise ConfigError(key, f"got {brief(value)}; expected a number {bounds}{units}")


# ----------------------------------------------------------------------------- building
def to_plain(data: Any) -> Any:
    """An OmegaConf node (or a dataclass, or anything) as plain dicts and lists."""
    omegaconf = sys.modules.get("omegaconf")     # not imported: no value can be one of its nodes (saves ~90 ms)
    if omegaconf is not None and isinstance(data, (omegaconf.DictConfig, omegaconf.ListConfig)):
        return omegaconf.OmegaConf.to_container(data, resolve=True)
    if dataclasses.is_dataclass(data) and not isinstance(data, type):
        return dataclasses.asdict(data)
    return data


def build(cls, data, key: str):
    """Instantiate dataclass ``cls`` from ``data`` (dict, dataclass, OmegaConf node, None for
    the defaults), checking every key, type and bound; raises :class:`ConfigError`."""
    data = to_plain(data)
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError(key, f"got {brief(data)}; expected a mapping")
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    kwargs = {}
    for k, v in data.items():
        if k not in fields:
            raise unknown_key(key, k, fields)
        kwargs[k] = coerce(hints[k], v, f"{key}.{k}")
        check_bounds(kwargs[k], fields[k].metadata, f"{key}.{k}")
    return cls(**kwargs)


def coerce(tp, v, key: str):
    """``v`` as type ``tp`` (a field's type hint), or a :class:`ConfigError` naming ``key``."""
    origin = typing.get_origin(tp)
    if dataclasses.is_dataclass(tp):
        return build(tp, v, key)
    if origin in (typing.Union, types.UnionType):                             # X | None
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if v is None:
            if len(args) < len(typing.get_args(tp)):
                return None
            raise ConfigError(key, f"got null; expected {_name(tp)}")
        for i, arg in enumerate(args):
            try:
                return coerce(arg, v, key)
            except ConfigError:
                if i == len(args) - 1:
                    raise
    if origin is typing.Literal:
        if v not in typing.get_args(tp):
            raise ConfigError(key, f"got {brief(v)}; expected one of {', '.join(map(str, typing.get_args(tp)))}")
        return v
    if origin in (list, tuple):
        if not isinstance(v, (list, tuple)):
            raise ConfigError(key, f"got {brief(v)}; expected a list")
        arg = typing.get_args(tp)[0] if typing.get_args(tp) else Any
        items = [coerce(arg, x, f"{key}[{i}]") for i, x in enumerate(v)]
        return tuple(items) if origin is tuple else items
    if origin is dict:
        if not isinstance(v, dict):
            raise ConfigError(key, f"got {brief(v)}; expected a mapping")
        _, arg = typing.get_args(tp) or (str, Any)
        return {str(k): coerce(arg, x, f"{key}.{k}") for k, x in v.items()}
    if tp is bool:
        if not isinstance(v, bool):
            raise ConfigError(key, f"got {brief(v)}; expected true or false")
        return v
    if tp in (int, float):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or (
                tp is int and isinstance(v, float) and not v.is_integer()):
            raise ConfigError(key, f"got {brief(v)}; expected {'a whole number' if tp is int else 'a number'}")
        if not math.isfinite(v):
            raise ConfigError(key, f"got {brief(v)}; expected a finite number")
        return tp(v)
    if tp is str:
        if not isinstance(v, str):
            raise ConfigError(key, f"got {brief(v)}; expected a string")
        return v
    return v


def _name(tp) -> str:
    return str(tp).replace("typing.", "").replace("NoneType", "null")

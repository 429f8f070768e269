"""Paths derived from input, resolved in one place and kept inside their root.

A config value (``protocol.name``, a sweep's overrides, an analysis ``name=``) ends up in a
directory name. Whatever it holds — ``../../X``, a slash, a NUL, 300 characters — the
directory must stay inside the root it was meant for (``outputs/``, the sweep directory,
the run's ``analyses/``). Every command builds such paths with these functions:

- :func:`slug` turns any text into one safe path component (used by the ``tf_name``
  resolver in ``conf/config.yaml``'s run and sweep directory names, so Hydra itself can only
  ever make a directory inside its root);
- :func:`component` refuses, with one line, a name that is not one plain component
  (an analysis's ``name=``, a protocol name);
- :func:`within` resolves a path (symbolic links included) and refuses it, with one line,
  when it is not inside its root;
- :func:`template_root` is the literal directory a path template starts with
  (``outputs`` for ``outputs/${now:...}/...``): the root of the run directories it makes.
"""

from __future__ import annotations

import hashlib
import os
import re
from pathlib import Path

#: characters kept in a slug; anything else becomes ``_`` (no ``=`` or ``,``: a run directory's path is
#: typed into Hydra overrides, ``run=PATH``, where they would be syntax)
_UNSAFE = re.compile(r"[^A-Za-z0-9._+@-]+")
MAX_COMPONENT = 120              # characters; a file system allows 255 bytes, a date and job number are added


class PathOutsideRoot(ValueError):
    """A path derived from input that would leave its root (or is not one plain component)."""


def slug(text, max_len: int = MAX_COMPONENT) -> str:
    """``text`` as one path component: characters other than letters, digits and ``._+@-``
    become ``_`` (a ``/`` or ``..`` can never survive), no leading dot or dash; longer than
    ``max_len``: cut, with 8 hex digits of its SHA-256 so that two long names stay apart.
    Empty text is ``_``."""
    text = str(text)
    out = _UNSAFE.sub("_", text).replace("..", "_").lstrip(".-") or "_"
    if len(out) > max_len:
        digest = hashlib.sha256(text.encode("utf-8", "surrogatepass")).hexdigest()[:8]
        out = out[:max_len - 9] + "-" + digest
    return out


def component(value, what: str, hidden: bool = False) -> str:
    """``value`` if it is one plain path component, else :class:`PathOutsideRoot` naming
    ``what``: no ``/`` or ``\\``, not ``.`` or ``..``, no leading dot (unless ``hidden``: the
    project's own ``.hydra``...), no control character, at most :data:`MAX_COMPONENT` characters."""
    text = str(value)
    bad = None
    if not text:
        bad = "it is empty"
    elif "/" in text or "\\" in text:
        bad = "it holds a path separator"
    elif text in (".", "..") or (text.startswith(".") and not hidden):
        bad = "it starts with a dot"
    elif any(ord(c) < 32 or ord(c) == 127 for c in text):
        bad = "it holds a control character"
    elif len(text) > MAX_COMPONENT:
        bad = f"it is {len(text)} characters long"
    if bad:
        shown = text if len(text) <= 60 else text[:57] + "..."
        raise PathOutsideRoot(f"{what}: {shown!r} names a directory, but {bad}; expected a plain name "
                              f"(letters, digits, ._-, at most {MAX_COMPONENT} characters)")
    return text


def within(root, path, what: str) -> Path:
    """``path`` resolved (links followed, ``..`` removed; it need not exist yet) if it lies
    inside ``root`` (resolved the same way), else :class:`PathOutsideRoot` naming ``what``.
    A relative ``path`` is taken as it is (relative to the working directory, as ``root``)."""
    real_root = Path(os.path.realpath(root))
    real = Path(os.path.realpath(path))
    if real != real_root and real_root not in real.parents:
        raise PathOutsideRoot(f"{what}: {path} resolves to {real}, outside {real_root}; a directory made from "
                              f"a config value stays inside its root")
    return real


def template_root(template: str) -> str:
    """The directory a path template starts with: its components before the first one that
    holds an interpolation (``outputs`` for ``outputs/${now:%Y-%m-%d}/..._${protocol.name}``);
    the template itself when it has none (a directory given literally is its own root)."""
    parts = Path(template).parts
    first = next((i for i, p in enumerate(parts) if "${" in p), len(parts))
    if first == len(parts):
        return template
    return str(Path(*parts[:first])) if first else "."


def run_name(protocol, surface="", overrides="") -> str:
    """A run directory's name after its time or job number: ``straws_sweep_on_sticks_hardware.
    seed-3_protocol.sweep_speed-20`` — the protocol, the surface it ran on, and the overrides
    that made it (Hydra's ``override_dirname``), as one :func:`slug`: what differs between the
    runs of a sweep is in their names."""
    parts = [str(protocol)]
    if surface not in ("", None, "None"):
        parts += ["on", str(surface)]
    if overrides not in ("", None):
        parts.append(str(overrides))
    return slug("_".join(parts))


def register_resolvers() -> None:
    """``${tf_name:...}`` (the :func:`slug` of its arguments joined by ``_``) and
    ``${tf_run_name:protocol,surface,overrides}`` (:func:`run_name`), for the run and sweep
    directory names of ``conf/config.yaml``. Call before Hydra composes."""
    from omegaconf import OmegaConf
    if not OmegaConf.has_resolver("tf_name"):
        OmegaConf.register_new_resolver("tf_name", lambda *parts: slug("_".join(str(p) for p in parts if p != "")))
    if not OmegaConf.has_resolver("tf_run_name"):
        OmegaConf.register_new_resolver("tf_run_name", run_name)

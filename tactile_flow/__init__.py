"""tactile-flow: computational tactile flow for a UR10 + Shadow Hand + BioTac fingertips, and the
framework that runs its experiments.

The one import name the distribution installs. The repository's folders are its subpackages
(``pyproject.toml`` maps them): ``tactile_flow.tactile`` (the method), ``.hardware``,
``.runstore``, ``.protocols``, ``.analysis``, ``.importers``, ``.viewer``, ``.cliapp``,
``.validation``, and ``.conf`` (the Hydra configs, shipped as package data).
"""

from __future__ import annotations

import json
from functools import lru_cache
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

try:
    __version__ = version("tactile-flow")
except PackageNotFoundError:        # run from a source tree that was never installed
    __version__ = "0+unknown"

SOURCE_TREE = Path(__file__).resolve().parents[1]     # the checkout, for an editable install


@lru_cache(maxsize=1)
def build_info() -> dict:
    """Which code this is: ``{"version", "commit", "dirty", "from"}``. ``from`` is ``"git"`` for a
    checkout (an editable install: asked of git now, ``dirty`` counting tracked files only),
    ``"build"`` for an installed wheel (the commit it was built from, ``tactile_flow/_build.json``),
    else ``"unknown"`` with ``commit`` and ``dirty`` ``"unknown"``."""
    baked = Path(__file__).with_name("_build.json")
    if baked.exists():
        return {"version": __version__, **json.loads(baked.read_text()), "from": "build"}
    from tactile_flow.runstore.provenance import git_state
    git = git_state(SOURCE_TREE)
    return {"version": __version__, "commit": git["commit"], "dirty": git["dirty"],
            "from": "unknown" if git["commit"] == "unknown" else "git"}


def version_line(prog: str = "tactile-flow") -> str:
    """``tactile-run 0.2.0 (commit 1a2b3c4d5e6f, with local changes)``: what ``--version`` prints."""
    info = build_info()
    commit = info["commit"] if info["commit"] == "unknown" else info["commit"][:12]
    local = ", with local changes" if info["dirty"] is True else ""
    return f"{prog} {__version__} (commit {commit}{local})"

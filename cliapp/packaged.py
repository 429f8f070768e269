"""The configs shipped inside the package (``tactile_flow.conf``). One that is missing or not
valid is a broken installation, not a user's mistake: the error names the file and says how to
repair it (reinstall; in a checkout, restore the file from git). Exit status 2, as any bad input."""

from __future__ import annotations

import sys
from pathlib import Path

from tactile_flow.conf import DIR

BAD_INPUT = 2


def repair_hint(path) -> str | None:
    """How to repair ``path`` if it is one of the packaged configs, else None."""
    try:
        rel = Path(path).resolve().relative_to(DIR)
    except (ValueError, OSError):
        return None
    from tactile_flow import build_info
    if build_info()["from"] == "git":
        return f"it is one of the project's configs: restore it (git checkout -- conf/{rel.as_posix()})"
    return "a config shipped with tactile-flow: the installation is broken; reinstall it " \
           "(pip install --force-reinstall tactile-flow)"


def require(config_name: str) -> None:
    """Exit with one line if the command's primary config ``<config_name>.yaml`` is not there."""
    path = DIR / f"{config_name}.yaml"
    if not path.is_file():
        print(f"error: {path}: missing; {repair_hint(path)}", file=sys.stderr)
        sys.exit(BAD_INPUT)

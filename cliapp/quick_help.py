"""``--help`` / ``-h`` (and ``--version``) answered before Hydra is imported (Hydra composing the whole config
costs ~0.45 s): the same text as Hydra's help, read from the app's ``hydra.help.template``
with ``$APP_CONFIG_GROUPS`` filled from the config directory's groups, as Hydra lists them."""

from __future__ import annotations

import os
import sys
from pathlib import Path
from string import Template


def config_groups(conf_dir: Path) -> str:
    """``group: option, option`` lines, sorted, Hydra's own groups left out."""
    lines = []
    for group in sorted(p for p in conf_dir.iterdir() if p.is_dir() and p.name != "hydra"):
        options = sorted(f.stem for f in group.glob("*.yaml"))
        if options:
            lines.append(f"{group.name}: {', '.join(options)}")
    return "\n".join(lines) + "\n"


def help_text(conf_dir: Path, config_name: str) -> str:
    """The help Hydra would print for ``config_name`` in ``conf_dir``."""
    import yaml
    template = yaml.safe_load((conf_dir / f"{config_name}.yaml").read_text())["hydra"]["help"]["template"]
    return Template(template).safe_substitute(APP_CONFIG_GROUPS=config_groups(conf_dir))


def wants_help(argv: list[str]) -> bool:
    return "--help" in argv or "-h" in argv


def answer_version(argv: list[str], prog: str) -> None:
    """``--version``: print the version and the commit it was built from, and exit 0."""
    if argv == ["--version"]:
        from tactile_flow import version_line
        print_and_exit(version_line(prog))


def print_and_exit(text: str) -> None:
    """Print ``text`` and exit 0. A reader that stops early (``tactile-run --help | head``) is
    not an error: no traceback, as for any command-line tool."""
    try:
        print(text, flush=True)
    except BrokenPipeError:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())   # the exit's flush goes nowhere
    sys.exit(0)

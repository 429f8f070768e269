"""The ``tactile-analyze`` entry point: ``--help`` / ``-h`` is answered before Hydra and the app
are imported (:mod:`cliapp.quick_help`); everything else goes to :func:`analysis.cli.main`."""

from __future__ import annotations

import sys
from pathlib import Path

from tactile_flow.cliapp.quick_help import help_text, print_and_exit, wants_help
from tactile_flow.cliapp.startup import end_at_once_on_signals

CONF_DIR = Path(__file__).resolve().parents[1] / "conf"


def main() -> None:
    end_at_once_on_signals()
    if wants_help(sys.argv[1:]):
        print_and_exit(help_text(CONF_DIR, "analyze"))
    from .cli import main as analyze
    analyze()

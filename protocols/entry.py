"""The ``tactile-run`` entry point: ``--help`` / ``-h`` and ``--list`` are answered before Hydra
and the app are imported (:mod:`cliapp.quick_help`); everything else goes to :func:`protocols.cli.main`."""

from __future__ import annotations

import sys
from pathlib import Path

from tactile_flow.cliapp.quick_help import help_text, print_and_exit, wants_help
from tactile_flow.cliapp.startup import end_at_once_on_signals

CONF_DIR = Path(__file__).resolve().parents[1] / "conf"


def main() -> None:
    end_at_once_on_signals()
    argv = sys.argv[1:]
    if wants_help(argv):
        print_and_exit(help_text(CONF_DIR, "config"))
    if argv in (["--list"], ["list"]):                 # what there is to run, one line each
        from .listing import listing
        print_and_exit(listing(CONF_DIR))
    from .cli import main as run
    run()

"""The ``tactile-run`` entry point: ``--help`` / ``-h`` and ``--list`` are answered before Hydra
and the app are imported (:mod:`cliapp.quick_help`); everything else goes to :func:`protocols.cli.main`."""

from __future__ import annotations

import sys

from tactile_flow.cliapp.quick_help import answer_version, help_text, print_and_exit, wants_help
from tactile_flow.cliapp.packaged import require
from tactile_flow.cliapp.startup import end_at_once_on_signals
from tactile_flow.conf import DIR as CONF_DIR


def main() -> None:
    end_at_once_on_signals()
    argv = sys.argv[1:]
    answer_version(argv, "tactile-run")
    require("config")
    if wants_help(argv):
        print_and_exit(help_text(CONF_DIR, "config"))
    if argv in (["--list"], ["list"]):                 # what there is to run, one line each
        from .listing import listing
        print_and_exit(listing(CONF_DIR))
    from .cli import main as run
    run()

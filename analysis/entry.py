"""The ``tactile-analyze`` entry point: ``--help`` / ``-h`` is answered before Hydra and the app
are imported (:mod:`cliapp.quick_help`); everything else goes to :func:`analysis.cli.main`."""

from __future__ import annotations

import sys

from tactile_flow.cliapp.packaged import require
from tactile_flow.cliapp.quick_help import (answer_version, bad_input_and_exit, help_text, print_and_exit,
                                            searchpath_entries, searchpath_problem, wants_help)
from tactile_flow.cliapp.startup import end_at_once_on_signals
from tactile_flow.conf import DIR as CONF_DIR


def main() -> None:
    end_at_once_on_signals()
    answer_version(sys.argv[1:], "tactile-analyze")
    require("analyze")
    if wants_help(sys.argv[1:]):
        searchpath = searchpath_entries(sys.argv[1:])
        problem = searchpath_problem(searchpath)
        if problem:
            bad_input_and_exit(problem)
        print_and_exit(help_text(CONF_DIR, "analyze", searchpath))
    from .cli import main as analyze
    analyze()

"""The ``tactile-run`` entry point: ``--help`` / ``-h`` and ``--list`` (with the command line's
``hydra.searchpath``, if any) are answered before Hydra and the app are imported
(:mod:`cliapp.quick_help`); everything else goes to :func:`protocols.cli.main`."""

from __future__ import annotations

import sys

from tactile_flow.cliapp.packaged import require
from tactile_flow.cliapp.quick_help import (answer_version, bad_input_and_exit, help_text, print_and_exit,
                                            searchpath_entries, searchpath_problem, wants_help)
from tactile_flow.cliapp.startup import end_at_once_on_signals
from tactile_flow.conf import DIR as CONF_DIR


def main() -> None:
    end_at_once_on_signals()
    argv = sys.argv[1:]
    answer_version(argv, "tactile-run")
    require("config")
    answer_without_hydra(argv)
    from .cli import main as run
    run()


def answer_without_hydra(argv) -> None:
    """``--help`` and ``--list`` (exit 0), or a bad ``hydra.searchpath`` with them (exit 2); a
    bare config option (``tactile-run pour_grasp``) named as the override it stands for (exit 2);
    anything else returns."""
    listing_asked = "--list" in argv or argv[-1:] == ["list"]
    if wants_help(argv) or listing_asked:
        searchpath = searchpath_entries(argv)
        problem = searchpath_problem(searchpath)
        if problem:
            bad_input_and_exit(problem)
        if wants_help(argv):
            print_and_exit(help_text(CONF_DIR, "config", searchpath))
        rest = [a for a in argv if a not in ("--list", "list") and not a.startswith("hydra.searchpath=")]
        if rest:
            bad_input_and_exit(f"--list: takes no other argument than hydra.searchpath=[...]; got {' '.join(rest)}")
        from .listing import listing                # what there is to run, one line each
        print_and_exit(listing(CONF_DIR, searchpath))
    for before, arg in zip([""] + list(argv), argv):
        if "=" not in arg and not arg.startswith(("-", "~", "+")) and not before.startswith("-"):
            groups = sorted(p.parent.name for p in CONF_DIR.glob(f"*/{arg}.yaml"))
            if groups:
                meant = " or ".join(f"{group}={arg}" for group in groups)
                bad_input_and_exit(f"{arg}: expected key=value; did you mean {meant}?")

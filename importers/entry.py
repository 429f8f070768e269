"""The ``tactile-import`` entry point: Ctrl-C while it starts ends it with one line
(:mod:`cliapp.startup`); everything else goes to :func:`importers.cli.main`."""

from __future__ import annotations

import sys

from tactile_flow.cliapp.packaged import require
from tactile_flow.cliapp.quick_help import answer_version
from tactile_flow.cliapp.startup import end_at_once_on_signals


def main() -> None:
    end_at_once_on_signals()
    answer_version(sys.argv[1:], "tactile-import")
    require("import")
    from .cli import main as import_
    import_()

"""The ``tactile-import`` entry point: Ctrl-C while it starts ends it with one line
(:mod:`cliapp.startup`); everything else goes to :func:`importers.cli.main`."""

from __future__ import annotations

from tactile_flow.cliapp.startup import end_at_once_on_signals


def main() -> None:
    end_at_once_on_signals()
    from .cli import main as import_
    import_()

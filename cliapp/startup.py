"""Ctrl-C (or SIGTERM) while a command is still starting: it ends there, with one line.

Importing Hydra, numpy, numba and zarr takes most of a second, and a ``KeyboardInterrupt``
raised inside a library's import can leave it half-initialised and surface as another error
with a traceback (seen: omegaconf's ``'…' object has no attribute '_invalidate_flags_cache'``,
exit 1). Nothing has been written while a command starts, so the entry points call
:func:`end_at_once_on_signals` first: a signal then prints ``interrupted`` and exits 3 on the
spot. :func:`cliapp.runner.run_app` (and a run's :class:`protocols.interrupts.Interrupts`)
take the signals over once the app can act on them.
"""

from __future__ import annotations

import os
import signal

INTERRUPTED = 3      # runstore.status.ExitCode.INTERRUPTED, not imported: this module stays light


def end_at_once(signum, frame) -> None:
    """The handler while a command starts: one line, exit status 3, no cleanup (nothing to clean)."""
    os.write(2, b"interrupted\n")
    os._exit(INTERRUPTED)


def end_at_once_on_signals() -> None:
    """Handle SIGINT and SIGTERM with :func:`end_at_once` (a signal ignored, as SIGINT in a
    program started in the background, stays ignored)."""
    for s in (signal.SIGINT, signal.SIGTERM):
        if signal.getsignal(s) != signal.SIG_IGN:
            signal.signal(s, end_at_once)


def interrupts_raise() -> None:
    """From here on SIGINT and SIGTERM raise ``KeyboardInterrupt`` (once the command has loaded
    what it needs and can clean up after itself and say ``interrupted``); an ignored signal stays
    ignored."""
    for s in (signal.SIGINT, signal.SIGTERM):
        if signal.getsignal(s) != signal.SIG_IGN:
            signal.signal(s, _raise_interrupt)


def _raise_interrupt(signum, frame) -> None:
    raise KeyboardInterrupt


def tactile_demo() -> None:
    """The ``tactile-demo`` entry point (``tactile`` imports nothing of the project): signals end
    it at once while numpy and numba load, then interrupt it with one line and exit status 3
    (its figure is written whole or not at all)."""
    end_at_once_on_signals()
    import sys

    from tactile_flow.tactile.demo import main
    interrupts_raise()
    try:
        code = main()
    except KeyboardInterrupt:
        os.write(2, b"interrupted\n")
        code = INTERRUPTED
    sys.exit(code)


def tactile_recover() -> None:
    """The ``tactile-recover`` entry point (here: its module, in ``runstore``, stands below
    ``cliapp`` and may not import this one): signals end it at once until it has loaded
    numpy and zarr and takes them over."""
    end_at_once_on_signals()
    from tactile_flow.runstore.recover import command
    command()


def tactile_runs() -> None:
    """The ``tactile-runs`` entry point (its module is in ``runstore``): signals end it at once
    until it has parsed its arguments and takes them over."""
    end_at_once_on_signals()
    import signal
    from tactile_flow.runstore.runs_cli import command
    for s in (signal.SIGINT, signal.SIGTERM):
        if signal.getsignal(s) == end_at_once:
            signal.signal(s, signal.default_int_handler)
    command()

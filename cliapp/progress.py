"""Progress bars for the terminal only.

A tqdm bar redraws itself with carriage returns; on a terminal that is one line that moves, in
a file (``tactile-run > run.log 2>&1``, a batch job's output) it is hundreds of ``\\r``-joined
copies on one line. :func:`progress_bar` is tqdm's bar, drawn only when its stream is a
terminal; elsewhere it counts silently (what a command prints as lines stays).
"""

from __future__ import annotations

import sys


def is_terminal(stream) -> bool:
    """Whether ``stream`` is an interactive terminal (a closed or odd stream is not)."""
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError, OSError):
        return False


def progress_bar(**kwargs):
    """``tqdm(**kwargs)`` on ``file`` (default stderr), disabled unless that is a terminal."""
    from tqdm import tqdm
    stream = kwargs.setdefault("file", sys.stderr)
    kwargs["disable"] = bool(kwargs.get("disable")) or not is_terminal(stream)
    return tqdm(**kwargs)

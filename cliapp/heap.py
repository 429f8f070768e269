"""The cyclic garbage collector during a long job (a recording, an analysis).

CPython's full collections walk every tracked object, most of them the modules imported at
start-up (a dry run holds ~300 000): six of them cost a default dry run 0.7 s, and each is a
pause of every thread, the device readers' included. :func:`long_lived_frozen` takes what is
alive when a job starts out of the collector's sight for the job's length.
"""

from __future__ import annotations

import gc
from contextlib import contextmanager


@contextmanager
def long_lived_frozen():
    """Within: every object alive at entry (modules, the lab's devices, the tactile model) is
    frozen (:func:`gc.freeze`), so a collection scans only what the job made since. At exit
    they are handed back (:func:`gc.unfreeze`): what the job left in reference cycles is still
    collected, so a sweep of many jobs in one process does not grow."""
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()

"""zarr writes that an interrupted call left running, and waiting for them to end.

zarr (3.x) does its I/O on an event loop in a background thread; the calling thread only
waits for the result. A ``KeyboardInterrupt`` (Ctrl-C, SIGTERM) raised in that wait leaves
the work running: chunks are still written after the caller has moved on, into a staging
directory the caller is removing, and at exit zarr's own hook finds its loop busy
("Cannot close a running event loop"). Call :func:`settle` before cleaning up after an
interrupted write.
"""

from __future__ import annotations

import asyncio
import sys


def settle(timeout_s: float = 30.0) -> None:
    """Wait (at most ``timeout_s``) until zarr's I/O loop has no task left; at once when
    zarr was never used in this process."""
    sync = sys.modules.get("zarr.core.sync")
    if sync is None or getattr(sync, "loop", [None])[0] is None:
        return
    sync.sync(_others_done(timeout_s))


async def _others_done(timeout_s: float) -> None:
    me = asyncio.current_task()
    pending = [t for t in asyncio.all_tasks() if t is not me and not t.done()]
    if pending:
        await asyncio.wait(pending, timeout=timeout_s)

"""A dataset's files or runs spread over processes: :func:`each_in_workers`.

Each worker is forked from the command's process, so it starts with everything the command has
imported (start-up paid once, not once per file or run), and does one item at a time. The
parent keeps the order of the results it is given to publish or print, handles Ctrl-C and
SIGTERM (the workers ignore SIGINT, die on SIGTERM and on their parent's death), and on any
error or interrupt ends every worker before it returns (nothing is left writing). A worker
killed (``kill -9``, the OOM killer) ends the whole loop with :class:`WorkerDied`.
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import signal
import sys
import threading
import time
from contextlib import contextmanager
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Callable, Iterable, Iterator

log = logging.getLogger(__name__)


class WorkerDied(RuntimeError):
    """A worker process ended without returning its item's result (killed)."""


def resolve_workers(value, key: str) -> int:
    """``value`` (``None``: the cores this process may use, :func:`tactile.warmup.available_cores`)
    as a number of workers; ``ValueError`` naming ``key`` for anything but a whole number ≥ 1."""
    from tactile_flow.tactile.warmup import available_cores
    if value is None:
        return available_cores()
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValueError(f"{key}={value!r}: expected a whole number of worker processes ≥ 1 (or null: the cores "
                         f"available)")
    return value


def can_fork() -> bool:
    return "fork" in multiprocessing.get_all_start_methods()


def each_in_workers(fn: Callable, items: Iterable, workers: int) -> Iterator[tuple[int, object]]:
    """``(index, fn(item))`` for every item, as each finishes (with one worker, or where the
    platform cannot fork: here, in order). ``fn`` and the items must be picklable (a module's
    function); an exception ``fn`` raises is yielded in place of the result (the others go on),
    so the caller decides. At most ``2 × workers`` items are queued at a time (memory stays
    bounded for thousands). Leaving the loop early (an error, an interrupt, ``break``) cancels
    what is queued and ends the workers (SIGKILL) before returning."""
    items = list(items)
    if workers <= 1 or len(items) <= 1 or not can_fork():
        for i, item in enumerate(items):
            try:
                yield i, fn(item)
            except Exception as exc:  # noqa: BLE001 - the caller's to judge, as from a worker
                yield i, exc
        return
    for stream in (sys.stdout, sys.stderr):
        stream.flush()                          # else a worker would flush this process's buffered output too
    others = set(multiprocessing.active_children())
    pool, done_cleanly, pending, queued = None, False, {}, 0

    def fill() -> None:
        nonlocal queued
        while queued < len(items) and len(pending) < 2 * workers:
            pending[pool.submit(fn, items[queued])] = queued
            queued += 1
    try:
        with signals_deferred():                # the workers are forked at the first submit
            pool = ProcessPoolExecutor(min(workers, len(items)), multiprocessing.get_context("fork"), worker_init,
                                       (os.getpid(),))
            fill()
        while pending:
            finished, _ = wait(pending, return_when=FIRST_COMPLETED)
            for fut in sorted(finished, key=pending.get):
                i = pending.pop(fut)
                exc = fut.exception()
                if isinstance(exc, BrokenProcessPool):
                    raise WorkerDied(f"a worker process died (killed?) with item {i + 1} of {len(items)} to do")
                yield i, (exc if exc is not None else fut.result())
            try:
                fill()
            except BrokenProcessPool:           # a worker died since the last result came
                raise WorkerDied(f"a worker process died (killed?) with item {queued + 1} of {len(items)} to "
                                 f"do") from None
        done_cleanly = True
    finally:
        if pool is not None and done_cleanly:
            pool.shutdown(wait=True)
        else:
            stop_workers(pool, others)


def stop_workers(pool, others: set, timeout_s: float = 10.0) -> None:
    """Cancel what ``pool`` has queued and end its workers now (the children started since
    ``others`` was taken), then wait, up to ``timeout_s``, until none is listed alive. SIGKILL,
    not SIGTERM: a worker forked a moment ago may not have set its handlers yet. Waited for by
    polling, not ``join``: the pool's own thread reaps the same workers, and of two threads
    waiting on one child the one that loses sees it as still running (measured: 6 stops in 300
    under load left a dead worker listed as alive)."""
    if pool is not None:
        pool.shutdown(wait=False, cancel_futures=True)
    killed, deadline = set(), time.monotonic() + timeout_s
    while workers := [p for p in multiprocessing.active_children() if p not in others]:
        for process in workers:
            if process not in killed:
                process.kill()
                killed.add(process)
        if time.monotonic() > deadline:         # reaped where the pool cannot see it (SIGCHLD ignored?)
            log.warning("workers: %d still listed %g s after SIGKILL (pids %s)", len(workers), timeout_s,
                        [p.pid for p in workers])
            return
        time.sleep(0.005)


@contextmanager
def signals_deferred():
    """SIGINT and SIGTERM noted during the block and delivered to their handlers after it (on
    the main thread; elsewhere nothing changes). Around the workers' start: a worker forked
    with the app's handlers would raise ``KeyboardInterrupt`` (and print a traceback) for a
    Ctrl-C that lands before :func:`worker_init` ignores it; with these, it is noted and
    dropped there, and acted on here once every worker is known. (Also around
    :mod:`analysis.figures`' pool.)"""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    noted = []
    before = {s: signal.signal(s, lambda signum, _: noted.append(signum)) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, handler in before.items():
            signal.signal(s, handler)
        for s in dict.fromkeys(noted):
            signal.raise_signal(s)


def worker_init(parent: int) -> None:
    """A worker: the parent handles Ctrl-C (SIGINT ignored here); SIGTERM ends it; so does its
    parent's death (a killed command leaves no worker writing); the objects it inherited stay
    out of its cyclic collector's sight."""
    import gc
    import time
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)

    def orphaned() -> None:
        while os.getppid() == parent:
            time.sleep(0.2)
        os._exit(1)
    threading.Thread(target=orphaned, daemon=True).start()
    gc.freeze()

"""One run directory, one writer: an exclusive lock held for as long as a process writes it.

``tactile-run`` takes the lock of its run directory (of its sweep directory with ``-m``)
before Hydra writes anything there (:class:`protocols.cli.RunDirLock`) and the run keeps it
until ``run.json`` is written; ``tactile-recover`` takes it too, so it never closes the store
of a run that is still recording, and two processes never write one directory.

The lock is ``fcntl.flock`` on ``<dir>/.tactile.lock`` (the file holds the owner's pid, for
messages), opened without following a link (:mod:`.files`: a lock file planted as a link is
refused, never truncated). The kernel releases it when the process ends, however it ends
(SIGKILL included), so a killed run leaves no stale lock. Within one process the lock is
re-entrant: the CLI and the run it starts share it.

A finished run's directory (it holds ``run.json``) is refused as the directory of a new run
(:func:`refuse_finished`) before anything is written there, and the run's log
(:class:`RunLog`, the handler of ``tactile-run.log``) never appends to a finished run's log.
"""

from __future__ import annotations

import fcntl
import logging
import os
import shutil
from contextlib import contextmanager
from pathlib import Path

from . import files

LOCK_NAME = ".tactile.lock"
_held: dict[str, list] = {}               # resolved directory -> [fd, depth], this process


class RunDirBusy(ValueError):
    """Another process holds the directory's lock."""


class RunFinished(ValueError):
    """The directory holds a finished run, whose record is never rewritten."""


def refuse_finished(directory, what: str = "run directory") -> None:
    """:class:`RunFinished` if ``directory`` holds a run (``run.json``, or a ``run.zarr``
    that no ``run.json`` closed yet): a new run there would rewrite its record."""
    directory = Path(directory)
    if files.finished(directory):
        raise RunFinished(f"{what} {directory} holds a finished run (run.json); a run's record is never rewritten: "
                          f"choose another directory (hydra.run.dir=...) or do it again with "
                          f"`tactile-runs reproduce {directory}`")
    if os.path.lexists(directory / "run.zarr"):
        raise RunFinished(f"{what} {directory} holds a run store (run.zarr) without run.json: a run still "
                          f"recording, or killed (close it with `tactile-recover {directory / 'run.zarr'}`); "
                          f"choose another directory (hydra.run.dir=...)")


def acquire(directory, shared: bool = False) -> None:
    """Take the lock of ``directory`` (created if needed); :class:`RunDirBusy` naming the
    owner's pid if another process holds it. ``shared``: several processes may hold it at once
    (analyses of a finished run, each in a directory of its own) but not beside an exclusive
    holder (a recording, ``tactile-recover``)."""
    directory = Path(directory)
    key = str(directory.resolve())
    if key in _held:
        _held[key][1] += 1
        return
    directory.mkdir(parents=True, exist_ok=True)
    fd = files.open_file(directory, LOCK_NAME, os.O_RDWR | os.O_CREAT)       # never through a link
    try:
        fcntl.flock(fd, (fcntl.LOCK_SH if shared else fcntl.LOCK_EX) | fcntl.LOCK_NB)
    except BlockingIOError:
        owner = _read_pid(fd)
        os.close(fd)
        raise RunDirBusy(f"{directory} is in use by another process{f' (pid {owner})' if owner else ''}; "
                         f"one run directory has one writer: choose another directory or wait for it "
                         f"to end") from None
    os.ftruncate(fd, 0)                    # the (last) holder's pid, for the messages
    os.write(fd, f"{os.getpid()}\n".encode())
    _held[key] = [fd, 1]


def release(directory) -> None:
    """Give back one :func:`acquire` of ``directory`` (the lock goes with the last one)."""
    key = str(Path(directory).resolve())
    entry = _held.get(key)
    if entry is None:
        return
    entry[1] -= 1
    if entry[1] == 0:
        del _held[key]
        os.close(entry[0])                 # closing the descriptor releases the flock


#: what Hydra, the lock, a sweep's job result (cliapp.jobresults) and the run's copies of its
#: inputs (protocols.record) put in a run directory whether or not a run started
SETUP_FILES = (".hydra", LOCK_NAME, "multirun.yaml", "job_result.json", "config", "code.diff")


def remove_if_unused(directory) -> bool:
    """Remove ``directory`` if it holds only what was written before a run started (Hydra's
    ``.hydra/``, the lock, log files), and its parent if that is then empty: a plan, a bad
    config or a failed connection leave no run directory behind (their one line was printed);
    then the date directory and the output root, if they are empty.
    Returns whether it was removed."""
    directory = Path(directory)
    if not directory.is_dir() or str(directory.resolve()) in _held:
        return False
    if any(p.name not in SETUP_FILES and p.suffix != ".log" for p in directory.iterdir()):
        return False
    shutil.rmtree(directory, ignore_errors=True)
    for parent in directory.parents[:2]:         # outputs/<date>/, then outputs/, if now empty
        try:
            parent.rmdir()
        except OSError:
            break
    return not directory.exists()


@contextmanager
def locked(directory, shared: bool = False):
    """``with locked(run_dir): ...`` — :func:`acquire` then :func:`release`."""
    acquire(directory, shared)
    try:
        yield
    finally:
        release(directory)


def holder(directory) -> int | None:
    """The pid of another process holding ``directory``'s lock, or ``None`` when it is free
    (or held by this process)."""
    path = Path(directory) / LOCK_NAME
    if str(Path(directory).resolve()) in _held or not files.is_plain_file(path):
        return None
    fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)      # held at all, shared or not
    except BlockingIOError:
        return _read_pid(fd) or -1
    finally:
        os.close(fd)
    return None


def _read_pid(fd: int) -> int | None:
    try:
        return int(os.pread(fd, 32, 0).decode().strip() or 0) or None
    except (OSError, ValueError):
        return None


class RunLog(logging.FileHandler):
    """The handler of a run's log file (``conf/hydra/job_logging/tactile.yaml``): it opens the
    file at its first record, appending, never through a link (:mod:`.files`), and writes
    nothing if the directory held a finished run at that moment: a second command aimed at a
    finished run, a resumed sweep skipping it, or the next job's first line logged before
    Hydra moves the handlers never add to that run's log. A log that cannot be opened is
    left alone (the console still has every line)."""

    def __init__(self, filename, mode: str = "a", encoding: str | None = "utf-8", delay: bool = True, errors=None):
        super().__init__(filename, mode="a", encoding=encoding, delay=True, errors=errors)
        self._refused = False

    def _open(self):
        path = Path(self.baseFilename)
        fd = files.open_file(path.parent, path.name, os.O_WRONLY | os.O_APPEND | os.O_CREAT)
        return os.fdopen(fd, "a", encoding=self.encoding, errors=self.errors)

    def emit(self, record) -> None:
        if self.stream is None:
            if self._refused:
                return
            if files.finished(Path(self.baseFilename).parent):
                self._refused = True
                return
            try:
                self.stream = self._open()
            except (OSError, ValueError):
                self._refused = True
                return
        super().emit(record)

    def retire(self) -> None:
        """Close the file and write nothing more (the job it belongs to has ended)."""
        self._refused = True
        self.close()


def retire_run_logs() -> None:
    """Retire every :class:`RunLog` of the root logger: called when a job ends, so that lines
    logged before the next job's handlers replace them never reach the ended run's log."""
    for handler in list(logging.getLogger().handlers):
        if isinstance(handler, RunLog):
            handler.retire()

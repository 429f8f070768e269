"""The one way a file in a run directory is written: never through a link, never outside it.

A run directory is shared: copied between machines, opened by colleagues, perhaps prepared
by someone else. A symbolic link planted in it (``analysis_history.jsonl -> ~/.bashrc``)
must never make a command write where the link points. Every file the commands write in a
run (or sweep) directory goes through these functions, which open each directory below the
given one with ``O_NOFOLLOW`` (a link is refused, whatever it points at) and then

- :func:`write_bytes` / :func:`write_text`: write a hidden temporary file and rename it over
  the name, atomically (a reader sees the old file or the new one; a link at the name is
  replaced, never followed);
- :func:`append_text`: append to the file, refusing a link (``O_NOFOLLOW``);
- :func:`open_file`: the descriptor of a file opened that way (the run-directory lock);
- :func:`make_dirs`: make directories below the given one, refusing links.

Names are relative paths of plain components (:func:`runstore.paths.component`). With
``record=True`` the file is part of the run's record (``run.json``, ``.hydra/``, the copied
config files, the code's diff): it is refused once the run has finished
(:func:`finished`: ``run.json`` exists), so a finished run's record is never rewritten.
The directory given (the run directory itself) is trusted: it was resolved from input by
:mod:`runstore.paths`, and may be reached through links (``outputs -> /data/outputs``).
"""

from __future__ import annotations

import errno
import os
import stat
import uuid
from contextlib import contextmanager
from pathlib import Path

from .paths import PathOutsideRoot, component

RUN_JSON = "run.json"


class UnsafePath(PathOutsideRoot):
    """A link where a run directory's file or directory was to be written, or a finished run's
    record that was to be rewritten."""


def finished(directory) -> bool:
    """Whether ``directory`` holds a finished run: a ``run.json`` (written when a run ends,
    by ``tactile-recover`` for a killed one, by ``tactile-import``), as a file or a link."""
    try:
        os.lstat(Path(directory) / RUN_JSON)
        return True
    except FileNotFoundError:
        return False
    except OSError:
        return True                 # unreadable: treat it as a record, never overwrite it


def _parts(name) -> list[str]:
    parts = Path(name).parts
    if not parts or Path(name).is_absolute():
        raise UnsafePath(f"{name}: expected a name relative to the run directory")
    return [component(p, str(name), hidden=True) for p in parts]


@contextmanager
def _dir_fd(directory, parts: list[str], create: bool):
    """A descriptor of ``directory/parts...``, each part opened (made, with ``create``) without
    following a link."""
    fd = os.open(directory, os.O_RDONLY | os.O_DIRECTORY)
    try:
        for i, part in enumerate(parts):
            if create:
                try:
                    os.mkdir(part, 0o755, dir_fd=fd)
                except FileExistsError:
                    pass
            try:
                sub = os.open(part, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW, dir_fd=fd)
            except OSError as exc:
                if exc.errno in (errno.ELOOP, errno.ENOTDIR):
                    raise _refused(Path(directory, *parts[:i + 1]), "directory") from None
                raise
            os.close(fd)
            fd = sub
        yield fd
    finally:
        os.close(fd)


def _refused(path: Path, what: str) -> UnsafePath:
    try:
        target = os.readlink(path)
        how = f"a symbolic link (to {target})"
    except OSError:
        how = "not a regular " + what
    return UnsafePath(f"{path}: is {how}; a run directory's files are never written through a link or "
                      f"outside it: remove it and try again")


def _check_record(directory, name, record: bool) -> None:
    if record and finished(directory):
        raise UnsafePath(f"{Path(directory) / name}: {directory} holds a finished run (run.json); its record is "
                         f"never rewritten")


def write_bytes(directory, name, data: bytes, *, record: bool = False, fsync: bool = True) -> Path:
    """Write ``data`` to ``directory/name`` atomically (temporary file, fsync, rename), making
    the directories of ``name`` as needed; never through a link. Returns the path."""
    parts = _parts(name)
    _check_record(directory, name, record)
    with _dir_fd(directory, parts[:-1], create=True) as fd:
        tmp = f".{parts[-1]}.{uuid.uuid4().hex[:8]}.partial"
        out = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o644, dir_fd=fd)
        try:
            with os.fdopen(out, "wb") as f:
                f.write(data)
                f.flush()
                if fsync:
                    os.fsync(f.fileno())
            os.replace(tmp, parts[-1], src_dir_fd=fd, dst_dir_fd=fd)
        except BaseException:
            try:
                os.unlink(tmp, dir_fd=fd)
            except OSError:
                pass
            raise
        if fsync:
            try:
                os.fsync(fd)                    # the rename itself durable
            except OSError:
                pass
    return Path(directory, *parts)


def write_text(directory, name, text: str, *, record: bool = False, fsync: bool = True) -> Path:
    """:func:`write_bytes` of ``text`` in UTF-8."""
    return write_bytes(directory, name, text.encode("utf-8"), record=record, fsync=fsync)


def open_file(directory, name, flags: int = os.O_RDWR | os.O_CREAT, mode: int = 0o644, *,
              record: bool = False) -> int:
    """A descriptor of ``directory/name`` opened with ``flags`` and ``O_NOFOLLOW`` (directories
    of ``name`` made as needed); :class:`UnsafePath` if it is a link."""
    parts = _parts(name)
    _check_record(directory, name, record)
    with _dir_fd(directory, parts[:-1], create=bool(flags & os.O_CREAT)) as fd:
        try:
            return os.open(parts[-1], flags | os.O_NOFOLLOW | os.O_CLOEXEC, mode, dir_fd=fd)
        except OSError as exc:
            if exc.errno == errno.ELOOP:
                raise _refused(Path(directory, *parts), "file") from None
            raise


def append_text(directory, name, text: str, *, record: bool = False) -> None:
    """Append ``text`` (UTF-8) to ``directory/name``, created if missing; never through a link."""
    fd = open_file(directory, name, os.O_WRONLY | os.O_APPEND | os.O_CREAT, record=record)
    with os.fdopen(fd, "ab") as f:
        f.write(text.encode("utf-8"))
        f.flush()
        os.fsync(f.fileno())


def make_dirs(directory, name) -> Path:
    """Make ``directory/name`` (and the directories between), refusing links; returns it."""
    parts = _parts(name)
    with _dir_fd(directory, parts, create=True):
        pass
    return Path(directory, *parts)


def refuse_links(directory, names) -> None:
    """:class:`UnsafePath` if any of ``names`` in ``directory`` is a link: checked before
    long work that will write them, so that it is refused before it starts."""
    for name in names:
        path = Path(directory) / name
        if os.path.islink(path):
            raise _refused(path, "file")


def is_plain_file(path) -> bool:
    """Whether ``path`` is a regular file, not a link (to decide whether to read it as ours)."""
    try:
        return stat.S_ISREG(os.lstat(path).st_mode)
    except OSError:
        return False

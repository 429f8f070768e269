"""Room to close a run, held from its start: a full disk never leaves a store saying ``running``.

Closing a run writes a little: the store's final root metadata (its consolidated metadata,
~150 kB, written beside the old one and renamed) and ``run.json`` (~25 kB). A disk that filled
while the run recorded has none of that left, so the store stayed ``running`` without a
``run.json`` until ``tactile-recover`` was run on a disk with room. :class:`RoomToClose` takes
:data:`RESERVE_BYTES` on the run's disk when the store is created (a hidden file beside it,
its blocks allocated) and gives them back just before the close writes: the close, and
``run.json`` after it, then fit whatever the recording left. ``tactile-recover`` releases a
reserve a killed run left behind the same way.
"""

from __future__ import annotations

import os
from pathlib import Path

RESERVE_BYTES = 1 << 20           # the close (~150 kB metadata, written twice over a rename) and run.json (~25 kB), with room to spare


def room_path(store: Path) -> Path:
    """The reserve of the store at ``store`` (``run.zarr`` → ``.run.zarr.room`` beside it)."""
    store = Path(store)
    return store.with_name(f".{store.name}.room")


class RoomToClose:
    """``nbytes`` of disk held in ``path`` until :meth:`release` (idempotent)."""

    def __init__(self, path, nbytes: int = RESERVE_BYTES):
        self.path = Path(path)
        fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o600)   # never through a link
        try:
            try:
                os.posix_fallocate(fd, 0, nbytes)          # the blocks themselves, not a sparse size
            except OSError as exc:
                if exc.errno not in (95, 22):              # EOPNOTSUPP / EINVAL: a filesystem without fallocate
                    raise
                _write_blocks(fd, nbytes)
        except BaseException:
            os.close(fd)
            self.path.unlink(missing_ok=True)
            raise
        os.close(fd)
        self.held = True

    def release(self) -> bool:
        """Give the room back; returns whether it was held."""
        if not self.held:
            return False
        self.held = False
        self.path.unlink(missing_ok=True)
        return True


def _write_blocks(fd: int, nbytes: int) -> None:
    """Write ``nbytes`` that no filesystem compresses away (random, not zeros)."""
    left = nbytes
    while left > 0:
        n = os.write(fd, os.urandom(min(left, 1 << 16)))
        left -= n
    os.fsync(fd)


def release_left_behind(store) -> bool:
    """Remove the reserve a killed run left beside ``store`` (recovery needs the room)."""
    path = room_path(store)
    if path.is_file() and not path.is_symlink():
        path.unlink()
        return True
    return False

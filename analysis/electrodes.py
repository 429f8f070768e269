"""A run's electrode counts, read from the store a stretch of frames at a time.

An 8-hour five-finger record holds 2.9 million frames of 5 × 24 electrodes: 2.8 GB as the
float64 the analysis computes with, more than a lab PC should spend on one record. So the
electrodes stay in the store: :class:`StoredElectrodes` reads the frames ``[a, b)`` asked for
(only the zarr chunks they lie in), through the screening's choice of frames (dropped frames are
skipped, the indices are those of the frames kept). Short records are read whole once
(:meth:`StoredElectrodes.materialise`) and analysed as a plain array.
"""

from __future__ import annotations

import hashlib

import numpy as np

COUNT_RANGE = (1.0, 4094.0)
"""Electrode counts a working channel can report (0: shorted, or a chunk read back as zeros;
4095: saturated, an impedance of 0 kΩ)."""

READ_FRAMES = 20_000
"""Frames read from the store at a time when a pass goes over the whole record."""


class StoredElectrodes:
    """The (T, F, 24) electrode counts (float64) of a run store, read on demand.

    ``array``: the store's ``biotac/electrodes`` (a ``zarr.Array``, read a slice at a time);
    ``keep``: indices (K,) of the stored frames kept by the screening, ascending, or ``None``
    for all of them; ``on_error(exc)`` turns a read failure (a corrupt chunk) into the
    caller's error. Indexing with a slice of frames (and optionally a finger) returns an array:
    ``source[a:b]`` → (b−a, F, 24), ``source[a:b, k]`` → (b−a, 24).
    """

    def __init__(self, array, keep: np.ndarray | None, on_error):
        self._array, self._keep, self._on_error = array, keep, on_error
        n = array.shape[0] if keep is None else len(keep)
        self.shape = (n, *array.shape[1:])

    def __len__(self) -> int:
        return self.shape[0]

    @property
    def ndim(self) -> int:
        return len(self.shape)

    def __getitem__(self, key):
        frames, rest = (key[0], key[1:]) if isinstance(key, tuple) else (key, ())
        if isinstance(frames, (int, np.integer)):
            i = int(frames) + (len(self) if frames < 0 else 0)
            return self.read(i, i + 1)[(0, *rest)]
        if not isinstance(frames, slice):
            raise TypeError("StoredElectrodes: index frames with an integer or a slice")
        a, b, step = frames.indices(len(self))
        return self.read(a, max(a, b))[(slice(None, None, step), *rest)]

    def read(self, a: int, b: int) -> np.ndarray:
        """Frames [a, b) (indices among the kept frames) as float64 counts (b−a, F, 24)."""
        if self._keep is None:
            return self._stored(a, b)
        rows = self._keep[a:b]
        if len(rows) == 0:
            return np.zeros((0, *self.shape[1:]))
        block = self._stored(int(rows[0]), int(rows[-1]) + 1)
        return block if len(block) == len(rows) else block[rows - rows[0]]

    def _stored(self, a: int, b: int) -> np.ndarray:
        try:
            return np.asarray(self._array[a:b], float)
        except Exception as exc:  # noqa: BLE001 - the codec's own error type varies
            raise self._on_error(exc) from None

    def chunks(self, frames: int = READ_FRAMES):
        """``(a, counts)`` for consecutive stretches of at most ``frames`` frames."""
        for a in range(0, len(self), frames):
            yield a, self.read(a, min(a + frames, len(self)))

    def materialise(self) -> np.ndarray:
        """Every kept frame as one (T, F, 24) float64 array."""
        return self.read(0, len(self))

    def select(self, keep: np.ndarray) -> StoredElectrodes:
        """The frames ``keep`` (boolean (T,) over this source's frames) as a new source."""
        if keep.all():
            return self
        base = np.arange(len(self)) if self._keep is None else self._keep
        return StoredElectrodes(self._array, base[keep], self._on_error)


def screen_counts(source) -> tuple[np.ndarray, np.ndarray, np.ndarray, str]:
    """One pass over the stored electrodes (T, F, 24) counts: which fingers read all 24
    electrodes in range in each frame, which frames read 0 everywhere, which read the
    saturated 4095 everywhere, and a checksum.

    Returns ``(in_range (T, F) bool, all_zero (T,) bool, all_saturated (T,) bool, sha256 hex)``;
    the checksum is of the counts as float64, frame after frame (the same for a plain array and
    a stored source)."""
    lo, hi = COUNT_RANGE
    in_range, zero, saturated = [], [], []
    h = hashlib.sha256()
    chunks = source.chunks() if isinstance(source, StoredElectrodes) else \
        ((a, source[a:a + READ_FRAMES]) for a in range(0, len(source), READ_FRAMES))
    for _, c in chunks:
        c = np.ascontiguousarray(c, float)
        in_range.append(np.all((c >= lo) & (c <= hi), axis=2))
        zero.append(np.all(c == 0, axis=(1, 2)))
        saturated.append(np.all(c >= 4095, axis=(1, 2)))
        h.update(c.tobytes())
    F = source.shape[1]
    return (np.concatenate(in_range) if in_range else np.zeros((0, F), bool),
            np.concatenate(zero) if zero else np.zeros(0, bool),
            np.concatenate(saturated) if saturated else np.zeros(0, bool), h.hexdigest())

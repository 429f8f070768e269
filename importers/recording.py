"""A recording read from a foreign file, before it becomes a run store — read in chunks.

Readers (:mod:`.bag`, :mod:`.csv`) read a file as a stream of :class:`Recording` chunks of at
most :data:`CHUNK_FRAMES` frames (the :class:`Reader` protocol), so nothing here ever holds a
whole file. The import reads each file twice: a first pass (:func:`.importer.scan`) checks it
and collects a :class:`Scan` (frame count, which fingers are connected — :class:`Connectivity`,
the early window for a baseline estimate, the clock model), a second pass writes it
(:mod:`.writer`). :func:`unconnected_fingers`, :func:`decide_fingers` and :func:`keep_fingers`
decide which fingers are stored. :func:`order_statistics` finds exact medians of data too
long to hold, reading them several times. Everything here is plain arrays and pure functions.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field, replace
from typing import Callable, Iterable, Iterator, Protocol

import numpy as np

from tactile_flow.hardware.biotac import FINGERS
from tactile_flow.hardware.errors import RATE_RANGE_HZ, brief
from tactile_flow.runstore.clockmodel import ClockFit

#: relative disagreement allowed between ``rate_hz`` and the rate of a file's own timestamps
RATE_TOLERANCE = 0.02

#: PDC reading of a BioTac port with no sensor on it (Shadow driver, 16-bit wrap of a bad read)
UNCONNECTED_PDC = -22072

#: frames per chunk read or written (five fingers: ~10 MB of int64 electrode counts)
CHUNK_FRAMES = 10_000


class ImportInputError(ValueError):
    """The source cannot be imported (bad path, missing topic, bad columns, bad rate...).

    The message is one sentence naming the file and what is wrong."""


@dataclass(frozen=True)
class Recording:
    """BioTac data of one source file (or one chunk of it), on its own clocks.

    Attributes:
        fingers: finger names along axis 1 of every (N, F, ...) array, Shadow order.
        seq: (N,) int64 frame sequence numbers.
        device_time: (N,) s, the sensor bridge's timestamp of each frame (header stamp,
            or the file's time column, or ``index / rate``).
        host_time: (N,) s, host receipt time (bag record time) or ``None`` if the file has none.
        electrodes: (N, F, E) int counts, electrodes 1..E (24 on a BioTac SP, 19 on a classic BioTac).
        pdc, tdc, tac: (N, F) int counts or ``None`` when the file does not hold the channel.
        pac: list of N arrays (F, n_k) of 2.2 kHz PAC counts per frame, or ``None``.
        meta: what the reader found (format, topic, message type, columns, notes...), JSON-ready.
    """

    fingers: tuple[str, ...]
    seq: np.ndarray
    device_time: np.ndarray
    host_time: np.ndarray | None
    electrodes: np.ndarray
    pdc: np.ndarray | None = None
    tdc: np.ndarray | None = None
    tac: np.ndarray | None = None
    pac: list[np.ndarray] | None = None
    meta: dict = field(default_factory=dict)

    @property
    def n_frames(self) -> int:
        return int(len(self.seq))

    @property
    def channels(self) -> tuple[str, ...]:
        """Optional channels the file holds, of ``pdc``, ``tdc``, ``tac``, ``pac``."""
        return tuple(c for c in ("pdc", "tdc", "tac", "pac") if getattr(self, c) is not None)

    def nominal_rate_hz(self) -> float:
        """Frame rate from the median device-time interval (Hz); NaN for fewer than 2 frames."""
        if self.n_frames < 2:
            return float("nan")
        return rate_of(np.median(np.diff(self.device_time)))


class Reader(Protocol):
    """A file read as chunks; :meth:`chunks` starts again from the beginning at every call.

    ``meta`` is what the reader found (JSON-ready), complete once :meth:`chunks` has been
    read to the end; ``path`` the file; ``finger_names`` every finger the file has.
    """

    path: object
    meta: dict
    finger_names: tuple[str, ...]

    def chunks(self, frames: int = CHUNK_FRAMES) -> Iterator[Recording]:
        """Every frame of the file, in :class:`Recording` s of at most ``frames`` frames."""

    def finish(self, rate_hz: float) -> None:
        """Check the frame rate measured from the stored times (Hz) and complete ``meta``;
        :class:`ImportInputError` if it disagrees with what the user gave."""


@dataclass
class Scan:
    """What the first pass over one file found (bounded: no per-frame array but ``head``).

    Attributes:
        frames: frames in the file.
        fingers: every finger the file has; ``channels``: its optional channels.
        unconnected: ``{finger: reason}`` (see :func:`unconnected_fingers`).
        head: the early frames (see :class:`.baseline.EarlyWindow`), every finger.
        clock: the clock model of device against host time (``None`` without host times).
        t0: the run's time origin, s: the first frame on the clock model (host clock), or
            its device time when the file has no host times.
    """

    frames: int
    fingers: tuple[str, ...]
    channels: tuple[str, ...]
    unconnected: dict
    head: Recording
    clock: ClockFit | None
    t0: float


@dataclass
class PreparedSource:
    """One file ready for the second pass: its reader, what the first pass found, the
    fingers to store (Shadow order), the finger decision (:func:`decide_fingers`), the
    frames per chunk, and its sensor model (:class:`tactile.sensor.SensorModel`) with how it
    was chosen."""

    reader: Reader
    scan: Scan
    fingers: tuple[str, ...]
    decision: dict
    chunk_frames: int = CHUNK_FRAMES
    sensor: object = None
    sensor_how: str = ""

    def chunks(self) -> Iterator[Recording]:
        """The file again, chunk by chunk, restricted to :attr:`fingers`."""
        for chunk in self.reader.chunks(self.chunk_frames):
            yield keep_fingers(chunk, self.fingers)


def rate_of(interval_s) -> float:
    """Rate (Hz) of a median interval (s): ``1 / interval`` (inf for 0, as numpy divides)."""
    with np.errstate(divide="ignore"):
        return float(np.float64(1.0) / np.float64(interval_s))


def parse_rate(rate_hz) -> float | None:
    """``rate_hz`` (Hz) as a float within :data:`hardware.errors.RATE_RANGE_HZ`, or ``None``;
    :class:`ImportInputError` otherwise."""
    if rate_hz is None:
        return None
    try:
        rate = float(rate_hz)
    except (TypeError, ValueError, OverflowError):
        raise ImportInputError(f"rate_hz={brief(rate_hz)}: expected a number of Hz") from None
    lo, hi = RATE_RANGE_HZ
    if not math.isfinite(rate) or rate <= 0:
        raise ImportInputError(f"rate_hz={brief(rate_hz)}: expected a positive number of Hz in [{lo:g}, {hi:g}]")
    if not lo <= rate <= hi:
        raise ImportInputError(f"rate_hz={brief(rate_hz)}: expected a number of Hz in [{lo:g}, {hi:g}] "
                               f"(a BioTac streams at about 100 Hz)")
    return rate


def check_rate(measured_hz: float, rate_hz: float | None, what: str) -> None:
    """Raise :class:`ImportInputError` when a given ``rate_hz`` differs from the rate measured
    from the file's own timestamps (``measured_hz``, median interval) by more than
    :data:`RATE_TOLERANCE`; ``what`` names the timestamps."""
    rate_hz = parse_rate(rate_hz)
    if rate_hz is not None and not abs(measured_hz - rate_hz) <= RATE_TOLERANCE * rate_hz:
        raise ImportInputError(f"{what}: rate_hz={rate_hz:g} disagrees with the recorded timestamps "
                               f"(median interval {1 / measured_hz:.6g} s = {measured_hz:.4g} Hz); "
                               f"drop rate_hz or correct it")


# ----------------------------------------------------------------------------- chunks
def concat(chunks: Iterable[Recording], meta: dict | None = None) -> Recording:
    """One :class:`Recording` of consecutive chunks (the whole file in memory: for tests and
    small files; the import itself never does this). Needs at least one chunk."""
    chunks = list(chunks)
    first = chunks[0]

    def cat(name):
        parts = [getattr(c, name) for c in chunks]
        return None if parts[0] is None else np.concatenate(parts)

    pac = None if first.pac is None else [p for c in chunks for p in c.pac]
    return Recording(fingers=first.fingers, seq=cat("seq"), device_time=cat("device_time"),
                     host_time=cat("host_time"), electrodes=cat("electrodes"), pdc=cat("pdc"), tdc=cat("tdc"),
                     tac=cat("tac"), pac=pac, meta=dict(meta if meta is not None else first.meta))


def head_of(rec: Recording, n: int) -> Recording:
    """The first ``n`` frames of ``rec``."""
    def sub(a):
        return None if a is None else a[:n]
    return replace(rec, seq=rec.seq[:n], device_time=rec.device_time[:n], host_time=sub(rec.host_time),
                   electrodes=rec.electrodes[:n], pdc=sub(rec.pdc), tdc=sub(rec.tdc), tac=sub(rec.tac),
                   pac=sub(rec.pac))


# ----------------------------------------------------------------------------- fingers
@dataclass
class Connectivity:
    """The unconnected-port rule (:func:`unconnected_fingers`) applied chunk by chunk.

    Per finger (F,) booleans, true while *every* frame so far had all its electrodes at 0
    (``zero``), pdc = :data:`UNCONNECTED_PDC` (``bad_pdc``), or either (``either``).
    """

    fingers: tuple[str, ...]
    frames: int = 0
    zero: np.ndarray = field(init=False)
    bad_pdc: np.ndarray = field(init=False)
    either: np.ndarray = field(init=False)

    def __post_init__(self):
        F = len(self.fingers)
        self.zero, self.bad_pdc, self.either = (np.ones(F, bool) for _ in range(3))

    def update(self, rec: Recording) -> None:
        """Add the frames of ``rec`` (same fingers)."""
        zero = np.all(rec.electrodes == 0, axis=-1)                                 # (N, F)
        bad = (rec.pdc == UNCONNECTED_PDC) if rec.pdc is not None else np.zeros_like(zero)
        self.zero &= zero.all(axis=0)
        self.bad_pdc &= bad.all(axis=0)
        self.either &= (zero | bad).all(axis=0)
        self.frames += rec.n_frames

    def unconnected(self) -> dict[str, str]:
        """``{finger: reason}`` for the fingers whose every frame matched the rule."""
        out = {}
        if not self.frames:
            return out
        for k, f in enumerate(self.fingers):
            if not self.either[k]:
                continue
            if self.bad_pdc[k] and self.zero[k]:
                out[f] = f"pdc = {UNCONNECTED_PDC} and all electrodes 0 in every frame"
            elif self.bad_pdc[k]:
                out[f] = f"pdc = {UNCONNECTED_PDC} in every frame"
            elif self.zero[k]:
                out[f] = "all electrodes 0 in every frame"
            else:
                out[f] = f"pdc = {UNCONNECTED_PDC} or all electrodes 0 in every frame"
        return out


def unconnected_fingers(rec: Recording) -> dict[str, str]:
    """Fingers whose port has no sensor, with the reason, by name.

    A finger is unconnected when in *every* frame its PDC reads :data:`UNCONNECTED_PDC`
    (−22072, what the Shadow driver reports for an empty port) or all its electrodes read 0
    (no real sensor reads 0 on every electrode: rest counts are ~2000–3500). A finger that
    drops out for part of the record is kept (those frames are invalid, not the finger).
    """
    conn = Connectivity(rec.fingers)
    conn.update(rec)
    return conn.unconnected()


def keep_fingers(rec: Recording, fingers) -> Recording:
    """``rec`` restricted to ``fingers`` (any order; stored in Shadow order)."""
    order = [f for f in FINGERS if f in set(fingers)]
    if tuple(order) == tuple(rec.fingers):
        return rec
    idx = [rec.fingers.index(f) for f in order]

    def sub(a):
        return None if a is None else a[:, idx]

    pac = None if rec.pac is None else [p[idx] for p in rec.pac]
    return replace(rec, fingers=tuple(order), electrodes=rec.electrodes[:, idx], pdc=sub(rec.pdc),
                   tdc=sub(rec.tdc), tac=sub(rec.tac), pac=pac)


def decide_fingers(fingers, unconnected: dict, requested=None, src: str = "source") -> dict:
    """Which fingers of a file to store: every connected one, or the ``requested`` ones.

    Args:
        fingers: the fingers the file has.
        unconnected: ``{finger: reason}`` (:func:`unconnected_fingers`, :class:`Connectivity`).
        requested: finger names (or one name) the user asked for, or ``None``.
        src: the file, for messages.
    Returns the decision as a JSON-ready dict: ``kept``, ``dropped`` ({finger: reason}),
    ``rule``. Raises :class:`ImportInputError` when a requested finger is not in the file or
    is unconnected, or nothing is left.
    """
    fingers = tuple(fingers)
    dropped = dict(unconnected)
    if requested:
        requested = [requested] if isinstance(requested, str) else list(requested)
        unknown = [f for f in requested if f not in fingers]
        if unknown:
            raise ImportInputError(f"{src}: fingers={unknown} not in the recording (it has {list(fingers)})")
        dead = [f for f in requested if f in dropped]
        if dead:
            raise ImportInputError(f"{src}: fingers={dead} requested but unconnected ({dropped[dead[0]]})")
        for f in fingers:
            if f not in requested and f not in dropped:
                dropped[f] = "not requested (fingers=...)"
    kept = [f for f in fingers if f not in dropped]
    if not kept:
        raise ImportInputError(f"{src}: no connected finger in the recording ({dropped})")
    return {"kept": kept, "dropped": dropped,
            "rule": f"a finger is dropped (not stored) when every frame reads pdc = {UNCONNECTED_PDC} "
                    f"or all its electrodes 0 (an empty port)"}


def select_fingers(rec: Recording, requested=None) -> tuple[Recording, dict]:
    """Drop unconnected fingers (and, with ``requested``, every finger not asked for) from a
    whole recording; see :func:`decide_fingers`. Returns the recording with the kept fingers
    and the decision."""
    decision = decide_fingers(rec.fingers, unconnected_fingers(rec), requested, rec.meta.get("path", "source"))
    return keep_fingers(rec, decision["kept"]), decision


# ----------------------------------------------------------------------------- exact medians
_SIGN = 1 << 63
_MASK = (1 << 64) - 1
_BITS = 16                                    # radix per pass: 65 536 counters


def _ordered_keys(a: np.ndarray) -> np.ndarray:
    """float64 (N,) → uint64 (N,) keys with the same order (NaN excluded)."""
    bits = np.ascontiguousarray(a, np.float64).view(np.uint64)
    return np.where(bits >> np.uint64(63), ~bits, bits | np.uint64(_SIGN))


def _float_of_key(key: int) -> float:
    bits = key ^ _SIGN if key & _SIGN else ~key & _MASK
    return struct.unpack("<d", struct.pack("<Q", bits))[0]


def order_statistics(chunks: Callable[[], Iterable[np.ndarray]], ranks) -> list[float]:
    """The ``ranks``-th smallest (0-based) of all the values ``chunks()`` yields, exactly.

    Radix selection on the 64-bit ordered key of each float64, 16 bits per pass: four calls
    of ``chunks()`` and memory O(chunk + 65 536), however many values there are.

    Args:
        chunks: called once per pass; yields 1-D float arrays (no NaN), the same every call.
        ranks: 0-based ranks, each below the number of values.
    """
    state = [[0, int(r)] for r in ranks]                  # [key prefix so far, rank within it]
    for level in range(64 // _BITS):
        shift = np.uint64(64 - _BITS * (level + 1))
        hists = [np.zeros(1 << _BITS, np.int64) for _ in state]
        for a in chunks():
            keys = _ordered_keys(a)
            for (prefix, _), hist in zip(state, hists):
                sel = keys if level == 0 else keys[(keys >> (shift + np.uint64(_BITS))) == np.uint64(prefix)]
                digit = ((sel >> shift) & np.uint64((1 << _BITS) - 1)).astype(np.intp)
                hist += np.bincount(digit, minlength=1 << _BITS)
        for s, hist in zip(state, hists):
            cum = np.cumsum(hist)
            b = int(np.searchsorted(cum, s[1], side="right"))
            if b >= len(cum):
                raise ValueError(f"order_statistics: rank {s[1]} beyond the {int(cum[-1])} values")
            s[1] -= int(cum[b - 1]) if b else 0
            s[0] = (s[0] << _BITS) | b
    return [_float_of_key(p) for p, _ in state]


IN_MEMORY_MEDIAN = 1 << 20
"""Up to this many values (8 MB of float64) :func:`median_of` reads them once into memory."""


def median_of(chunks: Callable[[], Iterable[np.ndarray]], n: int) -> float:
    """``np.median`` of the ``n`` values ``chunks()`` yields (see :func:`order_statistics`),
    bit for bit: the middle value, or the mean of the two middle ones. NaN for ``n = 0``."""
    if n <= 0:
        return float("nan")
    if n <= IN_MEMORY_MEDIAN:                   # a short record: one read, not the four passes below
        return float(np.median(np.concatenate([np.asarray(a, np.float64) for a in chunks()])))
    if n % 2:
        return order_statistics(chunks, [n // 2])[0]
    a, b = order_statistics(chunks, [n // 2 - 1, n // 2])
    return float((np.float64(a) + np.float64(b)) / 2)


def diffs(chunks: Iterable[np.ndarray]) -> Iterator[np.ndarray]:
    """``np.diff`` of the concatenation of ``chunks``, chunk by chunk."""
    last = None
    for a in chunks:
        if not len(a):
            continue
        yield np.diff(a) if last is None else np.diff(np.r_[last, a])
        last = a[-1]

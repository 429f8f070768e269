"""A recording read from a foreign file, before it becomes a run store.

Readers (:mod:`.bag`, :mod:`.csv`) turn a file into a :class:`Recording` holding every
finger the file has; :func:`unconnected_fingers` and :func:`keep_fingers` then decide which
fingers are stored. Everything here is plain arrays and pure functions.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from hardware.biotac import FINGERS, N_TAXELS

#: relative disagreement allowed between ``rate_hz`` and the rate of a file's own timestamps
RATE_TOLERANCE = 0.02

#: PDC reading of a BioTac port with no sensor on it (Shadow driver, 16-bit wrap of a bad read)
UNCONNECTED_PDC = -22072


class ImportInputError(ValueError):
    """The source cannot be imported (bad path, missing topic, bad columns, bad rate...).

    The message is one sentence naming the file and what is wrong."""


@dataclass(frozen=True)
class Recording:
    """BioTac data of one source file, on its own clocks.

    Attributes:
        fingers: finger names along axis 1 of every (N, F, ...) array, Shadow order.
        seq: (N,) int64 frame sequence numbers.
        device_time: (N,) s, the sensor bridge's timestamp of each frame (header stamp,
            or the file's time column, or ``index / rate``).
        host_time: (N,) s, host receipt time (bag record time) or ``None`` if the file has none.
        electrodes: (N, F, 24) int counts, taxels 1..24.
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
        return float(1.0 / np.median(np.diff(self.device_time)))


def parse_rate(rate_hz) -> float | None:
    """``rate_hz`` (Hz) as a positive float, or ``None``; :class:`ImportInputError` otherwise."""
    if rate_hz is None:
        return None
    try:
        rate = float(rate_hz)
    except (TypeError, ValueError):
        raise ImportInputError(f"rate_hz={rate_hz!r}: expected a number of Hz") from None
    if not math.isfinite(rate) or rate <= 0:
        raise ImportInputError(f"rate_hz={rate_hz}: expected a positive number of Hz")
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


def unconnected_fingers(rec: Recording) -> dict[str, str]:
    """Fingers whose port has no sensor, with the reason, by name.

    A finger is unconnected when in *every* frame its PDC reads :data:`UNCONNECTED_PDC`
    (−22072, what the Shadow driver reports for an empty port) or all 24 electrodes read 0
    (no real sensor reads 0 on every electrode: rest counts are ~2000–3500). A finger that
    drops out for part of the record is kept (those frames are invalid, not the finger).
    """
    out = {}
    for k, f in enumerate(rec.fingers):
        zero = np.all(rec.electrodes[:, k, :] == 0, axis=-1)                      # (N,)
        bad_pdc = (rec.pdc[:, k] == UNCONNECTED_PDC) if rec.pdc is not None else np.zeros_like(zero)
        if rec.n_frames and np.all(zero | bad_pdc):
            if np.all(bad_pdc) and np.all(zero):
                out[f] = f"pdc = {UNCONNECTED_PDC} and all electrodes 0 in every frame"
            elif np.all(bad_pdc):
                out[f] = f"pdc = {UNCONNECTED_PDC} in every frame"
            elif np.all(zero):
                out[f] = "all electrodes 0 in every frame"
            else:
                out[f] = f"pdc = {UNCONNECTED_PDC} or all electrodes 0 in every frame"
    return out


def keep_fingers(rec: Recording, fingers) -> Recording:
    """``rec`` restricted to ``fingers`` (any order; stored in Shadow order)."""
    order = [f for f in FINGERS if f in set(fingers)]
    idx = [rec.fingers.index(f) for f in order]

    def sub(a):
        return None if a is None else a[:, idx]

    pac = None if rec.pac is None else [p[idx] for p in rec.pac]
    return replace(rec, fingers=tuple(order), electrodes=rec.electrodes[:, idx], pdc=sub(rec.pdc),
                   tdc=sub(rec.tdc), tac=sub(rec.tac), pac=pac)


def select_fingers(rec: Recording, requested=None) -> tuple[Recording, dict]:
    """Drop unconnected fingers (and, with ``requested``, every finger not asked for).

    Returns the recording with the kept fingers and the decision as a JSON-ready dict:
    ``kept``, ``dropped`` ({finger: reason}), ``rule``. Raises :class:`ImportInputError`
    when a requested finger is not in the file or is unconnected, or nothing is left.
    """
    src = rec.meta.get("path", "source")
    dropped = unconnected_fingers(rec)
    if requested:
        requested = [requested] if isinstance(requested, str) else list(requested)
        unknown = [f for f in requested if f not in rec.fingers]
        if unknown:
            raise ImportInputError(f"{src}: fingers={unknown} not in the recording (it has {list(rec.fingers)})")
        dead = [f for f in requested if f in dropped]
        if dead:
            raise ImportInputError(f"{src}: fingers={dead} requested but unconnected ({dropped[dead[0]]})")
        for f in rec.fingers:
            if f not in requested and f not in dropped:
                dropped[f] = "not requested (fingers=...)"
    kept = [f for f in rec.fingers if f not in dropped]
    if not kept:
        raise ImportInputError(f"{src}: no connected finger in the recording ({dropped})")
    decision = {"kept": kept, "dropped": dropped,
                "rule": f"a finger is dropped (not stored) when every frame reads pdc = {UNCONNECTED_PDC} "
                        f"or all {N_TAXELS} electrodes 0 (an empty port)"}
    return keep_fingers(rec, kept), decision

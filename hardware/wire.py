"""Wire data checked where it arrives: every message a driver cannot trust is refused, counted
by reason, and the last one kept for the operator.

A driver decodes what a device or a bridge sends (a rosbridge JSON message, a serial line) into
typed samples. A message with a field missing, of the wrong type, or a value its sample cannot
hold (an electrode at 70000 in a 16-bit count) is not a sample: the driver raises
:class:`WireError` while decoding, counts it in its :class:`WireRejects` and goes on with the
next message, so a stream of garbage never stops the driver's thread and never passes for a
silent sensor. Values that fit but lie outside the sensor's range (a BioTac count above 4095)
are samples, flagged invalid where they are stored (``biotac/valid``).

The run reports every device's counts (:meth:`hardware.device.Device.wire_report`) in the
store's root attribute ``wire`` and in ``run.json``; the BioTac interlock names a stream of
refused frames as such (``malformed_biotac``), not as a stale sensor.
"""

from __future__ import annotations

import threading
from collections import Counter

import numpy as np

INT16 = (-32768, 32767)


class WireError(ValueError):
    """A message that cannot be decoded: ``reason`` (a category, for the counts), ``detail``
    (the values, for the operator)."""

    def __init__(self, reason: str, detail: str = ""):
        self.reason, self.detail = reason, detail or reason
        super().__init__(self.detail)


class WireRejects:
    """Messages refused by one driver: the total, per reason, and the last one; thread-safe."""

    def __init__(self):
        self._lock = threading.Lock()
        self.total = 0
        self.by_reason: Counter = Counter()
        self.last: str | None = None

    def add(self, error: WireError) -> None:
        with self._lock:
            self.total += 1
            self.by_reason[error.reason] += 1
            self.last = error.detail

    def as_dict(self) -> dict:
        """``{"refused": n, "reasons": {reason: n}, "last": "..."}`` (JSON values)."""
        with self._lock:
            return {"refused": self.total, "reasons": dict(self.by_reason), "last": self.last}


def counts(values, what: str, bounds: tuple[int, int] = INT16) -> np.ndarray:
    """A list (or a number) of whole counts within ``bounds`` as an int64 array, or
    :class:`WireError` naming ``what``: not a number, not whole, a bool, or out of bounds."""
    if isinstance(values, (bool, str, bytes)) or values is None:
        raise WireError(f"{what}: not a number", f"{what}: got {_brief(values)}; expected whole counts")
    try:
        a = np.asarray(values)
    except (ValueError, TypeError):
        raise WireError(f"{what}: not a number", f"{what}: got {_brief(values)}; expected whole counts") from None
    if a.dtype.kind == "f" and np.all(np.isfinite(a)) and np.all(a == np.round(a)):
        a = a.astype(np.int64)
    if a.dtype.kind not in "iu":
        raise WireError(f"{what}: not a number", f"{what}: got {_brief(values)}; expected whole counts")
    a = a.astype(np.int64)
    lo, hi = bounds
    if a.size and (a.min() < lo or a.max() > hi):
        bad = int(a.flat[int(np.argmax((a < lo) | (a > hi)))])
        raise WireError(f"{what}: out of range", f"{what}: {bad} does not fit a count in {lo}..{hi}")
    return a


def _brief(value, limit: int = 40) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[:limit] + "..."

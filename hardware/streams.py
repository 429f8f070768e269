"""How a device declares what it records (as ophyd-async's ``describe()`` and LeRobot's
``observation_features``): each sample type's ``describe()`` returns :class:`Stream`
declarations, and the run store's layout (:mod:`runstore.layout`), the recorder's columns
(:mod:`protocols.recorder`) and recovery derive from them. Adding a stream is its sample type's
``describe()`` plus its driver.

Every stream records three times per sample: its time coordinate (s since run start, from
the clock model), the device's own timestamp and the host's receipt time (both raw, s).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np


@dataclass(frozen=True)
class Column:
    """One recorded variable. ``dims[0]`` is its stream's time dimension; ``dtype`` a numpy
    code (``f8``, ``i2``, ``i8``, ``bool``) or ``str``; ``source`` the sample's attribute (or
    method, called) that holds it, by default ``name``."""

    name: str
    dims: tuple[str, ...]
    dtype: str
    units: str
    long_name: str
    source: str | None = None

    def values(self, samples) -> np.ndarray:
        """This column of ``samples`` as one array, (N, ...) in :attr:`dtype` (integer counts
        beyond the dtype's range, only in corrupted frames, are clipped)."""
        attr = self.source or self.name
        raw = [getattr(s, attr) for s in samples]
        if raw and callable(raw[0]):
            raw = [r() for r in raw]
        if self.dtype == "str":
            return np.array(raw, dtype=object)
        return as_dtype(raw, self.dtype)


@dataclass(frozen=True)
class Coord:
    """The fixed values of a non-time dimension (``finger``, ``taxel``, ``axis6``...)."""

    name: str
    values: tuple
    units: str
    long_name: str


@dataclass(frozen=True)
class Stream:
    """What one device stream records.

    Attributes:
        name: the store block (``arm``); also the recorder's stream name.
        group: the store group holding it (``pour`` holds ``pump`` and ``scale``).
        time: its time coordinate, the block's append dimension (``time_arm``).
        what: what one sample is, for long names (``"arm state"``).
        device_time: the column of the device's own timestamp.
        host_time: the name of the host-receipt-time column.
        rate_hz: nominal sample rate (sizes the chunks only).
        columns: the data columns.
        coords: the fixed coordinates of the columns' other dimensions.
        host_time: the name of the host-receipt-time column.
        source: the recorder source it is derived from, if not its own (:attr:`source_name`).
        rows: ``rows(samples, previous_device_time) -> {column: array}`` where one sample is not
            one row (the PAC samples of a BioTac frame); by default :meth:`to_columns`.
    """

    name: str
    group: str
    time: str
    what: str
    device_time: Column
    rate_hz: float
    columns: tuple[Column, ...]
    coords: tuple[Coord, ...] = ()
    host_time: str = "host_time"
    source: str = ""
    rows: Callable | None = None

    @property
    def source_name(self) -> str:
        """The recorder source whose samples fill this stream (its own name unless a stream
        is derived from another's samples, as ``biotac_pac`` from ``biotac``)."""
        return self.source or self.name

    @property
    def time_columns(self) -> tuple[Column, ...]:
        """The time coordinate, the device time and the host time (raw columns first read)."""
        T = (self.time,)
        return (Column(self.time, T, "f8", "s", f"{self.what} time since run start (clock model of the device time)"),
                self.device_time,
                Column(self.host_time, T, "f8", "s", f"host receipt time of the {self.what} sample since run start",
                       source="host_time"))

    @property
    def all_columns(self) -> tuple[Column, ...]:
        return self.time_columns + self.columns

    def to_columns(self, samples, previous: float | None = None) -> dict[str, np.ndarray]:
        """``samples`` → {column: (N, ...) array}: the raw device and host times and every
        data column (the time coordinate is the recorder's, from the clock model).
        ``previous``: the device time of the stream's last row before these (for :attr:`rows`)."""
        if self.rows is not None:
            return self.rows(samples, previous)
        return {c.name: c.values(samples) for c in (self.device_time, self.time_columns[2], *self.columns)}


def as_dtype(values, dtype) -> np.ndarray:
    """``values`` as an array of ``dtype``; integers beyond a narrow integer dtype's range
    (counts of a corrupted frame, flagged invalid) are clipped rather than wrapped."""
    dtype = np.dtype(dtype)
    if dtype.kind == "i" and dtype.itemsize < 8:
        info = np.iinfo(dtype)
        return np.clip(np.asarray(values), info.min, info.max).astype(dtype)
    return np.asarray(values, dtype=dtype)


def device_time(name: str, time: str, long_name: str, source: str = "device_time") -> Column:
    """The device-timestamp column ``name`` of a stream whose time coordinate is ``time``,
    read from the samples' ``source`` attribute."""
    return Column(name, (time,), "f8", "s", long_name, source=source)

"""Read BioTac CSV files: one row per frame, one column per channel.

Columns (header row required; names case-insensitive, surrounding spaces ignored):

- one sensor: ``e1`` … ``e24`` and optionally ``pdc``, ``tdc``, ``tac`` (the finger is the
  import option ``fingers=[x]``, default ``ff``);
- several sensors: ``<finger>_e1`` … ``<finger>_e24`` and optionally ``<finger>_pdc``,
  ``<finger>_tdc``, ``<finger>_tac`` for fingers of ff, mf, rf, lf, th; an optional channel
  must then be there for every finger or for none;
- optionally ``time`` (s, any origin, strictly increasing).

Anything else is an error naming the columns at fault, as is an incomplete electrode set.
Values are raw 12-bit counts (non-integers are rounded). The sample rate is the ``time``
column's, or ``rate_hz`` when there is none; both given must agree within 2 %
(:data:`.recording.RATE_TOLERANCE`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hardware.biotac import FINGERS, N_TAXELS

from .recording import ImportInputError, Recording, check_rate, parse_rate

CHANNELS = ("pdc", "tdc", "tac")
_PREFIXED = re.compile(r"^(?P<finger>[a-z]+)_(?P<chan>e\d+|pdc|tdc|tac)$")


@dataclass(frozen=True)
class ColumnMap:
    """Where each channel is in the file's columns.

    Attributes:
        fingers: the fingers, Shadow order.
        electrodes: (F, 24) column indices of taxels 1..24.
        channels: ``{"pdc": (F,) indices, ...}`` for the optional channels present.
        time: index of the ``time`` column or ``None``.
        prefixed: whether columns are named ``<finger>_...``.
    """

    fingers: tuple[str, ...]
    electrodes: np.ndarray
    channels: dict
    time: int | None
    prefixed: bool


def is_csv(path: Path) -> bool:
    return Path(path).is_file() and Path(path).suffix.lower() == ".csv"


def electrode_names(prefix: str = "") -> list[str]:
    """``e1``…``e24`` (or ``<prefix>_e1``…)."""
    p = f"{prefix}_" if prefix else ""
    return [f"{p}e{i}" for i in range(1, N_TAXELS + 1)]


def map_columns(header: list[str], finger: str = "ff", where: str = "CSV") -> ColumnMap:
    """Check the header and say where every channel is.

    Args:
        header: the column names as in the file.
        finger: the finger of an unprefixed (single-sensor) file.
        where: the file, for messages.
    Raises :class:`ImportInputError` naming missing, unknown, duplicated or mixed columns.
    """
    names = [h.strip().lower() for h in header]
    dups = sorted({n for n in names if names.count(n) > 1})
    if dups:
        raise ImportInputError(f"{where}: duplicated columns: {', '.join(dups)}")
    pos = {n: i for i, n in enumerate(names)}
    flat = set(electrode_names()) | set(CHANNELS)
    per_finger: dict[str, set[str]] = {}
    extra = []
    for n in names:
        m = _PREFIXED.match(n)
        if n == "time" or n in flat:
            continue
        if m and m["finger"] in FINGERS and (m["chan"] in CHANNELS or m["chan"] in electrode_names()):
            per_finger.setdefault(m["finger"], set()).add(m["chan"])
        else:
            extra.append(n)
    unprefixed = [n for n in names if n in flat]
    if unprefixed and per_finger:
        raise ImportInputError(f"{where}: mixes unprefixed columns ({', '.join(unprefixed[:4])}...) with per-finger "
                               f"columns ({', '.join(sorted(per_finger))}); use one naming for the whole file")
    if extra:
        raise ImportInputError(f"{where}: unexpected columns: {', '.join(extra)} (expected e1..e24 or "
                               f"<finger>_e1..<finger>_e24, optional pdc, tdc, tac, time)")
    if not unprefixed and not per_finger:
        raise ImportInputError(f"{where}: no electrode columns (expected e1..e24 or <finger>_e1..<finger>_e24)")
    if unprefixed:
        if finger not in FINGERS:
            raise ImportInputError(f"finger={finger!r}: expected one of {', '.join(FINGERS)}")
        fingers, prefixes = (finger,), [""]
    else:
        fingers = tuple(f for f in FINGERS if f in per_finger)
        prefixes = list(fingers)
    missing = [n for p in prefixes for n in electrode_names(p) if n not in pos]
    if missing:
        raise ImportInputError(f"{where}: missing columns: {', '.join(missing)}")
    channels = {}
    for c in CHANNELS:
        cols = [f"{p}_{c}" if p else c for p in prefixes]
        have = [n for n in cols if n in pos]
        if have and len(have) < len(cols):
            raise ImportInputError(f"{where}: missing columns: {', '.join(n for n in cols if n not in pos)} "
                                   f"({c} is given for some fingers only)")
        if have:
            channels[c] = np.array([pos[n] for n in cols])
    elec = np.array([[pos[n] for n in electrode_names(p)] for p in prefixes])
    return ColumnMap(fingers, elec, channels, pos.get("time"), bool(per_finger))


def frame_times(time_col: np.ndarray | None, rate_hz: float | None, n: int, where: str = "CSV") -> tuple[np.ndarray, float]:
    """Device time (N,) s of each row and the sample rate (Hz).

    From the ``time`` column when there is one (checked strictly increasing; ``rate_hz``, if
    given, must agree with its median interval: :func:`.recording.check_rate`), else
    ``index / rate_hz``. Raises :class:`ImportInputError` for a missing, non-positive or
    disagreeing rate.
    """
    rate_hz = parse_rate(rate_hz)
    if time_col is None:
        if rate_hz is None:
            raise ImportInputError(f"{where}: no time column, so the sample rate must be given: rate_hz=...")
        return np.arange(n) / rate_hz, rate_hz
    t = np.asarray(time_col, float)
    dt = np.diff(t)
    bad = np.flatnonzero(~(dt > 0))
    if bad.size:
        i = int(bad[0]) + 1
        raise ImportInputError(f"{where}: the time column does not increase at data row {i + 1} "
                               f"({t[i - 1]:g} then {t[i]:g} s)")
    measured = float(1.0 / np.median(dt))
    check_rate(measured, rate_hz, f"{where}: time column")
    return t, measured


def read_csv(path, rate_hz: float | None = None, finger: str = "ff") -> Recording:
    """The CSV file at ``path`` as a :class:`Recording` (``host_time`` ``None``, ``seq`` = row
    index, no PAC). See the module docstring for the columns. Raises
    :class:`ImportInputError` (one sentence naming the file) on any problem."""
    path = Path(path)
    where = str(path)
    try:
        with open(path, newline="", encoding="utf-8-sig") as f:
            first = f.readline()
    except (OSError, UnicodeDecodeError) as exc:
        raise ImportInputError(f"{where}: cannot be read ({type(exc).__name__}: {exc})") from None
    if not first.strip():
        raise ImportInputError(f"{where}: empty file (expected a header row of column names)")
    delim = max((",", ";", "\t"), key=first.count)
    header = first.rstrip("\r\n").split(delim)
    cols = map_columns(header, finger, where)
    try:
        data = np.loadtxt(path, delimiter=delim, skiprows=1, ndmin=2, dtype=float, encoding="utf-8-sig")
    except ValueError as exc:
        raise ImportInputError(f"{where}: not all values are numbers ({str(exc).splitlines()[0]})") from None
    if data.shape[0] < 2:
        raise ImportInputError(f"{where}: {data.shape[0]} data row(s); need at least 2")
    if data.shape[1] != len(header):
        raise ImportInputError(f"{where}: {data.shape[1]} values per row but {len(header)} columns in the header")
    finite = np.isfinite(data)
    if not finite.all():
        r, c = np.argwhere(~finite)[0]
        raise ImportInputError(f"{where}: value {data[r, c]} in column {header[c].strip()} at data row {r + 1}")
    time_col = data[:, cols.time] if cols.time is not None else None
    device_time, rate = frame_times(time_col, rate_hz, len(data), where)
    counts = np.rint(data).astype(np.int64)
    used = np.concatenate([cols.electrodes.ravel(), *(i for i in cols.channels.values())])
    meta = {"format": "csv", "path": str(path), "columns": [h.strip() for h in header],
            "naming": "per-finger" if cols.prefixed else f"unprefixed (finger={cols.fingers[0]})",
            "rows": int(len(data)), "rate_hz": rate,
            "rate_source": "time column" if time_col is not None else "rate_hz",
            "seq_source": "row index", "host_time": "not recorded (NaN)",
            "rounded_to_integer_counts": bool(np.any(counts[:, used] != data[:, used]))}
    chan = {c: counts[:, idx] for c, idx in cols.channels.items()}
    return Recording(fingers=cols.fingers, seq=np.arange(len(data), dtype=np.int64), device_time=device_time,
                     host_time=None, electrodes=counts[:, cols.electrodes], pdc=chan.get("pdc"),
                     tdc=chan.get("tdc"), tac=chan.get("tac"), pac=None, meta=meta)

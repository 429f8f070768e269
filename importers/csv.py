"""Read BioTac CSV files: one row per frame, one column per channel — streamed, checked cell by cell.

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

:class:`CsvFile` reads the rows in chunks of :data:`.recording.CHUNK_FRAMES` (memory does not
grow with the file) and refuses the first bad row with its line number (the header is line
1) and column: a blank line before the last row, a row of binary data, a row with the wrong
number of cells, a cell that is not a number, NaN or infinity, a count outside the int16
range (−32768..32767; counts outside 0..4095 but within it are stored and flagged
``valid = False``, as the recorder does), a ``time`` that does not increase, a line longer
than :func:`max_line_chars`. Blank lines after the last row are ignored.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Iterator

import numpy as np

from tactile_flow.hardware.biotac import FINGERS, N_TAXELS

from tactile_flow.hardware.errors import brief

from .recording import CHUNK_FRAMES, ImportInputError, Recording, check_rate, concat, parse_rate

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


# ----------------------------------------------------------------------------- rows
_I16 = np.iinfo(np.int16)
#: a number as numpy reads it (decimal, exponent, nan, inf); anything else in a cell is refused
_NUMBER = re.compile(r"[+-]?(?:(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?|nan|inf|infinity)", re.IGNORECASE)
#: control characters and undecodable bytes (decoded as lone surrogates): a binary line
_BINARY = re.compile("[\x00-\x08\x0b-\x1f\x7f\udc80-\udcff]")
HEADER_MAX_CHARS = 1 << 16


def max_line_chars(n_columns: int) -> int:
    """Longest data line accepted (characters): 64 per column plus 1024, far above any row of
    numbers, so one line of junk cannot take the memory of a whole file."""
    return 64 * n_columns + 1024


def show_cell(text: str, limit: int = 32) -> str:
    """A cell (or line) for a message: quoted, escapes for bytes that are not printable ASCII,
    cut to ``limit`` bytes."""
    raw = text.encode("utf-8", "surrogateescape")
    return repr(raw[:limit])[1:] + ("..." if len(raw) > limit else "")


def line_batches(f, rows: int, max_chars: int, where: str, first_line: int = 2) -> Iterator[tuple[int, list[str]]]:
    """The data lines of an open text file, in batches of at most ``rows`` lines.

    Yields ``(line number of the batch's first line, lines)``; the lines of a batch are
    consecutive. Blank lines after the last data line are dropped; a blank line followed by
    more data, or a line longer than ``max_chars``, is an :class:`ImportInputError`.
    """
    batch: list[str] = []
    start = n = first_line
    blank = None                               # first line of the current run of blank lines
    while line := f.readline(max_chars + 1):
        if len(line) > max_chars and not line.endswith("\n"):
            raise ImportInputError(f"{where} line {n}: longer than {max_chars} characters "
                                   f"(starts {show_cell(line)}); expected a row of numbers")
        if line.isspace():
            blank = n if blank is None else blank
        else:
            if blank is not None:
                raise ImportInputError(f"{where} line {blank}: blank line before more rows (line {n}); blank "
                                       f"lines are allowed only after the last row")
            if not batch:
                start = n
            batch.append(line)
            if len(batch) == rows:
                yield start, batch
                batch = []
        n += 1
    if batch:
        yield start, batch


def diagnose_rows(lines: list[str], first_line: int, header: list[str], delim: str, where: str) -> None:
    """Raise the :class:`ImportInputError` of the first bad line of ``lines`` (binary data,
    wrong number of cells, a cell that is not a number); return if every line is well formed."""
    for k, line in enumerate(lines):
        no, text = first_line + k, line.rstrip("\r\n")
        if _BINARY.search(text):
            raise ImportInputError(f"{where} line {no}: binary data ({show_cell(text)}), not a row of numbers")
        cells = text.split(delim)
        if len(cells) != len(header):
            raise ImportInputError(f"{where} line {no}: {len(cells)} cells, expected {len(header)} "
                                   f"(one per column of the header)")
        for name, cell in zip(header, cells):
            if not _NUMBER.fullmatch(cell.strip()):
                raise ImportInputError(f"{where} line {no}, column {name.strip()}: {show_cell(cell)} is not a number")


def parse_rows(lines: list[str], first_line: int, header: list[str], delim: str, where: str) -> np.ndarray:
    """(n, C) float values of ``n`` data lines of ``C`` cells (numpy's parser; on any error the
    first bad line is found and named by :func:`diagnose_rows`)."""
    try:
        data = np.loadtxt(lines, delimiter=delim, dtype=float, ndmin=2, comments=None, quotechar=None)
    except ValueError as exc:
        diagnose_rows(lines, first_line, header, delim, where)
        raise ImportInputError(f"{where} lines {first_line}-{first_line + len(lines) - 1}: not all values are "
                               f"numbers ({str(exc).splitlines()[0]})") from None
    if data.shape[1] != len(header):
        diagnose_rows(lines, first_line, header, delim, where)
    return data


def check_values(data: np.ndarray, first_line: int, header: list[str], counts: np.ndarray, where: str) -> None:
    """Refuse the first (in file order) value of ``data`` (n, C) that is NaN or infinite, or,
    in a ``counts`` column (indices), outside the int16 range once rounded."""
    bad = ~np.isfinite(data)
    rounded = np.rint(data[:, counts])
    bad[:, counts] |= (rounded < _I16.min) | (rounded > _I16.max)
    if not bad.any():
        return
    r, c = (int(i) for i in np.argwhere(bad)[0])
    v, where_cell = data[r, c], f"{where} line {first_line + r}, column {header[c].strip()}"
    if not np.isfinite(v):
        raise ImportInputError(f"{where_cell}: {v} is not a finite number")
    raise ImportInputError(f"{where_cell}: {v:g} is outside the range of a count (int16, "
                           f"{_I16.min}..{_I16.max}; BioTac counts are 0..4095)")


def check_increasing(t: np.ndarray, previous: float | None, first_line: int, where: str) -> None:
    """Refuse the first time (s) of ``t`` (n,) not above the one before it (``previous``: the
    last time of the preceding lines, or ``None``)."""
    full = t if previous is None else np.r_[previous, t]
    bad = np.flatnonzero(~(np.diff(full) > 0))
    if bad.size:
        j = int(bad[0])
        i = j if previous is not None else j + 1                    # index in t
        raise ImportInputError(f"{where} line {first_line + i}, column time: {full[j + 1]:g} s does not increase "
                               f"on the line before ({full[j]:g} s); the time column must be strictly increasing")


#: the largest step of a ``time`` column (s): a recording does not pause for an hour; a step
#: longer than that is a broken clock or a corrupt cell, and the file is refused
MAX_TIME_STEP_S = 3600.0
#: a step this many times the chunk's median step is a gap: kept, and said (``import.reader.time_gaps``,
#: a warning on the output line)
GAP_FACTOR = 10.0


def check_steps(t: np.ndarray, previous: float | None, first_line: int, where: str) -> list[tuple[int, float]]:
    """Refuse the first step of ``t`` (n,) s longer than :data:`MAX_TIME_STEP_S`; return
    ``(line, step s)`` of every step longer than :data:`GAP_FACTOR` × the median step."""
    full = t if previous is None else np.r_[previous, t]
    steps = np.diff(full)
    if not steps.size:
        return []
    offset = 1 if previous is None else 0                    # line of steps[j] = first_line + j + offset
    huge = np.flatnonzero(steps > MAX_TIME_STEP_S)
    if huge.size:
        j = int(huge[0])
        raise ImportInputError(f"{where} line {first_line + j + offset}, column time: {brief(full[j + 1])} s is "
                               f"{brief(steps[j])} s after the line before, more than {MAX_TIME_STEP_S:g} s; "
                               f"a time column must not jump (a broken clock or a corrupt cell?)")
    gaps = np.flatnonzero(steps > GAP_FACTOR * np.median(steps))
    return [(first_line + int(j) + offset, float(steps[j])) for j in gaps]


class CsvFile:
    """A BioTac CSV file read in chunks (the :class:`.recording.Reader` protocol).

    Opening reads and checks the header and the rate (``rate_hz`` needed without a ``time``
    column); :meth:`chunks` reads and checks the rows. ``host_time`` is ``None``, ``seq`` the
    row index, no PAC. :class:`ImportInputError` (one sentence naming the file, and the line
    and column when a row is at fault) on any problem.
    """

    def __init__(self, path, rate_hz: float | None = None, finger: str = "ff"):
        self.path = Path(path)
        self.where = where = str(self.path)
        try:
            with self._open() as f:
                first = f.readline(HEADER_MAX_CHARS + 1)
        except OSError as exc:
            raise ImportInputError(f"{where}: cannot be read ({type(exc).__name__}: {exc})") from None
        if len(first) > HEADER_MAX_CHARS:
            raise ImportInputError(f"{where} line 1: longer than {HEADER_MAX_CHARS} characters; expected a "
                                   f"header row of column names")
        if not first.strip():
            raise ImportInputError(f"{where}: empty file (expected a header row of column names)")
        if _BINARY.search(first.rstrip("\r\n")):
            raise ImportInputError(f"{where} line 1: binary data ({show_cell(first)}), expected a header row "
                                   f"of column names")
        self.delim = max((",", ";", "\t"), key=first.count)
        self.header = first.rstrip("\r\n").split(self.delim)
        self.cols = cols = map_columns(self.header, finger, where)
        self.rate_hz = parse_rate(rate_hz)
        if cols.time is None and self.rate_hz is None:
            raise ImportInputError(f"{where}: no time column, so the sample rate must be given: rate_hz=...")
        self.finger_names = cols.fingers
        self.counts = np.concatenate([cols.electrodes.ravel(), *(i for i in cols.channels.values())])
        self.meta = {"format": "csv", "path": where, "columns": [h.strip() for h in self.header],
                     "naming": "per-finger" if cols.prefixed else f"unprefixed (finger={cols.fingers[0]})",
                     "rows": None, "rate_hz": self.rate_hz if cols.time is None else None,
                     "rate_source": "time column" if cols.time is not None else "rate_hz",
                     "seq_source": "row index", "host_time": "not recorded (NaN)",
                     "rounded_to_integer_counts": False}

    def _open(self):
        # undecodable bytes become lone surrogates, reported as binary data with their line
        return open(self.path, newline=None, encoding="utf-8-sig", errors="surrogateescape")

    def chunks(self, frames: int = CHUNK_FRAMES) -> Iterator[Recording]:
        """Every row, checked, as :class:`Recording` chunks of at most ``frames`` rows."""
        cols, where = self.cols, self.where
        rows, last_t, rounded, gaps = 0, None, False, []
        with self._open() as f:
            f.readline(HEADER_MAX_CHARS + 1)
            for first, lines in line_batches(f, frames, max_line_chars(len(self.header)), where):
                data = parse_rows(lines, first, self.header, self.delim, where)
                check_values(data, first, self.header, self.counts, where)
                n = len(data)
                if cols.time is not None:
                    t = data[:, cols.time].copy()
                    check_increasing(t, last_t, first, where)
                    gaps += check_steps(t, last_t, first, where)
                    last_t = float(t[-1])
                else:
                    t = np.arange(rows, rows + n) / self.rate_hz
                counts = np.zeros(data.shape, np.int64)
                counts[:, self.counts] = np.rint(data[:, self.counts])
                rounded = rounded or bool(np.any(counts[:, self.counts] != data[:, self.counts]))
                chan = {c: counts[:, idx] for c, idx in cols.channels.items()}
                yield Recording(fingers=cols.fingers, seq=np.arange(rows, rows + n, dtype=np.int64), device_time=t,
                                host_time=None, electrodes=counts[:, cols.electrodes], pdc=chan.get("pdc"),
                                tdc=chan.get("tdc"), tac=chan.get("tac"), pac=None, meta=self.meta)
                rows += n
        if rows < 2:
            raise ImportInputError(f"{where}: {rows} data row(s); need at least 2")
        self.meta.update(rows=rows, rounded_to_integer_counts=rounded)
        if gaps:
            line, step = max(gaps, key=lambda g: g[1])
            self.meta["time_gaps"] = {"count": len(gaps), "largest_s": step, "at_line": line,
                                      "rule": f"a step of the time column over {GAP_FACTOR:g} x the median step"}

    def finish(self, rate_hz: float) -> None:
        """With a ``time`` column: check a given ``rate_hz`` against the measured rate (Hz, from the
        median interval) and record it."""
        if self.cols.time is not None:
            check_rate(rate_hz, self.rate_hz, f"{self.where}: time column")
            self.meta["rate_hz"] = rate_hz


def read_csv(path, rate_hz: float | None = None, finger: str = "ff") -> Recording:
    """The whole CSV file at ``path`` as one :class:`Recording` (in memory: for small files and
    tests; the import streams it with :class:`CsvFile`). See the module docstring."""
    reader = CsvFile(path, rate_hz, finger)
    rec = concat(reader.chunks())
    reader.finish(rec.nominal_rate_hz())
    return replace(rec, meta=dict(reader.meta))

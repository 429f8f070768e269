"""Read tactile CSV files: one row per frame, one column per channel — streamed, checked cell by cell.

Columns (header row required; names case-insensitive, surrounding spaces ignored), in the
layouts labs publish:

- electrodes: ``e1`` … ``eN``, ``ele1`` …, ``electrode_1`` …, ``E01`` … (``e``, ``ele``,
  ``elec``, ``electrode``, ``taxel``; a number 1..N, zero-padded or not; ``_``, ``-``, ``.`` or
  nothing between), or the sensor model's taxel names (``T1`` …); N is the number of
  electrodes, the same for every finger, and chooses the sensor model when it is not given
  (``sensor=``, :func:`tactile.sensor.sensor_for_taxels`): 19 → the classic BioTac, 24 → the
  BioTac SP;
- one sensor: those names, and optionally ``pdc``, ``tdc``, ``tac`` (the finger is the import
  option ``fingers=[x]``, default ``ff``); several sensors: the same names prefixed by the
  finger, ``<finger>_e1`` … (``ff``, ``mf``, ``rf``, ``lf``, ``th``; ``_``, ``-``, ``.`` or
  nothing after it); an optional channel must then be there for every finger or for none;
- optionally PAC as K samples per frame, ``pac1`` … ``pacK`` (or ``<finger>_pac1`` …): stored on
  its own time axis at the sensor model's vibration rate, the frame's K samples ending at its
  time (as a recorder stores the Shadow driver's batches);
- optionally a time column: ``time``, ``t``, ``timestamp``, ``stamp`` or ``ts``, in seconds,
  or ``time_ms``, ``time_us``, ``time_ns`` (also ``time (ns)``), any origin, strictly
  increasing. Its unit is the one its name says, or ``time_unit=s|ms|us|ns``, or guessed from
  its steps (the unit that makes the median frame interval a plausible frame rate,
  1 Hz – 10 kHz, nearest to 100 Hz; the guess is in ``meta["time_unit"]`` and said on the
  import's output line).

``columns={name: canonical}`` renames columns first (``columns={timestamp_us: time_us,
BT_1: e1}``), for names no convention covers. Anything else is an error naming the columns at
fault, as is an incomplete electrode set. Values are raw counts (non-integers are rounded),
or, with ``relative=true`` (or ``auto``: detected when the first rows' median electrode value
is below :data:`RELATIVE_BELOW` counts, which no connected BioTac reads at rest), counts relative to each electrode's rest: stored as ``rest + value`` with ``rest``
the calibration's counts (``calibration=``) or ``relative_rest_counts`` (default 2500, a
typical BioTac rest count), and that rest stored as the baseline. The sample rate is the time
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

from tactile_flow.hardware.biotac import FINGERS
from tactile_flow.hardware.errors import RATE_RANGE_HZ, brief

from .recording import CHUNK_FRAMES, ImportInputError, Recording, check_rate, concat, parse_rate

CHANNELS = ("pdc", "tdc", "tac")
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}
RELATIVE_BELOW = 400.0
"""Electrode values whose median over the first rows is below this (counts) are relative to
rest (``relative=auto``): a connected BioTac reads ~1000–3500 at rest."""
RELATIVE_REST_COUNTS = 2500.0
_SEP = r"[_\-. ]?"
_FINGER = r"(?:(?P<finger>" + "|".join(FINGERS) + r")" + _SEP + r")?"
_ELECTRODE = re.compile(r"^" + _FINGER + r"(?P<stem>e|el|ele|elec|electrode|taxel)" + _SEP + r"(?P<i>\d+)$")
_PAC = re.compile(r"^" + _FINGER + r"pac" + _SEP + r"(?P<i>\d+)$")
_CHANNEL = re.compile(r"^" + _FINGER + r"(?P<chan>pdc|tdc|tac)$")
_TIME = re.compile(r"^(?:time|t|timestamp|stamp|ts)(?:" + _SEP + r"(?P<unit>s|sec|ms|us|ns)|\s*\((?P<unit2>s|ms|us|ns)\))?$")


@dataclass(frozen=True)
class ColumnMap:
    """Where each channel is in the file's columns.

    Attributes:
        fingers: the fingers, Shadow order.
        electrodes: (F, N) column indices of electrodes 1..N.
        channels: ``{"pdc": (F,) indices, ...}`` for the optional channels present.
        pac: (F, K) column indices of the K PAC samples per frame, or ``None``.
        time: index of the time column or ``None``; ``time_unit``: the unit its name says, or ``None``.
        prefixed: whether columns are named ``<finger>_...``.
        naming: how the electrode columns are named (``e<i>``, ``ele<i>``, ...), for messages.
    """

    fingers: tuple[str, ...]
    electrodes: np.ndarray
    channels: dict
    time: int | None
    prefixed: bool
    pac: np.ndarray | None = None
    time_unit: str | None = None
    naming: str = "e<i>"

    @property
    def n_electrodes(self) -> int:
        return int(self.electrodes.shape[1])


def is_csv(path: Path) -> bool:
    return Path(path).is_file() and Path(path).suffix.lower() == ".csv"


def electrode_names(prefix: str = "", n: int = 24) -> list[str]:
    """``e1``…``eN`` (or ``<prefix>_e1``…)."""
    p = f"{prefix}_" if prefix else ""
    return [f"{p}e{i}" for i in range(1, n + 1)]


def _classify(name: str, taxel_names: dict):
    """``(finger or "", kind, index)`` of a (lower-case) column name: kind ``time`` (index: the
    unit its name says, or None), ``e`` (index 1..), ``pac`` (index 1..), ``pdc``/``tdc``/``tac``;
    ``None`` if it is none of them."""
    m = _TIME.match(name)
    if m:
        unit = m["unit"] or m["unit2"]
        return "", "time", {"sec": "s"}.get(unit, unit)
    for pattern in (_ELECTRODE, _PAC, _CHANNEL):
        m = pattern.match(name)
        if m:
            finger = m["finger"] or ""
            if finger and finger not in FINGERS:
                return None
            if pattern is _CHANNEL:
                return finger, m["chan"], None
            return finger, "pac" if pattern is _PAC else "e", int(m["i"])
    base = name
    for f in FINGERS:
        for sep in ("_", "-", ".", " ", ""):
            if name.startswith(f + sep) and name[len(f) + len(sep):] in taxel_names:
                return f, "e", taxel_names[name[len(f) + len(sep):]]
    if base in taxel_names:
        return "", "e", taxel_names[base]
    return None


def map_columns(header: list[str], finger: str = "ff", where: str = "CSV", *, sensor=None,
                columns: dict | None = None) -> ColumnMap:
    """Check the header and say where every channel is (module docstring: the conventions).

    Args:
        header: the column names as in the file.
        finger: the finger of an unprefixed (single-sensor) file.
        where: the file, for messages.
        sensor: the :class:`tactile.sensor.SensorModel` asked for (its taxel names are
            recognised too, and its electrode count is expected), or ``None``.
        columns: renames applied first, ``{name in the file: canonical name}``.
    Raises :class:`ImportInputError` naming missing, unknown, duplicated or mixed columns.
    """
    rename = {str(k).strip().lower(): str(v).strip().lower() for k, v in (columns or {}).items()}
    raw = [h.strip().lower() for h in header]
    unused = sorted(set(rename) - set(raw))
    if unused:
        raise ImportInputError(f"{where}: columns={{{unused[0]}: ...}}: the file has no column {unused[0]!r} "
                               f"(it has {', '.join(raw[:8])}{', ...' if len(raw) > 8 else ''})")
    names = [rename.get(n, n) for n in raw]
    dups = sorted({n for n in names if names.count(n) > 1})
    if dups:
        raise ImportInputError(f"{where}: duplicated columns: {', '.join(dups)}")
    taxel_names = {} if sensor is None else {n.lower(): i + 1 for i, n in enumerate(sensor.taxel_names)}
    found: dict[str, dict] = {}                              # finger ("" unprefixed) -> {(kind, i): column}
    time, time_unit, extra, stems = None, None, [], {}
    for col, n in enumerate(names):
        c = _classify(n, taxel_names)
        if c is None:
            extra.append(header[col].strip())
            continue
        f, kind, i = c
        if kind == "time":
            if time is not None:
                raise ImportInputError(f"{where}: two time columns: {header[time].strip()}, {header[col].strip()}")
            time, time_unit = col, i
            continue
        key = (kind, i)
        if key in found.setdefault(f, {}):
            raise ImportInputError(f"{where}: columns {header[found[f][key]].strip()} and {header[col].strip()} "
                                   f"are the same channel ({(f + '_') if f else ''}{kind}{i or ''})")
        found[f][key] = col
        if kind == "e":
            m = _ELECTRODE.match(n)
            stems[f] = (m["stem"], m["i"]) if m else None
    if "" in found and len(found) > 1:
        unprefixed = sorted(header[c].strip() for c in found[""].values())
        raise ImportInputError(f"{where}: mixes unprefixed columns ({', '.join(unprefixed[:4])}...) with per-finger "
                               f"columns ({', '.join(sorted(f for f in found if f))}); use one naming for the "
                               f"whole file")
    if extra:
        raise ImportInputError(f"{where}: unexpected columns: {', '.join(extra)} (expected electrodes e1..eN, "
                               f"ele1.., electrode_1.. or <finger>_e1..; optional pdc, tdc, tac, pac1..pacK, time; "
                               f"or rename them with columns={{name: e1, ...}})")
    if not any(k == "e" for f in found.values() for k, _ in f):
        raise ImportInputError(f"{where}: no electrode columns (expected e1..eN, ele1..eleN, electrode_1.. or "
                               f"<finger>_e1..)")
    if "" in found:
        if finger not in FINGERS:
            raise ImportInputError(f"finger={finger!r}: expected one of {', '.join(FINGERS)}")
        fingers, prefixes = (finger,), [""]
    else:
        fingers = tuple(f for f in FINGERS if f in found)
        prefixes = list(fingers)

    def name_of(p, kind, i):
        """A column's name as this file writes it (for messages)."""
        stem = stems.get(p)
        if kind == "e" and stem is not None:
            s_, digits = stem
            i = str(i).zfill(len(digits)) if digits.startswith("0") else i
            return f"{p + '_' if p else ''}{s_}{i}"
        return f"{p + '_' if p else ''}{kind}{i or ''}"

    counts = {p: max((i for k, i in found.get(p, {}) if k == "e"), default=0) for p in prefixes}
    n = sensor.n_taxels if sensor is not None else max(counts.values())
    over = [name_of(p, "e", i) for p in prefixes for k, i in found.get(p, {}) if k == "e" and i > n]
    if over:
        raise ImportInputError(f"{where}: electrode columns {', '.join(over[:4])} beyond the {n} electrodes of "
                               f"sensor={sensor.name}; expected {name_of(prefixes[0], 'e', 1)}.."
                               f"{name_of(prefixes[0], 'e', n)}")
    missing = [name_of(p, "e", i) for p in prefixes for i in range(1, n + 1) if ("e", i) not in found.get(p, {})]
    if missing:
        raise ImportInputError(f"{where}: missing columns: {', '.join(missing)}")
    channels = {}
    for c in CHANNELS:
        have = [p for p in prefixes if (c, None) in found.get(p, {})]
        if have and len(have) < len(prefixes):
            raise ImportInputError(f"{where}: missing columns: "
                                   f"{', '.join(name_of(p, c, None) for p in prefixes if p not in have)} "
                                   f"({c} is given for some fingers only)")
        if have:
            channels[c] = np.array([found[p][(c, None)] for p in prefixes])
    pac = None
    k_pac = {p: max((i for k, i in found.get(p, {}) if k == "pac"), default=0) for p in prefixes}
    if any(k_pac.values()):
        k = max(k_pac.values())
        missing = [name_of(p, "pac", i) for p in prefixes for i in range(1, k + 1) if ("pac", i) not in found[p]]
        if missing:
            raise ImportInputError(f"{where}: missing columns: {', '.join(missing[:6])} (PAC samples pac1..pac{k} "
                                   f"for every finger)")
        pac = np.array([[found[p][("pac", i)] for i in range(1, k + 1)] for p in prefixes])
    elec = np.array([[found[p][("e", i)] for i in range(1, n + 1)] for p in prefixes])
    stem = stems.get(prefixes[0])
    naming = f"{stem[0]}<i>" if stem else "taxel names"
    return ColumnMap(fingers, elec, channels, time, bool(prefixes[0]), pac, time_unit, naming)


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


def guess_time_unit(steps: np.ndarray) -> tuple[str, str]:
    """The unit of a time column from its steps (``(unit, why)``): of s, ms, us, ns, the one
    whose median step makes a frame rate within 1 Hz – 10 kHz, nearest to 100 Hz (log scale)."""
    step = float(np.median(steps))
    if not step > 0:
        return "s", "its steps are not positive: taken as seconds"
    lo, hi = max(RATE_RANGE_HZ[0], 1.0), min(RATE_RANGE_HZ[1], 1e4)
    fits = [(abs(np.log(1.0 / (step * f) / 100.0)), u) for u, f in TIME_UNITS.items() if lo <= 1.0 / (step * f) <= hi]
    if not fits:
        return "s", f"its median step {step:g} fits no unit: taken as seconds"
    unit = min(fits)[1]
    return unit, f"guessed from its median step {step:g} ({1.0 / (step * TIME_UNITS[unit]):.4g} Hz in {unit})"


class CsvFile:
    """A tactile CSV file read in chunks (the :class:`.recording.Reader` protocol).

    Opening reads and checks the header and the rate (``rate_hz`` needed without a time
    column); :meth:`chunks` reads and checks the rows. ``host_time`` is ``None``, ``seq`` the
    row index; PAC from ``pac1..pacK`` columns (else none). :class:`ImportInputError` (one
    sentence naming the file, and the line and column when a row is at fault) on any problem.

    Args:
        sensor: the :class:`tactile.sensor.SensorModel` asked for (``None``: chosen later from
            :attr:`n_taxels`); ``columns``: renames (module docstring); ``time_unit``:
            ``auto``, ``s``, ``ms``, ``us`` or ``ns``; ``relative``: ``auto``, True or False;
            ``rest_counts``: the rest counts relative values are added to (scalar, or (F, N)
            via :meth:`set_rest`).
    """

    def __init__(self, path, rate_hz: float | None = None, finger: str = "ff", *, sensor=None, columns=None,
                 time_unit: str = "auto", relative="auto", rest_counts: float = RELATIVE_REST_COUNTS):
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
        if time_unit not in ("auto", *TIME_UNITS):
            raise ImportInputError(f"time_unit={time_unit!r}: expected auto, {', '.join(TIME_UNITS)}")
        if relative not in ("auto", True, False):
            raise ImportInputError(f"relative={relative!r}: expected auto, true or false")
        self.delim = max((",", ";", "\t"), key=first.count)
        self.header = first.rstrip("\r\n").split(self.delim)
        self.cols = cols = map_columns(self.header, finger, where, sensor=sensor, columns=columns)
        self.rate_hz = parse_rate(rate_hz)
        if cols.time is None and self.rate_hz is None:
            raise ImportInputError(f"{where}: no time column, so the sample rate must be given: rate_hz=...")
        self.finger_names = cols.fingers
        self.n_taxels = cols.n_electrodes
        self.counts = np.concatenate([cols.electrodes.ravel(), *(i for i in cols.channels.values()),
                                      *([] if cols.pac is None else [cols.pac.ravel()])])
        self.pac_rate_hz = (float(sensor.vibration.rate_hz) if sensor is not None and sensor.vibration is not None
                            else 2200.0)
        self._unit = cols.time_unit or (None if time_unit == "auto" else time_unit)
        self._unit_why = ("the column's name" if cols.time_unit else f"time_unit={time_unit}") if self._unit else None
        self._relative = relative
        self.rest = np.asarray(rest_counts, float)
        self.meta = {"format": "csv", "path": where, "columns": [h.strip() for h in self.header],
                     "naming": "per-finger" if cols.prefixed else f"unprefixed (finger={cols.fingers[0]})",
                     "electrode_columns": cols.naming, "electrodes": self.n_taxels,
                     "rows": None, "rate_hz": self.rate_hz if cols.time is None else None,
                     "rate_source": "time column" if cols.time is not None else "rate_hz",
                     "seq_source": "row index", "host_time": "not recorded (NaN)",
                     "rounded_to_integer_counts": False}
        if columns:
            self.meta["renamed"] = {str(k): str(v) for k, v in columns.items()}
        if cols.pac is not None:
            self.meta["pac"] = f"{cols.pac.shape[1]} samples per frame (pac1..pac{cols.pac.shape[1]})"

    def set_rest(self, counts) -> None:
        """The rest counts (F, N) relative values are relative to (a calibration's)."""
        self.rest = np.asarray(counts, float)

    @property
    def relative(self) -> bool | None:
        """Whether the electrode values are relative to rest (None before the first rows are read
        with ``relative=auto``)."""
        return None if self._relative == "auto" else bool(self._relative)

    def _open(self):
        # undecodable bytes become lone surrogates, reported as binary data with their line
        return open(self.path, newline=None, encoding="utf-8-sig", errors="surrogateescape")

    def _decide(self, t_raw: np.ndarray | None, electrodes: np.ndarray) -> None:
        """On the first rows: the time unit and, with ``relative=auto``, whether values are relative."""
        if self._unit is None and t_raw is not None:
            if len(t_raw) < 2:
                raise ImportInputError(f"{self.where}: one data row; need at least 2")
            self._unit, self._unit_why = guess_time_unit(np.diff(t_raw))
        if self._relative == "auto":
            med = float(np.median(electrodes))
            self._relative = bool(med < RELATIVE_BELOW)
            self.meta["relative_detected"] = (f"electrode values {'relative to rest' if self._relative else 'raw counts'}"
                                              f" (first rows: median {med:g}, minimum {electrodes.min():g}; "
                                              f"relative below a median of {RELATIVE_BELOW:g})")
        if t_raw is not None:
            self.meta.update(time_unit=self._unit, time_unit_source=self._unit_why)

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
                counts = np.zeros(data.shape, np.int64)
                counts[:, self.counts] = np.rint(data[:, self.counts])
                rounded = rounded or bool(np.any(counts[:, self.counts] != data[:, self.counts]))
                electrodes = counts[:, cols.electrodes]
                if rows == 0:
                    self._decide(data[:, cols.time] if cols.time is not None else None, electrodes)
                if cols.time is not None:
                    t = data[:, cols.time] * TIME_UNITS[self._unit]
                    check_increasing(t, last_t, first, where)
                    gaps += check_steps(t, last_t, first, where)
                    last_t = float(t[-1])
                else:
                    t = np.arange(rows, rows + n) / self.rate_hz
                if self._relative:
                    electrodes = electrodes + np.rint(self.rest).astype(np.int64)
                chan = {c: counts[:, idx] for c, idx in cols.channels.items()}
                pac = None if cols.pac is None else list(counts[:, cols.pac])
                yield Recording(fingers=cols.fingers, seq=np.arange(rows, rows + n, dtype=np.int64), device_time=t,
                                host_time=None, electrodes=electrodes, pdc=chan.get("pdc"),
                                tdc=chan.get("tdc"), tac=chan.get("tac"), pac=pac, meta=self.meta)
                rows += n
        if rows < 2:
            raise ImportInputError(f"{where}: {rows} data row(s); need at least 2")
        self.meta.update(rows=rows, rounded_to_integer_counts=rounded)
        if self._relative:
            rest = self.rest
            self.meta["relative_to_rest"] = (f"stored as rest + value, rest = {float(rest):g} counts (nominal)"
                                             if rest.ndim == 0 else "stored as rest + value, rest = the calibration's "
                                                                    "counts")
        if gaps:
            line, step = max(gaps, key=lambda g: g[1])
            self.meta["time_gaps"] = {"count": len(gaps), "largest_s": step, "at_line": line,
                                      "rule": f"a step of the time column over {GAP_FACTOR:g} x the median step"}

    def finish(self, rate_hz: float) -> None:
        """With a time column: check a given ``rate_hz`` against the measured rate (Hz, from the
        median interval) and record it."""
        if self.cols.time is not None:
            check_rate(rate_hz, self.rate_hz, f"{self.where}: time column")
            self.meta["rate_hz"] = rate_hz


def read_csv(path, rate_hz: float | None = None, finger: str = "ff", **options) -> Recording:
    """The whole CSV file at ``path`` as one :class:`Recording` (in memory: for small files and
    tests; the import streams it with :class:`CsvFile`; ``options`` as :class:`CsvFile`'s)."""
    reader = CsvFile(path, rate_hz, finger, **options)
    rec = concat(reader.chunks())
    reader.finish(rec.nominal_rate_hz())
    return replace(rec, meta=dict(reader.meta))

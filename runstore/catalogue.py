"""The run catalogue: an SQLite index of run directories, searched by ``tactile-runs list``.

The run directories are the truth; the catalogue is an index that can always be rebuilt from
them (``tactile-runs index --rebuild``, and at once, with a message, when the file is found
corrupt). Each run is one row of ``runs`` (the fields every listing shows, and the whole flat
row of :func:`runstore.runinfo.summary` as JSON) and one row per key of ``kv`` (every config
key, override, headline and score number: ``num`` for numbers, ``text`` for the rest), so a
filter on any key is an indexed lookup. Runs, imports and analyses register themselves when
they close (:func:`register_quietly`: never fails the run that calls it).

Why SQLite (the standard library's ``sqlite3``) in WAL mode, not DuckDB: runs close in
several processes at once (a joblib sweep's workers, an import beside a sweep) and each
registers itself. DuckDB lets one process open a database for writing at a time (a second
one gets a lock error); SQLite in WAL mode lets readers go on while one writer commits and
queues writers behind a busy timeout, so no entry is lost; and it adds no dependency. The
queries here are point lookups on indexed keys, where SQLite is fast (``benchmarks/
bench_catalogue.py``: 10,000 runs, a filtered query in a few ms). WAL needs a local file
system (its shared memory): the default file is in the user's cache directory.

Where it lives: ``--catalogue FILE``, else ``$TACTILE_CATALOGUE``, else
``runs.sqlite`` in the tactile-flow cache directory (``$TACTILE_CACHE_DIR``, else
``$XDG_CACHE_HOME/tactile-flow``, else ``~/.cache/tactile-flow``): one catalogue per user
for every working directory the lab runs from, on a local disk.
"""

from __future__ import annotations

import csv
import io
import json
import os
import re
import sqlite3
import sys
import time
from contextlib import contextmanager
from pathlib import Path

from . import runinfo
from .runinfo import RunRecordError

SCHEMA = 1
ENV = "TACTILE_CATALOGUE"
BUSY_TIMEOUT_S = 30.0
#: the columns of ``runs`` a filter can name directly (else a key of ``kv``)
FIELDS = ("path", "run_id", "kind", "protocol", "surface", "status", "start_time", "end_time", "seed", "commit",
          "dirty", "host", "analysis", "sweep", "reproduces")
DEFAULT_COLUMNS = ("start_time", "protocol", "surface", "status", "params", "analysis", "targets", "commit", "path")
#: overrides that change how a run is shown, not what it does: left out of the params column
QUIET_PARAMS = ("progress", "analysis.progress", "verbose", "resume", "analyze", "analysis.figures")
SKIP_DIRS = {".hydra", "analyses", "config", "figures", "previous", "__pycache__", ".git"}
_FILTER = re.compile(r"^\s*([A-Za-z_][\w.\-/\[\]]*)\s*(>=|<=|!=|=|<|>|~)(.*)$")
OPERATORS = ("=", "!=", "<", "<=", ">", ">=", "~")


class CatalogueError(ValueError):
    """A catalogue that cannot be used (locked, unreadable), or a malformed filter."""


def default_path() -> Path:
    if os.environ.get(ENV):
        return Path(os.environ[ENV])
    from tactile_flow.tactile.disk_cache import default_cache_dir
    return default_cache_dir() / "runs.sqlite"


def _roots_of(run_dir: Path) -> Path:
    """The root a run lives under: its nearest ``outputs``/``multirun``/``imported`` ancestor,
    else the run directory itself (never a parent that may be a home directory): what
    ``index`` walks again to notice new, moved and deleted runs."""
    for parent in run_dir.parents:
        if parent.name in ("outputs", "multirun", "imported"):
            return parent
    return run_dir


def _value(v) -> tuple[float | None, str | None]:
    if isinstance(v, bool):
        return float(v), str(v).lower()
    if isinstance(v, (int, float)):
        return float(v), None
    if v is None:
        return None, None
    if isinstance(v, (list, dict)):
        return None, json.dumps(v, sort_keys=True)
    try:
        return float(v), str(v)
    except ValueError:
        return None, str(v)


class Catalogue:
    """An open catalogue (``Catalogue.open(path)``). ``rebuilt`` says why it was made again."""

    def __init__(self, path: Path, db: sqlite3.Connection, rebuilt: str | None = None):
        self.path, self.db, self.rebuilt = path, db, rebuilt

    # ------------------------------------------------------------------ opening
    @classmethod
    def open(cls, path=None, console=None) -> "Catalogue":
        """Open (or make) the catalogue at ``path`` (:func:`default_path`). A file that is not a
        catalogue, or a damaged one, is moved aside (``<file>.corrupt-<time>``) and made again
        from the run directories it knew (``<file>.roots``), with a line on ``console``."""
        path = Path(path) if path else default_path()
        console = console or (lambda line: print(line, file=sys.stderr))
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise CatalogueError(f"catalogue {path}: its directory cannot be made ({exc.strerror})") from None
        try:
            return cls(path, cls._connect(path))
        except sqlite3.OperationalError as exc:
            if "locked" in str(exc) or "busy" in str(exc):
                raise CatalogueError(f"catalogue {path} is locked by another process ({exc}); try again when "
                                     f"it is done") from None
            reason = str(exc)
        except sqlite3.DatabaseError as exc:
            reason = str(exc)
        aside = path.with_name(f"{path.name}.corrupt-{time.strftime('%Y%m%d-%H%M%S')}")
        for suffix in ("", "-wal", "-shm"):
            if Path(f"{path}{suffix}").exists():
                os.replace(f"{path}{suffix}", f"{aside}{suffix}")
        cat = cls(path, cls._connect(path), rebuilt=reason)
        roots = cat.known_roots()
        console(f"catalogue {path} was damaged ({reason}); moved to {aside.name} and rebuilt from the run "
                f"directories ({len(roots)} roots)")
        cat.index(roots or None, console=lambda *_: None)
        return cat

    @staticmethod
    def _connect(path: Path) -> sqlite3.Connection:
        db = sqlite3.connect(str(path), timeout=BUSY_TIMEOUT_S, isolation_level=None)
        db.execute(f"PRAGMA busy_timeout = {int(BUSY_TIMEOUT_S * 1000)}")
        mode = db.execute("PRAGMA journal_mode = WAL").fetchone()[0]
        if mode.lower() != "wal":
            db.execute("PRAGMA journal_mode = DELETE")
        db.execute("PRAGMA synchronous = NORMAL")
        db.executescript("""
            CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT);
            CREATE TABLE IF NOT EXISTS runs (
                path TEXT PRIMARY KEY, run_id TEXT, kind TEXT, protocol TEXT, surface TEXT, status TEXT,
                start_time TEXT, end_time TEXT, seed TEXT, "commit" TEXT, dirty TEXT, host TEXT, analysis TEXT,
                sweep TEXT, reproduces TEXT, mtime REAL, row TEXT);
            CREATE INDEX IF NOT EXISTS runs_start ON runs (start_time);
            CREATE INDEX IF NOT EXISTS runs_run_id ON runs (run_id);
            CREATE TABLE IF NOT EXISTS kv (path TEXT, key TEXT, num REAL, text TEXT, PRIMARY KEY (path, key))
                WITHOUT ROWID;
            CREATE INDEX IF NOT EXISTS kv_num ON kv (key, num);
            CREATE INDEX IF NOT EXISTS kv_text ON kv (key, text);
            CREATE TABLE IF NOT EXISTS keys (key TEXT PRIMARY KEY) WITHOUT ROWID;
            CREATE TABLE IF NOT EXISTS run_analyses (path TEXT, name TEXT, PRIMARY KEY (path, name)) WITHOUT ROWID;
            CREATE INDEX IF NOT EXISTS run_analyses_name ON run_analyses (name);
            CREATE TABLE IF NOT EXISTS roots (path TEXT PRIMARY KEY);
        """)
        row = db.execute("SELECT value FROM meta WHERE key = 'schema'").fetchone()
        if row is None:
            db.execute("INSERT OR IGNORE INTO meta VALUES ('schema', ?)", (str(SCHEMA),))
        elif int(row[0]) > SCHEMA:
            raise CatalogueError(f"catalogue {path}: schema {row[0]} is newer than this tactile-runs' {SCHEMA}")
        db.execute("SELECT count(*) FROM runs").fetchone()
        return db

    def close(self) -> None:
        self.db.close()

    def known_roots(self) -> list[str]:
        """The roots the catalogue has indexed (its table, and the ``.roots`` file kept beside it
        so that a damaged catalogue can be rebuilt)."""
        roots = set()
        try:
            roots |= {r for (r,) in self.db.execute("SELECT path FROM roots")}
        except sqlite3.DatabaseError:
            pass
        side = Path(f"{self.path}.roots")
        if side.is_file():
            roots |= {line.strip() for line in side.read_text().splitlines() if line.strip()}
        return sorted(roots)

    def _add_root(self, root: Path) -> None:
        root = str(root.resolve())
        if self.db.execute("INSERT OR IGNORE INTO roots VALUES (?)", (root,)).rowcount:
            side = Path(f"{self.path}.roots")
            known = set(side.read_text().splitlines()) if side.is_file() else set()
            if root not in known:
                with open(side, "a") as f:
                    f.write(root + "\n")

    # ------------------------------------------------------------------ writing
    def _write(self, fn):
        """``fn()`` in one write transaction (waiting for another writer's, up to the busy timeout)."""
        try:
            self.db.execute("BEGIN IMMEDIATE")
        except sqlite3.OperationalError as exc:
            raise CatalogueError(f"catalogue {self.path} is locked by another process ({exc}); try again when "
                                 f"it is done") from None
        try:
            out = fn()
            self.db.execute("COMMIT")
            return out
        except BaseException:
            if self.db.in_transaction:       # a Ctrl-C landing just after the COMMIT: nothing to undo, and
                self.db.execute("ROLLBACK")  # ROLLBACK's error would replace (and so lose) the interrupt
            raise

    def _upsert(self, run_dir: Path, row: dict, mtime: float) -> None:
        path = row["path"]
        sweep = str(run_dir.parent.resolve()) if (run_dir.parent / "multirun.yaml").exists() else None
        fields = {k: row.get(k) for k in FIELDS if k not in ("sweep",)}
        fields["sweep"] = sweep
        fields["dirty"] = None if row.get("dirty") is None else str(row.get("dirty")).lower()
        fields["seed"] = None if row.get("seed") is None else str(row.get("seed"))
        slim = {**{k: v for k, v in row.items() if not k.startswith("config.")}, "sweep": sweep}
        self.db.execute("DELETE FROM kv WHERE path = ?", (path,))
        self.db.execute("DELETE FROM run_analyses WHERE path = ?", (path,))
        cols = ", ".join(f'"{c}"' for c in FIELDS)
        self.db.execute(f"INSERT OR REPLACE INTO runs ({cols}, mtime, row) VALUES ({', '.join('?' * len(FIELDS))}, ?, ?)",
                        [fields[c] for c in FIELDS] + [mtime, json.dumps(slim, default=str)])
        kv = []
        for k, v in row.items():
            if k.startswith(("config.", "headline.", "score.")):
                kv.append((path, k, *_value(v)))
        for k, v in (row.get("params") or {}).items():
            kv.append((path, f"params.{k}", *_value(v)))
        self.db.executemany("INSERT OR REPLACE INTO kv VALUES (?, ?, ?, ?)", kv)
        self.db.executemany("INSERT OR IGNORE INTO keys VALUES (?)", [(k[1],) for k in kv])
        self.db.executemany("INSERT OR IGNORE INTO run_analyses VALUES (?, ?)",
                            [(path, n) for n in row.get("analyses") or []])

    def register(self, run_dir) -> dict:
        """Add or refresh one run directory; its row."""
        run_dir = Path(run_dir)
        row = runinfo.summary(run_dir)

        def write():
            self._upsert(run_dir, row, runinfo.newest_mtime(run_dir))
            self._add_root(runinfo_root(run_dir))
        self._write(write)
        return row

    def index(self, paths=None, rebuild: bool = False, console=print) -> str:
        """Walk ``paths`` (default: the known roots, else ``./outputs``, ``./multirun``,
        ``./outputs/imported``): add runs not in the catalogue, refresh those changed since
        (their ``run.json``, analysis pointer or journal), drop those under the walked roots
        that are gone, and say which moved (same run id at a new path). One line."""
        t0 = time.perf_counter()
        if paths:
            roots = [Path(p) for p in paths]
            for r in roots:
                if not r.is_dir():
                    raise CatalogueError(f"index {r}: no such directory; expected a directory of runs")
        else:                                        # a root deleted since: its runs are gone
            roots = [Path(p) for p in self.known_roots()] or [p for p in (Path("outputs"), Path("multirun"))
                                                               if p.is_dir()]
        if rebuild:
            self._write(lambda: [self.db.execute(f"DELETE FROM {t}") for t in ("runs", "kv", "keys", "run_analyses")])
        known = {p: (m, rid) for p, m, rid in self.db.execute("SELECT path, mtime, run_id FROM runs")}
        found, added, refreshed, bad = {}, [], [], []
        for root in roots:
            for run_dir in walk_runs(root):
                found[str(run_dir.resolve())] = run_dir
        pending = []
        for path, run_dir in found.items():
            mtime = runinfo.newest_mtime(run_dir)
            if path in known and known[path][0] == mtime:
                continue
            try:
                pending.append((run_dir, runinfo.summary(run_dir), mtime, path in known))
            except RunRecordError as exc:
                bad.append(str(exc))
        walked = [str(r.resolve()) for r in roots]
        gone = [p for p in known if p not in found and any(p == w or p.startswith(w + os.sep) for w in walked)
                and not runinfo.is_run_dir(p)]
        new_ids = {row["run_id"]: row["path"] for _, row, _, _ in pending}
        moved = [(p, new_ids[known[p][1]]) for p in gone if known[p][1] in new_ids]

        def write():
            for run_dir, row, mtime, was in pending:
                self._upsert(run_dir, row, mtime)
                (refreshed if was else added).append(row["path"])
            for p in gone:
                for table in ("runs", "kv", "run_analyses"):
                    self.db.execute(f"DELETE FROM {table} WHERE path = ?", (p,))
            for r in roots:
                if r.is_dir():
                    self._add_root(r)
                else:
                    self.db.execute("DELETE FROM roots WHERE path = ?", (str(r.resolve()),))
        self._write(write)
        for line in bad[:5]:
            console(f"index: skipped {line}")
        took = time.perf_counter() - t0
        total = self.db.execute("SELECT count(*) FROM runs").fetchone()[0]
        arrived = {new for _, new in moved}
        added = [p for p in added if p not in arrived]
        return (f"catalogue {self.path}: {total} runs; {len(added)} added, {len(refreshed)} refreshed, "
                f"{len(gone) - len(moved)} gone, {len(moved)} moved" + (f", {len(bad)} unreadable" if bad else "")
                + f" ({took:.2f} s)")

    # ------------------------------------------------------------------ reading
    def keys(self) -> list[str]:
        return [k for (k,) in self.db.execute("SELECT key FROM keys")]

    def query(self, filters, limit: int | None = None) -> list[dict]:
        """The rows (newest first) that every filter (:func:`parse_filter`) holds for."""
        where, params = [], []
        known = None
        for text in filters or []:
            key, op, value = parse_filter(text)
            if known is None:
                known = self.keys()
            clause, args = self._clause(key, op, value, known)
            where.append(clause)
            params += args
        sql = "SELECT row FROM runs" + (" WHERE " + " AND ".join(where) if where else "") + \
              " ORDER BY start_time DESC, path" + (f" LIMIT {int(limit)}" if limit else "")
        return [json.loads(r) for (r,) in self.db.execute(sql, params)]

    def _clause(self, key: str, op: str, value: str, known: list[str]) -> tuple[str, list]:
        sql_op = {"=": "=", "!=": "!=", "<": "<", "<=": "<=", ">": ">", ">=": ">="}.get(op)
        if key in ("since", "until"):
            if op != "=":
                raise CatalogueError(f"{key}{op}{value}: expected {key}=DATE (YYYY-MM-DD or ISO time)")
            if not re.match(r"^\d{4}-\d{2}-\d{2}", value):
                raise CatalogueError(f"{key}={value}: expected a date, YYYY-MM-DD")
            return ("start_time >= ?" if key == "since" else "start_time < ?"), \
                   [value if key == "since" or "T" in value else value + "T99"]
        if key == "analysis" and op in ("=", "~"):
            if op == "~":
                return "path IN (SELECT path FROM run_analyses WHERE name LIKE ?)", [f"%{value}%"]
            return "path IN (SELECT path FROM run_analyses WHERE name = ?)", [value]
        if key in FIELDS:
            col = f'"{key}"'
            if op == "~":
                return f"{col} LIKE ?", [f"%{value}%"]
            if key in ("commit", "run_id") and op == "=":
                return f"{col} LIKE ?", [value + "%"]
            if key == "seed" and op not in ("=", "!="):
                return f"CAST({col} AS REAL) {sql_op} ?", [_number(key, op, value)]
            return f"{col} {sql_op} ?", [value.lower() if key == "dirty" else value]
        full = resolve_key(key, known)
        num = _maybe_number(value)
        if op == "~":
            return "path IN (SELECT path FROM kv WHERE key = ? AND text LIKE ?)", [full, f"%{value}%"]
        if op in ("<", "<=", ">", ">="):
            return f"path IN (SELECT path FROM kv WHERE key = ? AND num {sql_op} ?)", [full, _number(key, op, value)]
        if num is not None:
            return f"path IN (SELECT path FROM kv WHERE key = ? AND num {sql_op} ?)", [full, num]
        return f"path IN (SELECT path FROM kv WHERE key = ? AND text {sql_op} ?)", [full, value]


def runinfo_root(run_dir: Path) -> Path:
    return _roots_of(run_dir.resolve())


def walk_runs(root: Path):
    """Every run directory (holding ``run.json``) below ``root``, not looking inside one (nor
    inside stores, analyses, ``.hydra``)."""
    root = Path(root)
    if (root / runinfo.RUN_JSON).is_file():
        yield root
        return
    stack = [root]
    while stack:
        here = stack.pop()
        try:
            entries = list(os.scandir(here))
        except OSError:
            continue
        for e in entries:
            if not e.is_dir(follow_symlinks=False) or e.name in SKIP_DIRS or e.name.endswith(".zarr"):
                continue
            if os.path.isfile(os.path.join(e.path, runinfo.RUN_JSON)):
                yield Path(e.path)
            else:
                stack.append(Path(e.path))


def _maybe_number(value: str):
    try:
        return float(value)
    except ValueError:
        return None


def _number(key: str, op: str, value: str) -> float:
    n = _maybe_number(value)
    if n is None:
        raise CatalogueError(f"{key}{op}{value}: {op} compares numbers; {value!r} is not one")
    return n


def parse_filter(text: str) -> tuple[str, str, str]:
    """``key OP value`` (OP: ``= != < <= > >= ~``), or :class:`CatalogueError` in one line."""
    m = _FILTER.match(text)
    value = m.group(3).strip() if m else ""
    if not m or not value or value[0] in "<>=!~":
        raise CatalogueError(f"malformed filter {text!r}: expected KEY OP VALUE with OP one of "
                             f"{' '.join(OPERATORS)} (protocol=straws_sweep, protocol.sweep_speed>=10, "
                             f"since=2026-11-01)")
    return m.group(1), m.group(2), value


def resolve_key(key: str, known: list[str]) -> str:
    """A key as the catalogue stores it: ``protocol.sweep_speed`` is ``config.protocol.sweep_speed``,
    ``width_mm_median`` ``headline.width_mm_median``; unknown: :class:`CatalogueError` with the
    nearest known key."""
    known_set = set(known)
    for candidate in (key, f"config.{key}", f"headline.{key}", f"score.{key}", f"params.{key}"):
        if candidate in known_set:
            return candidate
    from tactile_flow.validation import suggest
    short = sorted({k.split(".", 1)[1] if k.startswith("config.") else k for k in known} | set(FIELDS)
                   | {"since", "until"})
    near = suggest(key, short)
    raise CatalogueError(f"unknown key {key!r}: no run in the catalogue has it" +
                         (f"; did you mean `{near}`?" if near else "; tactile-runs list --columns all shows the keys"))


# ----------------------------------------------------------------------------- output
def _flat_for_output(row: dict) -> dict:
    out = {}
    for k, v in row.items():
        if k == "params" and isinstance(v, dict):
            out[k] = " ".join(f"{a}={b}" for a, b in v.items() if a not in QUIET_PARAMS)
        elif k == "analyses" and isinstance(v, list):
            out[k] = ",".join(v)
        else:
            out[k] = v
    if "targets" not in row:
        met = row.get("headline.score_all_targets_met")
        out["targets"] = "" if met is None else ("met" if met else "NOT met")
    return out


def columns_for(rows: list[dict], spec: str | None) -> list[str]:
    if spec == "all":
        return list(dict.fromkeys(k for r in rows for k in r))
    if spec:
        return [c.strip() for c in spec.split(",") if c.strip()]
    return list(DEFAULT_COLUMNS)


def _cell(v) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def render(rows: list[dict], columns: list[str], fmt: str = "table") -> str:
    """The rows as an aligned table, CSV or JSON (a list of objects)."""
    flat = [_flat_for_output(r) for r in rows]
    if fmt == "json":
        return json.dumps([{c: r.get(c) for c in columns} for r in flat], indent=1, default=str)
    if fmt == "csv":
        buf = io.StringIO()
        w = csv.DictWriter(buf, fieldnames=columns, extrasaction="ignore")
        w.writeheader()
        w.writerows([{c: r.get(c) for c in columns} for r in flat])
        return buf.getvalue().rstrip("\n")
    cells = [[_cell(r.get(c))[:10] if c == "commit" else _cell(r.get(c)) for c in columns] for r in flat]
    widths = [max([len(c)] + [len(row[i]) for row in cells]) for i, c in enumerate(columns)]
    lines = ["  ".join(c.ljust(w) for c, w in zip(columns, widths)).rstrip()]
    lines += ["  ".join(v.ljust(w) for v, w in zip(row, widths)).rstrip() for row in cells]
    lines.append(f"({len(rows)} run{'s' if len(rows) != 1 else ''})")
    return "\n".join(lines)


def export(rows: list[dict], path: Path) -> Path:
    """Every column of ``rows`` (config keys included) to ``path``: ``.csv`` (``pandas.read_csv``),
    ``.json`` (records: ``pandas.read_json``), ``.parquet`` (needs pandas and pyarrow)."""
    full = []
    for r in rows:
        try:
            full.append({**_flat_for_output(r), **{f"config.{k}": v for k, v in
                                                   runinfo.flatten(runinfo.load(r["path"]).get("config") or {}).items()}})
        except RunRecordError:
            full.append(_flat_for_output(r))
    columns = list(dict.fromkeys(k for r in full for k in r))
    suffix = path.suffix.lower()
    if suffix == ".csv":
        path.write_text(render(full, columns, "csv") + "\n")
    elif suffix == ".json":
        path.write_text(json.dumps([{c: r.get(c) for c in columns} for r in full], default=str) + "\n")
    elif suffix == ".parquet":
        try:
            import pandas as pd
            pd.DataFrame([{c: (json.dumps(r.get(c)) if isinstance(r.get(c), (list, dict)) else r.get(c))
                           for c in columns} for r in full]).to_parquet(path)
        except ImportError as exc:
            raise CatalogueError(f"--export {path}: parquet needs pandas and pyarrow ({exc}); use .csv or .json") from None
    else:
        raise CatalogueError(f"--export {path}: expected a .csv, .json or .parquet file")
    return path


def resolve_run(text: str, catalogue_path=None) -> Path:
    """A run directory from what a user typed: a directory, else a run id (or its first
    characters) or part of a path the catalogue knows (exactly one)."""
    p = Path(text)
    if p.is_dir():
        if not runinfo.is_run_dir(p):
            runinfo.load(p)                          # says what it is instead
        return p
    cat = Catalogue.open(catalogue_path)
    rows = cat.db.execute("SELECT path FROM runs WHERE run_id LIKE ? OR path LIKE ? ORDER BY start_time DESC LIMIT 5",
                          (text + "%", f"%{text}%")).fetchall()
    if not rows:
        raise RunRecordError(f"{text}: no such run directory, and no run id or path in the catalogue "
                             f"{cat.path} starts with or holds it (tactile-runs index to add runs)")
    if len(rows) > 1:
        raise RunRecordError(f"{text}: {len(rows)}{'+' if len(rows) == 5 else ''} runs match "
                             f"({', '.join(Path(r[0]).name for r in rows[:3])}, ...); give more of the id or the path")
    return Path(rows[0][0])


def show(run_dir: Path, fmt: str = "text") -> str:
    """One run: what it is (protocol, surface, parameters), provenance, analyses and results."""
    from . import analyses
    info = runinfo.load(run_dir)
    row = runinfo.summary(run_dir, info)
    listing = analyses.listing(run_dir)
    if fmt == "json":
        return json.dumps({**row, "analyses": listing, "packages": info.get("packages"),
                           "inputs": info.get("inputs"), "code": info.get("code") or info.get("git")},
                          indent=1, default=str)
    code = info.get("code") or info.get("git") or {}
    lines = [f"run {run_dir}",
             f"  id          {row['run_id']}  ({row['kind']}{', reproduces ' + row['reproduces'] if row['reproduces'] else ''})",
             f"  protocol    {row['protocol']}  on surface {row['surface']}",
             f"  parameters  {' '.join(f'{k}={v}' for k, v in row['params'].items()) or '(the protocol defaults)'}",
             f"  status      {row['status']}{' (' + str(row['error']) + ')' if row.get('error') else ''}",
             f"  time        {row['start_time']} -> {row['end_time']}",
             f"  seed        {row['seed']}",
             f"  code        commit {code.get('commit')}" + (" + code.diff" if code.get("diff_file") else
                                                             " (dirty)" if code.get("dirty") else ""),
             f"  host        {info.get('host')}  python {(info.get('python') or {}).get('version')}  "
             f"tactile-flow {(info.get('packages') or {}).get('tactile-flow')}",
             f"  store       {row.get('store_sha256') or '(no checksum recorded)'}"]
    if info.get("importer"):
        lines.append(f"  imported    {row.get('source')} by {info['importer']}")
    lines.append(f"  analyses    {len(listing)}")
    for a in listing:
        lines.append(f"    {'*' if a.get('current') else ' '} {a['name']}  {a.get('created') or ''}")
    nums = {k: v for k, v in row.items() if k.startswith(("headline.", "score."))}
    if nums:
        lines.append(f"  results ({row['analysis']})")
        lines += [f"    {k:<44} {_cell(v)}" for k, v in nums.items()]
    return "\n".join(lines)


def diff(a: Path, b: Path, show_all: bool = False) -> str:
    """Two runs side by side: the config keys that differ, provenance (code, packages,
    calibration), results."""
    ia, ib = runinfo.load(a), runinfo.load(b)
    ra, rb = runinfo.summary(a, ia), runinfo.summary(b, ib)
    out = [f"{'':<44} {'A':<28} B", f"{'run':<44} {a.name[:28]:<28} {b.name}"]

    def section(title, pairs):
        rows = [(k, x, y) for k, x, y in pairs if show_all or x != y]
        if rows:
            out.append(f"{title}:")
            out.extend(f"  {k[:42]:<42} {_cell(x)[:28]:<28} {_cell(y)}" for k, x, y in rows)
    fa, fb = runinfo.flatten(ia.get("config") or {}), runinfo.flatten(ib.get("config") or {})
    section("config", [(k, fa.get(k), fb.get(k)) for k in sorted(set(fa) | set(fb))])
    ca, cb = ia.get("code") or ia.get("git") or {}, ib.get("code") or ib.get("git") or {}
    prov = [("code.commit", ca.get("commit"), cb.get("commit")), ("code.diff", ca.get("diff_sha256"),
                                                                   cb.get("diff_sha256")),
            ("host", ia.get("host"), ib.get("host")), ("status", ia.get("status"), ib.get("status")),
            ("store", ra.get("store_sha256"), rb.get("store_sha256"))]
    pa, pb = ia.get("packages") or {}, ib.get("packages") or {}
    prov += [(f"packages.{k}", pa.get(k), pb.get(k)) for k in sorted(set(pa) | set(pb))]
    ka, kb = runinfo.flatten(ia.get("calibration") or {}), runinfo.flatten(ib.get("calibration") or {})
    prov += [(f"calibration.{k}", ka.get(k), kb.get(k)) for k in sorted(set(ka) | set(kb))]
    section("provenance", prov)
    na = {k: v for k, v in ra.items() if k.startswith(("headline.", "score."))}
    nb = {k: v for k, v in rb.items() if k.startswith(("headline.", "score."))}
    section(f"results ({ra.get('analysis')} / {rb.get('analysis')})", [(k, na.get(k), nb.get(k))
                                                                        for k in sorted(set(na) | set(nb))])
    if len(out) == 2:
        out.append("identical config, provenance and results")
    return "\n".join(out)


_KEPT: dict | None = None
"""While :func:`kept_open` is entered: (process id, catalogue file) → its open :class:`Catalogue`."""


@contextmanager
def kept_open():
    """Within the block, :func:`register_quietly` keeps the default catalogue open between runs:
    one connection per process (a worker forked inside the block opens its own, closed when it
    ends), not one per run (opening and closing it, a WAL checkpoint each time, was ~5 ms of
    a short record's import or analysis). Each run is still its own committed transaction.
    Nested: the outer block's."""
    global _KEPT
    outer = _KEPT
    if outer is not None:
        yield
        return
    _KEPT = {}
    try:
        yield
    finally:
        kept, _KEPT = _KEPT, None
        for (pid, _), cat in kept.items():
            if pid == os.getpid():
                cat.close()


def _open_for_register(console) -> tuple[Catalogue, bool]:
    """The default catalogue and whether the caller closes it (not while :func:`kept_open`)."""
    if _KEPT is None:
        return Catalogue.open(console=console), True
    key = (os.getpid(), str(default_path()))
    cat = _KEPT.get(key)
    if cat is None:
        cat = _KEPT[key] = Catalogue.open(console=console)
        import multiprocessing.util                 # a forked worker runs no atexit: closed as it exits
        multiprocessing.util.Finalize(cat, cat.close, exitpriority=10)
    return cat, False


def register_quietly(run_dir, console=None) -> None:
    """Register ``run_dir`` in the default catalogue; never raises (a run's end must not fail
    on its index: ``tactile-runs index`` adds it later). A problem is one line on ``console``."""
    try:
        cat, close = _open_for_register(console or (lambda *_: None))
        try:
            cat.register(run_dir)
        finally:
            if close:
                cat.close()
    except Exception as exc:  # noqa: BLE001
        if console is not None:
            console(f"catalogue: {run_dir} not registered ({type(exc).__name__}: {exc}); tactile-runs index adds it")

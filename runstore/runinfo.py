"""A run directory's record as data: what ``tactile-runs`` lists, shows, compares and reproduces.

:func:`load` reads ``run.json`` (refusing, in one line, a directory that is not a run, a
record that is not one, or one from a newer schema) and :func:`summary` turns it, with the
run's current analysis, into one flat row: protocol, surface, the overrides that made it,
provenance (commit, dirty), status, times, headline and score numbers, every config key as
a dotted name (``config.protocol.sweep_speed``). Records written before 0.2 name the old
top-level modules (``importers.csv.read_csv``); :func:`modern_name` maps them.
"""

from __future__ import annotations

import json
import math
import os
import re
from pathlib import Path

from . import analyses
from .jsonvalues import read_object
from .layout import SCHEMA_VERSION
from .reader import StoreVersionError, check_version

RUN_JSON = "run.json"
#: the packages that were top-level modules before 0.2 (issue 37): their names in old records
LEGACY_PACKAGES = ("analysis", "cliapp", "hardware", "importers", "protocols", "runstore", "tactile", "validation",
                   "viewer")
_LEGACY = re.compile(rf"^({'|'.join(LEGACY_PACKAGES)})(\.|:|$)")


class RunRecordError(ValueError):
    """A path that is not a run directory, or a record that cannot be read."""


def modern_name(name) -> str:
    """A module or entry point named in a record written before 0.2 (``importers.csv.read_csv``,
    ``analysis.run:analyze_run``) under the ``tactile_flow`` namespace; other names unchanged."""
    text = str(name)
    return f"tactile_flow.{text}" if _LEGACY.match(text) else text


def is_run_dir(path) -> bool:
    return (Path(path) / RUN_JSON).is_file()


def sweep_jobs(path) -> list[Path]:
    """The job directories of a sweep directory (each holding a ``run.json``), in job order."""
    def order(p: Path):
        head = p.name.split("_", 1)[0]
        return (int(head) if head.isdigit() else 1 << 30, p.name)
    return sorted((p.parent for p in Path(path).glob(f"*/{RUN_JSON}")), key=order)


def load(run_dir) -> dict:
    """``run.json`` of ``run_dir``, validated: :class:`RunRecordError` in one line for a path
    that is not a run directory (naming what it holds instead), unreadable JSON, a record
    without ``run_id``/``status``, or a schema newer than this reader's."""
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise RunRecordError(f"{run_dir}: no such directory; expected a run directory (holding run.json)")
    path = run_dir / RUN_JSON
    if not path.is_file():
        jobs = sweep_jobs(run_dir)
        hint = (f"; it is a sweep directory of {len(jobs)} runs" if jobs else
                "; it holds a run.zarr without run.json: close it with tactile-recover first"
                if (run_dir / "run.zarr").is_dir() else "")
        raise RunRecordError(f"{run_dir}: not a run directory (no run.json){hint}")
    try:
        info = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise RunRecordError(f"{path}: unreadable ({type(exc).__name__}: {str(exc)[:80]})") from None
    if not isinstance(info, dict) or "run_id" not in info or "status" not in info:
        raise RunRecordError(f"{path}: not a run record (no run_id and status)")
    try:
        check_version(info, str(path))
    except StoreVersionError as exc:
        raise RunRecordError(str(exc)) from None
    if info.get("importer"):
        info["importer"] = modern_name(info["importer"])
    return info


def flatten(node, prefix: str = "") -> dict:
    """A nested config as ``{"protocol.sweep_speed": 10.0, "protocol.steps[3].sweep.speed": 10.0, ...}``
    (lists of plain values kept as values)."""
    out = {}
    if isinstance(node, dict):
        for k, v in node.items():
            key = f"{prefix}.{k}" if prefix else str(k)
            if isinstance(v, dict) and v:
                out.update(flatten(v, key))
            elif isinstance(v, list) and v and any(isinstance(x, dict) for x in v):
                for i, x in enumerate(v):          # protocol.steps[3].sweep.speed
                    out.update(flatten(x, f"{key}[{i}]") if isinstance(x, dict) else {f"{key}[{i}]": x})
            else:
                out[key] = v
    return out


def overrides_as_params(overrides) -> dict:
    """``["protocol.sweep_speed=10", "+experiment=x"]`` as ``{"protocol.sweep_speed": "10", ...}``
    (the ``+``/``~`` prefixes left out)."""
    out = {}
    for o in overrides or []:
        key, sep, value = str(o).partition("=")
        if sep:
            out[key.lstrip("+~")] = value
    return out


def _num(v):
    if isinstance(v, bool) or v is None:
        return v
    if isinstance(v, (int, float)):
        return v if not (isinstance(v, float) and math.isnan(v)) else None
    return v


def _score_numbers(score: dict) -> dict:
    """``score.json``'s summary numbers and targets, flat: ``width_error_mm_median``..."""
    out = {}
    for k, v in (score.get("summary") or {}).items():
        if isinstance(v, (int, float, bool)) or v is None:
            out[k] = _num(v)
    for k, t in (score.get("targets") or {}).items():
        if isinstance(t, dict):
            out[f"target_met.{k}"] = t.get("met")
    return out


def analysis_numbers(directory) -> dict:
    """``headline.*`` (``summary.json``) and ``score.*`` (``score.json``: summary numbers,
    ``target_met.*``) of an analysis directory, flat."""
    directory = Path(directory)
    row = {}
    meta = analyses.read_meta(directory)                 # small; summary.json for analyses made before it
    headline = meta["headline"] if isinstance(meta.get("headline"), dict) else \
        read_object(directory / analyses.SUMMARY).get("headline")
    for k, v in (headline or {}).items():
        if isinstance(v, (int, float, str, bool)) or v is None:
            row[f"headline.{k}"] = _num(v)
    for k, v in _score_numbers(read_object(directory / "score.json")).items():
        row[f"score.{k}"] = v
    return row


def summary(run_dir, info: dict | None = None) -> dict:
    """One flat row for the run: ``path``, ``run_id``, ``kind`` (run | import), ``protocol``,
    ``surface``, ``status``, ``start_time``, ``end_time``, ``seed``, ``commit``, ``dirty``,
    ``params`` (the overrides that made it), ``analysis`` (the current analysis's name),
    ``analyses`` (every kept one), ``headline.*``, ``score.*``, ``config.*``,
    ``reproduces`` (the run it reproduces, if any), ``store_sha256``."""
    run_dir = Path(run_dir)
    info = load(run_dir) if info is None else info
    config = info.get("config") if isinstance(info.get("config"), dict) else {}
    git = info.get("code") or info.get("git") or {}
    surface = config.get("surface") or {}
    row = {"path": str(run_dir.resolve()), "run_id": info.get("run_id"),
           "kind": "import" if info.get("protocol") == "import" or info.get("importer") else "run",
           "protocol": info.get("protocol") or (config.get("protocol") or {}).get("name"),
           "surface": surface.get("name") or surface.get("kind") if isinstance(surface, dict) else None,
           "status": info.get("status"), "start_time": info.get("start_time"), "end_time": info.get("end_time"),
           "seed": info.get("seed"), "commit": git.get("commit"), "dirty": git.get("dirty"),
           "host": info.get("host"), "params": overrides_as_params(info.get("overrides")),
           "store_sha256": (info.get("store_checksum") or {}).get("sha256"),
           "reproduces": (info.get("reproduces") or {}).get("run_id"), "error": info.get("error")}
    if info.get("importer"):
        row["source"] = (info.get("source") or {}).get("path")
    current = analyses.current_dir(run_dir)
    row["analysis"] = analyses.current_name(run_dir)
    row["analyses"] = [a["name"] for a in analyses.listing(run_dir)]
    if current is not None:
        row.update(analysis_numbers(current))
    for k, v in flatten(config).items():
        row[f"config.{k}"] = v
    return row



def newest_mtime(run_dir) -> float:
    """The latest change time among what a row reads (``run.json``, the analysis pointer and
    journal): a catalogue refreshes a row when it moved forward."""
    run_dir = Path(run_dir)
    times = []
    for name in (RUN_JSON, analyses.CURRENT, analyses.HISTORY):
        try:
            times.append(os.lstat(run_dir / name).st_mtime)
        except OSError:
            pass
    return max(times, default=0.0)


__all__ = ["load", "summary", "flatten", "modern_name", "is_run_dir", "sweep_jobs", "RunRecordError",
           "overrides_as_params", "newest_mtime", "SCHEMA_VERSION"]

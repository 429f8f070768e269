"""The run catalogue at lab scale: 10,000 run directories indexed, queried, refreshed.

    python benchmarks/bench_catalogue.py [--runs 10000] [--new 100] [--keep DIR]

Makes N synthetic run directories (``make_run``: the ``run.json`` of a real simulated run,
with its protocol, surface, speed, seed, status and start time varied, and an analysis with
its ``analysis.json`` and ``score.json``) under a temporary ``outputs/``, then prints JSON lines:

- ``index``: ``tactile-runs index`` of all of them into an empty catalogue (s, ms per run);
- ``query``: filtered queries (``protocol=straws_sweep protocol.sweep_speed>=10
  score.width_error_mm_median<1 status=success since=...``, one key, an analysis name), the
  median of 20 each (ms; target < 100 ms);
- ``incremental``: ``index`` again after M new runs appear (s; target < 2 s for 100);
- ``catalogue_bytes``: the size of the file.
"""

from __future__ import annotations

import argparse
import copy
import json
import random
import shutil
import statistics
import tempfile
import time
import uuid
from pathlib import Path

PROTOCOLS = {"straws_sweep": "straws", "sticks_sweep": "sticks", "pour_grasp": "bottle", "slip_in_place": "cylinder"}
TEMPLATE = {
    "schema_version": "1.0", "host": "lab-pc", "seed": 0, "status": "success", "store": "run.zarr",
    "python": {"version": "3.11.7", "implementation": "CPython", "executable": "/usr/bin/python3"},
    "packages": {f"package-{i}": f"1.{i}.0" for i in range(160)},   # a lab's environment: ~160 distributions
    "calibration": {"taxels_mm": [[float(i), float(i) / 2, -1.0] for i in range(24)],
                    "baseline_counts": {f: [2000.0 + i for i in range(24)] for f in ("ff", "mf", "rf", "lf", "th")}},
    "hardware": {"arm": {"model": "UR10 (simulated)", "serial_or_address": "sim", "firmware": "sim"}},
    "code": {"commit": "0" * 40, "dirty": False, "diff_sha256": None, "package": "0.2.0"},
}


def make_run(directory: Path, *, protocol="straws_sweep", speed=10.0, seed=0, status="success",
             start="2026-11-01T10:00:00.000000Z", width_error=0.8, analysis="farneback-0123456789ab",
             run_id=None) -> Path:
    """A run directory as ``tactile-run`` leaves it, for the catalogue: ``run.json`` (config,
    overrides, provenance), ``analyses/<analysis>/`` (``analysis.json`` with the headline,
    ``score.json``) and the ``analysis`` pointer."""
    directory.mkdir(parents=True)
    surface = PROTOCOLS.get(protocol, "flat")
    config = {"protocol": {"name": protocol, "sweep_speed": speed, "sweep_depth": 1.5, "finger": "ff",
                           "labels": ["approach", "before", "during", "after", "lift"],
                           "steps": [{"move_to": {"at": "before:first", "height": 10.0}},
                                     {"sweep": {"to": "after:last", "speed": speed}}, {"lift": {"height": 20.0}}]},
              "surface": {"name": surface, "kind": surface, "count": 3, "spacing_mm": 20.0},
              "hardware": {"backend": "sim", "seed": seed, "rate_hz": 100.0, "fingers": ["ff"]},
              "analysis": {"flow": {"method": analysis.split("-")[0]}, "figures": True},
              "plan_only": False, "analyze": True}
    info = {**copy.deepcopy(TEMPLATE), "run_id": run_id or str(uuid.uuid4()), "protocol": protocol, "seed": seed,
            "status": status, "start_time": start, "end_time": start, "config": config,
            "overrides": [f"protocol={protocol}", f"protocol.sweep_speed={speed}", f"hardware.seed={seed}"],
            "store_checksum": {"sha256": uuid.uuid4().hex * 2, "arrays": {}}}
    (directory / "run.json").write_text(json.dumps(info, indent=2))
    a = directory / "analyses" / analysis
    a.mkdir(parents=True)
    headline = {"segments": 11, "skipped": 0, "crossings": 3, "width_mm_median": 6.0 + width_error,
                "direction_sensor_deg": -0.3, "score_width_error_mm_median": width_error,
                "score_all_targets_met": width_error <= 1.0, "status": "ok"}
    (a / "analysis.json").write_text(json.dumps({"analysis_id": uuid.uuid4().hex, "name": analysis, "created": start,
                                                 "headline": headline, "config": config["analysis"]}))
    (a / "summary.json").write_text(json.dumps({"analysis_id": "x", "headline": headline}))
    (a / "score.json").write_text(json.dumps({"summary": {"width_error_mm_median": width_error,
                                                          "direction_correct_fraction": 1.0,
                                                          "boundary_error_ms_median": 33.5},
                                              "targets": {"width_error_mm_median": {"met": width_error <= 1.0}}}))
    (directory / "analysis").symlink_to(f"analyses/{analysis}")
    return directory


def make_runs(root: Path, n: int, offset: int = 0, rng=None) -> list[Path]:
    rng = rng or random.Random(offset)
    out = []
    for i in range(offset, offset + n):
        protocol = rng.choice(list(PROTOCOLS))
        day = 1 + i * 29 // max(n + offset, 1)
        start = f"2026-11-{day:02d}T{i % 24:02d}:{i % 60:02d}:00.{i:06d}Z"
        out.append(make_run(root / f"2026-11-{day:02d}" / f"{i:06d}_{protocol}", protocol=protocol,
                            speed=rng.choice([5.0, 10.0, 20.0]), seed=rng.randrange(10),
                            status=rng.choice(["success"] * 9 + ["aborted"]), start=start,
                            width_error=round(rng.uniform(0.2, 1.6), 3),
                            analysis=rng.choice(["farneback", "dis"]) + f"-{i:012x}"))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=10_000)
    ap.add_argument("--new", type=int, default=100)
    ap.add_argument("--keep", type=Path, help="make the runs here and keep them")
    args = ap.parse_args()
    from tactile_flow.runstore.catalogue import Catalogue

    work = args.keep or Path(tempfile.mkdtemp(prefix="bench-catalogue-"))
    try:
        outputs = work / "outputs"
        t0 = time.perf_counter()
        make_runs(outputs, args.runs)
        print(json.dumps({"made": args.runs, "s": round(time.perf_counter() - t0, 2)}), flush=True)
        cat = Catalogue.open(work / "runs.sqlite")
        t0 = time.perf_counter()
        cat.index([outputs], console=lambda *_: None)
        took = time.perf_counter() - t0
        print(json.dumps({"index": args.runs, "s": round(took, 2), "ms_per_run": round(1000 * took / args.runs, 3)}),
              flush=True)
        queries = {"issue_filter": ["protocol=straws_sweep", "protocol.sweep_speed>=10",
                                    "score.width_error_mm_median<1", "status=success", "since=2026-11-10"],
                   "one_key": ["protocol.sweep_speed=20"],
                   "analysis_name": ["analysis~dis-"],
                   "everything": []}
        for name, filters in queries.items():
            times, n = [], 0
            for _ in range(20):
                t0 = time.perf_counter()
                n = len(cat.query(filters))
                times.append(1000 * (time.perf_counter() - t0))
            print(json.dumps({"query": name, "filters": " ".join(filters), "runs_found": n,
                              "ms_median": round(statistics.median(times), 2), "ms_max": round(max(times), 2),
                              "target_ms": 100}), flush=True)
        make_runs(outputs, args.new, offset=args.runs)
        t0 = time.perf_counter()
        report = cat.index([outputs], console=lambda *_: None)
        print(json.dumps({"incremental": args.new, "s": round(time.perf_counter() - t0, 3), "target_s": 2.0,
                          "report": report.split(": ", 1)[1]}), flush=True)
        cat.close()
        size = sum(p.stat().st_size for p in work.glob("runs.sqlite*"))
        print(json.dumps({"catalogue_bytes": size, "bytes_per_run": size // (args.runs + args.new)}), flush=True)
    finally:
        if args.keep is None:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()

"""Peak memory and wall time of ``tactile-analyze`` on an N-hour five-finger import (JSON lines).

    python benchmarks/bench_long_analysis.py [--hours 0.1 0.25 0.5 1 2] [--press-every 300] [--stages] [--keep DIR]

The record (``tests/long_record.py``): the real resting bag tiled end to end to N hours, five
fingers at 100 Hz, with a 2 s press on one finger every ``--press-every`` s, written as
``tactile-import`` would write it. Then ``tactile-analyze run=RUN_DIR/run.zarr`` runs
in a child process; its peak resident memory (``ru_maxrss`` of the child) and wall time are
printed, one JSON line per length; ``--stages`` adds what each stage holds and peaks at
(tracemalloc, in this process; ``analyse`` runs ``prepare`` again inside). The curve is what issue
13 item 15 asks about: it must stay flat with the hours (docs/performance.md).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from long_record import RATE_HZ, make_store  # noqa: E402  (the record the tests use too)


def analyse_child(run_dir: Path) -> dict:
    """Run ``tactile-analyze run=RUN_DIR/run.zarr`` as a child; its exit code, peak RSS (MB, the
    child's own ``ru_maxrss`` from ``os.wait4``) and wall time (s)."""
    exe = Path(sys.executable).parent / "tactile-analyze"
    t0 = time.perf_counter()
    with tempfile.TemporaryFile("w+") as err:
        p = subprocess.Popen([str(exe), f"run={run_dir / 'run.zarr'}"], cwd=run_dir,
                             stdout=subprocess.DEVNULL, stderr=err)
        _, status, usage = os.wait4(p.pid, 0)
        p.returncode = os.waitstatus_to_exitcode(status)
        err.seek(0)
        tail = err.read().strip().splitlines()[-1:]
    wall = time.perf_counter() - t0
    return {"rc": p.returncode, "peak_rss_mb": round(usage.ru_maxrss / 1024, 1), "wall_s": round(wall, 1),
            "stderr_tail": tail if p.returncode else []}


def stage_memory(store: Path) -> dict:
    """Where the memory goes, in this process (tracemalloc, MB): what ``load_run``,
    ``preprocess.prepare`` and ``pipeline.analyse`` each hold after and peak at."""
    import tracemalloc

    from tactile_flow.analysis.config import load_config
    from tactile_flow.analysis.load import load_run
    from tactile_flow.analysis.pipeline import analyse, get_model
    from tactile_flow.analysis.preprocess import prepare
    cfg = load_config({"progress": False})
    model = get_model(cfg.tactile)
    out = {}

    def mark(name):
        held, peak = tracemalloc.get_traced_memory()
        out[name] = {"held_mb": round(held / 1e6), "peak_mb": round(peak / 1e6)}
        tracemalloc.reset_peak()

    tracemalloc.start()
    run = load_run(store)
    mark("load_run")
    prepared = prepare(run, cfg, model)
    mark("prepare")
    del prepared
    tracemalloc.reset_peak()
    analyse(run, cfg, model)
    mark("analyse")
    tracemalloc.stop()
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", type=float, nargs="+", default=[0.1, 0.25, 0.5, 1, 2])
    ap.add_argument("--press-every", type=float, default=300.0, help="s between presses (fingers in turn)")
    ap.add_argument("--stages", action="store_true",
                    help="also trace the memory of load_run / prepare / analyse in this process")
    ap.add_argument("--keep", help="work directory to keep (default: a temporary one, removed)")
    args = ap.parse_args()
    work = Path(args.keep or tempfile.mkdtemp(prefix="bench-long-"))
    for hours in sorted(args.hours):
        run_dir = work / f"{hours:g}h"
        t0 = time.perf_counter()
        store = make_store(run_dir, hours, args.press_every)
        write_s = time.perf_counter() - t0
        frames = int(round(hours * 3600 * RATE_HZ))
        out = {"hours": hours, "frames": frames, "finger_frames": frames * 5, "write_s": round(write_s, 1),
               **analyse_child(run_dir), "store": str(store) if args.keep else None}
        if args.stages:
            out["stages"] = stage_memory(store)
        print(json.dumps(out), flush=True)
        if not args.keep:
            subprocess.run(["rm", "-rf", str(run_dir)], check=False)
    if not args.keep:
        os.rmdir(work)


if __name__ == "__main__":
    main()

"""Peak memory and wall time of ``tactile-analyze`` on an N-hour five-finger import (JSON lines).

    python benchmarks/bench_long_analysis.py [--hours 0.1 0.25 0.5 1 2] [--press-every 300] [--stages] [--keep DIR]

The record: the real resting bag ``tests/data/biotac_rest_untouched.bag`` (100 Hz; its two
unconnected fingers get a connected finger's data, so five fingers rest) tiled end to end to N
hours, with a 2 s press on one finger every ``--press-every`` s (the fingers in turn): the
electrodes move by up to ~300 counts in a spatial bump that travels across the taxels, PDC rises
by ~200 counts. It is written through the importer's own streaming writer
(:func:`importers.writer.write_import_store`, one chunk in memory), so the store is what
``tactile-import`` would write for such a bag. Then ``tactile-analyze run=RUN_DIR/run.zarr`` runs
in a child process; its peak resident memory (``ru_maxrss`` of the child) and wall time are
printed, one JSON line per length; ``--stages`` adds what each stage holds and peaks at
(tracemalloc, in this process; ``analyse`` runs ``prepare`` again inside). The curve is what issue
13 item 15 asks about: today it grows with the hours (~3.4 GB per hour: 8 h needs ~28 GB, so it is
not in the default list); streamed, it should stay flat.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
BAG = ROOT / "tests" / "data" / "biotac_rest_untouched.bag"
RATE_HZ = 100.0
PRESS_S = 2.0


def five_fingers(rec):
    """The bag with its unconnected fingers (all-zero electrodes) given a connected finger's data,
    so that all five fingers carry a real resting signal."""
    live = [i for i in range(len(rec.fingers)) if rec.electrodes[:, i].any()]
    src = [i if i in live else live[i % len(live)] for i in range(len(rec.fingers))]
    pick = (lambda a: None if a is None else a[:, src])
    return replace(rec, electrodes=pick(rec.electrodes), pdc=pick(rec.pdc), tdc=pick(rec.tdc), tac=pick(rec.tac))


class TiledReader:
    """The resting bag tiled to ``frames`` frames with presses (the importer's Reader protocol)."""

    def __init__(self, frames: int, press_every_s: float):
        from importers.bag import BagFile, read_bag
        rest = read_bag(BAG)
        self.path, self.meta, self.finger_names = BAG, dict(BagFile(BAG).meta), rest.fingers
        self.rest = five_fingers(replace(rest, pac=None))      # PAC is not what the analysis reads
        self.frames, self.press_every_s = frames, press_every_s

    def chunks(self, frames: int = 5000):
        r, n_rest = self.rest, self.rest.n_frames
        for start in range(0, self.frames, frames):
            i = np.arange(start, min(start + frames, self.frames))
            k = i % n_rest
            t = i / RATE_HZ
            el = r.electrodes[k].astype(np.int64)
            pdc = r.pdc[k].astype(np.int64) if r.pdc is not None else None
            self._press(t, el, pdc)
            yield replace(r, seq=i.astype(np.int64), device_time=t, host_time=t + 1e-3,
                          electrodes=el, pdc=pdc,
                          tdc=None if r.tdc is None else r.tdc[k], tac=None if r.tac is None else r.tac[k])

    def _press(self, t: np.ndarray, el: np.ndarray, pdc: np.ndarray | None) -> None:
        """Add the presses in place: press j starts at (j + 0.5) · press_every_s on finger j mod F."""
        j = np.floor(t / self.press_every_s - 0.5).astype(int)
        phase = t - (j + 0.5) * self.press_every_s       # s into press j
        on = (j >= 0) & (phase >= 0) & (phase < PRESS_S)
        if not on.any():
            return
        w = np.sin(np.pi * phase[on] / PRESS_S) ** 2          # 0 → 1 → 0 over the press
        centre = 24 * phase[on] / PRESS_S                     # the bump travels over the taxels
        bump = np.exp(-0.5 * ((np.arange(24)[None, :] - centre[:, None]) / 3.0) ** 2)
        f = j[on] % el.shape[1]
        rows = np.flatnonzero(on)
        el[rows, f, :] -= np.rint(300 * w[:, None] * bump).astype(np.int64)
        if pdc is not None:
            pdc[rows, f] += np.rint(200 * w).astype(np.int64)

    def finish(self, rate_hz: float) -> None:
        pass


def make_store(run_dir: Path, hours: float, press_every_s: float) -> Path:
    """Write ``run_dir/run.zarr`` (+ run.json) holding ``hours`` h of tiled record."""
    from importers.importer import scan
    from importers.recording import PreparedSource
    from importers.writer import write_import_store
    reader = TiledReader(int(round(hours * 3600 * RATE_HZ)), press_every_s)
    found = scan(reader)
    prepared = PreparedSource(reader, found, found.fingers, {"kept": list(found.fingers)})
    run_dir.mkdir(parents=True)
    write_import_store(prepared, run_dir / "run.zarr", {"source": str(BAG), "importer": "bench_long_analysis"},
                       {"source": str(BAG), "fingers": list(found.fingers)})
    return run_dir / "run.zarr"


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

    from analysis.config import load_config
    from analysis.load import load_run
    from analysis.pipeline import analyse, get_model
    from analysis.preprocess import prepare
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

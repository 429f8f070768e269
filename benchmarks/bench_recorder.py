"""Benchmark the recorder's cost against the simulation it records (issue 15, goal 4).

Scenario: the straws sweep of ``bench_sim.py`` (ff back and forth at 10 mm/s, five BioTacs, every
device streaming) for ``--sim-s`` simulated seconds, recorded through the real recorder into a
real run store, the simulated clock held back by ``Recorder.keep_up`` as the run engine does.
The simulation runs on the main thread; everything else in the process (the acquisition
threads, the writer, zarr's I/O) is the recording. Prints one JSON line per run and a summary:
CPU seconds of each per simulated second and their ratio (target: recorder / simulation ≤ 1).

    python benchmarks/bench_recorder.py [--sim-s 60] [--repeat 3]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from tactile_flow.hardware.sim import make_sim_lab  # noqa: E402
from tactile_flow.hardware.sim.scenarios import pad_height_pose  # noqa: E402
from tactile_flow.protocols.recorder import Recorder  # noqa: E402
try:
    from tactile_flow.runstore import RunStore  # noqa: E402
except ImportError:                 # a checkout before the runstore package (for a before/after figure)
    from tactile_flow.protocols.store import RunStore  # noqa: E402


def process_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def sources(lab) -> dict:
    if hasattr(lab, "sources"):
        return lab.sources()
    out = {"biotac": lab.biotac.read, "arm": lab.arm.read_states, "hand": lab.hand.read_states,
           "pump": lab.pump.read_states, "scale": lab.scale.read}
    return out | ({"stage": lab.stage.read_states} if lab.stage is not None else {})


def record_sweep(sim_s: float, directory: Path, seed: int = 0) -> dict:
    lab = make_sim_lab({"seed": seed}, {"kind": "straws"})
    with lab:
        store = RunStore.create(directory / "run.zarr", protocol="bench_recorder", fingers=lab.biotac.fingers,
                                stage=lab.stage is not None)
        rec = Recorder(store, sources(lab), lab.clock)
        s = lab.surface
        u = s.features[-1].u + 0.015
        ends = [pad_height_pose(lab, *(s.origin[:2] - u * s.across[:2]), 0.0015),
                pad_height_pose(lab, *(s.origin[:2] + u * s.across[:2]), 0.0015)]
        lab.arm.move_linear(ends[0], 0.05, 0.5)
        rec.start()
        cpu0, main0, wall0, sim0 = process_cpu(), time.thread_time(), time.perf_counter(), lab.clock.now()
        k = 1
        while lab.clock.now() - sim0 < sim_s:
            lab.arm.move_linear(ends[k], 0.01, 0.5, asynchronous=True)
            while lab.arm.is_moving() and lab.clock.now() - sim0 < sim_s:
                lab.clock.sleep(0.01)                     # the engine's poll period
                rec.keep_up()
            k = 1 - k
        sim_cpu = time.thread_time() - main0
        rec.stop("success")
        total = process_cpu() - cpu0
        simulated = lab.clock.now() - sim0
    rec_cpu = total - sim_cpu                 # every other thread, and the main thread's stop()
    return {"bench": "recorder", "sim_s": round(simulated, 3), "wall_s": round(time.perf_counter() - wall0, 3),
            "sim_cpu_s": round(sim_cpu, 3), "recorder_cpu_s": round(rec_cpu, 3),
            "sim_cpu_per_sim_s": round(sim_cpu / simulated, 4), "recorder_cpu_per_sim_s": round(rec_cpu / simulated, 4),
            "ratio": round(rec_cpu / sim_cpu, 3), "commits": store.n_commits,
            "flush_ms_median": round(1000 * float(np.median(rec.flush_durations)), 1), "cpus": os.cpu_count()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sim-s", type=float, default=60.0)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    ratios = []
    for i in range(args.repeat):
        with tempfile.TemporaryDirectory() as tmp:
            r = record_sweep(args.sim_s, Path(tmp), seed=i)
        ratios.append(r["ratio"])
        print(json.dumps(r), flush=True)
    print(json.dumps({"bench": "recorder_summary", "sim_s": args.sim_s, "ratio_min": min(ratios),
                      "ratio_median": float(np.median(ratios)), "target_ratio": 1.0,
                      "ok": float(np.median(ratios)) <= 1.0}), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

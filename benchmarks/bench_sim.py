"""Benchmark the simulated lab: 60 s of simulated time, five BioTacs, wall time.

Scenario: sweep the ff fingertip back and forth across the straws board at 10 mm/s
(every device streaming, all buffers drained every 50 ms of simulated time, as a recorder
would), until 60 s of simulated time have passed. Prints one JSON line per measurement.
Target (issue 3): under 10 s of wall time on one core.

    /tmp/venv/bin/python benchmarks/bench_sim.py [--sim-s 60] [--repeat 3]
"""

from __future__ import annotations

import argparse
import json
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")       # one core, as the target says
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from tactile_flow.hardware.sim import make_sim_lab  # noqa: E402
from tactile_flow.hardware.sim.scenarios import pad_height_pose, record  # noqa: E402


def sweep_for(sim_s: float, seed: int = 0) -> dict:
    t_build = time.perf_counter()
    lab = make_sim_lab({"seed": seed}, {"kind": "straws"})
    build_s = time.perf_counter() - t_build
    frames: dict = {}
    t0 = time.perf_counter()
    with lab:
        s = lab.surface
        u = s.features[-1].u + 0.015
        ends = [pad_height_pose(lab, *(s.origin[:2] - u * s.across[:2]), 0.0015),
                pad_height_pose(lab, *(s.origin[:2] + u * s.across[:2]), 0.0015)]
        lab.arm.move_linear(ends[0], 0.05, 0.5)
        k = 1
        while lab.clock.now() < sim_s:
            lab.arm.move_linear(ends[k], 0.01, 0.5, asynchronous=True)
            while lab.arm.is_moving() and lab.clock.now() < sim_s:
                lab.clock.sleep(0.05)
                record(lab, frames)
            k = 1 - k
    wall = time.perf_counter() - t0
    return {"bench": "sim_sweep", "sim_s": round(lab.clock.now(), 3), "wall_s": round(wall, 3),
            "build_s": round(build_s, 3), "fingers": len(lab.biotac.fingers),
            "biotac_frames": len(frames["biotac"]), "arm_states": len(frames["arm"]),
            "pac_samples": int(sum(f.pac.shape[1] for f in frames["biotac"])),
            "speedup": round(lab.clock.now() / wall, 1), "cpus": os.cpu_count()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sim-s", type=float, default=60.0)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    walls = []
    for i in range(args.repeat):
        r = sweep_for(args.sim_s, seed=i)
        walls.append(r["wall_s"])
        print(json.dumps(r), flush=True)
    print(json.dumps({"bench": "sim_sweep_summary", "sim_s": args.sim_s, "wall_s_median": float(np.median(walls)),
                      "wall_s_max": max(walls), "target_wall_s": 10.0,
                      "ok": max(walls) < 10.0}), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

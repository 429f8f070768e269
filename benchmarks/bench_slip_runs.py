"""Wall time of slip-in-place runs on the simulated lab (recording included, analysis off).

    python benchmarks/bench_slip_runs.py [--all]

One JSON line per run (condition, wall s, simulated s, frames) and a summary line; by default a
sample of the grid (each motion kind, both forces, both objects, with and without tare: 12 runs),
``--all`` the 72 runs of ``+experiment=slip_in_place_grid``.
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import xarray as xr

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tactile_flow.protocols.slip_grid import conditions, run_slip_in_place  # noqa: E402


def main() -> None:
    grid = conditions()
    if "--all" not in sys.argv:
        grid = [c for c in grid if c.direction_deg in (0.0,) and c.rotation_deg in (0.0, 30.0)]
    walls = []
    with tempfile.TemporaryDirectory() as tmp:
        run_slip_in_place(Path(tmp) / "warm-up", grid[0])       # imports, Hydra, caches
        for c in grid:
            t0 = time.perf_counter()
            r = run_slip_in_place(Path(tmp) / c.name, c)
            wall = time.perf_counter() - t0
            tree = xr.open_datatree(str(r.store), engine="zarr")
            frames = int(tree["biotac"].sizes["time"])
            walls.append(wall)
            print(json.dumps({"condition": c.name, "status": r.status, "wall_s": round(wall, 2),
                              "recorded_s": round(frames / 100.0, 2), "frames": frames}), flush=True)
    print(json.dumps({"runs": len(walls), "wall_s_median": round(float(np.median(walls)), 2),
                      "wall_s_max": round(float(np.max(walls)), 2), "wall_s_total": round(float(np.sum(walls)), 1)}))


if __name__ == "__main__":
    main()

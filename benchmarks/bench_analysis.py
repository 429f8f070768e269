"""Analysis time of a 60 s five-finger run and the fraction spent in tactile flow (JSON lines).

    python benchmarks/bench_analysis.py [--figures] [--keep DIR]

The run: a simulated straws sweep (``tactile-run``, one finger sweeping three straws, 15 s),
tiled to 60 s with every finger carrying the sweeping finger's data — all five fingers in
contact for 12 crossings each, a worst case for the flow (every finger analysed). Reports
the wall time of ``analysis.run.analyze_run`` (model cached as in a long session, and the
one-off model build separately), the time in rendering + optical flow, and frame counts.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
import xarray as xr


def make_store(work: Path, seconds: float = 60.0) -> Path:
    env = dict(os.environ)
    bin_dir = Path(sys.executable).parent
    subprocess.run([str(bin_dir / "tactile-run"), "analyze=false", "progress=false"], cwd=work, check=True,
                   capture_output=True, env=env)
    (src,) = work.glob("outputs/*/*/run.zarr")
    tree = xr.open_datatree(str(src), engine="zarr").load()
    d = {node.path: node.to_dataset() for node in tree.subtree if not node.path.startswith("/truth")}
    b, a = d["/biotac"], d["/arm"]
    span = float(b.time[-1] - b.time[0]) + 0.01
    n = int(np.ceil(seconds / span))
    ff = b.sel(finger="ff")

    def tile(ds, dim, fn=None):
        parts = []
        for i in range(n):
            p = ds.assign_coords({dim: ds[dim] + i * span})
            parts.append(p)
        return xr.concat(parts, dim=dim, data_vars="all")     # every variable along dim, as before
    bt = tile(b, "time")
    for var in ("electrodes", "pdc", "tdc", "tac"):
        src_v = tile(ff[[var]], "time")[var]
        bt[var] = src_v.expand_dims(finger=b.finger.values, axis=1).transpose(*b[var].dims).astype(b[var].dtype)
    bt["seq"] = ("time", np.arange(bt.sizes["time"]))
    bt = bt.isel(time=slice(0, int(seconds * 100)))
    d["/biotac"] = bt
    d["/arm"] = tile(a, "time_arm").isel(time_arm=slice(0, int(seconds * 500)))
    for k in [k for k in d if k.startswith(("/hand", "/pour", "/biotac_pac"))]:
        del d[k]
    out = work / "bench" / "run.zarr"
    out.parent.mkdir()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        xr.DataTree.from_dict(d).to_zarr(str(out), zarr_format=3, consolidated=True)
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--figures", action="store_true")
    ap.add_argument("--keep")
    args = ap.parse_args()
    from tactile_flow.analysis.config import load_config
    from tactile_flow.analysis.pipeline import get_model
    from tactile_flow.analysis.run import analyze_run
    work = Path(args.keep or tempfile.mkdtemp(prefix="bench-analysis-"))
    work.mkdir(parents=True, exist_ok=True)
    store = make_store(work)
    t0 = time.perf_counter()
    get_model(load_config({}).tactile)
    build = time.perf_counter() - t0
    t0 = time.perf_counter()
    s = analyze_run(store, {"progress": False, "figures": args.figures}, console=lambda *a: None)
    wall = time.perf_counter() - t0
    tm = s["timing"]
    print(json.dumps({"bench": "analysis_60s_5fingers", "record_s": 60.0, "fingers_in_contact":
                      s["headline"]["fingers_in_contact"], "segments": s["headline"]["segments"],
                      "wall_s": round(wall, 2), "model_build_s": round(build, 2),
                      "compute_s": round(tm["total_s"], 2), "flow_s": round(tm["flow_s"], 2),
                      "flow_fraction": round(tm["flow_s"] / wall, 3),
                      "frames_processed": tm["frames_processed"], "frames_total": tm["frames_total"],
                      "ms_per_view_frame": round(1e3 * tm["flow_s"] / max(tm["frames_processed"], 1), 3),
                      "figures": args.figures}))


if __name__ == "__main__":
    main()

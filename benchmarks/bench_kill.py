"""What a SIGKILL loses: kill real ``tactile-run`` processes mid-run and compare the run's own
time at the kill with the last committed sample in the store. Prints JSON lines.

    python benchmarks/bench_kill.py [--trials 8] [--modes default realtime]

Each trial runs the default protocol (straws sweep, ~14.7 s of run time) through
``benchmarks/clock_probe.py`` (the real ``tactile-run``, its simulated clock printed every
5 ms of wall time), kills it with SIGKILL when the run has reached a target time drawn
uniformly over the run, then reads the store as a reader (or ``tactile-recover``) sees it:

- ``run_s_at_kill``: the run's time (s since recording start) at the kill, from the probe;
- ``last_committed_s``: the time of the last BioTac frame the store holds;
- ``lost_s``: their difference — what the kill lost, in the run's own time.

``default`` runs the simulated lab as fast as the CPU allows (several times real time),
``realtime`` paces it to the wall clock (``hardware.realtime=true``).
"""

from __future__ import annotations

import argparse
import json
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import xarray as xr

ROOT = Path(__file__).resolve().parents[1]
PROBE = ROOT / "benchmarks" / "clock_probe.py"
RUN_S = 14.0                   # the default protocol's length in run time (s), a little short of it
MODES = {"default": [], "realtime": ["hardware.realtime=true"]}


def kill_at(run_dir: Path, target_s: float, extra=(), timeout_s: float = 120.0) -> dict:
    """Run the default protocol into ``run_dir``, SIGKILL it once its run time passes
    ``target_s``; return the trial's figures (see the module docstring)."""
    proc = subprocess.Popen([sys.executable, str(PROBE), "progress=false", "analyze=false",
                             f"hydra.run.dir={run_dir}", *extra], cwd=run_dir.parent,
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    store, t0, last_t, deadline = run_dir / "run.zarr", None, None, time.monotonic() + timeout_s
    for line in proc.stdout:
        if not line.startswith("t "):
            continue
        last_t = float(line.split()[1])
        if t0 is None:
            t0 = _t0(store)
        if (t0 is not None and last_t - t0 >= target_s) or time.monotonic() > deadline:
            proc.send_signal(signal.SIGKILL)
            break
    rest, _ = proc.communicate(timeout=30)
    times = [float(x.split()[1]) for x in rest.splitlines() if x.startswith("t ")]
    last_t = times[-1] if times else last_t
    t0 = _t0(store) if t0 is None else t0
    tree = xr.open_datatree(store, engine="zarr")
    frames = tree["biotac"]["time"].values
    last = float(frames[-1]) if len(frames) else 0.0
    return {"target_s": round(target_s, 3), "run_s_at_kill": round(last_t - t0, 3), "last_committed_s": round(last, 3),
            "lost_s": round(last_t - t0 - last, 3), "frames": int(len(frames)), "status": tree.attrs["status"]}


def _t0(store: Path) -> float | None:
    """The run's time origin on the simulated clock, once the store has committed it."""
    try:
        return float(json.loads((store / "zarr.json").read_text())["attributes"]["t0_clock_s"])
    except (OSError, ValueError, KeyError):
        return None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=8)
    parser.add_argument("--modes", nargs="+", default=list(MODES), choices=list(MODES))
    parser.add_argument("--seed", type=int, default=13)
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    for mode in args.modes:
        lost = []
        with tempfile.TemporaryDirectory() as tmp:
            for i in range(args.trials):
                row = kill_at(Path(tmp) / f"{mode}_{i}", float(rng.uniform(0.3, RUN_S)), MODES[mode])
                lost.append(row["lost_s"])
                print(json.dumps({"bench": "kill", "mode": mode, "trial": i, **row}), flush=True)
        print(json.dumps({"bench": "kill", "mode": mode, "trials": len(lost), "lost_s_max": max(lost),
                          "lost_s_median": round(float(np.median(lost)), 3), "lost_s_min": min(lost)}), flush=True)


if __name__ == "__main__":
    main()

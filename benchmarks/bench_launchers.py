"""Re-analysing many runs on Hydra's launchers (issue 15, goal 6): wall time as JSON lines.

    python benchmarks/bench_launchers.py [--runs 8] [--repeat 3] [--kind wait|straws] [--figures] [--keep DIR]

Records ``--runs`` simulated runs once (``tactile-run -m hardware.seed=1,2,... analyze=false``;
``wait``: a 2 s run with no contact, whose analysis is mostly start-up; ``straws``: the default
straws sweep, three straws crossed), then times ``tactile-analyze`` over their directory, each way
``--repeat`` times (wall time of the child process, min and median; ``vs_one_process`` is the
min against that of ``run=DIR``, all runs in one process):

- ``run=DIR``: one process, one run after another (no ``-m``);
- ``-m run=DIR``: one job per run on Hydra's basic launcher (one process, one job after another);
- ``joblib``, ``batch=B``: ``hydra/launcher=joblib hydra.launcher.n_jobs=2``, B runs per job;
- ``submitit_local``, ``batch=B``: a process per job (what SLURM runs), when installed.

Figures are off unless ``--figures`` (``analysis.figures=false``, as in a batch re-analysis).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ANALYZE = "from tactile_flow.analysis.cli import main; main()"
RUN = "from tactile_flow.protocols.cli import main; main()"


def record(work: Path, runs: int, kind: str) -> Path:
    """``runs`` simulated runs under ``work/multirun/...``; returns their sweep directory."""
    steps = ["protocol.steps=[{wait: {duration: 2}}]"] if kind == "wait" else []
    seeds = ",".join(str(i) for i in range(1, runs + 1))
    subprocess.run([sys.executable, "-c", RUN, "-m", *steps, f"hardware.seed={seeds}", "analyze=false",
                    "progress=false", "hydra/launcher=joblib", "hydra.launcher.n_jobs=2"], cwd=work, check=True,
                   capture_output=True)
    (sweep,) = work.glob("multirun/*/*")
    return sweep


def ways(sweep: Path) -> dict[str, list[str]]:
    joblib = ["hydra/launcher=joblib", "hydra.launcher.n_jobs=2"]
    out = {"run=DIR": [f"run={sweep}"], "-m run=DIR": ["-m", f"run={sweep}"]}
    out |= {f"joblib batch={b}": ["-m", f"run={sweep}", f"batch={b}", *joblib] for b in (1, 2, 4)}
    if importlib.util.find_spec("hydra_plugins.hydra_submitit_launcher"):
        out |= {f"submitit_local batch={b}": ["-m", f"run={sweep}", f"batch={b}", "hydra/launcher=submitit_local"]
                for b in (1, 4)}
    return out


def wall(args: list[str], cwd: Path) -> float:
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", ANALYZE, *args], cwd=cwd, capture_output=True, text=True)
    elapsed = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"tactile-analyze {' '.join(args)}: exit {proc.returncode}: {proc.stderr[-500:]}")
    return elapsed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=8)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--kind", choices=("wait", "straws"), default="wait")
    parser.add_argument("--figures", action="store_true")
    parser.add_argument("--keep", type=Path, help="work here and keep the runs (default: a temporary directory)")
    a = parser.parse_args()
    work = a.keep or Path(tempfile.mkdtemp(prefix="bench-launchers-"))
    work.mkdir(parents=True, exist_ok=True)
    try:
        sweep = record(work, a.runs, a.kind)
        common = ["analysis.progress=false", f"analysis.figures={str(a.figures).lower()}"]
        times = {name: [] for name in ways(sweep)}
        for _ in range(a.repeat):                       # interleaved: the machine's load hits every way alike
            for name, args in ways(sweep).items():
                times[name].append(wall(args + common, work))
        base = min(times["run=DIR"])
        for name, values in times.items():
            print(json.dumps({"bench": "launchers", "way": name, "kind": a.kind, "runs": a.runs,
                              "figures": a.figures, "n": len(values), "min_s": round(min(values), 2),
                              "median_s": round(statistics.median(values), 2),
                              "vs_one_process": round(min(values) / base, 2)}), flush=True)
    finally:
        if a.keep is None:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()

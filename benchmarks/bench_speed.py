"""Speed figures of issue 15 as JSON lines (min and median of several runs, paired ratios).

    python benchmarks/bench_speed.py [--repeat 3] [--only analysis,farneback,workers,startup,dryrun,dis] [--keep DIR]
    python benchmarks/bench_speed.py --only firstrun --repeat 2      # minutes: not in the default set

- ``analysis``: CPU of ``analyze_run`` (one worker, figures on) of the 60 s five-finger store
  of ``bench_analysis.py`` against the bare dynamic Farnebäck calls on the same frames, each
  repetition paired (ratio = analysis CPU / bare flow CPU); the figures' CPU alone, and the
  ratio without them. Each repetition analyses a fresh copy of the store (its first analysis);
  then analyses it again under another name with the same inputs (a new version of the
  analysis code would do the same): its figures are linked from the first, not drawn
  (``analysis/figure_reuse.py``), and that ratio is reported too.
- ``farneback``: CPU per flow of the same record's frames, OpenCV's call against
  ``tactile.farneback`` (each frame expanded once), consecutive pairs (dynamic) and pairs from
  one reference (static), paired within each repetition; the flows are checked equal.
- ``workers``: wall time of the same analysis with 1, 2, … the cores available, figures off and
  on (with several workers the figures are drawn in forked processes beside the writing); the
  serial part, and an Amdahl projection to 4 and 8 workers (figures off).
- ``startup``: ``tactile-run --help`` and ``tactile-analyze --help`` (wall and CPU of the child).
- ``dryrun``: the default dry run ``tactile-run progress=false`` (wall and CPU of the child).
- ``firstrun``: the default dry run on a machine that has compiled nothing (empty numba and
  geodesic caches), its kernels compiled in child processes (``tactile.warmup``, the default)
  and in the analysing process alone (``analysis.workers=1``), taking turns; wall, CPU and the
  paired ratio.
- ``dis``: each flow method / DIS preset on a simulated straws sweep and pour: flow CPU and the
  scores that the presets move (sweep direction error, pour phase onsets).
CPU is ``time.process_time`` (every thread of the process); the machine's other load shows in
the spread between min and median.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
BIN = Path(sys.executable).parent
QUIET = lambda *a: None  # noqa: E731


def stats(name: str, values: list[float], **extra) -> dict:
    return {"bench": name, "n": len(values), "min": round(min(values), 4),
            "median": round(statistics.median(values), 4), **extra}


def emit(row: dict) -> None:
    print(json.dumps(row), flush=True)


def fresh(store: Path, work: Path, name: str) -> Path:
    d = work / name
    shutil.rmtree(d, ignore_errors=True)
    d.mkdir(parents=True)
    shutil.copytree(store, d / "run.zarr")
    return d / "run.zarr"


def bare_dynamic_cpu(store: Path, cfg) -> float:
    """CPU of OpenCV's Farnebäck between consecutive frames of every (window, view) the analysis
    renders: every pair, called directly (the analysis skips pairs of empty frames)."""
    import cv2
    from tactile_flow.analysis.load import load_run
    from tactile_flow.analysis.pipeline import analyse, get_model
    a = analyse(load_run(store), cfg, get_model(cfg.tactile))
    c = cfg.tactile.flow
    frames = [vr.frames for cf in a.flows for vr in cf.views.values()]
    t0 = time.process_time()
    for fr in frames:
        for t in range(1, len(fr)):
            cv2.calcOpticalFlowFarneback(fr[t - 1], fr[t], None, c.pyr_scale, c.levels, c.winsize, c.iterations,
                                         c.poly_n, c.poly_sigma, c.flags)
    return time.process_time() - t0


def bench_analysis(store: Path, work: Path, repeat: int) -> None:
    from tactile_flow.analysis import figures
    from tactile_flow.analysis.config import load_config
    from tactile_flow.analysis.load import load_run
    from tactile_flow.analysis.pipeline import analyse, get_model
    from tactile_flow.analysis.run import analyze_run
    from tactile_flow.cliapp.heap import long_lived_frozen
    cfg = load_config({"progress": False, "workers": 1})
    get_model(cfg.tactile)
    analyze_run(fresh(store, work, "warm"), {"progress": False, "figures": False}, console=QUIET)   # numba, caches
    full, bare, ratio, figs, again = [], [], [], [], []
    for i in range(repeat):
        run, settings = fresh(store, work, f"a{i}"), {"progress": False, "workers": 1, "figures": True}
        t0 = time.process_time()
        analyze_run(run, settings, console=QUIET)
        full.append(time.process_time() - t0)
        t0 = time.process_time()
        s = analyze_run(run, settings, name="again", console=QUIET)                # its figures as drawn before
        again.append(time.process_time() - t0)
        assert len(s["figures"]) == len(json.loads((run.parent / "analyses" / "again" / "analysis.json").read_text())
                                        ["figures_reused"]), "the re-analysis drew figures"
        bare.append(bare_dynamic_cpu(store, cfg))
        ratio.append(full[-1] / bare[-1])
        a = analyse(load_run(store), cfg, get_model(cfg.tactile))
        with long_lived_frozen():                        # as analyze_run draws them
            t0 = time.process_time()
            figures.make_all(a, get_model(cfg.tactile), work / f"f{i}", cfg)
            figs.append(time.process_time() - t0)
    emit(stats("analysis_cpu_s", full, workers=1, figures=True, record="60 s, 5 fingers"))
    emit(stats("bare_dynamic_farneback_cpu_s", bare))
    emit(stats("analysis_over_bare_dynamic_ratio", ratio, paired=True, target=1.3))
    emit(stats("figures_cpu_s", figs))
    emit(stats("analysis_without_figures_over_bare_dynamic_ratio", [(f - g) / b for f, g, b in zip(full, figs, bare)],
               paired=True))
    emit(stats("reanalysis_figures_reused_over_bare_dynamic_ratio", [r / b for r, b in zip(again, bare)], paired=True,
               target=1.3))


def bench_farneback(store: Path, repeat: int) -> None:
    import cv2
    import numpy as np
    from tactile_flow.analysis.config import load_config
    from tactile_flow.analysis.load import load_run
    from tactile_flow.analysis.pipeline import analyse, get_model
    from tactile_flow.tactile import flow
    cfg = load_config({"progress": False, "workers": 1})
    a = analyse(load_run(store), cfg, get_model(cfg.tactile))
    c = cfg.tactile.flow
    windows = [vr.frames for cf in a.flows for vr in cf.views.values()]
    n = sum(len(fr) for fr in windows)

    def opencv(static: bool) -> list:
        return [[cv2.calcOpticalFlowFarneback(fr[0] if static else fr[t - 1], fr[t], None, c.pyr_scale, c.levels,
                                              c.winsize, c.iterations, c.poly_n, c.poly_sigma, c.flags)
                 for t in range(0 if static else 1, len(fr))] for fr in windows]

    def shared(static: bool) -> list:
        return [flow.static_flow(fr, 0, config=c) if static else flow.dynamic_flow(fr, config=c)[1:] for fr in windows]

    flow.dynamic_flow(windows[0][:2], config=c)                       # numba's kernels loaded
    for static in (False, True):
        kind = "static" if static else "dynamic"
        pairs = n if static else n - len(windows)
        ours, theirs = [], []
        for _ in range(repeat):
            t0 = time.process_time()
            got = shared(static)
            ours.append(time.process_time() - t0)
            t0 = time.process_time()
            want = opencv(static)
            theirs.append(time.process_time() - t0)
        equal = all(np.array_equal(g, np.asarray(w)) for g, w in zip(got, want) if len(w))
        emit(stats(f"farneback_{kind}_us_per_pair_opencv", [x / pairs * 1e6 for x in theirs], pairs=pairs))
        emit(stats(f"farneback_{kind}_us_per_pair_shared", [x / pairs * 1e6 for x in ours], pairs=pairs,
                   equal_to_opencv=equal))
        emit(stats(f"farneback_{kind}_shared_over_opencv_ratio", [o / t for o, t in zip(ours, theirs)], paired=True))


def bench_workers(store: Path, work: Path, repeat: int) -> None:
    from tactile_flow.tactile.warmup import available_cores
    from tactile_flow.analysis.run import analyze_run
    cores = available_cores()
    walls, serial, jobs = {}, {}, {}
    for figures in (False, True):
        for w in sorted({1, *range(2, cores + 1)}):
            key = (w, figures)
            walls[key], serial[key], jobs[key] = [], [], []
            for i in range(repeat):
                s = fresh(store, work, f"w{w}_{i}")
                t0 = time.perf_counter()
                timing = analyze_run(s, {"progress": False, "figures": figures, "workers": w},
                                     console=QUIET)["timing"]
                walls[key].append(time.perf_counter() - t0)
                serial[key].append(walls[key][-1] - timing["flow_stage_s"])   # loading, estimates, writing, figures
                jobs[key].append(timing["flow_s"])                              # the (window, view) jobs, summed
            speedup = statistics.median(walls[1, figures]) / statistics.median(walls[key])
            emit(stats("analysis_wall_s", walls[key], workers=w, cores=cores, figures=figures,
                       speedup_median=round(speedup, 3)))
            emit(stats("analysis_serial_wall_s", serial[key], workers=w, figures=figures))
            emit(stats("analysis_flow_jobs_s", jobs[key], workers=w, figures=figures))
    # Amdahl with the one-worker job time, figures off: cores that do not slow each other (this VM's do, goal 2).
    for n in (4, 8):
        emit({"bench": "analysis_wall_s_projected", "workers": n, "figures": False, "target": 2.0 if n == 8 else None,
              "value": round(statistics.median(serial[1, False]) + statistics.median(jobs[1, False]) / n, 3)})


def _child(cmd: list[str]) -> tuple[float, float]:
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def bench_startup(repeat: int) -> None:
    for cmd in ("tactile-run", "tactile-analyze"):
        runs = [_child([str(BIN / cmd), "--help"]) for _ in range(max(repeat, 5))]
        emit(stats(f"{cmd}_help_wall_s", [w for w, _ in runs], target=0.5))
        emit(stats(f"{cmd}_help_cpu_s", [c for _, c in runs]))
        r = subprocess.run([sys.executable, "-X", "importtime", "-c", f"import {'protocols' if cmd == 'tactile-run' else 'analysis'}.cli"],
                           capture_output=True, text=True)
        total = int(r.stderr.strip().splitlines()[-1].split("|")[1])
        emit({"bench": f"{cmd}_import_s", "value": round(total / 1e6, 4)})


def reference_cpu() -> float:
    """CPU seconds of a fixed workload (a Python loop and a numpy product, like the dry run's
    mix): on a shared machine the same work costs more CPU when the host is busy, so a dry
    run's CPU over this, paired, tells a slower program from a slower hour."""
    import numpy as np
    a = np.random.default_rng(0).random((300, 300))
    t0 = time.process_time()
    total = 0
    for i in range(4_000_000):
        total += i & 7
    for _ in range(20):
        a = np.tanh(a @ a / 300)
    return time.process_time() - t0


def bench_dryrun(work: Path, repeat: int) -> None:
    """The README's main job, ``tactile-run progress=false`` (simulation, recording, analysis,
    figures), in a child process: its wall and CPU, and its CPU over :func:`reference_cpu`
    measured just before it."""
    runs, refs = [], []
    for i in range(repeat):
        refs.append(reference_cpu())
        runs.append(_child([str(BIN / "tactile-run"), "progress=false", f"hydra.run.dir={work / f'dry{i}'}"]))
    emit(stats("dry_run_wall_s", [w for w, _ in runs], target=8.0))
    emit(stats("dry_run_cpu_s", [c for _, c in runs]))
    emit(stats("reference_cpu_s", refs))
    emit(stats("dry_run_cpu_over_reference", [c / r for (_, c), r in zip(runs, refs)], paired=True))


def bench_firstrun(work: Path, repeat: int) -> None:
    """:func:`bench_dryrun`'s job with empty caches (``NUMBA_CACHE_DIR``, ``TACTILE_CACHE_DIR``
    of its own), with the warm-up's children and without them (one worker), taking turns."""
    runs: dict[str, list] = {"children": [], "one_process": []}
    for i in range(repeat):
        for kind, extra in (("children", []), ("one_process", ["analysis.workers=1"])):
            caches = work / f"caches_{kind}{i}"
            os.environ.update(NUMBA_CACHE_DIR=str(caches / "numba"), TACTILE_CACHE_DIR=str(caches / "tactile"))
            try:
                runs[kind].append(_child([str(BIN / "tactile-run"), "progress=false", *extra,
                                          f"hydra.run.dir={work / f'first_{kind}{i}'}"]))
            finally:
                del os.environ["NUMBA_CACHE_DIR"], os.environ["TACTILE_CACHE_DIR"]
            shutil.rmtree(caches, ignore_errors=True)
    for kind, values in runs.items():
        emit(stats(f"first_dry_run_wall_s_{kind}", [w for w, _ in values]))
        emit(stats(f"first_dry_run_cpu_s_{kind}", [c for _, c in values]))
    emit(stats("first_dry_run_wall_children_over_one_process",
               [a[0] / b[0] for a, b in zip(runs["children"], runs["one_process"])], paired=True))


def simulated(protocol: str, work: Path) -> Path:
    d = work / f"sim_{protocol}"
    if not (d / "run.zarr").exists():
        subprocess.run([str(BIN / "tactile-run"), f"protocol={protocol}", "analyze=false", "progress=false",
                        f"hydra.run.dir={d}"], check=True, capture_output=True, cwd=work)
    return d / "run.zarr"


def bench_dis(work: Path) -> None:
    from tactile_flow.analysis.run import analyze_run
    methods = [("farneback", {}), *((f"dis_{p}", {"method": "dis", "dis_preset": p})
                                    for p in ("ultrafast", "fast", "medium"))]
    for protocol in ("straws_sweep", "pour_grasp"):
        store = simulated(protocol, work)
        for name, flow in methods:
            s = analyze_run(fresh(store, work, f"dis_{protocol}_{name}"),
                            {"progress": False, "figures": False, "workers": 1, "flow": flow}, console=QUIET)
            score = json.loads((work / f"dis_{protocol}_{name}" / "score.json").read_text())
            keep = ("direction_error_deg_max", "width_error_mm_median", "boundary_error_ms_max", "pour_phase_error_ms_max")
            emit({"bench": "flow_method", "protocol": protocol, "method": name, "flow_s": round(s["timing"]["flow_s"], 3),
                  **{k: score["summary"].get(k) for k in keep},
                  "rotation_error_ms": score.get("pour", {}).get("rotation", {}).get("error_ms"),
                  "all_targets_met": score.get("all_targets_met")})


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--only", default="analysis,farneback,workers,startup,dryrun,dis")
    ap.add_argument("--keep", help="work directory to keep (default: a temporary one)")
    args = ap.parse_args()
    parts = set(args.only.split(","))
    work = Path(args.keep or tempfile.mkdtemp(prefix="bench-speed-"))
    work.mkdir(parents=True, exist_ok=True)
    if "startup" in parts:
        bench_startup(args.repeat)
    if parts & {"analysis", "farneback", "workers"}:
        from bench_analysis import make_store
        store = work / "bench" / "run.zarr"
        if not store.exists():
            store = make_store(work)
        if "analysis" in parts:
            bench_analysis(store, work, args.repeat)
        if "farneback" in parts:
            bench_farneback(store, args.repeat)
        if "workers" in parts:
            bench_workers(store, work, args.repeat)
    if "dryrun" in parts:
        bench_dryrun(work, args.repeat)
    if "dis" in parts:
        bench_dis(work)
    if "firstrun" in parts:
        bench_firstrun(work, args.repeat)
    if not args.keep:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    os.environ.setdefault("PYTHONWARNINGS", "ignore")
    main()

"""A dataset of short recordings imported and analysed: files, bytes and records per second.

    python benchmarks/bench_dataset.py                       # 300 records
    python benchmarks/bench_dataset.py --large               # 3,000 records
    git archive <commit> | tar -x -C /tmp/before             # the code before, for a paired ratio
    python benchmarks/bench_dataset.py --before /tmp/before

Writes a synthetic dataset of ``--records`` short one-finger BioTac SP recordings made by the
simulated lab's fingertip (:func:`record_counts`; electrode-only CSVs at 100 Hz, 275 frames
each, laid out as a dataset of touches is: one folder per object, ``--folders``). Then, each
as its own process, the way a researcher runs them:

1. ``tactile-import source=DATASET rate_hz=100 out=IMPORTED workers=N``;
2. ``tactile-analyze run=IMPORTED workers=N`` (every run below it, figures on; off with
   ``--no-figures``; only some with ``--figures pressure,flow``: ``analysis.figures=[pressure,flow]``).

once with ``N`` = the cores available (``--workers``) and once with one worker (today's one
process), taking turns (``--repeat``), so their ratio is paired (the machine is shared and
noisy: compare the ratio, and the CPU seconds, not one wall time). With ``--before TREE`` (a
checkout of older code, e.g. ``git archive``'s) a third pass runs that code (its default
workers).

Prints one JSON line per pass (``"measure": "pass"``: wall and CPU seconds of import and
analysis, records/s, records/s per core, the load) and then the summary (``"summary":
"dataset"``): records/s imported + analysed with the cores and with one worker, their ratio,
CPU seconds per record, whether the two passes gave identical results (every analysis's
headline, ``analysis_summary.csv``, and the imported arrays of a sample of runs), and per
record the files and bytes of its ``run.zarr``, of its run directory without analyses, of
its current analysis without figures and of its figures, against its raw counts (275 × 24
int16 = 13.2 kB). A first import and analysis of a few records warms the numba caches and is
not counted. Target (issue 36): ≥ 10 records/s imported + analysed on 2 cores.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
FRAMES, RATE_HZ = 275, 100.0
REST_S, PRESS_S = 0.6, 0.3
RAW_BYTES = FRAMES * 24 * 2                       # int16 counts of one finger


def emit(**record) -> None:
    print(json.dumps(record), flush=True)


def cores() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def record_counts(sensor, seed: int) -> np.ndarray:
    """(FRAMES, n) electrode counts of one record, made by the simulated lab's fingertip (the
    contact model of :mod:`hardware.sim.world`, the sensor model's electrodes and noise,
    :class:`hardware.sim.sensor.BiotacModel`, as ``tests/sensor_record.py`` makes its presses):
    ``ff`` rests above a flat board for 0.6 s, presses 0.6-1.2 mm into it in 0.3 s, then slides
    along a heading and at a speed of its own (2-8 mm/s) to the end; a seed per record."""
    from tactile_flow.hardware.config import SensorModelConfig, load_config
    from tactile_flow.hardware.sim.sensor import BiotacModel, SensorInputs
    from tactile_flow.hardware.sim.world import SimWorld
    from tactile_flow.hardware.surfaces import load_surface
    rng = np.random.default_rng(seed)
    cfg = load_config({"fingers": ["ff"], "stage": None, "pour": {"bottle_in_hand": False}})
    world = SimWorld(cfg, load_surface({"kind": "flat", "name": "flat"}), sensor)
    model = BiotacModel(("ff",), SensorModelConfig(), rng, 1.0 / RATE_HZ, sensor)
    pole, top = sensor.shape.pole * 1e-3, world.surface.max_z
    heading, speed, depth_m = rng.uniform(0, 2 * np.pi), rng.uniform(2e-3, 8e-3), rng.uniform(0.6e-3, 1.2e-3)
    direction = np.array([np.cos(heading), np.sin(heading)])
    out = []
    for i in range(FRAMES):
        t = i / RATE_HZ
        s = np.clip((t - REST_S) / PRESS_S, 0, 1)
        moving = t > REST_S + PRESS_S
        xy = direction * speed * max(0.0, t - REST_S - PRESS_S)
        depth = depth_m * s - 2e-3 * (s == 0)
        pose = np.r_[0.3 + xy[0], xy[1], top - depth - pole[2], np.pi, 0.0, 0.0]
        world.follow(t, 1.0 / RATE_HZ, pose, np.r_[direction * speed * moving, 0.0])
        c = world.contacts["ff"]
        inputs = SensorInputs(np.array([c.load]), np.array([c.force]), np.array([world.force_rate["ff"]]),
                              np.array([c.friction]), np.array([c.shear_load]))
        out.append(model.frame(t, inputs)[0][0])
    return np.array(out).astype(np.int64)


def write_dataset(root: Path, records: int, folders: int, seed: int = 0, sensor: str = "biotac_sp") -> list[Path]:
    """``records`` CSVs (``e1..eN``, no time column: ``rate_hz=100``) in ``folders`` folders
    (``object_00``...) under ``root``."""
    from tactile_flow.tactile.sensor import builtin_sensor
    model = builtin_sensor(sensor)
    header = ",".join(f"e{i}" for i in range(1, model.n_taxels + 1))
    paths = []
    for k in range(records):
        d = root / f"object_{k % folders:02d}"
        d.mkdir(parents=True, exist_ok=True)
        counts = record_counts(model, seed * 1_000_003 + k)
        p = d / f"take_{k // folders:04d}.csv"
        p.write_text(header + "\n" + "\n".join(",".join(map(str, row)) for row in counts) + "\n")
        paths.append(p)
    return paths


def launcher(tree: Path | None, module: str) -> list[str]:
    """The command running ``tactile_flow.<module>:main`` from ``tree`` (a checkout, as an editable
    install of it would), or from the installed package."""
    if tree is None:
        return [sys.executable, "-c", f"from tactile_flow.{module} import main; main()"]
    code = ("import importlib.util, sys; root = sys.argv.pop(1); spec = importlib.util.spec_from_file_location("
            "'tactile_flow', root + '/tactile_flow/__init__.py', submodule_search_locations=[root + '/tactile_flow', "
            "root]); m = importlib.util.module_from_spec(spec); sys.modules['tactile_flow'] = m; "
            f"spec.loader.exec_module(m); from tactile_flow.{module} import main; main()")
    return [sys.executable, "-c", code, str(tree)]


def timed(cmd: list[str], cwd: Path) -> dict:
    """Run ``cmd`` (exit status 0 expected); its wall seconds and its output."""
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(cmd[:3])}... exited {proc.returncode}: {proc.stderr.strip()[-2000:]}")
    return {"wall_s": round(wall, 3), "stdout": proc.stdout}


def cpu_children() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def tree_size(path: Path, skip=()) -> tuple[int, int]:
    """Files and bytes under ``path`` (not following links), leaving out subtrees named in ``skip``;
    a file (a packed store, ``run.zarr.zip``) is one file."""
    if path.is_file():
        return 1, path.stat().st_size
    n = b = 0
    for here, dirs, names in os.walk(path):
        dirs[:] = [d for d in dirs if d not in skip]
        for name in names:
            p = Path(here) / name
            if not p.is_symlink():
                n += 1
                b += p.stat().st_size
    return n, b


def run_stores(root: Path) -> list[Path]:
    """Every run store below ``root``: ``run.zarr`` directories, packed ``run.zarr.zip`` files."""
    return sorted([*root.rglob("run.zarr"), *root.rglob("run.zarr.zip")])


def files_per_record(imported: Path) -> dict:
    """Median files and bytes per record: run.zarr, the run directory without analyses, the
    current analysis without figures, and its figures."""
    rows = []
    for store in run_stores(imported):
        run = store.parent
        analysis = (run / "analysis").resolve() if (run / "analysis").exists() else None
        row = {"store": tree_size(store), "run_dir": tree_size(run, skip=("analyses", "analysis"))}
        if analysis is not None:
            row["analysis"] = tree_size(analysis, skip=("figures",))
            row["figures"] = tree_size(analysis / "figures") if (analysis / "figures").is_dir() else (0, 0)
        rows.append(row)
    out = {"records": len(rows), "raw_counts_bytes": RAW_BYTES}
    for key in ("store", "run_dir", "analysis", "figures"):
        vals = [r[key] for r in rows if key in r]
        if vals:
            out[f"{key}_files"] = int(np.median([v[0] for v in vals]))
            out[f"{key}_bytes"] = int(np.median([v[1] for v in vals]))
    out["store_over_raw"] = round(out["store_bytes"] / RAW_BYTES, 2)
    out["run_dir_over_raw"] = round(out["run_dir_bytes"] / RAW_BYTES, 2)
    return out


FIGURES = {"on": True, "only": None}


def figure_overrides(before: bool = False) -> list[str]:
    """The ``analysis.figures`` override of the passes (the code before has no list: every figure)."""
    if not FIGURES["on"]:
        return ["analysis.figures=false"]
    if FIGURES["only"] and not before:
        return [f"analysis.figures=[{','.join(FIGURES['only'])}]"]
    return []


def one_pass(code: str, tree: Path | None, dataset: Path, work: Path, n: int, workers: int | None) -> dict:
    """Import then analyse the whole dataset with one code and ``workers`` (``None``: the
    code's default); the measures of both steps."""
    imported = work / f"imported_{code}"
    shutil.rmtree(imported, ignore_errors=True)
    extra = [f"workers={workers}"] if workers else []
    c0 = cpu_children()
    imp = timed(launcher(tree, "importers.cli") + [f"source={dataset}", f"out={imported}", f"rate_hz={RATE_HZ:g}",
                                                   *extra], work)
    c1 = cpu_children()
    ana = timed(launcher(tree, "analysis.cli") + [f"run={imported}", "analysis.progress=false", *extra,
                                                  *figure_overrides(code.endswith("before"))], work)
    c2 = cpu_children()
    out = {"code": code, "workers": workers, "records": n, "import_wall_s": imp["wall_s"],
           "import_cpu_s": round(c1 - c0, 2), "analyze_wall_s": ana["wall_s"], "analyze_cpu_s": round(c2 - c1, 2)}
    total = imp["wall_s"] + ana["wall_s"]
    out["records_per_s"] = round(n / total, 3)
    out["records_per_s_per_core"] = round(n / total / cores(), 3)
    out["import_records_per_s"] = round(n / imp["wall_s"], 3)
    out["analyze_records_per_s"] = round(n / ana["wall_s"], 3)
    out["cpu_s_per_record"] = round((c2 - c0) / n, 4)
    out["files"] = files_per_record(imported)
    return out


def same_results(a: Path, b: Path, sample: int = 10) -> dict:
    """Whether two imports + analyses of one dataset agree: ``analysis_summary.csv`` (every
    run's headline: segments, slip class, direction, displacement, confidence...) with the
    paths made alike, and every array of ``sample`` run stores, value for value."""
    from tactile_flow.runstore import open_group
    table = [(d / "analysis_summary.csv").read_text().replace(str(d.name), "IMPORTED") for d in (a, b)]
    stores = sorted(p.relative_to(a) for p in run_stores(a))
    step = max(1, len(stores) // sample)
    arrays = 0
    same_arrays = True
    for rel in stores[::step]:
        ga, gb = open_group(a / rel), open_group(b / rel)
        for path in _array_paths(ga):
            arrays += 1
            x, y = ga[path][...], gb[path][...]
            same_arrays &= bool(np.array_equal(x, y, equal_nan=x.dtype.kind == "f"))
    return {"summary_tables_equal": table[0] == table[1], "arrays_compared": arrays, "arrays_equal": same_arrays}


def _array_paths(group, prefix: str = "") -> list[str]:
    out = []
    for name, member in group.members():
        path = f"{prefix}{name}"
        out += _array_paths(member, path + "/") if hasattr(member, "members") else [path]
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--records", type=int, default=300)
    p.add_argument("--large", action="store_true", help="3,000 records")
    p.add_argument("--folders", type=int, default=10, help="objects (subfolders) the records are spread over")
    p.add_argument("--workers", type=int, default=None, help="import and analysis workers (default: the cores)")
    p.add_argument("--before", type=Path, default=None, help="a checkout of older code to compare with too")
    p.add_argument("--no-figures", action="store_true", help="analyse with analysis.figures=false")
    p.add_argument("--figures", default=None, help="draw only these figures, e.g. pressure,flow (analysis.figures="
                                                   "[pressure,flow]; the code before draws them all)")
    p.add_argument("--repeat", type=int, default=1, help="passes of each, taking turns")
    p.add_argument("--dir", type=Path, default=None, help="work here (kept; the dataset reused) instead of a "
                                                          "temporary directory")
    a = p.parse_args(argv)
    n = 3000 if a.large else a.records
    FIGURES["on"] = not a.no_figures
    FIGURES["only"] = [f.strip() for f in a.figures.split(",") if f.strip()] if a.figures else None
    workers = a.workers or cores()
    work = a.dir or Path(tempfile.mkdtemp(prefix="bench_dataset_"))
    work.mkdir(parents=True, exist_ok=True)
    try:
        dataset, warm = work / f"dataset_{n}", work / "warm"
        if not dataset.is_dir() or len(list(dataset.rglob("*.csv"))) != n:
            shutil.rmtree(dataset, ignore_errors=True)
            write_dataset(dataset, n, a.folders)
        shutil.rmtree(warm, ignore_errors=True)
        write_dataset(warm, 4, 2, seed=1)
        raw = sum(p.stat().st_size for p in dataset.rglob("*.csv"))
        emit(measure="dataset", records=n, files=n, csv_bytes=raw, folders=a.folders)
        passes = [("cores", None, workers), ("one_worker", None, 1)]
        passes += [("before", a.before.resolve(), None)] if a.before else []
        for code, tree, w in passes:                    # numba caches, the geodesics: not counted
            one_pass(f"warm_{code}", tree, warm, work, 4, w)
        load_before = round(os.getloadavg()[0], 2)
        results = {code: [] for code, *_ in passes}
        for rep in range(a.repeat):
            for code, tree, w in passes if rep % 2 == 0 else passes[::-1]:
                r = one_pass(code, tree, dataset, work, n, w)
                r["load"] = round(os.getloadavg()[0], 2)
                results[code].append(r)
                emit(measure="pass", repeat=rep, **r)
        summary = {"records": n, "figures": (FIGURES["only"] or True) if FIGURES["on"] else False, "cores": cores(), "workers": workers, "load_before": load_before,
                   "load_after": round(os.getloadavg()[0], 2)}
        for code, rs in results.items():
            summary[f"{code}_records_per_s"] = [r["records_per_s"] for r in rs]
            summary[f"{code}_cpu_s_per_record"] = [r["cpu_s_per_record"] for r in rs]
        summary["ratio_cores_over_one_worker"] = [round(x["records_per_s"] / y["records_per_s"], 3)
                                                  for x, y in zip(results["cores"], results["one_worker"])]
        if a.before:
            summary["ratio_cores_over_before"] = [round(x["records_per_s"] / y["records_per_s"], 3)
                                                  for x, y in zip(results["cores"], results["before"])]
        summary["identical_to_one_worker"] = same_results(work / "imported_cores", work / "imported_one_worker")
        summary["files"] = results["cores"][-1]["files"]
        summary["target_records_per_s"] = 10.0
        emit(summary="dataset", **summary)
    finally:
        if a.dir is None:
            shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Feature widths read per electrode, with and without each electrode's share of the pad's load.

    python benchmarks/bench_widths.py [--out DIR] [--sensor biotac biotac_sp] [--gains 3 6 12]
                                      [--seeds 0 1] [--protocol straws_sweep sticks_sweep]
                                      [--electrodes] [--load-fraction F]

Records (or reuses, in ``--out``) each ``tactile-run sensor=S protocol=P
hardware.sensor.shear_kohm_per_n=G hardware.seed=N`` (not analysed there), analyses it twice with
``tactile-analyze``'s defaults in memory — ``analysis.estimates.width_load_fraction`` at 0 (the
activation as it is: the reading before) and at its default (each electrode's share of the pad's
load taken off first, ``analysis/estimates.py`` ``remove_load_share``; ``--load-fraction``: at F) —
and scores both against
the simulator's truth. Prints JSON lines: per run, the score's ``width_error_mm_median`` and
``boundary_error_mm_median`` of both readings; with ``--electrodes``, per run and electrode of the
width's plateaus (median over the crossings): its name, its position along the sweep from the
pad's centre (mm, + where the feature arrives first), its rise as a fraction of the largest, its
width and the distance the finger had travelled at its rise and its fall (mm), both readings
(before: every electrode that felt the feature, ``used`` for the width's). Then
a markdown table of the width errors (docs/sensors.md, "Measured").
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from tactile_flow.analysis import score as scoring
from tactile_flow.analysis.config import for_sensor, load_config
from tactile_flow.analysis.load import load_run, open_truth
from tactile_flow.analysis.pipeline import analyse, get_model

TRUE_WIDTH_MM = {"straws_sweep": 6.0, "sticks_sweep": 10.0}


def record(out: Path, sensor: str, protocol: str, gain: float, seed: int) -> Path:
    run = out / f"{sensor}_{protocol}_g{gain:g}_s{seed}"
    if not (run / "run.zarr").exists() or "success" not in (run / "tactile-run.log").read_text(errors="replace"):
        cmd = [str(Path(sys.executable).parent / "tactile-run"), f"sensor={sensor}", f"protocol={protocol}",
               f"hardware.sensor.shear_kohm_per_n={gain:g}", f"hardware.seed={seed}", "analyze=false",
               "progress=false", f"hydra.run.dir={run}"]
        proc = subprocess.run(cmd, capture_output=True, text=True)
        if proc.returncode != 0:
            raise SystemExit(f"error: {' '.join(cmd)} failed: {proc.stderr.strip().splitlines()[-1:]}")
    return run


def read(run_dir: Path, load_fraction: float | None):
    """(analysis, score) with the defaults, ``width_load_fraction`` replaced unless None."""
    node = {"figures": False, "progress": False}
    if load_fraction is not None:
        node["estimates"] = {"width_load_fraction": load_fraction}
    run = load_run(run_dir / "run.zarr")
    cfg = for_sensor(load_config(node), run.sensor)
    a = analyse(run, cfg, get_model(cfg.tactile, run.sensor))
    return a, scoring.score(a, open_truth(run))


def electrodes(a, true_width: float, every: bool, fraction: float) -> list[dict]:
    """Per electrode of the width's plateaus (median over the crossings of the first finger);
    ``every``: of every electrode that felt the feature (the texture angle's plateaus, read on the
    activation as it is), ``used`` saying which rose by ``fraction`` of the largest (the width's)."""
    run = a.run
    pad = np.arange(run.n_taxels)[run.sensor.pad if run.sensor.pad is not None else slice(None)]
    per: dict[int, list] = {}
    passed: dict[int, list] = {}
    for (_f, _start, _stop), (texture, width) in sorted(a.plateaus.items()):
        if width is None or texture is None:
            continue
        for j, e in enumerate(texture.used):
            passed.setdefault(int(e), []).append(texture.passing_mm[j])
        p = texture if every else width
        for j, e in enumerate(p.used):
            per.setdefault(int(e), []).append((p.rise_fraction[j], p.width_mm[j], p.start_mm[j],
                                               p.end_mm[j]))
    if not per:
        return []
    xy = run.sensor.taxels[pad, :2]
    # along the sweep: the electrodes' positions projected on the direction in which the feature
    # passes them (the passing distance, of every electrode that felt it, grows along it); + where
    # it arrives first
    used = sorted(per)
    felt = sorted(passed)
    pos = xy[felt] - xy.mean(axis=0)
    passing = np.array([np.median(passed[e]) for e in felt])
    q = np.linalg.lstsq(np.c_[np.ones(len(felt)), pos], passing, rcond=None)[0][1:] if len(felt) >= 3 else np.zeros(2)
    along = -(xy - xy.mean(axis=0)) @ (q / np.linalg.norm(q)) if np.linalg.norm(q) > 0 else np.zeros(len(pad))
    return [{"electrode": run.sensor.taxel_names[pad[e]], "along_mm": round(float(along[e]), 2),
             "rise_fraction": round(float(np.median([r[0] for r in per[e]])), 2),
             "width_mm": round(float(np.median([r[1] for r in per[e]])), 2),
             "width_error_mm": round(float(np.median([r[1] for r in per[e]])) - true_width, 2),
             "rise_mm": round(float(np.median([r[2] for r in per[e]])), 2),
             "fall_mm": round(float(np.median([r[3] for r in per[e]])), 2),
             "used": bool(np.median([r[0] for r in per[e]]) >= fraction)} for e in used]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("/tmp/bench_widths"))
    ap.add_argument("--sensor", nargs="+", default=["biotac", "biotac_sp"])
    ap.add_argument("--gains", nargs="+", type=float, default=[3.0, 6.0, 12.0])
    ap.add_argument("--seeds", nargs="+", type=int, default=[0, 1])
    ap.add_argument("--protocol", nargs="+", default=["straws_sweep", "sticks_sweep"], choices=sorted(TRUE_WIDTH_MM))
    ap.add_argument("--electrodes", action="store_true", help="also each electrode's plateau, both readings")
    ap.add_argument("--load-fraction", type=float, default=None,
                    help="the second reading's width_load_fraction (default: the analysis's default)")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    for sensor in args.sensor:
        for protocol in args.protocol:
            for gain in args.gains:
                for seed in args.seeds:
                    run_dir = record(args.out, sensor, protocol, gain, seed)
                    row = {"sensor": sensor, "protocol": protocol, "gain": gain, "seed": seed}
                    for tag, fraction in (("kept", 0.0), ("taken", args.load_fraction)):
                        a, s = read(run_dir, fraction)
                        row[f"width_error_mm_{tag}"] = s["summary"]["width_error_mm_median"]
                        row[f"boundary_error_mm_{tag}"] = s["summary"]["boundary_error_mm_median"]
                        if args.electrodes:
                            row[f"electrodes_{tag}"] = electrodes(a, TRUE_WIDTH_MM[protocol], tag == "kept",
                                                                  load_config({}).estimates.width_taxel_fraction)
                    print(json.dumps(row), flush=True)
                    rows.append(row)
    print("\n| sensor | protocol | gain | seed | width error, load kept (mm) | load taken off (mm) | "
          "boundaries, kept | taken |\n| --- | --- | --- | --- | --- | --- | --- | --- |")
    f = lambda v: "–" if v is None else f"{v:.2f}"                                    # noqa: E731
    for r in rows:
        figures = [f(r[f"{k}_error_mm_{tag}"]) for k in ("width", "boundary") for tag in ("kept", "taken")]
        print(f"| {r['sensor']} | {r['protocol']} | {r['gain']:g} | {r['seed']} | " + " | ".join(figures) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

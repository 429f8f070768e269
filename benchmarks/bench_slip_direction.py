"""Accuracy of the slip estimate on simulated slip-in-place runs, per evidence source, and the
real grasp frames' contact detection rate.

    python benchmarks/bench_slip_direction.py [--out DIR] [--noise 0.5 1 2] [--quick] [--sensor biotac_sp biotac]

Runs (or reuses, in ``--out``) the slip-in-place grid of ``conf/experiment/slip_in_place_grid.yaml``
(6 directions × 2 rotations × touch × 2 forces × 2 objects × with/without tare) at each noise
level (``hardware.sensor.noise_scale`` and the object's tremor scaled together) for each sensor
model (``sensor=``: by default the BioTac SP and the classic BioTac), analyses every run with
``tactile-analyze``'s defaults and scores it against the simulator's truth. Prints one JSON line
per (sensor, noise, force, object, tare) cell and evidence source, then the totals per sensor,
then a markdown table per sensor (docs/analysis.md, docs/sensors.md). Sources:

- ``static_unloaded`` (negated: docs/analysis.md), ``static_onset``, ``dynamic``,
  ``cop_unloaded``, ``cop_onset``: each alone — direction of translations within 45°, rotation
  sense of rotations (the flow sources that measure one), touch vs slip at the best single
  threshold on the source's magnitude (an upper bound: what fitting one threshold could reach);
- ``combined``: the slip estimate as shipped (``slip_class``, ``slip_direction_sensor_deg``,
  ``rotation_deg`` with the default thresholds).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SOURCES = ("static_unloaded", "static_onset", "dynamic", "cop_unloaded", "cop_onset")
SIGN = {"static_unloaded": -1.0}


def angle_error(a, b) -> float:
    return abs((a - b + 180.0) % 360.0 - 180.0)


def runs(out: Path, noise: float, quick: bool, sensor: str = "biotac_sp"):
    """Yield (condition, store) for every grid run at ``noise`` with the sensor model ``sensor``,
    running the missing ones."""
    from tactile_flow.protocols.slip_grid import conditions, run_slip_in_place
    conds = conditions()
    if quick:
        conds = [c for c in conds if c.surface == "flat" and c.press_force == conds[0].press_force]
    for c in conds:
        d = out / sensor / f"noise{noise:g}" / c.name
        if not (d / "run.zarr").exists():
            r = run_slip_in_place(d, c, noise=noise, overrides=[f"sensor={sensor}"])
            if r.status != "success":
                print(json.dumps({"run": c.name, "status": r.status, "error": r.error}), file=sys.stderr)
                continue
        yield c, d / "run.zarr"


def evaluate(store: Path, cfg):
    """(truth row, slip estimate of the matched contact segment) of one run, analysed with the
    sensor model it was recorded with."""
    from tactile_flow.analysis.load import load_run, open_truth
    from tactile_flow.analysis.pipeline import analyse
    from tactile_flow.analysis.score import score
    a = analyse(load_run(store), cfg)
    sc = score(a, open_truth(store))
    row = sc.get("object_motions", [{}])[0]
    est = a.slips.get(row.get("segment"))
    return row, est


def source_values(est: dict, source: str):
    """(direction deg or None, magnitude mm or None, rotation deg or None) of one evidence source."""
    ev = est["evidence"].get(source) or {}
    v = ev.get("vector_mm")
    direction = mag = None
    if v is not None and any(v):
        s = SIGN.get(source, 1.0)
        direction = math.degrees(math.atan2(s * v[1], s * v[0]))
        mag = math.hypot(*v)
    return direction, mag, ev.get("rotation_deg")


def best_threshold_accuracy(values, is_slip) -> float | None:
    """Fraction right of 'slip if value ≥ t' at the best t (an upper bound of one fitted threshold)."""
    pairs = [(v, s) for v, s in zip(values, is_slip) if v is not None]
    if not pairs:
        return None
    vals = sorted({v for v, _ in pairs})
    cuts = [vals[0] - 1.0] + [(a + b) / 2 for a, b in zip(vals, vals[1:])] + [vals[-1] + 1.0]
    return max(np.mean([(v >= t) == s for v, s in pairs]) for t in cuts)


def summarise(rows) -> dict:
    """Accuracy per source and combined over ``rows`` = [(condition, truth row, estimate)]."""
    out = {}
    for source in SOURCES:
        dirs, rots, mags, slips = [], [], [], []
        for c, tr, est in rows:
            if est is None:
                continue
            d, m, r = source_values(est, source)
            if c.motion == "translate":
                dirs.append(d is not None and angle_error(d, tr["true_direction_sensor_deg"]) <= 45.0)
            if c.motion == "rotate" and r is not None:
                rots.append(r != 0 and math.copysign(1, r) == math.copysign(1, tr["true_rotation_deg"]))
            mags.append(m)
            slips.append(c.motion != "none")
        out[source] = {"direction": float(np.mean(dirs)) if dirs else None,
                       "rotation_sense": float(np.mean(rots)) if rots else None,
                       "touch_vs_slip_best_threshold": best_threshold_accuracy(mags, slips)}
    found = [tr.get("contact_found", False) for _, tr, _ in rows]
    comb = defaultdict(list)
    for c, tr, est in rows:
        if c.motion == "translate":
            comb["direction"].append(bool(tr.get("direction_correct")))
        if c.motion == "rotate":
            comb["rotation_sense"].append(bool(tr.get("rotation_sense_correct")))
        comb["touch_vs_slip"].append(bool(tr.get("touch_vs_slip_correct")))
        comb["class"].append(bool(tr.get("class_correct")))
    out["combined"] = {k: float(np.mean(v)) for k, v in comb.items()}
    out["combined"]["contact_found"] = float(np.mean(found)) if found else None
    out["runs"] = len(rows)
    return out


def real_contact_rate() -> dict:
    """Rows of the real grasp frames (tests/data) found in contact on at least one finger, against
    a baseline pooled over each file and the real resting sensors' noise (as the tests do)."""
    import csv

    from tactile_flow.analysis.preprocess import despike
    from tactile_flow.importers import read_bag, select_fingers
    from tactile_flow.tactile import contact, signals
    data = ROOT / "tests" / "data"
    rec, _ = select_fingers(read_bag(data / "biotac_rest_untouched.bag"))
    z = signals.counts_to_impedance(rec.electrodes.astype(float))
    base = z.mean(axis=0)
    smooth = base + signals.kalman_smooth(despike(z - base, 5), R=0.005, Q=0.00015)
    noise = contact.residual_noise(np.log(z), np.log(smooth))
    found = total = 0
    for path in sorted((data / "biotac_sp_grasps").glob("*.csv")):
        with open(path) as f:
            rows = np.array([[float(x) for x in r[2:]] for r in list(csv.reader(f))[1:]]).reshape(-1, 3, 24)
        rows = np.clip(rows, 1, 4094)
        ch = contact.relative_change(signals.counts_to_impedance(rows),
                                     signals.counts_to_impedance(np.percentile(rows, 95, axis=0)))
        score = contact.contact_score(ch, noise).max(axis=1)
        found += int((score > 6.0).sum())
        total += len(rows)
    rest_max = float(contact.contact_score(contact.relative_change(smooth, base), noise).max())
    return {"real_grasp_rows": total, "found_in_contact": found, "rate": found / total,
            "real_resting_recording_max_score": rest_max}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path(os.environ.get("TMPDIR", "/tmp")) / "bench_slip_direction")
    ap.add_argument("--noise", type=float, nargs="+", default=[1.0])
    ap.add_argument("--quick", action="store_true", help="flat object and light force only")
    ap.add_argument("--sensor", nargs="+", default=["biotac_sp", "biotac"],
                    help="sensor models (conf/sensor/): the BioTac SP and the classic BioTac by default")
    args = ap.parse_args(argv)
    from tactile_flow.analysis.config import load_config
    cfg = load_config({"figures": False, "progress": False})
    totals = {}
    for sensor in args.sensor:
        t0 = time.perf_counter()
        everything = []
        for noise in args.noise:
            cells = defaultdict(list)
            for c, store in runs(args.out, noise, args.quick, sensor):
                tr, est = evaluate(store, cfg)
                cells[(c.press_force, c.surface, c.tare)].append((c, tr, est))
                everything.append((noise, c, tr, est))
            for (force, surface, tare), rows in sorted(cells.items()):
                print(json.dumps({"sensor": sensor, "noise": noise, "force_n": force, "object": surface, "tare": tare,
                                  **summarise(rows)}))
        totals[sensor] = total = summarise([(c, tr, est) for _, c, tr, est in everything])
        print(json.dumps({"sensor": sensor, "all": True, **total, "seconds": round(time.perf_counter() - t0, 1)}))
        for tare in (True, False):
            print(json.dumps({"sensor": sensor, "tare": tare,
                              **summarise([(c, tr, e) for _, c, tr, e in everything if c.tare == tare])}))
    print(json.dumps({"sensor": "biotac_sp", "real_contact_detection": real_contact_rate()}))
    fmt = lambda v: "–" if v is None else f"{100 * v:.0f} %"  # noqa: E731
    for sensor, total in totals.items():
        print(f"\n{sensor}:\n\n| source | direction (≤45°) | rotation sense | touch vs slip |\n| --- | --- | --- | --- |")
        for source in SOURCES:
            r = total[source]
            print(f"| {source} | {fmt(r['direction'])} | {fmt(r['rotation_sense'])} | "
                  f"{fmt(r['touch_vs_slip_best_threshold'])} (best threshold) |")
        r = total["combined"]
        print(f"| combined (shipped) | {fmt(r.get('direction'))} | {fmt(r.get('rotation_sense'))} | "
              f"{fmt(r.get('touch_vs_slip'))} |")


if __name__ == "__main__":
    main()

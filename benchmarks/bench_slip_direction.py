"""The slip estimate on simulated slip-in-place runs, per evidence source, and on real touches.

    python benchmarks/bench_slip_direction.py [--out DIR] [--grid classic|varied] [--noise 1]
                                              [--real-touch 6] [--quick] [--sensor biotac_sp biotac]
                                              [--seeds 1]

Runs (or reuses, in ``--out``) the slip-in-place grid — ``classic``: the 72 conditions of
``+experiment=slip_in_place_grid`` (6 directions 60° apart, both rotation senses, a touch × light
1.3 N and firm 5 N × flat and cylinder × with and without tare); ``varied``: the 120 of
``protocols.slip_grid.varied_conditions()`` (contacts off the pad's pole, twists about an axis
away from the contact, pulls and twists of every speed, a hand's wander) — at each noise level,
analyses every run with ``tactile-analyze``'s defaults and scores it against the simulator's
truth. Then it writes records of real touches (``tests/real_touch.py``: real contact frames held
under the real resting noise, from the first frame and reached from rest; ``--real-touch`` frames
per finger and grasp file) and counts how many read as touch. ``--seeds N`` runs every condition
with the simulator's seeds 0 … N−1 (``hardware.seed``: the sensor's noise and the holder's
tremor): a grid N times the size, for figures with more than 16 rotations behind them.

Each sensor model of ``--sensor`` (``conf/sensor/``; by default the BioTac SP and the classic
BioTac, docs/sensors.md) runs the grid with its own fingertips, and its lines and tables are
headed by its name. Prints JSON lines (per run: the truth, what it was read as, its displacement and rotation
evidence, the onset's error; per condition cell: tare/no tare × light/firm; the totals; the onset; the
real touches), then markdown tables (docs/analysis.md):

- the confusion matrix of the shipped estimate over the true motion (each translation
  direction, each rotation sense, touch) and what it was read as (translations, true and read,
  binned to the nearest of 0°, 60°, … 300°; a rotation by its sense; touch), per cell and over all;
- per evidence source, the shipped decision with that source alone in its place: the
  direction of translations from ``motion`` (the centre of pressure since the first settled
  frames), ``cop_unloaded``, ``static_unloaded`` (negated), ``static_onset``, ``dynamic``; the
  rotation, for every contact, from ``rotation_dynamic``, ``rotation_static``, ``rotation_turn``
  (the pattern's second moments), ``rotation_peak`` (the 90th percentile of the two flows' mean
  turn over the contact, not its end) or ``rotation_mean`` (the two flows' end values averaged:
  round 2's decision) — the shipped turn reads the peak where the contact stayed in place and
  the end values where it moved (``analysis.slip.turn``) — and ``rotation:beyond_pulls``, the
  end values less what a pull's spurious turn explains (the pulls' median |turn| per mm of the
  grid × the displacement) — each class's share read right, with its count;
- the slip onset's error against the truth's (ms): within 50 ms, median, 90th and 95th percentiles of
  its magnitude, and how many of the dated slips have the truth within ± their
  ``slip_onset_uncertainty_s`` (is the uncertainty honest).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import sys
import time
from collections import Counter, defaultdict
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DIRECTION_SOURCES = ("motion", "cop_unloaded", "static_unloaded", "static_onset", "dynamic")
ROTATION_SOURCES = ("rotation_mean", "rotation_dynamic", "rotation_static", "rotation_turn", "rotation_peak")
SIGN = {"static_unloaded": -1.0}


def angle_error(a, b) -> float:
    return abs((a - b + 180.0) % 360.0 - 180.0)


def runs(out: Path, grid: str, noise: float, quick: bool, sensor: str = "biotac_sp", seed: int = 0,
         overrides: tuple[str, ...] = ()):
    """Yield (condition, store) for every run of the grid at ``noise`` with the fingertips of the
    sensor model ``sensor`` and the simulator's ``seed``, running the missing ones (the BioTac
    SP's in ``out/<grid>``, as before; another model's in ``out/<sensor>/<grid>``; a seed other
    than 0 in ``…/<grid>/seed<seed>``; runs with Hydra ``overrides`` in ``…/<grid>/set-<them>``)."""
    from tactile_flow.protocols.slip_grid import conditions, run_slip_in_place, varied_conditions
    conds = varied_conditions() if grid == "varied" else conditions()
    if quick:
        conds = conds[::4]
    for c in conds:
        d = (out if sensor == "biotac_sp" else out / sensor) / grid / (f"seed{seed}" if seed else "") \
            / ("set-" + ",".join(overrides).replace("/", "_") if overrides else "") / f"noise{noise:g}" / c.name
        if not (d / "run.zarr").exists():
            shutil.rmtree(d, ignore_errors=True)
            try:
                r = run_slip_in_place(d, c, noise=noise, seed=seed, overrides=[f"sensor={sensor}", *overrides])
            except Exception as exc:  # noqa: BLE001 - a condition the plan check refuses: said, skipped
                print(json.dumps({"run": c.name, "status": "refused", "error": str(exc)}), file=sys.stderr)
                continue
            if r.status != "success":
                print(json.dumps({"run": c.name, "status": r.status, "error": r.error}), file=sys.stderr)
                continue
        yield c, d / "run.zarr"


def evaluate(store: Path, model, cfg):
    """(truth row of score.json's object_motions, the slip estimate it was scored on)."""
    from tactile_flow.analysis.load import load_run, open_truth
    from tactile_flow.analysis.pipeline import analyse
    from tactile_flow.analysis.score import score
    run = load_run(store)
    a = analyse(run, cfg, model if model is not None and model.sensor is run.sensor else None)   # the store's model
    sc = score(a, open_truth(store))
    row = (sc.get("object_motions") or [{}])[0]
    return row, a.slips.get(row.get("segment"))


def true_label(c, bins=None) -> str:
    """The truth in the confusion matrix's terms (a translation binned to ``bins`` if given)."""
    if c.motion == "translate":
        d = c.direction_deg if bins is None else min(bins, key=lambda b: angle_error(c.direction_deg, b))
        return f"translate {d % 360:.0f}°"
    if c.motion == "rotate":
        return "rotate ccw" if c.rotation_deg > 0 else "rotate cw"
    return "touch"


def read_label(slip_class, direction, rotation, bins) -> str:
    """What an estimate says, in the confusion matrix's terms (a translation binned to ``bins``)."""
    if slip_class == "translation" and direction is not None:
        nearest = min(bins, key=lambda b: angle_error(direction, b))
        return f"translate {nearest % 360:.0f}°"
    if slip_class == "rotation" and rotation:
        return "rotate ccw" if rotation > 0 else "rotate cw"
    if slip_class == "none":
        return "touch"
    return "undecided"


def source_direction(est, source):
    ev = est["evidence"].get(source) or {}
    v = ev.get("vector_mm")
    if not v or not any(v):
        return None
    s = SIGN.get(source, 1.0)
    return math.degrees(math.atan2(s * v[1], s * v[0]))


def source_rotation(est, source):
    rot = est["evidence"].get("rotation") or {}
    key = {"rotation_mean": "rotation_deg", "rotation_dynamic": "dynamic_deg", "rotation_static": "static_deg",
           "rotation_turn": "pattern_turn_deg",
           "rotation_peak": "peak_deg"}[source]
    return rot.get(key)


def reread(est, cfg, rotation_source=None, direction_source=None, per_mm=None):
    """The shipped decision with one evidence source in place of the shipped one (a rotation
    source in place of every one of the shipped turn's readings: the end values, the peak and the
    static turn's rise and end).
    ``per_mm`` (deg/mm): the turn read is the flows' end values less ``per_mm`` × the
    displacement (what a pull's spurious turn explains), towards 0."""
    from tactile_flow.analysis.slip import classify, turn
    if est is None or est.get("slip_class") is None:
        return None, None, None
    rot_ev = dict(est["evidence"]["rotation"])
    motion = est["evidence"]["motion"]
    if rotation_source:
        rot_ev.update(rotation_deg=source_rotation(est, rotation_source), peak_deg=None, static_deg=None,
                      static_rise_deg=None)
    if per_mm is not None:
        end = rot_ev.get("rotation_deg") or 0.0
        rot_ev.update(rotation_deg=math.copysign(max(0.0, abs(end) - per_mm * motion["displacement_mm"]), end),
                      peak_deg=None, static_deg=None, static_rise_deg=None)
    cls, _ = classify(motion["displacement_mm"], rot_ev, motion["radius_mm"], est.get("direction_agreement"), cfg)
    direction = source_direction(est, direction_source) if direction_source else est["slip_direction_sensor_deg"]
    if direction is None and cls == "translation":     # a variant reads as a translation what the shipped did not
        direction = (est["evidence"].get("direction") or {}).get("direction_deg")
    return cls, direction, turn(motion["displacement_mm"], rot_ev, cfg)[0]


def summarise(rows, cfg, bins, per_mm=None) -> dict:
    """Rates per true class of the shipped estimate and of each source in its place (and, with
    ``per_mm``, of the turn beyond what the pulls' spurious turn per mm explains: :func:`reread`)."""
    out = {"runs": len(rows)}
    variants = {"shipped": {}}
    variants.update({f"direction:{s}": {"direction_source": s} for s in DIRECTION_SOURCES})
    variants.update({f"rotation:{s}": {"rotation_source": s} for s in ROTATION_SOURCES})
    if per_mm is not None:
        variants["rotation:beyond_pulls"] = {"per_mm": per_mm}
    for name, kw in variants.items():
        right = defaultdict(list)
        for c, tr, est in rows:
            cls, direction, rotation = reread(est, cfg.slip, **kw)
            truth = true_label(c, bins)
            got = read_label(cls, direction, rotation, bins)
            right[c.motion].append(got == truth if c.motion != "translate" else
                                   (cls == "translation" and direction is not None
                                    and angle_error(direction, c.direction_deg) <= 45.0))
            right["touch_vs_slip"].append((cls == "none") == (c.motion == "none"))
            if c.motion == "rotate":
                right["rotation_sense"].append(bool(rotation) and rotation * c.rotation_deg > 0)
                right["rotation_recognised"].append(cls == "rotation")
        out[name] = {k: float(np.mean(v)) for k, v in right.items()}
        out[name]["counts"] = {k: [int(np.sum(v)), len(v)] for k, v in right.items()}
    errs = [1e3 * (est["slip_onset_s"] - tr["true_slip_onset_s"]) for c, tr, est in rows
            if c.motion != "none" and est and est.get("slip_onset_s") is not None
            and tr.get("true_slip_onset_s") is not None and math.isfinite(tr["true_slip_onset_s"])]
    slips = sum(c.motion != "none" for c, *_ in rows)
    inside = [abs(est["slip_onset_s"] - tr["true_slip_onset_s"]) <= est["slip_onset_uncertainty_s"]
              for c, tr, est in rows if c.motion != "none" and est and est.get("slip_onset_s") is not None
              and est.get("slip_onset_uncertainty_s") is not None
              and tr.get("true_slip_onset_s") is not None and math.isfinite(tr["true_slip_onset_s"])]
    out["onset"] = {"slips": slips, "dated": len(errs), "within_uncertainty": int(sum(inside)),
                    "within_50ms": (float(np.sum(np.abs(errs) <= 50.0)) / slips) if slips else None,
                    "median_ms": float(np.median(errs)) if errs else None,
                    "abs_q90_ms": float(np.percentile(np.abs(errs), 90)) if errs else None,
                    "abs_q95_ms": float(np.percentile(np.abs(errs), 95)) if errs else None}
    return out


def spurious_per_mm(rows) -> float | None:
    """The pulls' median spurious turn per mm of displacement (|end values' mean| / displacement,
    deg/mm) over ``rows``: the constant of the compensated variant, taken from the pulls alone."""
    v = [abs(est["evidence"]["rotation"]["rotation_deg"]) / est["slip_displacement_mm"]
         for c, _, est in rows if c.motion == "translate" and est and est.get("slip_displacement_mm")
         and (est["evidence"].get("rotation") or {}).get("rotation_deg") is not None]
    return float(np.median(v)) if v else None


def confusion(rows, cfg, bins) -> tuple[list[str], Counter]:
    labels = [f"translate {b % 360:.0f}°" for b in bins] + ["rotate ccw", "rotate cw", "touch"]
    counts = Counter()
    for c, tr, est in rows:
        cls, direction, rotation = reread(est, cfg.slip)
        counts[(true_label(c, bins), read_label(cls, direction, rotation, bins))] += 1
    return labels, counts


def markdown_confusion(labels, counts) -> str:
    cols = labels + ["undecided"]
    lines = ["| true \\ read | " + " | ".join(cols) + " | right |", "| --- " * (len(cols) + 2) + "|"]
    for t in labels:
        n = sum(counts[(t, r)] for r in cols)
        if not n:
            continue
        lines.append(f"| {t} | " + " | ".join(str(counts[(t, r)] or "·") for r in cols)
                     + f" | {counts[(t, t)]}/{n} |")
    return "\n".join(lines)


def spurious_turns(rows, bins) -> str:
    """Markdown: what the pulls' rotation evidence reads per mm of displacement (deg/mm, median
    and range over the pulls of each direction): a pull has no turn, so this is the flows' own
    spurious turn, the noise the rotation decision must rise above."""
    per = defaultdict(lambda: defaultdict(list))
    for c, tr, est in rows:
        if c.motion != "translate" or not est or not est.get("slip_displacement_mm"):
            continue
        rot, d = est["evidence"].get("rotation") or {}, est["slip_displacement_mm"]
        b = min(bins, key=lambda x: angle_error(c.direction_deg, x)) % 360
        for key in ("dynamic_deg", "static_deg", "rotation_deg"):
            if rot.get(key) is not None:
                per[b][key].append(rot[key] / d)
    cell = lambda v: f"{np.median(v):+.2f} ({min(v):+.2f}…{max(v):+.2f})" if v else "–"  # noqa: E731
    lines = ["\n| pull direction | pulls | dynamic flow, deg/mm | static flow, deg/mm | their mean (shipped), deg/mm |",
             "| --- | --- | --- | --- | --- |"]
    for b in sorted(per):
        p = per[b]
        lines.append(f"| {b:.0f}° | {len(p['rotation_deg'])} | {cell(p['dynamic_deg'])} | {cell(p['static_deg'])} | "
                     f"{cell(p['rotation_deg'])} |")
    return "\n".join(lines)


def real_touch(out: Path, per_finger: int) -> dict:
    """Records of real contact frames held still, read as touch (``tests/real_touch.py``)."""
    sys.path.insert(0, str(ROOT / "tests"))
    import real_touch as rt
    work = out / "real_touch"
    shutil.rmtree(work, ignore_errors=True)
    dirs = rt.write_records(work / "csv", per_finger)
    result = {}
    for kind, ds in dirs.items():
        read = Counter()
        for d in ds:
            for row in rt.read_as_touch(d, work / "imported" / kind, rt.BASELINE[kind]):
                read[(row["slip"] or {}).get("slip_class") or "no estimate"] += 1
        n = sum(read.values())
        result[kind] = {"records": n, "read_as": dict(read), "touch_rate": read["none"] / n if n else None}
    return result


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path(os.environ.get("TMPDIR", "/tmp")) / "bench_slip_direction")
    ap.add_argument("--grid", choices=("classic", "varied"), default="classic")
    ap.add_argument("--noise", type=float, nargs="+", default=[1.0])
    ap.add_argument("--real-touch", type=int, default=6, help="real contact frames per finger and grasp file (0: none)")
    ap.add_argument("--quick", action="store_true", help="every fourth condition")
    ap.add_argument("--seeds", type=int, default=1, help="run each condition with the simulator's seeds 0 … N−1")
    ap.add_argument("--set", nargs="+", default=[], metavar="KEY=VALUE",
                    help="Hydra overrides of every run, e.g. hardware.sensor.shear_kohm_per_n=3 (runs kept apart)")
    ap.add_argument("--sensor", nargs="+", default=["biotac_sp", "biotac"],
                    help="sensor models (conf/sensor/): the BioTac SP and the classic BioTac by default")
    args = ap.parse_args(argv)
    for sensor in args.sensor:
        print(f"\n## sensor {sensor}\n", flush=True)
        bench(args, sensor)


def bench(args, sensor: str) -> None:
    """The benchmark of :func:`main` with the fingertips of the sensor model ``sensor``."""
    from tactile_flow.analysis.config import load_config
    from tactile_flow.analysis.pipeline import get_model
    from tactile_flow.protocols.slip_grid import DIRECTIONS_DEG
    cfg = load_config({"figures": False, "progress": False})
    model = get_model(cfg.tactile) if sensor == "biotac_sp" else None
    bins = DIRECTIONS_DEG if args.grid == "classic" else tuple(range(0, 360, 60))
    t0 = time.perf_counter()
    everything = []
    for noise, seed in [(n, s) for n in args.noise for s in range(args.seeds)]:
        for c, store in runs(args.out, args.grid, noise, args.quick, sensor, seed, tuple(args.set)):
            tr, est = evaluate(store, model, cfg)
            everything.append((noise, c, tr, est))
            rot = ((est or {}).get("evidence") or {}).get("rotation") or {}
            print(json.dumps({"sensor": sensor, "run": c.name, "noise": noise, "seed": seed, "truth": true_label(c, bins),
                              "read": read_label(*reread(est, cfg.slip), bins),
                              "displacement_mm": (est or {}).get("slip_displacement_mm"),
                              **{k: rot.get(k) for k in ("dynamic_deg", "static_deg", "peak_deg")},
                              "onset_error_ms": None if not est or est.get("slip_onset_s") is None
                              or not math.isfinite(tr.get("true_slip_onset_s", float("nan")))
                              else round(1e3 * (est["slip_onset_s"] - tr["true_slip_onset_s"]), 1)}),
                  flush=True)
    rows = [(c, tr, est) for _, c, tr, est in everything]
    per_mm = spurious_per_mm(rows)
    cells = defaultdict(list)
    for c, tr, est in rows:
        force = "light" if c.press_force < 3.0 else "firm"
        cells[("tare" if c.tare else "no tare", force)].append((c, tr, est))
    for (tare, force), cell in sorted(cells.items()):
        print(json.dumps({"sensor": sensor, "grid": args.grid, "tare": tare, "force": force,
                          **summarise(cell, cfg, bins, per_mm)}))
    total = summarise(rows, cfg, bins, per_mm)
    print(json.dumps({"sensor": sensor, "grid": args.grid, "all": True, "pulls_spurious_deg_per_mm": per_mm, **total,
                      "seconds": round(time.perf_counter() - t0, 1)}))
    touch = real_touch(args.out, args.real_touch) if args.real_touch and sensor == "biotac_sp" else None   # real SPs
    if touch:
        print(json.dumps({"real_touch": touch}))
    fmt = lambda v: "–" if v is None else f"{100 * v:.0f} %"  # noqa: E731
    print(f"\n{sensor}, {args.grid} grid, {len(rows)} runs: the shipped estimate\n")
    print(markdown_confusion(*confusion(rows, cfg, bins)))
    for (tare, force), cell in sorted(cells.items()):
        print(f"\n{tare}, {force} ({len(cell)} runs)\n")
        print(markdown_confusion(*confusion(cell, cfg, bins)))
    print("\n| evidence in the decision | translations (direction ≤ 45°) | rotations (class and sense) | "
          "touches | touch vs slip | rotation sense | rotation recognised |\n| --- | --- | --- | --- | --- | --- | --- |")
    for name, r in total.items():
        if not isinstance(r, dict) or name == "onset":
            continue
        cell = lambda k: fmt(r.get(k)) + (" ({}/{})".format(*r["counts"][k]) if k in r["counts"] else "")  # noqa: E731
        print(f"| {name} | " + " | ".join(cell(k) for k in ("translate", "rotate", "none", "touch_vs_slip",
                                                             "rotation_sense", "rotation_recognised")) + " |")
    if per_mm is not None:
        print(f"\n(rotation:beyond_pulls: the end values less {per_mm:.2f} deg/mm × the displacement, "
              "the pulls' median spurious turn per mm on this grid)")
    print(spurious_turns(rows, bins))
    o = total["onset"]
    print(f"\nslip onset: {o['dated']} of {o['slips']} slips dated; within 50 ms of the truth: {fmt(o['within_50ms'])}; "
          f"median error {o['median_ms'] if o['median_ms'] is None else round(o['median_ms'], 1)} ms; "
          f"90th percentile of |error| {o['abs_q90_ms'] if o['abs_q90_ms'] is None else round(o['abs_q90_ms'], 1)} ms; "
          f"95th {o['abs_q95_ms'] if o['abs_q95_ms'] is None else round(o['abs_q95_ms'], 1)} ms; "
          f"the truth within ± slip_onset_uncertainty_s: {o['within_uncertainty']} of {o['dated']}")
    if touch:
        for kind, r in touch.items():
            print(f"real touches ({kind}): {r['records']} records, read as touch {fmt(r['touch_rate'])} ({r['read_as']})")


if __name__ == "__main__":
    main()

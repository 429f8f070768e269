"""How each rotation evidence of the slip estimate separates twists from touches and from pulls.

    python benchmarks/bench_rotation_evidence.py [--out DIR] [--set KEY=VALUE ...] [--real-touch 6]
                                                 [--rows FILE ...]

Reads the slip-in-place grid that ``benchmarks/bench_slip_direction.py`` wrote (same ``--out``,
``--set``, ``--grid``, ``--noise``, ``--seeds``; missing runs are run), analyses every run with
``tactile-analyze``'s defaults, and prints one JSON line per run with all of its rotation
evidence (``evidence.rotation`` of the slip estimate: ``dynamic_deg``, ``static_deg``, the rise of
the static turn's ramp ``static_rise_deg``, the mean of the dynamic and static end values
``rotation_deg``, ``peak_deg``, ``pattern_turn_deg``, and the turn the decision read), its
displacement and its contact's radius. Then a markdown table, per evidence: the twists' smallest
|turn| and how many read the right sense, the touches' and the pulls' largest |turn|, the margins
(twists' smallest over touches' largest; the pulls compared by the decision's arc ratio,
|turn|·r/displacement, twists' smallest over pulls' largest) and, with ``--real-touch N``, the
same evidence of records of real touches (``tests/real_touch.py``, ``N`` frames per finger and
grasp file, written in ``--out``): its 95th percentile and largest |turn|. Last, for the
contacts that stayed in place, what a threshold on the decision's turn or on ``static_deg``
alone would recognise and read wrongly (docs/analysis.md), and for them the static turn with
how straight it went (``static_straightness``: |end| / the path it travelled), alone and together
with a threshold on the turn. ``--rows FILE ...``
tabulates the JSON lines of earlier runs instead of analysing the grid (real touches added
either way).

Used to measure the grid at the shear gain the real contact frames allow
(``--set hardware.sensor.shear_kohm_per_n=3``; docs/analysis.md, "At the shear gain the real
frames allow").
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_slip_direction as bsd  # noqa: E402

EVIDENCE = ("dynamic_deg", "static_deg", "static_rise_deg", "rotation_deg", "peak_deg", "pattern_turn_deg", "turn_deg")


def rows_of(args) -> list[dict]:
    """One dict per run of the grid: its truth and every rotation evidence of its slip estimate."""
    from tactile_flow.analysis.config import load_config
    from tactile_flow.analysis.pipeline import get_model
    cfg = load_config({"figures": False, "progress": False})
    model = get_model(cfg.tactile)
    out = []
    for noise in args.noise:
        for seed in range(args.seeds):
            for c, store in bsd.runs(args.out, args.grid, noise, False, "biotac_sp", seed, tuple(args.set)):
                _, est = bsd.evaluate(store, model, cfg)
                if not est or est.get("slip_class") is None:
                    continue
                rot, motion = est["evidence"]["rotation"], est["evidence"]["motion"]
                row = {"run": c.name, "seed": seed, "motion": c.motion,
                       "sense": (1 if c.rotation_deg > 0 else -1) if c.motion == "rotate" else 0,
                       "read": est["slip_class"], "displacement_mm": est["slip_displacement_mm"],
                       "radius_mm": motion["radius_mm"], "elongation": rot.get("pattern_elongation"),
                       "change": motion.get("change"), "change_noise": motion.get("change_noise"),
                       "read_as": rot.get("read_as"), "static_straightness": rot.get("static_straightness"),
                       **{k: rot.get(k) for k in EVIDENCE}}
                print(json.dumps(row), flush=True)
                out.append(row)
    return out


def real_touch_rows(out: Path, per_finger: int) -> list[dict]:
    """The same evidence of records of real touches (``tests/real_touch.py``: real contact frames
    held under the real resting noise, from the first frame and reached from rest), as
    ``benchmarks/bench_slip_direction.py --real-touch`` writes them."""
    import shutil
    sys.path.insert(0, str(bsd.ROOT / "tests"))
    import real_touch as rt
    work = out / "real_touch_evidence"
    shutil.rmtree(work, ignore_errors=True)
    rows = []
    for kind, ds in rt.write_records(work / "csv", per_finger).items():
        for d in ds:
            for r in rt.read_as_touch(d, work / "imported" / kind, rt.BASELINE[kind]):
                est = r["slip"]
                if not est or est.get("slip_class") is None:
                    continue
                rot = est["evidence"]["rotation"]
                row = {"run": f"{kind}/{d.name}/{r['record']}", "motion": "real_touch", "sense": 0,
                       "read": est["slip_class"], "displacement_mm": est["slip_displacement_mm"],
                       "radius_mm": est["evidence"]["motion"]["radius_mm"],
                       "change": est["evidence"]["motion"].get("change"),
                       "change_noise": est["evidence"]["motion"].get("change_noise"),
                       "elongation": rot.get("pattern_elongation"), "read_as": rot.get("read_as"),
                       "static_straightness": rot.get("static_straightness"),
                       **{k: rot.get(k) for k in EVIDENCE}}
                print(json.dumps(row), flush=True)
                rows.append(row)
    return rows


def arc_ratio(row, key) -> float:
    """|turn| as the arc it sweeps at the contact's radius, over the displacement (the decision's test)."""
    v = row.get(key)
    if v is None:
        return float("nan")
    return abs(v) * math.pi / 180.0 * row["radius_mm"] / max(row["displacement_mm"], 1e-9)


def _real_cell(values) -> str:
    return f"{np.percentile(values, 95):.2f}, {max(values):.2f}" if values else "–"


def table(rows: list[dict]) -> str:
    """Markdown: per evidence, the twists against the touches (|turn|) and the pulls (arc ratio)."""
    twists = [r for r in rows if r["motion"] == "rotate"]
    touches = [r for r in rows if r["motion"] == "none"]
    pulls = [r for r in rows if r["motion"] == "translate"]
    real = [r for r in rows if r["motion"] == "real_touch"]
    lines = ["| evidence | twists: smallest \\|turn\\|, median, deg | right sense | touches: largest \\|turn\\|, deg "
             "| twists' smallest / touches' largest | pulls: largest \\|turn\\|, deg | twists' smallest / pulls' "
             "largest arc ratio | real touches from the first frame: 95th percentile, largest \\|turn\\|, deg "
             "| real touches reached from rest: 95th percentile, largest \\|turn\\|, deg |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for key in EVIDENCE:
        tw = np.array([abs(r[key]) for r in twists if r.get(key) is not None])
        sense = sum(1 for r in twists if r.get(key) is not None and r[key] * r["sense"] > 0)
        to = np.array([abs(r[key]) for r in touches if r.get(key) is not None])
        pu = np.array([abs(r[key]) for r in pulls if r.get(key) is not None])
        tw_arc = min((arc_ratio(r, key) for r in twists if r.get(key) is not None), default=float("nan"))
        pu_arc = max((arc_ratio(r, key) for r in pulls if r.get(key) is not None), default=float("nan"))
        if not len(tw):
            continue
        real_cell = " | ".join(_real_cell([abs(r[key]) for r in real if r.get(key) is not None
                                           and r["run"].startswith(kind + "/")]) for kind in ("first", "rest"))
        lines.append(f"| `{key}` | {tw.min():.2f}, {np.median(tw):.2f} | {sense}/{len(twists)} | "
                     f"{to.max() if len(to) else float('nan'):.2f} | "
                     f"{tw.min() / to.max() if len(to) and to.max() > 0 else float('nan'):.2f} | "
                     f"{pu.max() if len(pu) else float('nan'):.2f} | "
                     f"{tw_arc:.3f} / {pu_arc:.3f} = {tw_arc / pu_arc if pu_arc > 0 else float('nan'):.1f} | {real_cell} |")
    d_tw = max(r["displacement_mm"] for r in twists)
    d_to = max(r["displacement_mm"] for r in touches)
    d_pu = min(r["displacement_mm"] for r in pulls)
    lines.append(f"\n(displacement: twists ≤ {d_tw:.2f} mm, touches ≤ {d_to:.2f} mm, pulls ≥ {d_pu:.2f} mm; "
                 f"{len(twists)} twists, {len(touches)} touches, {len(pulls)} pulls, {len(real)} real touches)")
    return "\n".join(lines)


THRESHOLDS = (("turn_deg", (0.9, 0.2, 0.35, 0.45)), ("static_deg", (0.25, 0.35, 0.45)),
              ("static_rise_deg", (0.3, 0.45)))
"""The readings and thresholds (deg) :func:`thresholds` counts."""


def thresholds(rows: list[dict], min_displacement_mm: float) -> str:
    """Markdown: for the contacts that stayed in place (displacement under
    ``min_displacement_mm``), what a threshold on each reading of :data:`THRESHOLDS` gives —
    twists recognised with the right sense, touches (simulated, real from the first frame, real
    reached from rest) read as rotations."""
    def still(r, key, t):
        return r["displacement_mm"] < min_displacement_mm and r.get(key) is not None and abs(r[key]) >= t
    groups = {"twists": lambda r: r["motion"] == "rotate", "touches": lambda r: r["motion"] == "none",
              "real, first frame": lambda r: r["motion"] == "real_touch" and r["run"].startswith("first/"),
              "real, from rest": lambda r: r["motion"] == "real_touch" and r["run"].startswith("rest/")}
    lines = ["| threshold | reading | " + " | ".join(groups) + " |", "| --- " * (len(groups) + 2) + "|"]
    for key, ts in THRESHOLDS:
        for t in ts:
            cells = []
            for name, member in groups.items():
                mine = [r for r in rows if member(r)]
                hit = sum(still(r, key, t) and (name != "twists" or r[key] * r["sense"] > 0) for r in mine)
                cells.append(f"{hit}/{len(mine)}")
            lines.append(f"| {t:.2f}° | `{key}` | " + " | ".join(cells) + " |")
    return "\n".join(lines)


STRAIGHT = ((0.25, 0.15), (0.25, 0.2), (0.3, 0.15), (0.35, 0.0))
"""(|``static_deg``| deg, ``static_straightness``) pairs :func:`straightness` counts."""


def straightness(rows: list[dict], min_displacement_mm: float) -> str:
    """Markdown: for the contacts that stayed in place, the static turn and how straight it went
    (``static_straightness``: |end| / the path it travelled) — the twists' smallest, the touches'
    (simulated, real from the first frame, real reached from rest) largest — and what reading a
    twist by both at once would recognise and read wrongly (docs/analysis.md)."""
    groups = {"twists": lambda r: r["motion"] == "rotate", "touches": lambda r: r["motion"] == "none",
              "real, first frame": lambda r: r["motion"] == "real_touch" and r["run"].startswith("first/"),
              "real, from rest": lambda r: r["motion"] == "real_touch" and r["run"].startswith("rest/")}
    still = [r for r in rows if r["displacement_mm"] < min_displacement_mm and r.get("static_deg") is not None
             and r.get("static_straightness") is not None]
    lines = ["| | " + " | ".join(groups) + " |", "| --- " * (len(groups) + 1) + "|"]
    for key, label in (("static_deg", "\\|`static_deg`\\|, deg"), ("static_straightness", "`static_straightness`")):
        cells = []
        for name, member in groups.items():
            v = [abs(r[key]) for r in still if member(r)]
            cells.append("–" if not v else (f"smallest {min(v):.2f}" if name == "twists" else f"largest {max(v):.2f}"))
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    for t, q in STRAIGHT:
        cells = []
        for name, member in groups.items():
            mine = [r for r in still if member(r)]
            hit = sum(abs(r["static_deg"]) >= t and r["static_straightness"] >= q
                      and (name != "twists" or r["static_deg"] * r["sense"] > 0) for r in mine)
            cells.append(f"{hit}/{len(mine)}")
        lines.append(f"| ≥ {t:.2f}° and straightness ≥ {q:.2f} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path(os.environ.get("TMPDIR", "/tmp")) / "bench_slip_direction")
    ap.add_argument("--grid", choices=("classic", "varied"), default="classic")
    ap.add_argument("--noise", type=float, nargs="+", default=[1.0])
    ap.add_argument("--seeds", type=int, default=1)
    ap.add_argument("--set", nargs="+", default=[], metavar="KEY=VALUE")
    ap.add_argument("--real-touch", type=int, default=0,
                    help="real contact frames per finger and grasp file whose records to add (0: none)")
    ap.add_argument("--rows", type=Path, nargs="+",
                    help="JSON lines of earlier runs: tabulate them instead of analysing the grid")
    args = ap.parse_args(argv)
    if args.rows:
        rows = [json.loads(x) for f in args.rows for x in f.read_text().splitlines() if x.startswith("{")]
    else:
        rows = rows_of(args)
    if args.real_touch:
        rows += real_touch_rows(args.out, args.real_touch)
    from tactile_flow.analysis.config import load_config
    print()
    print(table(rows))
    print("\n(twists: recognised with the right sense; touches: read as rotations)\n")
    print(thresholds(rows, load_config({}).slip.min_displacement_mm))
    print("\n(contacts that stayed in place: the static turn and how straight it went; twists: recognised "
          "with the right sense, touches: read as rotations)\n")
    print(straightness(rows, load_config({}).slip.min_displacement_mm))


if __name__ == "__main__":
    main()

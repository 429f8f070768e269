"""The simulated BioTac SP's electrode changes against the real contact frames the project ships.

    python benchmarks/bench_sim_vs_real.py [--out DIR] [--seed 0] [--shear-scales 1,0.5,0.25]

Deterministic (numpy only, seeded; ~20 s of CPU). Prints JSON lines and markdown tables,
and writes ``DIR/sim_vs_real.png`` (default ``DIR`` = ``docs/figures``, the figure
docs/simulator.md shows):

1. **The press**: every real finger contact of ``tests/data/biotac_sp_grasps`` (3698 rows of
   ff, mf, th; 10 859 finger contacts) measured as :mod:`hardware.sim.calibrate_contact` measures
   them — local drops from the unloaded state and the far level, an electrode *moved* when its
   drop passes the calibration's threshold (5 × the rest noise ⊕ the baseline uncertainty,
   102 counts) — split into light / mid / firm terciles of the summed drop; beside them
   simulated presses of the ff pad on the flat board at the light and firm forces
   (``hardware.sim.contact_check.PRESS_FORCES``), measured the same way against the simulated
   sensor's true unloaded counts. Per measure: the real quantiles (5, 25, 50, 75, 95 %) and
   the percentile of the real distribution at which the simulated median falls.
2. **The resting recording** (``tests/data/biotac_rest_untouched.bag``): the same measures on
   frames of sensors at rest (against their own mean): how often noise alone passes the
   threshold (the floor of "electrodes moved").
3. **Pull and twist against press**: the same simulated presses, then the object stage pulls
   4 mm at 5 mm/s (four directions) or twists ±30° at 40°/s, or nothing happens (a touch, the
   noise floor), then 0.3 s of hold. The change of every electrode from the pressed state
   (the mean of the 0.5 s hold before the motion) at its largest (a 50 ms moving mean) and at
   the end (the last 100 ms), as the summed |change| over the 24 electrodes, the largest
   |change|, the electrodes whose |change| passes the threshold, and the ratio of the summed
   |change| to the press's summed drop; the shift of the pattern's centre (mm); and the state
   after the motion measured as the real frames are (its percentile among the real contacts).
4. **The shear's size**: a pull at 0° and a twist of +30° again with
   ``hardware.sensor.shear_kohm_per_n`` scaled by each of ``--shear-scales`` (a configuration
   override; the simulator is not changed): which size keeps a pulled contact inside the real ones.

No real recording of a known tangential force or torque exists here, so 3 has no real
counterpart: it says how large the simulator makes a pull and a twist, to be read with the
published figures in ``docs/simulator.md``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tactile_flow.hardware.sim.calibrate_contact import (  # noqa: E402
    FINGERS, REST_CALIBRATION, contact_stats, local_pattern, read_grasps, unloaded_state)
from tactile_flow.hardware.sim.contact_check import CALIBRATION, PRESS_FORCES  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
GRASPS = ROOT / "tests" / "data" / "biotac_sp_grasps"
REST_BAG = ROOT / "tests" / "data" / "biotac_rest_untouched.bag"
#: the measures compared (contact_stats' names)
MEASURES = ("n_beyond", "max_drop_counts", "sum_drop_counts", "top_share", "rms_radius_mm")
LABELS = {"n_beyond": "electrodes moved (> threshold)", "max_drop_counts": "largest drop (counts)",
          "sum_drop_counts": "summed drop (counts)", "top_share": "largest drop / sum",
          "rms_radius_mm": "RMS radius of the drops (mm)"}
LEVELS = ("light", "mid", "firm")
QUANTILES = (5, 25, 50, 75, 95)
#: the stage motions after the press: (kind, base-frame direction deg or signed angle deg)
MOTIONS = (("none", 0.0), ("translate", 0.0), ("translate", 90.0), ("translate", 180.0), ("translate", 270.0),
           ("rotate", 30.0), ("rotate", -30.0))
TWIST_DEG_S = 40.0
PULL_MM, PULL_MM_S = 4.0, 5.0
AFTER_S = 0.3


def _taxels() -> np.ndarray:
    from tactile_flow.tactile.geometry import load_taxels
    return load_taxels()


def real_contacts(directory=GRASPS) -> dict[str, np.ndarray]:
    """Per finger contact of the real grasp frames: each of :data:`MEASURES` (arrays), ``finger``,
    ``slipped`` (the row's label: the object slipped when lifted) and ``level`` (0 light, 1 mid, 2 firm: terciles of the summed drop), with the baselines and
    the threshold the shipped calibration derives (same seed, same order, same median of
    5 × rest noise ⊕ baseline uncertainty), and only rows where an electrode moved."""
    from tactile_flow.hardware.sim.calibrate_contact import K_NOISE, TEMPLATE

    taxels = _taxels()
    cal = json.loads(CALIBRATION.read_text())
    rest = json.loads(CALIBRATION.with_name(REST_CALIBRATION).read_text())["sensors"]
    rng = np.random.default_rng(cal["parameters"]["seed"])
    sensors = []
    for path in sorted(Path(directory).glob("*.csv")):
        _, e = read_grasps(path)
        slipped = _slipped(path)
        for i, f in enumerate(FINGERS):
            u = unloaded_state(e[:, i], rng)
            sigma = np.asarray(rest[TEMPLATE[f]]["electrode_noise_std"], float)
            sensors.append((f, u, local_pattern(e[:, i], u["baseline"], taxels), K_NOISE * np.hypot(sigma, u["uncertainty"]),
                            slipped))
    threshold = float(np.median([s[3] for s in sensors]))
    out: dict[str, list] = {}
    for f, u, lp, _, slipped in sensors:
        s = contact_stats(lp["local"], u["baseline"] + lp["far"][:, None], threshold, taxels)
        keep = s["n_beyond"] > 0
        for k in MEASURES:
            out.setdefault(k, []).append(s[k][keep])
        out.setdefault("finger", []).append(np.full(int(keep.sum()), f))
        out.setdefault("slipped", []).append(slipped[keep])
    res = {k: np.concatenate(v) for k, v in out.items()}
    cuts = np.percentile(res["sum_drop_counts"], [100 / 3, 200 / 3])
    res["level"] = np.digitize(res["sum_drop_counts"], cuts)
    res["threshold_counts"] = threshold
    return res


def _slipped(path) -> np.ndarray:
    """The ``slipped`` column of a grasp CSV (1: the object slipped when lifted), as int (N,)."""
    import csv
    with open(path, newline="") as fh:
        return np.array([int(float(r["slipped"])) for r in csv.DictReader(fh)])


def resting_floor(threshold: float | None = None) -> dict:
    """The real resting bag's frames measured as contacts against each sensor's own mean: the
    share of frames in which any electrode passes the threshold, the largest |deviation| and
    the median per-electrode noise std (counts)."""
    from tactile_flow.importers.bag import read_bag
    from tactile_flow.importers.recording import select_fingers

    threshold = json.loads(CALIBRATION.read_text())["threshold_counts"] if threshold is None else threshold
    rec, _ = select_fingers(read_bag(REST_BAG))
    e = rec.electrodes.astype(float)                                   # (T, F, 24)
    dev = e - e.mean(0)
    moved = np.abs(dev) > threshold
    return {"frames": int(e.shape[0]), "fingers": list(rec.fingers),
            "share_frames_any_moved": float(moved.any(-1).mean()),
            "max_abs_deviation_counts": float(np.abs(dev).max()),
            "noise_std_counts_median": float(np.median(e.std(0))),
            "threshold_over_noise": float(threshold / np.median(e.std(0)))}


def _press_measures(e: np.ndarray, rest: np.ndarray, threshold: float, taxels) -> dict[str, np.ndarray]:
    lp = local_pattern(e, rest, taxels)
    return contact_stats(lp["local"], rest + lp["far"][:, None], threshold, taxels)


def _centre(e: np.ndarray, rest: np.ndarray, taxels) -> np.ndarray:
    """Drop-weighted centre (x, y mm) of rows ``e`` (T, 24) below ``rest``."""
    d = np.clip(rest - e, 0, None)
    return (d / np.maximum(d.sum(-1, keepdims=True), 1e-9)) @ taxels[:, :2]


class _watching_skin:
    """Within ``with``, record what the world hands :func:`hardware.sim.skin.step` (the contact's
    radius and normal force) and the largest traction and torque it returns: the simulator's
    own mechanics of each motion, read without changing it (the call is passed through)."""

    def __init__(self, module):
        self.module, self.seen = module, {"traction_n": 0.0, "torque_n_mm": 0.0}

    def __enter__(self) -> dict:
        step, seen = self.module.step, self.seen

        def watched(sk, move_mm, turn_rad, force_n, radius_mm, *args, **kw):
            out = step(sk, move_mm, turn_rad, force_n, radius_mm, *args, **kw)
            seen.update(radius_mm=radius_mm, force_n=force_n)
            seen["traction_n"] = max(seen["traction_n"], sk.traction_n)
            seen["torque_n_mm"] = max(seen["torque_n_mm"], abs(sk.torque_n_mm))
            return out

        self._step, self.module.step = step, watched
        return seen

    def __exit__(self, *exc) -> None:
        self.module.step = self._step


def mechanics(seen: dict, contact) -> dict:
    """The skin model's quantities at the pressed contact (``hardware.sim.skin``): radius a (mm),
    tangential and torsional stiffness, the traction and torque capacity μs·F and (3π/16)·μs·F·a,
    the stretch and twist at gross slip, and the largest traction / torque the motion reached."""
    from tactile_flow.hardware.sim import skin

    if "radius_mm" not in seen:
        return {}
    a, f, mu = seen["radius_mm"], seen["force_n"], contact.friction_static
    kt, kr = skin.stiffness(a, contact.skin_shear_modulus_n_mm2)
    m_cap = skin.TORSION_CAPACITY * mu * f * a
    return {"radius_mm": round(a, 2), "k_t_n_mm": round(kt, 3), "k_r_n_mm_rad": round(kr, 1),
            "traction_capacity_n": round(mu * f, 3), "torque_capacity_n_mm": round(m_cap, 2),
            "stretch_at_slip_mm": round(skin.breakaway(mu * f, kt), 3),
            "twist_at_slip_deg": round(float(np.degrees(skin.breakaway(m_cap, kr))), 2),
            "traction_max_n": round(seen["traction_n"], 3), "torque_max_n_mm": round(seen["torque_n_mm"], 2)}


def simulate(force_n: float, kind: str, amount: float, seed: int = 0, threshold: float | None = None,
             sensor: dict | None = None) -> dict:
    """Press ff on the flat board at ``force_n`` (0.5 s hold), then a stage motion ``kind``
    (``translate`` by :data:`PULL_MM` towards ``amount`` deg in the base frame, ``rotate`` by
    ``amount`` deg, ``none``: a touch as long as the pull) and :data:`AFTER_S` of hold. Returns
    the press's measures (median over the hold's frames) and the motion's change measures.
    ``sensor``: overrides of ``hardware.sensor`` keys (e.g. ``{"shear_kohm_per_n": 6.0}``)."""
    from tactile_flow.hardware.sim import make_sim_lab, skin
    from tactile_flow.hardware.sim.scenarios import biotac_arrays, press, record

    taxels = _taxels()
    threshold = json.loads(CALIBRATION.read_text())["threshold_counts"] if threshold is None else threshold
    cfg = {"seed": seed, "fingers": ["ff"]} | ({"sensor": sensor} if sensor else {})
    lab = make_sim_lab(cfg, {"kind": "flat"})
    with lab, _watching_skin(skin) as seen:
        held = biotac_arrays(press(lab, force_n, hold_s=0.5)["biotac"])["electrodes"][:, 0].astype(float)
        rest = lab.biotac.sensor.rest_counts(lab.world.time)[0]
        force = lab.world.contacts["ff"].force
        if kind == "translate":
            a = np.radians(amount)
            lab.stage.translate(PULL_MM * 1e-3 * np.cos(a), PULL_MM * 1e-3 * np.sin(a), PULL_MM_S * 1e-3)
        elif kind == "rotate":
            lab.stage.rotate(np.radians(amount), np.radians(TWIST_DEG_S))
        else:
            lab.clock.sleep(PULL_MM / PULL_MM_S)
        lab.clock.sleep(AFTER_S)
        frames: dict = {}
        record(lab, frames)
        moved = biotac_arrays(frames["biotac"])["electrodes"][:, 0].astype(float)
    p = {k: float(np.nanmedian(v)) for k, v in _press_measures(held, rest, threshold, taxels).items()}
    after = {k: float(np.nanmedian(v)) for k, v in _press_measures(moved[-10:], rest, threshold, taxels).items()}
    p0 = held.mean(0)
    w = 5                                                                  # 50 ms moving mean
    smooth = np.stack([moved[i:i + w].mean(0) for i in range(len(moved) - w + 1)])
    d = np.abs(smooth - p0)
    end = np.abs(moved[-10:].mean(0) - p0)
    shift = _centre(moved[-10:].mean(0)[None], rest, taxels)[0] - _centre(p0[None], rest, taxels)[0]
    return {"force_n": round(float(force), 3), "kind": kind, "amount": amount, "press": p, "after": after,
            "mechanics": mechanics(seen, lab.world.cfg.contact),
            "change": {"peak_sum_abs_counts": float(d.sum(1).max()), "peak_max_abs_counts": float(d.max()),
                       "peak_n_beyond": int((d > threshold).sum(1).max()),
                       "end_sum_abs_counts": float(end.sum()), "end_max_abs_counts": float(end.max()),
                       "end_n_beyond": int((end > threshold).sum()),
                       "peak_sum_over_press_sum": float(d.sum(1).max() / p["sum_drop_counts"]),
                       "end_sum_over_press_sum": float(end.sum() / p["sum_drop_counts"]),
                       "centre_shift_mm": float(np.hypot(*shift))}}


def percentile_of(x: np.ndarray, value: float) -> float:
    """Share (%) of ``x`` below ``value`` (ties half)."""
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    return float(100 * ((x < value).sum() + 0.5 * (x == value).sum()) / len(x))


def compare(real: dict, sims: dict) -> list[dict]:
    """Rows of the press table: per level (light, firm) and measure, the real quantiles and the
    simulated median's percentile in the real distribution of that level."""
    rows = []
    for level, force in PRESS_FORCES.items():
        m = real["level"] == LEVELS.index(level)
        sim = sims[(level, "none", 0.0)]["press"]
        for k in MEASURES:
            x = real[k][m]
            x = x[np.isfinite(x)]
            rows.append({"level": level, "force_n": force, "measure": k,
                         "real": {f"q{q}": round(float(np.percentile(x, q)), 3) for q in QUANTILES},
                         "sim": round(sim[k], 3), "sim_percentile": round(percentile_of(x, sim[k]), 1)})
    return rows


def figure(real: dict, sims: dict, path: Path) -> None:
    """Real distributions (light, firm) beside the simulated presses; pull / twist / touch changes."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    fig, axes = plt.subplots(2, 3, figsize=(13, 7.5))
    colours = {"light": "tab:blue", "firm": "tab:red"}
    for ax, k in zip(axes.flat, MEASURES):
        for level in PRESS_FORCES:
            x = real[k][real["level"] == LEVELS.index(level)]
            x = x[np.isfinite(x)]
            bins = np.arange(0.5, 25) if k == "n_beyond" else 40
            ax.hist(x, bins=bins, histtype="step", density=True, color=colours[level], label=f"real {level} ({len(x)})")
            s = sims[(level, "none", 0.0)]["press"][k]
            ax.axvline(s, color=colours[level], ls="--", lw=2, label=f"sim {PRESS_FORCES[level]} N")
            pulled = np.median([r["after"][k] for (lv, kind, _), r in sims.items() if lv == level and kind == "translate"])
            ax.axvline(pulled, color=colours[level], ls=":", lw=2, label=f"sim {PRESS_FORCES[level]} N after a pull")
        ax.set_xlabel(LABELS[k])
        ax.xaxis.set_major_locator(MaxNLocator(5))
        ax.set_yticks([])
    axes.flat[0].legend(fontsize=7)
    ax = axes.flat[5]
    names = [{"none": "touch", "translate": "pull", "rotate": "twist"}[kind] + ("" if kind == "none" else f" {amount:+g}°")
             for kind, amount in MOTIONS]
    xs = np.arange(len(MOTIONS))
    for j, level in enumerate(PRESS_FORCES):
        v = [sims[(level, kind, amount)]["change"]["peak_sum_over_press_sum"] for kind, amount in MOTIONS]
        ax.bar(xs + (j - 0.5) * 0.4, v, 0.4, color=colours[level], label=f"sim {PRESS_FORCES[level]} N")
    ax.set_xticks(xs, names, rotation=45, fontsize=8)
    ax.set_ylabel("peak Σ abs change / press Σ drop")
    ax.set_title("pull / twist / touch vs the press (simulated only)", fontsize=9)
    ax.legend(fontsize=7)
    fig.suptitle("BioTac SP electrode changes: real grasp frames (tests/data) vs the simulator")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "figures",
                    help="where sim_vs_real.png goes (default: docs/figures, the figure docs/simulator.md shows)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--shear-scales", default="1,0.5,0.25",
                    help="also pull (0°) with hardware.sensor.shear_kohm_per_n × each of these (comma-separated)")
    args = ap.parse_args(argv)
    real = real_contacts()
    print(json.dumps({"real_contacts": int(len(real["level"])),
                      "per_level": {lv: int((real["level"] == i).sum()) for i, lv in enumerate(LEVELS)}}), flush=True)
    print(json.dumps({"real_all_contacts": {k: {f"q{q}": round(float(np.nanpercentile(real[k], q)), 3) for q in (1, 50, 99)}
                                            | {"max": round(float(np.nanmax(real[k])), 3)} for k in MEASURES}}), flush=True)
    print(json.dumps({"real_by_label": {lab: {k: round(float(np.nanmedian(real[k][real["slipped"] == v])), 3)
                                              for k in MEASURES} | {"contacts": int((real["slipped"] == v).sum())}
                                        for lab, v in (("stable", 0), ("slipped", 1))}}), flush=True)
    rest = resting_floor()
    print(json.dumps({"resting_recording": rest}), flush=True)
    sims = {}
    for level, force in PRESS_FORCES.items():
        for kind, amount in MOTIONS:
            r = simulate(force, kind, amount, seed=args.seed)
            sims[(level, kind, amount)] = r
            print(json.dumps({"sim": level, **r}), flush=True)
    rows = compare(real, sims)
    for r in rows:
        print(json.dumps({"press": r}))
    print("\n| measure | level | real q5 | q25 | q50 | q75 | q95 | sim | sim's percentile in real |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for r in rows:
        q = r["real"]
        print(f"| {LABELS[r['measure']]} | {r['level']} ({r['force_n']} N) | " +
              " | ".join(f"{q[f'q{p}']:.3g}" for p in QUANTILES) + f" | {r['sim']:.3g} | {r['sim_percentile']:.0f} |")
    print("\n| motion | level | peak Σ abs Δ (counts) | peak max abs Δ | peak electrodes > threshold | "
          "end Σ abs Δ | end max abs Δ | peak Σ abs Δ / press Σ drop | end / press | centre shift (mm) |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for (level, kind, amount), r in sims.items():
        c = r["change"]
        name = "touch" if kind == "none" else f"{'pull' if kind == 'translate' else 'twist'} {amount:+g}°"
        print(f"| {name} | {level} | {c['peak_sum_abs_counts']:.0f} | {c['peak_max_abs_counts']:.0f} | "
              f"{c['peak_n_beyond']} | {c['end_sum_abs_counts']:.0f} | {c['end_max_abs_counts']:.0f} | "
              f"{c['peak_sum_over_press_sum']:.2f} | {c['end_sum_over_press_sum']:.2f} | {c['centre_shift_mm']:.2f} |")
    print("\n| simulated state, measured as the real frames | " +
          " | ".join(f"{LABELS[k]} (real %ile)" for k in MEASURES) + " |")
    print("| --- |" + " --- |" * len(MEASURES))
    for (level, kind, amount), r in sims.items():
        name = "pressed (touch)" if kind == "none" else f"after {'pull' if kind == 'translate' else 'twist'} {amount:+g}°"
        a = r["after"]
        print(f"| {name}, {level} | " + " | ".join(
            f"{a[k]:.3g} ({percentile_of(real[k], a[k]):.0f})" for k in MEASURES) + " |")
    print("\n| press | contact radius a (mm) | k_t (N/mm) | k_r (N·mm/rad) | traction capacity μs·F (N) | "
          "torque capacity (N·mm) | stretch at gross slip (mm) | twist at gross slip (°) |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for level in PRESS_FORCES:
        m = sims[(level, "translate", 0.0)]["mechanics"]
        print(f"| {level} ({sims[(level, 'translate', 0.0)]['force_n']:.2f} N) | {m['radius_mm']} | {m['k_t_n_mm']} | "
              f"{m['k_r_n_mm_rad']} | {m['traction_capacity_n']} | {m['torque_capacity_n_mm']} | "
              f"{m['stretch_at_slip_mm']} | {m['twist_at_slip_deg']} |")
    scales = [float(x) for x in args.shear_scales.split(",") if x.strip()]
    if scales:
        from tactile_flow.hardware.config import SensorModelConfig
        base = SensorModelConfig().shear_kohm_per_n
        print("\n| shear_kohm_per_n | motion | level | peak Σ abs Δ / press Σ drop | peak electrodes > threshold | "
              "after it, as the real frames: " + " | ".join(f"{LABELS[k]} (real %ile)" for k in MEASURES) + " |")
        print("| --- | --- | --- | --- | --- |" + " --- |" * len(MEASURES))
        for sc in scales:
            for kind, amount in (("translate", 0.0), ("rotate", 30.0)):
                for level, force in PRESS_FORCES.items():
                    r = simulate(force, kind, amount, seed=args.seed, sensor={"shear_kohm_per_n": base * sc})
                    print(json.dumps({"shear_scale": sc, "sim": level, "kind": kind, "amount": amount,
                                      "change": r["change"], "after": r["after"]}))
                    a, c = r["after"], r["change"]
                    print(f"| {base * sc:g} (×{sc:g}) | {'pull' if kind == 'translate' else 'twist'} {amount:+g}° | "
                          f"{level} | {c['peak_sum_over_press_sum']:.2f} | {c['peak_n_beyond']} | " + " | ".join(
                              f"{a[k]:.3g} ({percentile_of(real[k], a[k]):.0f})" for k in MEASURES) + " |")
    png = args.out / "sim_vs_real.png"
    figure(real, sims, png)
    print(json.dumps({"figure": str(png)}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

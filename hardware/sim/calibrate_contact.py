"""Contact statistics of real BioTac SP frames, the targets the simulated contact is tuned to.

Run once (numpy only)::

    python -m tactile_flow.hardware.sim.calibrate_contact tests/data/biotac_sp_grasps \\
        hardware/sim/biotac_contact_calibration.json

Input: the grasp CSVs of ``tests/data/biotac_sp_grasps`` (raw electrode counts of ff, mf, th;
every row in contact on at least one finger; no rest rows, no time column). Derivation, per
file and finger (the sensors of one file share a session; files differ by up to ~1400 counts):

1. **Unloaded state** (:func:`unloaded_state`). Pressing raises an electrode's impedance, so
   its count falls: the unloaded count is near the top of what the electrode reads when the
   finger is least loaded. Iterate three times: load index of a row = Σ over electrodes of
   the impedance rise above the current estimate (kΩ); take the least-loaded 10 % of the rows
   (at least 30); new estimate = each electrode's 90th percentile over them (start: the 95th
   over all rows). Uncertainty per electrode: the bootstrap standard deviation of that
   percentile (200 resamples of the chosen rows) combined with half the spread between its
   75th and 95th percentiles (how much the choice of quantile matters).
2. **Common mode and local pattern** (:func:`local_pattern`). Real rows also carry an offset
   shared by all electrodes that does not grow with the load (correlation with the local load
   below 0.3: the sensors drift between grasps). The median deviation of the electrodes more
   than ``FAR_MM`` from the pattern's centre (weighted by the drops) is that row's far level;
   the *local* deviation is the reading minus baseline minus far level.
3. **Statistics per finger contact** (:func:`contact_stats`; rows whose largest local drop
   exceeds the threshold): electrodes beyond ``K_NOISE`` × noise (noise: the resting noise of
   the real bag's sensor for that finger, ``biotac_rest_calibration.json``, combined with the
   baseline uncertainty), the largest and the summed local drop (counts) and impedance rise
   (kΩ), the share of the largest drop in the sum and the RMS distance of the drops from
   their centre (mm): how concentrated a pattern is.
4. **Light / firm**: contacts pooled over fingers and files, split in terciles of the summed
   local drop; quantiles (10, 50, 90 %) of every statistic per tercile.
5. **Far-field rise**: least-squares slope of the far level against the summed local drop
   (counts of rise per 1000 counts of local drop) with a bootstrap interval; the residual
   spread is the between-grasp drift (common mode, counts).
6. **Noise in contact**: consecutive rows of one object may belong to one grasp: the robust
   standard deviation (1.4826 × median absolute difference / √2) of the local deviations'
   difference over the electrodes of a pair, for loaded (beyond the threshold) and unloaded
   electrodes. The lowest decile over pairs is an **upper bound** of the noise in contact
   (pairs from different grasps only raise it); the resting noise is the lower reference.
"""

from __future__ import annotations

import csv
import hashlib
import json
import sys
from pathlib import Path

import numpy as np

FINGERS = ("ff", "mf", "th")
K_NOISE = 5.0          # electrodes beyond K_NOISE × noise count as moved
FAR_MM = 10.0          # electrodes this far from the pattern's centre give the far level
LEAST_LOADED = 0.10    # share of rows (at least MIN_ROWS) the unloaded state is taken from
MIN_ROWS = 30
QUANTILE = 90.0        # per-electrode percentile over the least-loaded rows
N_BOOT = 200
REST_CALIBRATION = "biotac_rest_calibration.json"
TEMPLATE = {"ff": 0, "mf": 1, "th": 2}       # the bag's sensors, as hardware.sim.sensor uses them
ATTRIBUTION = ("3dperceptionlab/tactile-gcn (commit e05cd574f097a372a612e8fcbeb7645c316dd97a), folder "
               "data/biotacsp/raw/; MIT licence, Copyright (c) 2018 3D Perception Lab. Garcia-Garcia et al., "
               "TactileGCN, IJCNN 2019.")


def kohm(counts) -> np.ndarray:
    """Electrode impedance (kΩ) of raw counts, ``(4095/E − 1)·10`` (counts clipped to 1..4095)."""
    return (4095.0 / np.clip(np.asarray(counts, float), 1.0, 4095.0) - 1.0) * 10.0


def read_grasps(path) -> tuple[np.ndarray, np.ndarray]:
    """``objects`` (N,) str and ``electrodes`` (N, 3, 24) counts (ff, mf, th) of one grasp CSV.
    A missing column or a cell that is not a number is a ``ValueError`` naming the file and line."""
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    head = rows[0] if rows else []
    names = ["object"] + [f"{f}_biotac_{k}" for f in FINGERS for k in range(1, 25)]
    missing = [n for n in names if n not in head]
    if missing:
        raise ValueError(f"{path}: no column {missing[0]} (expected object and <finger>_biotac_1..24 of ff, mf, th)")
    cols = [head.index(n) for n in names[1:]]
    objects, e = [], []
    for line, r in enumerate(rows[1:], start=2):
        try:
            e.append([float(r[c]) for c in cols])
        except (ValueError, IndexError):
            raise ValueError(f"{path}: line {line} is not a row of electrode counts") from None
        objects.append(r[head.index("object")])
    return np.array(objects), np.array(e).reshape(len(e), len(FINGERS), 24)


def unloaded_state(e: np.ndarray, rng: np.random.Generator) -> dict:
    """Unloaded counts of one sensor from in-contact rows ``e`` (N, 24); see the module doc.

    Returns ``baseline`` (24,), ``uncertainty`` (24,) counts, ``rows`` (indices used).
    """
    b = np.percentile(e, 95, axis=0)
    n = max(MIN_ROWS, int(round(LEAST_LOADED * len(e))))
    for _ in range(3):
        load = np.clip(kohm(e) - kohm(b), 0, None).sum(1)
        rows = np.argsort(load, kind="stable")[:n]
        b = np.percentile(e[rows], QUANTILE, axis=0)
    sub = e[rows]
    boot = np.array([np.percentile(sub[rng.integers(0, n, n)], QUANTILE, axis=0) for _ in range(N_BOOT)])
    spread = (np.percentile(sub, 95, axis=0) - np.percentile(sub, 75, axis=0)) / 2
    return {"baseline": b, "uncertainty": np.hypot(boot.std(0), spread), "rows": rows}


def local_pattern(e: np.ndarray, baseline: np.ndarray, taxels: np.ndarray) -> dict:
    """Split deviations from ``baseline`` into a far level and a local pattern.

    ``e`` (N, 24) counts. Returns ``far`` (N,) median deviation of the electrodes more than
    ``FAR_MM`` from the drop-weighted centre (counts), ``local`` (N, 24) deviation minus that
    level (counts; negative = pressed), ``centre`` (N, 3) mm. Two passes: the centre of the
    raw drops, then of the local drops.
    """
    dev = e - baseline
    drop = np.clip(-dev, 0, None)
    for _ in range(2):
        w = drop / np.maximum(drop.sum(1, keepdims=True), 1e-9)
        centre = w @ taxels
        far_mask = np.linalg.norm(taxels[None] - centre[:, None], axis=-1) > FAR_MM
        far_mask[~far_mask.any(1)] = True                  # degenerate: every electrode
        far = np.array([np.median(d[m]) for d, m in zip(dev, far_mask)])
        local = dev - far[:, None]
        drop = np.clip(-local, 0, None)
    return {"far": far, "local": local, "centre": centre}


def contact_stats(local: np.ndarray, reference: np.ndarray, threshold, taxels: np.ndarray) -> dict:
    """Per-contact statistics of local deviations.

    Args:
        local: (N, 24) counts relative to ``reference`` (negative = pressed).
        reference: (N, 24) or (24,) counts the deviations are taken from (for kΩ).
        threshold: scalar or (24,) counts; an electrode whose local drop exceeds it has *moved*.
        taxels: (24, 3) mm.
    Returns arrays (N,): ``n_beyond`` (electrodes moved), ``max_drop_counts``, and over the
    moved electrodes only (so that baseline errors of the others do not count):
    ``sum_drop_counts``, ``max_rise_kohm``, ``sum_rise_kohm``, ``top_share`` (largest drop /
    summed drop) and ``rms_radius_mm`` (drop-weighted RMS distance from their centre; NaN with
    no electrode moved).
    """
    ref = np.broadcast_to(reference, local.shape)
    moved = local < -np.asarray(threshold, float)
    drop = np.where(moved, -local, 0.0)
    dz = np.where(moved, kohm(ref + local) - kohm(ref), 0.0)
    total = drop.sum(1)
    with np.errstate(invalid="ignore", divide="ignore"):
        w = drop / total[:, None]
        centre = w @ taxels
        r2 = ((taxels[None] - centre[:, None]) ** 2).sum(-1)
        return {"n_beyond": moved.sum(1).astype(float), "max_drop_counts": np.clip(-local, 0, None).max(1),
                "sum_drop_counts": total, "max_rise_kohm": dz.max(1), "sum_rise_kohm": dz.sum(1),
                "top_share": drop.max(1) / total, "rms_radius_mm": np.sqrt((w * r2).sum(1))}


def quantiles(x, q=(10, 50, 90)) -> dict:
    return {f"q{p}": round(float(np.percentile(x, p)), 3) for p in q}


NOISE_BINS = (0.0, 50.0, 200.0, 500.0, 1000.0, 4096.0)   # local drop (counts) of the electrodes compared


def pair_noise(local: np.ndarray, objects: np.ndarray, bins=NOISE_BINS) -> list[np.ndarray]:
    """Noise estimates (counts) from consecutive same-object rows, one array per drop bin.

    For every pair, the electrodes whose mean local drop falls in a bin (at least 3) give
    ``1.4826 × median |difference| / √2``, a robust standard deviation.
    """
    same = objects[1:] == objects[:-1]
    d = (local[1:] - local[:-1])[same]
    level = (-(local[1:] + local[:-1]) / 2)[same]
    out = [[] for _ in bins[1:]]
    for diff, lvl in zip(d, level):
        for k, (lo, hi) in enumerate(zip(bins[:-1], bins[1:])):
            m = (lvl >= lo) & (lvl < hi)
            if m.sum() >= 3:
                out[k].append(1.4826 * np.median(np.abs(diff[m])) / np.sqrt(2))
    return [np.array(x) for x in out]


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def derive(directory, seed: int = 0) -> dict:
    """The calibration dict (JSON-ready) from every ``*.csv`` of ``directory``."""
    from tactile_flow.tactile.geometry import load_taxels

    taxels = load_taxels()
    rest = json.loads(Path(__file__).with_name(REST_CALIBRATION).read_text())["sensors"]
    rng = np.random.default_rng(seed)
    files = sorted(Path(directory).glob("*.csv"))
    if not files:
        raise ValueError(f"{directory}: no .csv files")
    sensors = []                                  # (file, finger, objects, unloaded, local pattern, rest noise)
    for path in files:
        objects, e = read_grasps(path)
        for i, f in enumerate(FINGERS):
            u = unloaded_state(e[:, i], rng)
            sigma = np.asarray(rest[TEMPLATE[f]]["electrode_noise_std"], float)
            sensors.append((path.name, f, objects, u, local_pattern(e[:, i], u["baseline"], taxels), sigma))
    threshold = float(np.median([K_NOISE * np.hypot(s[5], s[3]["uncertainty"]) for s in sensors]))
    stats: dict[str, list] = {}
    far_x, far_y, far_group, unloaded = [], [], [], {}
    noise = [[] for _ in NOISE_BINS[1:]]
    for name, f, objects, u, lp, sigma in sensors:
        s = contact_stats(lp["local"], u["baseline"] + lp["far"][:, None], threshold, taxels)
        touching = s["n_beyond"] > 0
        for k, v in s.items():
            stats.setdefault(k, []).append(v[touching])
        stats.setdefault("finger", []).append(np.full(touching.sum(), f))
        far_x.append(s["sum_drop_counts"][touching])
        far_y.append(lp["far"][touching])
        far_group.append(np.full(touching.sum(), f"{name}:{f}"))
        for k, x in enumerate(pair_noise(lp["local"], objects)):
            noise[k].append(x)
        unloaded.setdefault(name, {})[f] = {
            "baseline_counts": np.round(u["baseline"], 1).tolist(),
            "uncertainty_counts": np.round(u["uncertainty"], 1).tolist(),
            "uncertainty_median_counts": round(float(np.median(u["uncertainty"])), 1),
            "rows_used": int(len(u["rows"])), "rows": int(len(objects)), "contacts": int(touching.sum())}
    pooled = {k: np.concatenate(v) for k, v in stats.items()}
    fingers = pooled.pop("finger")
    cuts = np.percentile(pooled["sum_drop_counts"], [100 / 3, 200 / 3])
    level = np.digitize(pooled["sum_drop_counts"], cuts)
    groups = {name: {k: quantiles(v[level == g]) for k, v in pooled.items()} | {"contacts": int((level == g).sum())}
              for g, name in enumerate(("light", "mid", "firm"))}
    per_finger = {f: {k: quantiles(v[fingers == f]) for k, v in pooled.items()}
                  | {"contacts": int((fingers == f).sum())} for f in FINGERS}
    far = _far_field(np.concatenate(far_x), np.concatenate(far_y), np.concatenate(far_group), rng)
    rest_sigma = np.concatenate([s[5] for s in sensors])
    return {
        "source": {"files": [{"file": p.name, "sha256": _sha256(p)} for p in files], "origin": ATTRIBUTION,
                   "contacts": int(len(fingers)), "rows": int(sum(len(s[2]) for s in sensors) // len(FINGERS))},
        "method": __doc__.split("Input:", 1)[1].strip(),
        "parameters": {"k_noise": K_NOISE, "far_mm": FAR_MM, "least_loaded_share": LEAST_LOADED,
                       "min_rows": MIN_ROWS, "quantile": QUANTILE, "bootstrap": N_BOOT, "seed": seed},
        "threshold_counts": round(threshold, 1),
        "light_firm_cuts_sum_drop_counts": np.round(cuts, 1).tolist(),
        "contacts": groups,
        "per_finger": per_finger,
        "far_field": far,
        "noise": {"rest_std_counts": quantiles(rest_sigma),
                  "in_contact_upper_bound_counts": [
                      {"drop_counts": [lo, hi], "pairs": int(sum(len(x) for x in noise[k])),
                       **quantiles(np.concatenate(noise[k]), (5, 10, 50))}
                      for k, (lo, hi) in enumerate(zip(NOISE_BINS[:-1], NOISE_BINS[1:]))],
                  "note": "consecutive rows of one object may come from different grasps: the lowest decile "
                          "(q10) of the pair estimates bounds the in-contact noise from above"},
        "unloaded_state": unloaded,
    }


def _far_field(x, y, group, rng) -> dict:
    """Slope of the far level against the summed local drop, within each file and finger
    (its mean removed), with a bootstrap interval; the residual spread is the common-mode drift."""
    yc, xc = y.copy(), x.copy()
    for g in np.unique(group):
        m = group == g
        yc[m] -= y[m].mean()
        xc[m] -= x[m].mean()
    slope = float((xc @ yc) / (xc @ xc))
    boot = []
    for _ in range(N_BOOT):
        i = rng.integers(0, len(x), len(x))
        boot.append((xc[i] @ yc[i]) / (xc[i] @ xc[i]))
    resid = yc - slope * xc
    return {"rise_per_1000_drop_counts": round(1000 * slope, 2),
            "interval_90": [round(1000 * float(np.percentile(boot, p)), 2) for p in (5, 95)],
            "correlation": round(float(np.corrcoef(xc, yc)[0, 1]), 3),
            "common_mode_std_counts": round(float(resid.std()), 1),
            "far_level_counts": quantiles(y)}


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 2:
        print("usage: python -m tactile_flow.hardware.sim.calibrate_contact GRASP_DIR OUT.json", file=sys.stderr)
        return 2
    try:
        cal = derive(argv[0])
    except (OSError, ValueError) as exc:
        print(f"calibrate_contact: {exc}", file=sys.stderr)
        return 2
    Path(argv[1]).write_text(json.dumps(cal, indent=1) + "\n")
    g = cal["contacts"]
    print(f"wrote {argv[1]}: {cal['source']['contacts']} finger contacts; median summed drop light "
          f"{g['light']['sum_drop_counts']['q50']:.0f}, firm {g['firm']['sum_drop_counts']['q50']:.0f} counts")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

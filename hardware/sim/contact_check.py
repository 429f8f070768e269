"""Simulated presses measured as the real grasp frames were: the contact calibration's check.

    python -m tactile_flow.hardware.sim.contact_check [hardware/sim/biotac_contact_calibration.json]

prints the table of ``docs/simulator.md``: the real light and firm contacts' median statistics
(:mod:`hardware.sim.calibrate_contact`) beside those of simulated presses of the ``ff`` pad on
the flat board at :data:`PRESS_FORCES` (frames of a 0.5 s hold, each measured against the
simulated sensor's true unloaded counts with the same far-level split and threshold), the
far-field rise between the two presses and the noise in contact. ``tests/test_sim_contact.py``
holds the simulator to these figures.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from .calibrate_contact import NOISE_BINS, contact_stats, local_pattern, pair_noise

#: N, the presses matching the real grasp frames' light and firm terciles (median summed drop)
PRESS_FORCES = {"light": 1.3, "firm": 5.0}
CALIBRATION = Path(__file__).with_name("biotac_contact_calibration.json")
COMPARED = ("n_beyond", "max_drop_counts", "sum_drop_counts", "sum_rise_kohm", "top_share", "rms_radius_mm")


def simulated_press(force_n: float, surface=None, seed: int = 0, hold_s: float = 0.5) -> dict:
    """Press ``ff`` on ``surface`` (default the flat board) with ``force_n``; returns the hold's
    ``electrodes`` (T, 24) counts, the sensor's true unloaded ``rest`` (24,) and the force reached."""
    from . import make_sim_lab
    from .scenarios import biotac_arrays, press

    lab = make_sim_lab({"seed": seed, "fingers": ["ff"]}, surface or {"kind": "flat"})
    with lab:
        frames = press(lab, force_n, hold_s=hold_s)
        e = biotac_arrays(frames["biotac"])["electrodes"][:, 0].astype(float)
        return {"electrodes": e, "rest": lab.biotac.sensor.rest_counts(lab.world.time)[0],
                "force_n": lab.world.contacts["ff"].force}


def press_statistics(force_n: float, threshold: float, **kw) -> dict:
    """Median :func:`contact_stats` over the frames of a simulated press, its far level
    (counts) and the in-contact noise per drop bin (median of the frame-pair estimates)."""
    from tactile_flow.tactile.geometry import load_taxels

    taxels = load_taxels()
    p = simulated_press(force_n, **kw)
    lp = local_pattern(p["electrodes"], p["rest"], taxels)
    s = contact_stats(lp["local"], p["rest"] + lp["far"][:, None], threshold, taxels)
    noise = pair_noise(lp["local"], np.zeros(len(lp["local"])))
    return {**{k: float(np.nanmedian(v)) for k, v in s.items()}, "far_counts": float(np.median(lp["far"])),
            "force_n": p["force_n"], "noise_counts": [float(np.median(x)) if len(x) else None for x in noise]}


def compare(cal: dict, seed: int = 0) -> dict:
    """Real vs simulated: per level (light, firm) the real median and the simulated value of each
    statistic, the far-field rise (counts per 1000 counts of summed drop) and the noise bins."""
    sim = {level: press_statistics(f, cal["threshold_counts"], seed=seed) for level, f in PRESS_FORCES.items()}
    rise = 1000 * (sim["firm"]["far_counts"] - sim["light"]["far_counts"]) / \
        (sim["firm"]["sum_drop_counts"] - sim["light"]["sum_drop_counts"])
    return {"levels": {level: {k: (cal["contacts"][level][k]["q50"], sim[level][k]) for k in COMPARED}
                       | {"force_n": sim[level]["force_n"]} for level in PRESS_FORCES},
            "far_rise_per_1000": (cal["far_field"]["rise_per_1000_drop_counts"], rise),
            "noise": {"bins": [list(b) for b in zip(NOISE_BINS[:-1], NOISE_BINS[1:])],
                      "real_upper_bound": [b["q10"] for b in cal["noise"]["in_contact_upper_bound_counts"]],
                      "light": sim["light"]["noise_counts"], "firm": sim["firm"]["noise_counts"]}}


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    path = Path(argv[0]) if argv else CALIBRATION
    c = compare(json.loads(path.read_text()))
    print("| statistic | real light | sim light | real firm | sim firm |\n| --- | --- | --- | --- | --- |")
    for k in COMPARED:
        (rl, sl), (rf, sf) = c["levels"]["light"][k], c["levels"]["firm"][k]
        print(f"| {k} | {rl:.3g} | {sl:.3g} | {rf:.3g} | {sf:.3g} |")
    print(f"| far-field rise per 1000 counts of summed drop | {c['far_rise_per_1000'][0]:.3g} (both) | "
          f"{c['far_rise_per_1000'][1]:.3g} | | |")
    print("\n| local drop (counts) | real upper bound (q10) | sim light | sim firm |\n| --- | --- | --- | --- |")
    n = c["noise"]
    for b, r, sl, sf in zip(n["bins"], n["real_upper_bound"], n["light"], n["firm"]):
        fmt = lambda x: "-" if x is None else f"{x:.3g}"
        print(f"| {b[0]:g}–{b[1]:g} | {r:.3g} | {fmt(sl)} | {fmt(sf)} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

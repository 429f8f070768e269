"""The simulated press, pull and twist against the real BioTac SP contact frames
(``benchmarks/bench_sim_vs_real.py``; the tables of docs/simulator.md, "Compared with what the
literature reports").

The real per-contact distributions come from tests/data/biotac_sp_grasps measured as the
shipped contact calibration measures them; a simulated press at the light and firm forces must
sit inside the real light / firm distribution on every measure the simulator is tuned to
(near the middle of it), the pattern's spread (a documented departure) inside its lower part;
the pull's and the twist's sizes are the docs' table, and that a pulled contact looks like a real
one is a strict xfail: the known departure, reported for a simulator change.
"""

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from tactile_flow.hardware.sim.contact_check import CALIBRATION, PRESS_FORCES

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("bench_sim_vs_real", ROOT / "benchmarks" / "bench_sim_vs_real.py")
bench = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(bench)

#: the measures the simulated press matches, with the band of the real distribution (percentiles)
#: its median must fall in; the RMS radius is the known departure (tested separately)
MATCHED = {"n_beyond": (20, 80), "max_drop_counts": (25, 75), "sum_drop_counts": (25, 75), "top_share": (20, 80)}


@pytest.fixture(scope="module")
def real():
    return bench.real_contacts()


@pytest.fixture(scope="module")
def sims():
    out = {}
    for level, force in PRESS_FORCES.items():
        for kind, amount in (("none", 0.0), ("translate", 0.0), ("rotate", 30.0)):
            out[(level, kind)] = bench.simulate(force, kind, amount, seed=0)
    return out


def _level(real, level):
    return real["level"] == bench.LEVELS.index(level)


def test_the_real_contacts_are_the_shipped_calibrations(real):
    """The per-contact arrays reproduce the calibration's quantiles (same baselines, same cuts)."""
    cal = json.loads(CALIBRATION.read_text())
    assert len(real["level"]) == cal["source"]["contacts"]
    for level in PRESS_FORCES:
        m = _level(real, level)
        assert m.sum() == cal["contacts"][level]["contacts"]
        for k in bench.MEASURES:
            x = real[k][m]
            assert np.percentile(x[np.isfinite(x)], 50) == pytest.approx(cal["contacts"][level][k]["q50"], abs=0.01)


@pytest.mark.parametrize("level", list(PRESS_FORCES))
def test_a_simulated_press_sits_inside_the_real_contacts(real, sims, level):
    press = sims[(level, "none")]["press"]
    m = _level(real, level)
    for k, (lo, hi) in MATCHED.items():
        pct = bench.percentile_of(real[k][m], press[k])
        assert lo <= pct <= hi, (level, k, press[k], pct)


def test_the_pattern_spread_is_the_documented_departure(real, sims):
    """The simulated press is more concentrated than the real contacts (docs/simulator.md): its
    RMS radius sits in the real distribution's lower part but not outside it."""
    for level in PRESS_FORCES:
        pct = bench.percentile_of(real["rms_radius_mm"][_level(real, level)], sims[(level, "none")]["press"]["rms_radius_mm"])
        assert 1 <= pct <= 30, (level, pct)


def test_the_resting_recording_stays_below_the_threshold():
    floor = bench.resting_floor()
    assert floor["share_frames_any_moved"] < 0.01
    assert floor["threshold_over_noise"] > 15


def test_pull_and_twist_against_the_press(sims):
    """What the docs' table says of a pull and a twist (a change of the shear's gain changes these
    figures: rerun the benchmark and update both): a 4 mm pull changes the electrodes by
    more than the press itself (2-3x at 5 N, 4-6x at 1.3 N: the shear loads' size, not
    calibrated on real data); a 30 degree twist far less than a pull (0.2-0.7 of the press), and
    at 1.3 N by no electrode beyond the contact threshold; a touch stays near the noise."""
    ratio = {k: v["change"]["peak_sum_over_press_sum"] for k, v in sims.items()}
    assert 2.0 <= ratio[("firm", "translate")] <= 3.0
    assert 4.0 <= ratio[("light", "translate")] <= 6.0
    for level in PRESS_FORCES:
        assert 0.2 <= ratio[(level, "rotate")] <= 0.7
        assert ratio[(level, "rotate")] < ratio[(level, "translate")] / 3
        assert sims[(level, "none")]["change"]["peak_n_beyond"] == 0
    assert sims[("light", "rotate")]["change"]["peak_n_beyond"] == 0
    assert sims[("firm", "translate")]["change"]["peak_n_beyond"] >= 20


@pytest.mark.xfail(strict=True, reason="known departure (docs/simulator.md): the shear's electrode gain is about "
                   "4x too large for a pulled contact to look like a real one; reported, not changed here")
def test_a_pulled_contact_looks_like_a_real_contact(real, sims):
    """Measured as the real frames, the state a 5 N pull leaves must be a contact the real frames
    contain: its summed drop within their 99th percentile, its largest drop's share above their
    5th. Today it is not (12 400-16 600 counts against 10 870; share at the 0-5th percentile):
    strict xfail, so the fix of the shear's gain turns this into a failure until the mark goes."""
    after = sims[("firm", "translate")]["after"]
    assert after["sum_drop_counts"] <= np.nanpercentile(real["sum_drop_counts"], 99)
    assert bench.percentile_of(real["top_share"], after["top_share"]) >= 5


def test_the_skin_mechanics_grow_with_the_force(sims):
    """Mindlin/Hertz: the stiffness, the capacities and the twist at gross slip grow with the force
    (du Bois de Dunilac et al. 2023 observe the twist to full slip grow with the normal force)."""
    light, firm = sims[("light", "translate")]["mechanics"], sims[("firm", "translate")]["mechanics"]
    for k in ("radius_mm", "k_t_n_mm", "k_r_n_mm_rad", "torque_capacity_n_mm", "twist_at_slip_deg"):
        assert firm[k] > light[k], k
    assert firm["traction_capacity_n"] == pytest.approx(0.8 * sims[("firm", "translate")]["force_n"], rel=0.01)

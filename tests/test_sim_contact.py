"""The simulated contact against real BioTac SP contact frames (tests/data/biotac_sp_grasps).

The real statistics are derived by ``hardware.sim.calibrate_contact`` (shipped as
``hardware/sim/biotac_contact_calibration.json``); simulated presses of the ff pad on the flat
board at the light and firm forces (``hardware.sim.contact_check.PRESS_FORCES``) are measured
the same way and must match them within the tolerances below (docs/simulator.md).
"""

import json
from pathlib import Path

import numpy as np
import pytest

from tactile_flow.hardware.sim.calibrate_contact import FINGERS, derive, read_grasps, unloaded_state
from tactile_flow.hardware.sim.contact_check import CALIBRATION, PRESS_FORCES, compare

DATA = Path(__file__).parent / "data"
GRASPS = DATA / "biotac_sp_grasps"

#: |sim − real| / real allowed per statistic (n_beyond: electrodes); the real firm contacts' kΩ
#: sum has a long tail of bottomed-out electrodes (q90 ≈ 880 kΩ), hence its wider tolerance
TOLERANCE = {"max_drop_counts": 0.25, "sum_drop_counts": 0.25, "sum_rise_kohm": 0.45}
N_BEYOND = {"light": 2, "firm": 3}
TOP_SHARE = 0.1


@pytest.fixture(scope="module")
def calibration():
    return json.loads(CALIBRATION.read_text())


@pytest.fixture(scope="module")
def comparison(calibration):
    return compare(calibration)


def test_the_shipped_calibration_is_what_the_script_derives_from_the_test_data(calibration):
    assert json.loads(json.dumps(derive(GRASPS))) == calibration
    import hashlib
    for f in calibration["source"]["files"]:
        assert hashlib.sha256((GRASPS / f["file"]).read_bytes()).hexdigest() == f["sha256"]
    assert "MIT" in calibration["source"]["origin"]
    assert calibration["source"]["rows"] == 3698 and calibration["source"]["contacts"] > 10000


def test_the_unloaded_estimate_finds_the_rest_of_a_sensor_at_rest():
    """On the real resting bag (every row unloaded) the estimator returns the rest level within
    its stated uncertainty plus the noise's upper tail (it takes a 90th percentile)."""
    from tactile_flow.importers.bag import read_bag
    from tactile_flow.importers.recording import select_fingers

    rec, _ = select_fingers(read_bag(DATA / "biotac_rest_untouched.bag"))
    rng = np.random.default_rng(0)
    for i, f in enumerate(rec.fingers):
        e = rec.electrodes[:, i].astype(float)
        u = unloaded_state(e, rng)
        err = u["baseline"] - e.mean(0)
        assert np.all(np.abs(err) <= u["uncertainty"] + 2.5 * e.std(0) + 1), (f, err.round(1))


def test_unloaded_states_differ_between_files_as_the_readme_says():
    """The grasp sensors are not the bag's and their unloaded counts differ between files."""
    cal = json.loads(CALIBRATION.read_text())["unloaded_state"]
    ff = np.array([cal[name]["ff"]["baseline_counts"] for name in sorted(cal)])
    assert np.ptp(ff, axis=0).max() > 300
    _, e = read_grasps(GRASPS / "palm_45_test.csv")
    assert e.shape[1:] == (len(FINGERS), 24)


@pytest.mark.parametrize("level", list(PRESS_FORCES))
def test_simulated_presses_look_like_the_real_contacts(comparison, level):
    stats = comparison["levels"][level]
    assert abs(stats["force_n"] - PRESS_FORCES[level]) < 0.15 * PRESS_FORCES[level]
    for k, tol in TOLERANCE.items():
        real, sim = stats[k]
        assert abs(sim - real) <= tol * real, (level, k, real, sim)
    real, sim = stats["n_beyond"]
    assert abs(sim - real) <= N_BEYOND[level], (level, real, sim)
    real, sim = stats["top_share"]
    assert abs(sim - real) <= TOP_SHARE, (level, real, sim)


def test_far_electrodes_rise_with_the_load_as_the_real_ones(comparison):
    real, sim = comparison["far_rise_per_1000"]
    assert real > 0 and abs(sim - real) <= 0.25 * real, (real, sim)


def test_noise_in_contact_grows_but_stays_within_the_real_upper_bound(comparison, calibration):
    """Noise relative to the sensor's own rest level (the simulated ff is the bag's noisy ff):
    above it where the electrodes are pressed, never beyond what the real pairs allow."""
    n = comparison["noise"]
    real_rest = calibration["noise"]["rest_std_counts"]["q50"]
    for level in PRESS_FORCES:
        sim_rest = n[level][0]
        loaded = [(s, r) for s, r, (lo, _) in zip(n[level], n["real_upper_bound"], n["bins"]) if s and lo >= 50]
        assert loaded, level
        for sim, bound in loaded:
            assert sim / sim_rest <= bound / real_rest, (level, n)
        assert max(s for s, _ in loaded) > 1.1 * sim_rest, (level, n)

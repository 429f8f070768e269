"""Filling a held bottle: mass grows with the pump rate, slip follows the expected sequence."""

import math

import numpy as np
import pytest

from tactile_flow.hardware.sim import make_sim_lab
from tactile_flow.hardware.sim.scenarios import biotac_arrays, close_grasp, pour_until_slip

LOOSE = {"pour": {"grip_n_per_rad": 2.0}}


@pytest.fixture(scope="module")
def pour():
    lab = make_sim_lab({"seed": 5, **LOOSE})
    with lab:
        frames = pour_until_slip(lab, rate_ml_min=150.0, flexion_rad=1.3)
    return lab, frames


def test_slip_happens_in_the_expected_sequence(pour):
    lab, _ = pour
    p = lab.truth.to_dict()["pour"]
    order = [p[k] for k in ("pour_start", "slip_onset", "rotation", "downward", "full_slip")]
    assert not any(math.isnan(t) for t in order), p
    assert order == sorted(order) and len(set(order)) == 5, p


def test_scale_and_pump_report_the_water_moved(pour):
    lab, frames = pour
    pump, scale = frames["pump"], frames["scale"]
    dispensed = np.array([s.dispensed_ml for s in pump])
    assert np.all(np.diff(dispensed) >= 0) and dispensed[-1] > 50
    mass = np.array([s.mass_g for s in scale])
    # the scale weighs the reservoir: it falls by the dispensed mass (1 g/ml)
    assert mass[0] - mass[-1] == pytest.approx(dispensed[-1] - dispensed[0], abs=0.5)
    assert not scale[len(scale) // 2].stable and scale[-1].stable


def test_grip_loads_the_grasp_fingers_and_pac_rises_during_the_slide(pour):
    lab, frames = pour
    b = biotac_arrays(frames["biotac"])
    ff = lab.biotac.fingers.index("ff")
    p = lab.truth.pour
    t_pac = np.repeat(b["time"], 22)
    pac = b["pac"][:, ff].astype(float)
    stick = (t_pac > p["pour_start"]) & (t_pac < p["slip_onset"])
    slide = (t_pac > p["downward"]) & (t_pac < p["full_slip"])
    assert pac[slide].std() > 1.3 * pac[stick].std()
    # after the bottle falls the fingertip unloads: electrodes back near rest
    e = b["electrodes"][:, ff].astype(float)
    loaded = e[(b["time"] > p["slip_onset"]) & (b["time"] < p["downward"])].mean(0)
    after = e[b["time"] > p["full_slip"] + 0.2].mean(0)
    assert (after - loaded).max() > 100


def _slip_onset(rate, flexion, seed=5, grip=2.0):
    lab = make_sim_lab({"seed": seed, "pour": {"grip_n_per_rad": grip}})
    with lab:
        close_grasp(lab, flexion)
        lab.clock.sleep(0.5)
        lab.pump.set_rate(rate)
        t0 = lab.clock.now()
        lab.clock.sleep(5.0)
        dispensed_5s = lab.pump.status().dispensed_ml
        while math.isnan(lab.truth.pour["slip_onset"]) and lab.clock.now() < t0 + 120:
            lab.clock.sleep(0.1)
    return lab.truth.pour["slip_onset"] - t0, dispensed_5s


def test_faster_pump_fills_faster_and_slips_sooner():
    slow, d_slow = _slip_onset(75.0, 1.3)
    fast, d_fast = _slip_onset(150.0, 1.3)
    assert d_fast == pytest.approx(2 * d_slow, rel=0.02)
    assert fast < slow


def test_tighter_grip_holds_more_weight():
    loose, _ = _slip_onset(150.0, 1.3)
    tight, _ = _slip_onset(150.0, 1.4)
    assert tight > loose


def test_slip_onset_leaves_a_tactile_trace_on_every_grasp_finger(pour):
    """When the bottle first gives, the skin's recoil takes load off the pads (a PDC trough)
    and the sudden release rings the PAC; the thumb, opposing the fingers, feels it too."""
    lab, frames = pour
    b = biotac_arrays(frames["biotac"])
    t = b["time"]
    i = int(np.searchsorted(t, lab.truth.pour["slip_onset"]))
    for f in ("ff", "mf", "th"):
        k = lab.biotac.fingers.index(f)
        pdc = b["pdc"][:, k].astype(float)
        before, dip = pdc[i - 20:i - 2].mean(), pdc[i - 1:i + 3].min()
        assert before - dip > 4 * pdc[i - 100:i - 10].std(), f
        pac = b["pac"][:, k].astype(float).reshape(len(t), -1)
        quiet = pac[i - 100:i - 10]
        assert np.abs(pac[i - 1:i + 3] - quiet.mean()).max() > 6 * quiet.std(), f


def test_bottle_rotation_turns_the_shear_pattern():
    """The skin under the pads turns with the bottle: the pressure pattern rotates (the thumb,
    facing the fingers, sees it mirrored)."""
    from tactile_flow.hardware.sim.config import load_config
    from tactile_flow.hardware.sim.world import SimWorld
    w = SimWorld(load_config({"seed": 0}), None)
    w.grasp.stretch_mm, w.grasp.shear_n = 0.8, 2.0
    _, _, a0 = w._grasp_patch(0.8, 0.0)
    _, _, a1 = w._grasp_patch(0.8, 0.4)
    assert np.degrees(np.arccos(a0 @ a1)) == pytest.approx(np.degrees(0.4), abs=0.1)

"""Sweeping a fingertip across straws: PDC peaks at the true crossings, shear ordering."""

import numpy as np
import pytest
from scipy.signal import find_peaks

from tactile_flow.hardware.sim import make_sim_lab
from tactile_flow.hardware.sim.scenarios import biotac_arrays, straws_sweep

# taxels a straw passes under at 1.5 mm depth, ahead of and behind the pad's centre
PLUS_X = [20, 21, 22]          # taxels 21, 22, 23: x = 4.3..6.6 mm
MINUS_X = [6, 7, 16, 17]       # taxels 7, 8, 17, 18: x = -3.5..-5.7 mm


def _sweep(direction, seed=3):
    lab = make_sim_lab({"seed": seed}, {"kind": "straws", "count": 3, "spacing_mm": 20.0})
    with lab:
        frames = straws_sweep(lab, speed=0.01, direction=direction)
    return biotac_arrays(frames["biotac"]), lab.truth.to_dict(), frames


@pytest.fixture(scope="module")
def forward():
    return _sweep(+1)


@pytest.fixture(scope="module")
def backward():
    return _sweep(-1)


def test_three_pdc_peaks_at_the_true_crossing_times(forward):
    b, truth, _ = forward
    pdc = b["pdc"][:, 0].astype(float)
    peaks, _ = find_peaks(pdc, prominence=50, distance=50)
    crossings = truth["feature_crossings"]
    assert list(crossings["feature"]) == ["feature_0", "feature_1", "feature_2"]
    assert len(peaks) == 3
    err = b["time"][peaks] - np.sort(crossings["centre_time"])
    assert np.all(np.abs(err) < 0.030), err
    # between straws the finger is free: PDC back near its resting level
    assert pdc[peaks].min() - np.median(pdc[:10]) > 100


def test_truth_describes_the_sweep_and_the_features(forward):
    _, truth, _ = forward
    sw = truth["sweeps"]
    assert len(sw["start"]) == 3 and set(sw["finger"]) == {"ff"}
    np.testing.assert_allclose(sw["dir_world"], [[1, 0, 0]] * 3, atol=1e-6)
    np.testing.assert_allclose(sw["dir_sensor"], [[1, 0, 0]] * 3, atol=1e-6)
    np.testing.assert_allclose(sw["speed_m_s"], 0.01, rtol=0.02)
    f = truth["features"]
    np.testing.assert_allclose(f["width_m"], 0.006)
    np.testing.assert_allclose(f["height_m"], 0.006)
    c = truth["feature_crossings"]
    assert np.all(c["entry"] < c["centre_time"]) and np.all(c["centre_time"] < c["exit"])
    # contacts: one interval per straw
    assert len(truth["contacts"]["start"]) == 3


def _load_time(b, taxels, t0, t1):
    """Time of the largest mean count drop of ``taxels`` (finger 0) within [t0, t1]."""
    e = b["electrodes"][:, 0, taxels].astype(float)
    drop = (e[:20].mean(0) - e).mean(1)
    m = (b["time"] >= t0) & (b["time"] <= t1)
    return b["time"][m][np.argmax(drop[m])]


@pytest.mark.parametrize("which", ["forward", "backward"])
def test_leading_taxels_load_before_trailing_ones(which, request):
    b, truth, _ = request.getfixturevalue(which)
    c = truth["feature_crossings"]
    order = np.argsort(c["entry"])
    entry, exit_ = c["entry"][order[0]], c["exit"][order[0]]
    t_plus = _load_time(b, PLUS_X, entry - 0.1, exit_ + 0.1)
    t_minus = _load_time(b, MINUS_X, entry - 0.1, exit_ + 0.1)
    if which == "forward":     # moving +x: the +x taxels meet the straw first
        assert t_plus < t_minus - 0.1
    else:                      # reversed: order reversed
        assert t_minus < t_plus - 0.1


def test_electrodes_fall_under_load_and_far_ones_rise(forward):
    b, truth, _ = forward
    e = b["electrodes"][:, 0, :].astype(float)
    rest = e[:20].mean(0)
    k = np.argmax(b["pdc"][:, 0])
    assert (rest - e[k])[[20, 21, 22, 23]].max() > 200      # pad taxels pressed
    far = [5, 15]                                             # taxels 6, 16: high on the sides
    assert (e[k] - rest)[far].mean() > 20                    # away from the contact: rise


def test_pac_vibrates_when_crossing_edges(forward):
    b, truth, _ = forward
    pac = b["pac"][:, 0].astype(float)
    t_pac = np.repeat(b["time"], 22)
    c = truth["feature_crossings"]
    near = np.zeros_like(t_pac, dtype=bool)
    for e0 in c["entry"]:
        near |= (t_pac > e0) & (t_pac < e0 + 0.3)
    free = t_pac < c["entry"].min() - 0.5
    assert pac[near].std() > 1.5 * pac[free].std()

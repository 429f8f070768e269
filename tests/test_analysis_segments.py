"""Segmentation on hand-made pressure signals (pure functions, no store)."""

import numpy as np
import pytest

from tactile_flow.analysis import labels as labelling
from tactile_flow.analysis import segments as seg
from tactile_flow.analysis.config import AnalysisConfigError, load_config

RATE = 100.0


def bump_train(centres_s, width_s, height, T_s=10.0, noise=0.0, seed=0):
    """PDC-like signal: flat-topped bumps (box convolved with a short Hann ramp) plus noise."""
    t = np.arange(int(T_s * RATE)) / RATE
    p = np.zeros_like(t)
    for c, h in zip(centres_s, np.broadcast_to(height, len(centres_s))):
        p += h * np.clip((width_s / 2 + 0.2 - np.abs(t - c)) / 0.4, 0, 1)   # trapezoid: FWHM = width_s
    return t, p + np.random.default_rng(seed).normal(0, noise, len(t))


def test_contacts_peaks_and_plateaus_of_three_bumps():
    t, p = bump_train([2.0, 5.0, 8.0], 1.0, [300, 200, 100], noise=0.3)
    ps = seg.smooth(p, RATE, 0.05)
    ivs = seg.contact_intervals(ps, 3.0, RATE, 0.1, 0.05)
    assert len(ivs) == 3
    ex = seg.extrema(ps, RATE, prominence=20.0, distance_s=0.5)
    assert len(ex.peaks) == 3
    for (a, b), centre in zip(ivs, [2.0, 5.0, 8.0]):
        (bump,) = seg.bumps(ps, (a, b), ex.peaks, 0.5)
        assert abs(t[bump.peak] - centre) <= 0.5          # anywhere on the flat top
        lo, hi, dur = seg.plateau_duration(ps, bump, RATE, 0.5)
        assert dur == pytest.approx(1.0, abs=0.03)           # FWHM of the trapezoid
        assert abs((lo + hi) / 2 - centre) < 0.02


def test_two_bumps_in_one_contact_are_split_at_the_trough():
    t, p = bump_train([3.0, 4.3], 0.6, 200, noise=0.2)
    p += 30 * ((t > 2) & (t < 5.5))                          # never leaves contact between them
    ps = seg.smooth(p, RATE, 0.05)
    ivs = seg.contact_intervals(ps, 3.0, RATE)
    assert len(ivs) == 1
    ex = seg.extrema(ps, RATE, 20.0, 0.5)
    bs = seg.bumps(ps, ivs[0], ex.peaks, 0.5)
    assert len(bs) == 2
    assert bs[0].stop == bs[1].start
    assert 3.3 < t[bs[0].stop] < 4.0


def test_extrema_distance_and_prominence_are_physical():
    t, p = bump_train([2.0, 2.3], 0.05, 100)                 # two peaks 0.3 s apart
    assert len(seg.extrema(p, RATE, 10.0, 0.5).peaks) == 1
    assert len(seg.extrema(p, RATE, 10.0, 0.1).peaks) == 2
    assert len(seg.extrema(p, RATE, 500.0, 0.1).peaks) == 0


def test_short_noise_is_not_a_contact_and_gaps_merge():
    p = np.zeros(1000)
    p[100:104] = 50                                           # 40 ms blip
    p[300:400] = 50
    p[403:500] = 50                                           # 30 ms gap
    ivs = seg.contact_intervals(p, 3.0, RATE, min_s=0.1, merge_gap_s=0.05)
    assert ivs == [(300, 500)]


def test_sweep_labels_cover_each_bump():
    t, p = bump_train([3.0, 6.0], 1.0, 300)
    ivs = seg.contact_intervals(p, 3.0, RATE)
    ex = seg.extrema(p, RATE, 20.0, 0.5)
    segs = labelling.sweep_segments("ff", len(p), ivs, [seg.bumps(p, iv, ex.peaks) for iv in ivs])
    labels = [s.label for s in segs]
    assert labels == ["approach", "before", "during", "after", "before", "during", "after", "lift"]
    for s in segs:
        assert s.start < s.stop


def test_knee_of_a_ramp_after_a_drift():
    t = np.arange(1000) / RATE
    y = 0.3 - 0.01 * t + np.clip(t - 4.0, 0, None) * 0.1     # a slow drift, a rise from 4 s
    for scale in (1.0, 0.01, 100.0):
        i = seg.knee(t, scale * y + 7.0, 200, 600)
        assert abs(t[i] - 4.0) < 0.02


def turn(t, onset_s, amplitude, noise, seed=0, drift=0.0):
    """A static-flow rotation as the pipeline reads it: a torsional breakaway at ``onset_s``
    (turns quickly, then levels), a slow drift, white noise, smoothed over 0.5 s."""
    rng = np.random.default_rng(seed)
    raw = amplitude * np.where(t > onset_s, 1 - np.exp(-np.clip(t - onset_s, 0, None) / 0.25), 0.0)
    return seg.smooth(raw + drift * t + rng.normal(0, noise, len(t)), RATE, 0.5)


@pytest.mark.parametrize("amplitude", [0.02, 0.005, -0.004])
def test_largest_change_and_its_knee_date_a_turn_at_any_scale(amplitude):
    """The rotation phase's reading: a quarter of the turn (the sensor's shear gain 3 instead
    of 12) is dated as well; the absolute threshold it replaces (0.015 rad) never saw it."""
    t = np.arange(4000) / RATE
    y = turn(t, 12.0, amplitude, 0.0004, drift=-0.0004)
    steep, sign = seg.largest_change(y, 250, 3400, 50)
    assert sign == np.sign(amplitude)
    assert abs(t[seg.knee(t, y, steep - 100, steep)] - 12.0) < 0.1


def test_largest_change_is_none_in_noise_and_drift():
    t = np.arange(4000) / RATE
    for seed in range(5):
        y = turn(t, 12.0, 0.0, 0.0004, seed=seed, drift=-0.0004)
        assert seg.largest_change(y, 250, 3400, 50) is None


def test_edge_crossing_reads_a_fall_by_its_own_depth():
    t = np.arange(3000) / RATE
    x = np.where(t < 20.0, 1.0 - 0.1 * t, -8.0)                 # sinks, then falls at 20 s to −8
    x = seg.smooth(x, RATE, 0.05)
    edge = int(np.argmin(np.diff(x)))
    i = seg.edge_crossing(x, edge, 0, 50, -8.0, 0.5)
    assert abs(t[i] - 20.0) < 0.03
    assert abs(t[seg.edge_crossing(7 * x + 3, edge, 0, 50, -53.0, 0.5)] - 20.0) < 0.03


def test_first_drop_dates_a_fall_that_a_smoother_led_by_its_steepest_step():
    """A non-causal smoother (the activation's RTS pass) starts a sudden fall early: a gentle
    decline ahead of the step. The fall is dated at its steepest step, however early the
    decline first passes the threshold."""
    t = np.arange(3000) / RATE
    x = 3.0 - 0.6 * np.clip((t - 9.4) / 0.6, 0, 1)                       # the smoother's lead
    x = x - 1.0 * np.clip((t - 10.0) / 0.03, 0, 1) * np.exp(-np.clip(t - 10.03, 0, None) / 0.3)
    x = x + np.random.default_rng(2).normal(0, 0.005, len(t))
    for fraction in (0.15, 0.05):
        i = seg.first_drop(x, 200, fraction, 50)
        assert abs(t[i] - 10.0) < 0.04, (fraction, t[i])


def fingers_holding_a_bottle_that_gives(seed=0, giving=(True, True, True)):
    """Three fingers' pressures (T,) as one bottle gives under them at 20 s (a shared dip), on a
    slow decline with the load; the first finger's contact is loose, its smoothed noise runs
    five times the others' and swells at 9 and 15 s into falls of 10× its median noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(4000) / RATE
    out = []
    for (scale, noise), gives in zip(((1.0, 0.03), (0.8, 0.006), (2.0, 0.009)), giving):
        x = scale * (2.0 - 0.02 * t) + seg.smooth(rng.normal(0, noise * 4, len(t)), RATE, 0.08)
        x = x - gives * 0.15 * scale * np.clip((t - 20.0) / 0.05, 0, 1) * np.exp(-np.clip(t - 20.05, 0, None) / 0.8)
        out.append(x)
    for at in (9.0, 15.0):
        out[0] = out[0] + 0.3 * np.exp(-((t - at) / 0.15) ** 2)
    return t, out


def test_a_fall_the_fingers_share_is_the_bottle_giving_not_one_finger_s_noise():
    t, fingers = fingers_holding_a_bottle_that_gives()
    alone = seg.first_drop(fingers[0], 200, 0.15, 50)
    assert alone is not None and t[alone] < 17.0                    # the loose finger alone: a swell
    i = seg.shared_first_drop(fingers, 200, 3800, 50)
    assert abs(t[i] - 20.0) < 0.05, t[i]
    # only ratios to each finger's own noise: a finger's scale or offset does not move it
    scaled = [fingers[0] * 30.0 + 5.0, fingers[1] * 0.01, fingers[2]]
    assert seg.shared_first_drop(scaled, 200, 3800, 50) == i


def test_no_shared_fall_when_one_finger_falls_alone():
    t, fingers = fingers_holding_a_bottle_that_gives(giving=(False, False, True))
    assert seg.first_drop(fingers[2], 200, 0.15, 50) is not None          # it falls, on its own
    assert seg.shared_first_drop(fingers, 200, 3800, 50) is None


def test_replateau_lasts_as_long_as_asked_centred_on_the_pressure():
    x = np.exp(-((np.arange(400) - 200.0) / 40.0) ** 2)
    b = seg.Bump(50, 350, 200, (170, 230), 1.0)
    assert seg.replateau(x, x, b, 0.5, frames=60.0).plateau == (170, 230)
    assert seg.replateau(x, np.roll(x, 10), b, 0.5, frames=30.0).plateau == (195, 225)


def made_up_grasp(gain):
    """A pour as the pads read it at a shear gain ``gain`` (12: the simulator's former
    default, 3: what real BioTac SP frames allow): the pad pressure sinks with the shear term
    as the load grows, dips when the bottle first gives at 8 s, breaks away at 20 s (the
    downward slide) and falls at 35 s (full slip); the static-flow rotation turns
    (0.0016 × gain rad) at 12 s."""
    t = np.arange(4000) / RATE
    g = gain / 12.0
    p = np.where((t > 1) & (t < 35), 4 + 0.05 * (t - 1) - (1 - g) * 0.15 * (t - 1), 0.0)
    p = np.where((t > 8) & (t < 35), p - 0.8 * np.exp(-np.clip(t - 8, 0, None) / 0.3), p)
    p = np.where((t > 20) & (t < 35), p - 1.0, p)
    rot = turn(t, 12.0, 0.02 * g, 0.0003, drift=-0.0003)
    p = p + np.random.default_rng(1).normal(0, 0.01, len(t))   # the pad's noise
    return t, seg.smooth(p, RATE, 0.05), rot


@pytest.mark.parametrize("gain", [12, 6, 3])
def test_pour_phases_from_a_made_up_grasp(gain):
    t, p, rot = made_up_grasp(gain)
    ph = labelling.pour_phases(t, p, (101, 3500), 110, rot, 200, 6.0, 0.15, 50)
    on = {k: (None if v is None else t[v]) for k, v in ph.onsets.items()}
    assert on["pour"] == pytest.approx(2.0)
    assert on["rotation"] == pytest.approx(12.0, abs=0.1)
    assert on["downward"] == pytest.approx(20.0, abs=0.05)
    assert on["full_slip"] == pytest.approx(35.0, abs=0.05)
    assert on["initial_slip"] == pytest.approx(8.0, abs=0.05)


def test_a_shared_initial_slip_leads_the_finger_s_later_phases():
    """A finger whose own first fall came early (its noise) takes the slip the fingers share; its
    downward phase is searched after it, not after its own early fall."""
    t, p, rot = made_up_grasp(12)
    noisy = p + np.where((t > 5.0) & (t < 5.3), 0.9, 0.0)            # a swell that falls at 5.3 s
    own = labelling.pour_phases(t, noisy, (101, 3500), 110, rot, 200, 6.0, 0.15, 50)
    assert t[own.onsets["initial_slip"]] == pytest.approx(5.3, abs=0.1)
    shared = labelling.pour_phases(t, noisy, (101, 3500), 110, rot, 200, 6.0, 0.15, 50, shared_slip=800)
    assert shared.onsets["initial_slip"] == 800 and "initial_slip" not in shared.reasons
    assert t[shared.onsets["downward"]] == pytest.approx(20.0, abs=0.05)
    assert shared.slip_search[0] == 200 and t[shared.slip_search[1]] == pytest.approx(35.0, abs=0.2)


def test_pour_without_a_turn_says_why():
    t, p, _ = made_up_grasp(12)
    rot = turn(t, 12.0, 0.0, 0.0003, drift=-0.0003)
    ph = labelling.pour_phases(t, p, (101, 3500), 110, rot, 200, 6.0, 0.15, 50)
    assert ph.onsets["rotation"] is None and "noise" in ph.reasons["rotation"]


def test_config_errors_name_the_key():
    with pytest.raises(AnalysisConfigError, match="analysis.segmentation.prominence"):
        load_config({"segmentation": {"prominence": 3}})
    with pytest.raises(AnalysisConfigError, match="analysis.flow.method"):
        load_config({"flow": {"method": "magic"}})
    with pytest.raises(AnalysisConfigError, match="analysis.bogus"):
        load_config({"bogus": 1})
    cfg = load_config({"tactile": {"sigma": 2.0}, "views": ["bottom"], "flow": {"method": "dis"}})
    assert cfg.tactile.sigma == 2.0 and cfg.tactile.views == ("bottom",) and cfg.tactile.flow.method == "dis"

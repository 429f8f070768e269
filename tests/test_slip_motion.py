"""The slip estimate's pure parts: the pattern's motion from its first settled frames
(``analysis.slip_motion``), the slip onset's knee (``analysis.slip_onset``) and the headline's
circular statistics (``analysis.headline``)."""

import math

import numpy as np
import pytest

from tactile_flow.analysis.headline import circular_mean_deg
from tactile_flow.analysis.slip_motion import pattern_motion, turn_deg
from tactile_flow.analysis.slip_onset import knee
from tactile_flow.tactile.geometry import load_taxels

TAXELS = load_taxels()


def blob(centre, sigma=(4.0, 2.0), angle_deg=0.0, load=5.0, taxels=TAXELS):
    """(n,) activation kΩ of an elliptical Gaussian contact at ``centre`` (x, y) mm, its long axis
    ``angle_deg`` from +x (counter-clockwise about +z)."""
    a = math.radians(angle_deg)
    r = np.array([[math.cos(a), math.sin(a)], [-math.sin(a), math.cos(a)]])
    d = (taxels[:, :2] - np.asarray(centre)) @ r.T
    return load * np.exp(-0.5 * ((d[:, 0] / sigma[0]) ** 2 + (d[:, 1] / sigma[1]) ** 2))


def record(frames):
    return np.stack(frames)


def test_a_shifted_pattern_moves_a_pressed_harder_one_does_not():
    still = record([blob((2.0, 1.0))] * 10 + [blob((2.0, 1.0), load=5.0 * (1 + 0.1 * i)) for i in range(30)])
    pm = pattern_motion(still, TAXELS, 0, len(still), 10)
    assert np.abs(pm.displacement).max() < 1e-9 and np.abs(pm.turn_deg).max() < 1e-6
    assert pm.change.max() < 1e-9
    moved = record([blob((2.0, 1.0))] * 10 + [blob((2.0 + 0.1 * i, 1.0)) for i in range(30)])
    pm = pattern_motion(moved, TAXELS, 0, len(moved), 10)
    d = pm.displacement[-1]
    assert d[0] > 1.0 and abs(d[1]) < 0.3 * d[0]                   # along +x, by most of the 2.9 mm
    assert pm.change[-1] > 10 * max(pm.change_noise, 1e-6)


@pytest.mark.parametrize("turn", [10.0, -10.0])
def test_an_elongated_pattern_turned_reads_its_sense(turn):
    """+ rotation_deg is counter-clockwise seen from outside the pad: about the sensor's −z, i.e.
    a negative angle about +z in the sensor's x–y coordinates."""
    frames = record([blob((0.0, 0.0))] * 10 + [blob((0.0, 0.0), angle_deg=-turn * i / 20) for i in range(1, 21)])
    pm = pattern_motion(frames, TAXELS, 0, len(frames), 10)
    assert np.sign(pm.turn_deg[-1]) == np.sign(turn)
    assert np.hypot(*pm.displacement[-1]) < 0.3
    assert pm.elongation > 0.2


def test_the_turn_of_second_moments_is_exact_for_a_small_rotation():
    m = np.array([[9.0, 1.0], [1.0, 3.0]])
    th = math.radians(2.0)
    r = np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]])
    turned, elongation = turn_deg((r @ m @ r.T)[None], m)
    assert turned[0] == pytest.approx(-2.0, abs=0.05)             # +2° about +z is −2° in rotation_deg
    assert 0 < elongation < 1


def test_nothing_pressed_is_no_motion():
    assert pattern_motion(np.zeros((30, len(TAXELS))), TAXELS, 0, 30, 10) is None


def test_the_knee_is_where_the_skin_stops_following():
    rng = np.random.default_rng(0)
    t = np.arange(250)
    y = 3.0 * np.clip((t - 60) / 40, 0, 1) + 0.0005 * np.clip(t - 100, 0, None) + rng.normal(0, 0.02, len(t))
    k = knee(y)
    assert abs(k.motion - 60) <= 2 and abs(k.slip - 100) <= 2 and k.slowed
    assert k.slip_lo <= k.slip <= k.slip_hi and k.slip_hi - k.slip_lo <= 8


def test_a_contact_that_slides_at_once_slips_when_it_starts_moving():
    t = np.arange(200)
    k = knee(0.02 * np.clip(t - 50, 0, None))
    assert not k.slowed and abs(k.slip - 50) <= 1


def test_a_flat_or_short_signal_has_no_knee():
    assert knee(np.zeros(100)) is None and knee(np.arange(5.0)) is None


def test_circular_mean_of_two_headings_is_not_their_vector_mean():
    assert circular_mean_deg([179.0, -179.0])[0] == pytest.approx(180.0, abs=1e-6) or \
        circular_mean_deg([179.0, -179.0])[0] == pytest.approx(-180.0, abs=1e-6)
    mean, spread = circular_mean_deg([10.0, 10.0, 10.0])
    assert mean == pytest.approx(10.0) and spread == pytest.approx(0.0, abs=1e-6)
    assert circular_mean_deg([0.0, 180.0]) == (None, None)          # opposite: no mean direction
    assert circular_mean_deg([]) == (None, None)


def test_a_twists_release_is_dated_along_the_pattern_the_stuck_skin_built_up():
    """A twist loads two opposite quadrants and unloads the others: the total positive load
    barely sees it (here the press still loading swamps it), but the raw change projected on the
    twist's own pattern falls when the skin breaks away (frame 60)."""
    from tactile_flow.analysis.slip import _release
    rng = np.random.default_rng(3)
    base = blob((0.0, 0.0), sigma=(4.0, 2.5))
    twist = 3.0 * (blob((0.0, 0.0), sigma=(4.0, 2.5), angle_deg=8.0) - base)
    frames = []
    for i in range(120):
        held = 0.0 if i < 20 else ((i - 20) / 40 if i < 60 else 0.6 + 0.01 * (i - 60))  # stuck, then released to 60 %
        frames.append((1.0 + 0.01 * min(i, 80)) * base + held * twist + rng.normal(0.0, 0.05, len(base)))
    raw = np.stack(frames)
    knee_only = {"motion_frame": 20, "slip_frame": 52, "uncertainty_frames": 1.0}
    _release(knee_only, raw, 20, 100.0)
    assert "dated_by" not in knee_only                          # the total load shows no release
    along = {"motion_frame": 20, "slip_frame": 52, "uncertainty_frames": 1.0}
    _release(along, raw, 20, 100.0, twist)
    assert along["dated_by"] == "release" and abs(along["slip_frame"] - 60) <= 3


def _faint_twist_under_a_settling_press(seed: int):
    """A tared press still loading its contact (+0.4 % a frame for 80 frames) while a faint twist
    (1/5 of the stuck skin's quadrant loads of the test above, at the noise's level) builds up
    from frame 20 and is released at frame 60, as at the shear gain the real contact frames allow
    (3 kΩ/N): the raw frames (120, n) and the smoothed change from the motion onset to the knee."""
    rng = np.random.default_rng(seed)
    base = blob((0.0, 0.0), sigma=(4.0, 2.5))
    twist = 0.6 * (blob((0.0, 0.0), sigma=(4.0, 2.5), angle_deg=8.0) - base)
    press = lambda i: 1.0 + 0.004 * min(i, 80)                                          # noqa: E731
    held = lambda i: 0.0 if i < 20 else ((i - 20) / 40 if i < 60 else 0.5)             # noqa: E731
    raw = np.stack([press(i) * base + held(i) * twist + rng.normal(0.0, 0.02, len(base)) for i in range(120)])
    along = (press(52) - press(20)) * base + (held(52) - held(20)) * twist              # the smoothed change
    return raw, along


def test_a_faint_twists_release_is_read_on_its_shape_not_on_the_press_still_settling():
    """The change from the motion onset to the knee is mostly the press going on loading the
    contact in proportion; projected on it the raw change keeps rising and no release shows (or
    the press's noise falls are taken). Less its part along the reference pattern (a firmer press
    of the same shape is not a stretch) it is the twist's own pattern, which falls back at the
    skin's release (frame 60)."""
    from tactile_flow.analysis.slip import _release
    dated = []
    for seed in range(8):
        raw, along = _faint_twist_under_a_settling_press(seed)
        when = {"motion_frame": 20, "slip_frame": 52, "uncertainty_frames": 1.0}
        _release(when, raw, 10, 100.0, along)
        dated.append(when.get("dated_by") == "release" and abs(when["slip_frame"] - 60) <= 3)
    assert sum(dated) >= 6, dated                      # on the press's change: 0 of 8


def _slip_cfg():
    from tactile_flow.analysis.config import Slip
    return Slip()


def test_a_twist_whose_flows_drifted_back_is_read_by_its_static_turn():
    """The SP grid's light twist on the flat board without tare: the pattern turned 1.35° while
    the board turned, then its dynamic flow drifted back (−0.58°) against the static flow (+0.82°),
    so their end values average 0.12°, below ``min_rotation_deg``; its centre of pressure stayed
    within 0.83 mm. A contact that stayed in place is read by its static flow's turn since the
    reference window: a rotation, the right sense."""
    from tactile_flow.analysis.slip import classify, turn
    cfg = _slip_cfg()
    rotation = {"rotation_deg": 0.12, "dynamic_deg": -0.58, "static_deg": 0.82, "peak_deg": 1.35}
    assert turn(0.83, rotation, cfg) == (0.82, "static")
    cls, confidence = classify(0.83, rotation, 2.74, None, cfg)
    assert cls == "rotation" and 0.5 < confidence <= 1.0
    # the same contact read by its end values alone is a touch (round 2's miss)
    assert classify(0.83, {**rotation, "peak_deg": None, "static_deg": None}, 2.74, None, cfg)[0] == "none"


def test_a_twist_at_the_shear_the_real_frames_allow_is_a_rotation():
    """The SP grid's firm counter-clockwise twist on the flat board without tare, with the
    simulator's shear gain at 3 kΩ/N (the bound the real contact frames allow): the pattern
    turned 0.79° in the static flow, while the dynamic curl summed read the wrong sense (−0.17°)
    and their mean and its peak (0.31°, 0.40°) stayed under ``min_rotation_deg`` — round 3 read it
    as a touch. Still (0.13 mm), read by the static turn: a rotation, counter-clockwise."""
    from tactile_flow.analysis.slip import classify, turn
    cfg = _slip_cfg()
    rotation = {"rotation_deg": 0.31, "dynamic_deg": -0.17, "static_deg": 0.79, "peak_deg": 0.40}
    assert turn(0.13, rotation, cfg) == (0.79, "static")
    assert classify(0.13, rotation, 2.94, None, cfg)[0] == "rotation"
    assert classify(0.13, {**rotation, "static_deg": None}, 2.94, None, cfg)[0] == "none"   # round 3


def test_a_still_touch_whose_static_flow_turned_a_little_stays_a_touch():
    """Real contact frames held still (tests/real_touch.py, 180 records) turn their static flow by
    at most 0.35° once the reference window starts after the press (0.15° held from the first
    frame): under ``min_still_rotation_deg``, a touch — while the same turn in a contact that
    moved is read by its end values against ``min_rotation_deg``."""
    from tactile_flow.analysis.slip import classify, turn
    cfg = _slip_cfg()
    rotation = {"rotation_deg": 0.2, "dynamic_deg": 0.05, "static_deg": 0.35, "peak_deg": 0.3}
    assert cfg.min_still_rotation_deg > 0.35
    assert classify(0.02, rotation, 7.0, None, cfg)[0] == "none"
    assert turn(2.0, rotation, cfg) == (0.2, "end")


def _static_turn(seed: int, ramp_deg: float, back_deg: float, drift_deg: float = 0.0) -> np.ndarray:
    """A static flow's turn since the reference window, deg, over a 1.8 s contact at 100 Hz: still
    for 0.45 s, a ramp of ``ramp_deg`` over 0.3 s (the stuck skin twisted), then ``back_deg`` of it
    let go over the rest (the skin broke away and the pattern drifts back), a slow ``drift_deg``
    over the whole contact and a smooth wander of a few hundredths of a degree (the flow of a
    still pattern under the resting noise)."""
    rng = np.random.default_rng(seed)
    t = np.arange(180)
    twist = ramp_deg * np.clip((t - 45) / 30.0, 0.0, 1.0) - back_deg * np.clip((t - 75) / 105.0, 0.0, 1.0)
    wander = np.convolve(rng.normal(0.0, 0.03, 200), np.ones(20) / 20.0, mode="same")[:180]
    return twist + drift_deg * t / 179.0 + wander - wander[0]


def test_a_light_twist_that_drifted_back_is_read_by_how_far_its_static_turn_rose():
    """Seed 0's light clockwise twist on the flat board without tare at the shear the real frames
    allow (3 kΩ/N): its static turn rose 0.50° while the skin stuck, then drifted back to an end
    value of 0.27° — under ``min_still_rotation_deg``, read as a touch before. How far it rose in
    its one ramp (``static_rise``) is the twist; a still touch's wander and slow drift (real
    contact frames: end values up to 0.23°, rises up to 0.26°) rises less."""
    from tactile_flow.analysis.slip import classify, static_rise, turn
    cfg = _slip_cfg()
    for seed in range(4):
        series = _static_turn(seed, -0.5, -0.25)
        end = float(np.median(series[-36:]))
        rise = static_rise(series)
        assert abs(end) < cfg.min_still_rotation_deg <= abs(rise) and rise < 0, (end, rise)
        rotation = {"rotation_deg": -0.12, "dynamic_deg": 0.03, "static_deg": end, "static_rise_deg": rise,
                    "peak_deg": -0.2}
        assert turn(0.15, rotation, cfg) == (rise, "static")
        assert classify(0.15, rotation, 2.6, None, cfg)[0] == "rotation"
        assert classify(0.15, {**rotation, "static_rise_deg": None}, 2.6, None, cfg)[0] == "none"   # its end value
        touch = _static_turn(seed, 0.0, 0.0, drift_deg=0.25)                  # a touch drifting 0.25°
        rise = static_rise(touch)
        assert abs(rise) < 0.3, rise
        assert classify(0.1, {"rotation_deg": 0.1, "static_deg": float(np.median(touch[-36:])),
                              "static_rise_deg": rise, "peak_deg": 0.15}, 2.6, None, cfg)[0] == "none"
    assert static_rise(np.zeros(50)) == 0.0 and static_rise(np.zeros(5)) is None


def test_a_pull_is_read_by_its_end_values_so_its_spurious_turn_on_the_way_stays_a_pull():
    """A 5 N pull at 300° on the flat board: the rendered pattern turned up to 2.3° on the way
    (a pull's spurious turn grows with its length), its flows' end values average 1.4°. It moved
    2.9 mm: its turn is read by the end values, and the arc they sweep at its radius is below
    ``arc_ratio`` of the displacement — a translation, as the peak alone would not have it."""
    from tactile_flow.analysis.slip import classify, turn
    cfg = _slip_cfg()
    rotation = {"rotation_deg": 1.38, "dynamic_deg": -0.86, "static_deg": 3.61, "peak_deg": 2.26}
    assert turn(2.87, rotation, cfg) == (1.38, "end")
    assert classify(2.87, rotation, 3.50, 0.9, cfg)[0] == "translation"
    assert classify(2.87, {**rotation, "rotation_deg": 2.26}, 3.50, 0.9, cfg)[0] == "rotation"


def test_a_still_touch_with_a_small_turn_stays_a_touch():
    """A real contact frame held under the real sensor's drift turns its flows by up to 0.86° at
    the most over a record (tests/real_touch.py, 180 records): below ``min_rotation_deg``, a touch."""
    from tactile_flow.analysis.slip import classify
    cfg = _slip_cfg()
    assert classify(0.02, {"rotation_deg": 0.82, "peak_deg": 0.86}, 3.0, None, cfg)[0] == "none"
    assert classify(0.02, {"rotation_deg": 0.0, "peak_deg": None}, 3.0, None, cfg)[0] == "none"


def test_a_still_contact_turned_late_is_read_by_its_end_values():
    """A firm twist that reaches its turn only in the contact's last frames: the 90th percentile
    over the contact (0.75°) under-reads it, the end values (0.92°) do not — the larger is read."""
    from tactile_flow.analysis.slip import classify, turn
    cfg = _slip_cfg()
    rotation = {"rotation_deg": -0.92, "peak_deg": -0.75}
    assert turn(0.85, rotation, cfg) == (-0.92, "end")
    assert classify(0.85, rotation, 3.43, None, cfg)[0] == "rotation"


def test_the_knees_wide_band_holds_its_one_standard_error_band_and_the_truth():
    rng = np.random.default_rng(1)
    t = np.arange(250)
    y = 0.8 * np.clip((t - 60) / 40, 0, 1) + rng.normal(0, 0.03, len(t))
    k = knee(y)
    assert k.wide_lo <= k.slip_lo <= k.slip <= k.slip_hi <= k.wide_hi
    assert k.wide_lo <= 100 <= k.wide_hi and k.wide_hi - k.wide_lo <= 30


def _light_twist_with_a_noise_fall(seed: int):
    """A light twist at the shear the real contact frames allow: its pattern turns 0.6° from
    frame 20 to the skin's release at frame 70, then holds (the turn's knee is clear), while the
    electrodes' twist pattern (1/10 of the stuck skin's quadrant loads of the tests above) is
    let go by only 1.5 × their noise at the release — and a noise fall of 6 × the projected
    noise lands at frame 45, on the way up. Returns (turn (N,) deg, raw (N, n) kΩ, along (n,))."""
    rng = np.random.default_rng(seed)
    base = blob((0.0, 0.0), sigma=(4.0, 2.5))
    twist = 0.3 * (blob((0.0, 0.0), sigma=(4.0, 2.5), angle_deg=8.0) - base)
    unit = twist / np.linalg.norm(twist)
    held = lambda i: 0.0 if i < 20 else ((i - 20) / 50 if i < 70 else 0.97)            # noqa: E731
    noise = 0.02
    raw = np.stack([base + held(i) * twist + rng.normal(0.0, noise, len(base)) for i in range(160)])
    raw[46:48] -= 6.0 * noise * unit * np.sqrt(2)                     # two frames down: a noise fall
    turn = np.array([0.6 * min(max(i - 20, 0) / 50, 1.0) for i in range(160)]) + rng.normal(0, 0.01, 160)
    return turn, raw, held(60) * twist


def test_a_noise_fall_before_the_turn_slowed_is_not_the_twists_release():
    """The light twist above, dated as ``analysis.slip.estimate`` does: the knee of its turn
    (frame 70), then the release looked for on the electrodes' twist pattern. The noise fall at
    frame 45 comes while the turn still ramps at the stuck skin's pace, before the knee's
    earliest slip onset at two standard errors: not a release. Without that bound it was taken
    (150–250 ms early). Noise falls after the knee are still taken as the release where they pass
    4 × the noise (2 of these 6 draws, 140 and 260 ms late): what is left at gain 3."""
    from types import SimpleNamespace

    from tactile_flow.analysis.slip import _onset, _release
    dated, unbounded_dated = [], []
    for seed in range(6):
        turn, raw, along = _light_twist_with_a_noise_fall(seed)
        pm = SimpleNamespace(displacement=np.zeros((len(turn), 2)))
        when = _onset(pm, len(turn), turn, "rotation")
        assert when["signal"] == "rotation" and when["release_from"] > 46
        unbounded = {**when, "release_from": 0}
        _release(when, raw, 10, 100.0, along)
        _release(unbounded, raw, 10, 100.0, along)
        dated.append(abs(when["slip_frame"] - 70) <= 5)             # within 50 ms
        unbounded_dated.append(abs(unbounded["slip_frame"] - 70) <= 5)
    assert sum(dated) >= 4, dated
    assert sum(unbounded_dated) <= 1, unbounded_dated          # the bound is what dates them


def test_a_pulls_release_may_fall_from_just_below_its_high():
    """A firm pull's stretch eases off its high (frames 60–64, by 2 % of its rise a frame) before
    the skin breaks away at frame 65 with a fall of a fifth of the rise: the release, though not
    from a new high. A twist's release still has to fall from a new high (its plateau wanders by
    its noise)."""
    from tactile_flow.analysis.slip import _release
    rng = np.random.default_rng(2)
    base = blob((0.0, 0.0))
    stretch = blob((1.0, 0.0)) - base
    level = lambda i: 0.0 if i < 20 else ((i - 20) / 40 if i < 60 else (1.0 - 0.02 * (i - 60) if i < 65 else 0.7))  # noqa: E731
    raw = np.stack([base + level(i) * stretch + rng.normal(0.0, 0.01, len(base)) for i in range(140)])
    pull = {"motion_frame": 20, "slip_frame": 58, "uncertainty_frames": 1.0, "signal": "displacement"}
    _release(pull, raw, 10, 100.0, level(58) * stretch)
    assert pull["dated_by"] == "release" and abs(pull["slip_frame"] - 65) <= 3, pull
    twist = {**{k: v for k, v in pull.items() if k != "dated_by"}, "slip_frame": 58, "signal": "rotation"}
    _release(twist, raw, 10, 100.0, level(58) * stretch)
    assert twist.get("dated_by") != "release" or abs(twist["slip_frame"] - 65) > 3


@pytest.mark.parametrize("n, offset", [(8, 0.0), (300, 0.0), (300, 1e4)])
def test_the_knees_fits_from_prefix_sums_are_the_frame_by_frame_fits(n, offset):
    """Every still → ramp → slope fit of the knee, read from prefix sums in O(1), is the fit made
    frame by frame (SSE and coefficients), also on a signal far from zero."""
    from tactile_flow.analysis.slip_onset import _fits, _fits_direct, _pairs
    rng = np.random.default_rng(n)
    t = np.arange(n)
    y = offset + np.clip((t - 0.3 * n) / (0.2 * n), 0, 1) + rng.normal(0, 0.03, n)
    a, b = _pairs(np.arange(0, n - 1), np.arange(0, n - 1), 2)
    sse, coef = _fits(y, a, b)
    sse_ref, coef_ref = _fits_direct(y, a, b)
    assert np.allclose(sse, sse_ref, rtol=1e-6, atol=1e-9 * n)
    assert np.allclose(coef, coef_ref, rtol=1e-6, atol=1e-4)      # the reference loses ~1e-5 far from 0


def test_a_long_contacts_knee_is_where_its_ramp_ends():
    """A 60 s contact at 100 Hz (6000 frames) that ramps from 20 s to 30 s: the knee at 30 s
    within a few frames, its two-standard-error band around it."""
    rng = np.random.default_rng(3)
    t = np.arange(6000)
    k = knee(np.clip((t - 2000) / 1000, 0, 1) + rng.normal(0, 0.03, len(t)))
    assert abs(k.slip - 3000) <= 5 and k.wide_lo <= k.slip <= k.wide_hi and k.wide_hi - k.wide_lo <= 30

"""Tactile flow on synthetic contacts whose motion is known (for each shipped sensor model:
the contacts are placed about its pad's lowest point)."""

import numpy as np
import pytest

from tactile_flow.tactile import aggregate, flow, synthetic
from tactile_flow.tactile.pipeline import process_view

RATE = 100.0


def _sensor_direction(model, activation, view="bottom"):
    """Mean dynamic-flow direction (sensor frame, degrees in the x–y plane) while loaded."""
    result = process_view(model, activation, view)
    loaded = np.flatnonzero(activation.sum(axis=1) > 2.0)
    summary = aggregate.window(result.dynamic, loaded[0] + 1, loaded[-1] + 1)
    vec = model.plans[view].image_to_sensor([summary["mean_col"], summary["mean_row"]])
    return np.degrees(np.arctan2(vec[1], vec[0])), summary


def _angle_diff(a, b):
    return abs((a - b + 180) % 360 - 180)


def _pole(model):
    return np.asarray(model.sensor.shape.pole) * [1, 1, 0]


@pytest.mark.parametrize("heading", [0, 180, 90, -90])
def test_bump_moving_across_the_pad_gives_its_direction(sensor_model, rng, heading):
    model = sensor_model
    d = np.array([np.cos(np.radians(heading)), np.sin(np.radians(heading)), 0.0])
    span = 16.0 if heading in (0, 180) else 8.0            # the pad is longer along x
    act = synthetic.moving_bump(model.taxels, start=_pole(model) - span / 2 * d, velocity=10.0 * d,
                                duration=span / 10.0, rate_hz=RATE)
    act = model.smooth(act + rng.normal(0, 0.07, act.shape))
    found, summary = _sensor_direction(model, act)
    assert _angle_diff(found, heading) < 10, f"flow direction {found:.1f}° for motion {heading}°"
    assert summary["confidence"] > 0.1


def test_rotation_about_the_pad_normal_gives_curl_of_its_sign(sensor_model):
    model = sensor_model
    for omega, sign in ((1.5, 1), (-1.5, -1)):
        act = synthetic.rotating_pattern(model.taxels, omega=omega, duration=1.5, rate_hz=RATE,
                                         centre=tuple(_pole(model)[:2]), radius=5.0)
        result = process_view(model, model.smooth(act), "bottom")
        curl = aggregate.window(result.dynamic, 1, len(act))["curl"]
        assert np.sign(curl) == sign, f"omega={omega} rad/s about +z gave curl {curl:.4f}"


def test_static_pattern_has_no_dynamic_flow(sensor_model, rng):
    model = sensor_model
    act = synthetic.moving_bump(model.taxels, start=_pole(model) + (2.0, 0, 0), velocity=(0, 0, 0), duration=1.0)
    act = model.smooth(act + rng.normal(0, 0.07, act.shape))
    result = process_view(model, act, "bottom")
    assert np.max(result.dynamic.magnitude[5:]) < 0.02   # px/frame


def test_static_flow_follows_slow_drift_after_reference(sensor_model):
    # Contact settles at the pad's lowest point, then drifts slowly by 3 mm along +y (static-friction creep).
    model = sensor_model
    n_settle, n_drift = 50, 150
    start = _pole(model) + (0, -1.5, 0)
    still = synthetic.moving_bump(model.taxels, start=start, velocity=(0, 0, 0), duration=n_settle / RATE)
    drift = synthetic.moving_bump(model.taxels, start=start, velocity=(0, 3.0 / (n_drift / RATE), 0),
                                  duration=n_drift / RATE)
    act = model.smooth(np.concatenate([still, drift]))
    ref = flow.contact_reference(act.sum(axis=1), threshold=2.0, settle=10)
    assert ref < n_settle
    result = process_view(model, act, "bottom", reference=ref)
    plan = model.plans["bottom"]
    end = result.static.mean[-1]
    vec = plan.image_to_sensor(end)
    angle = np.degrees(np.arctan2(vec[1], vec[0]))
    assert _angle_diff(angle, 90) < 15, f"static flow at the end points {angle:.1f}°, drift was +y"
    assert result.static.magnitude[ref] < 1e-3          # the reference against itself
    assert result.static.magnitude[-1] > result.static.magnitude[n_settle + 20]


@pytest.mark.parametrize("method", ["dis", "tvl1"])
def test_other_flow_methods_agree_on_direction(model, method):
    from dataclasses import replace
    from tactile_flow.tactile.pipeline import TactileModel
    m = TactileModel(**{**model.__dict__, "config": replace(model.config, flow=flow.FlowConfig(method=method))})
    act = synthetic.moving_bump(model.taxels, start=(-8, 0, 0), velocity=(10, 0, 0), duration=1.6)
    found, _ = _sensor_direction(m, model.smooth(act))
    assert _angle_diff(found, 0) < 15, f"{method}: {found:.1f}°"


def test_flow_units():
    px = np.ones((2, 4, 4, 2), np.float32)
    assert np.allclose(flow.to_mm_per_s(px, mm_per_px=0.8, rate_hz=100.0), 80.0)
    assert np.allclose(flow.to_mm(px, mm_per_px=0.8), 0.8)


def test_contact_reference_needs_a_settled_contact():
    with pytest.raises(ValueError, match="total_activation"):
        flow.contact_reference(np.r_[np.zeros(10), np.ones(5) * 3], threshold=2.0, settle=10)
    assert flow.contact_reference(np.r_[np.zeros(10), np.ones(20) * 3], threshold=2.0, settle=10) == 10


def test_bad_flow_input():
    with pytest.raises(ValueError, match="frames"):
        flow.dynamic_flow(np.zeros((3, 8, 8), np.float32))
    with pytest.raises(ValueError, match="frames"):
        flow.dynamic_flow(np.zeros((0, 8, 8), np.uint8))
    with pytest.raises(ValueError, match="flow.method"):
        flow.FlowConfig(method="lucas")
    with pytest.raises(ValueError, match="reference"):
        flow.static_flow(np.zeros((3, 8, 8), np.uint8), reference=7)


def test_aggregates_match_direct_finite_differences(rng):
    """The matrix form of mean/divergence/curl equals np.gradient averaged over the interior."""
    from scipy import ndimage
    mask = np.zeros((20, 30), bool)
    mask[3:17, 4:26] = True
    mask[3:6, 4:8] = False
    field = rng.normal(size=(5, 20, 30, 2)).astype(np.float32)
    agg = aggregate.aggregate_flow(field, mask)
    interior = ndimage.binary_erosion(mask)
    du_dr, du_dc = np.gradient(field[..., 0].astype(np.float64), axis=(1, 2))
    dv_dr, dv_dc = np.gradient(field[..., 1].astype(np.float64), axis=(1, 2))
    assert np.allclose(agg.divergence, (du_dc + dv_dr)[:, interior].mean(1), atol=1e-5)
    assert np.allclose(agg.curl, (dv_dc - du_dr)[:, interior].mean(1), atol=1e-5)
    assert np.allclose(agg.mean, field[:, mask].mean(1), atol=1e-5)
    # A rigid rotation ω about the view axis: u = −ω·row, v = ω·col → curl = 2ω, divergence 0.
    rows, cols = np.mgrid[0:20, 0:30].astype(np.float32)
    rot = np.stack([-0.1 * rows, 0.1 * cols], -1)[None]
    agg = aggregate.aggregate_flow(rot, mask)
    assert agg.curl[0] == pytest.approx(0.2, abs=1e-5) and abs(agg.divergence[0]) < 1e-5


def test_fused_aggregation_equals_the_matrix_form(rng):
    """aggregate_flow's one-pass kernel against flow_functionals and a direct confidence."""
    mask = np.zeros((28, 40), bool)
    mask[5:23, 6:34] = True
    mask[5:9, 6:12] = False
    field = (rng.normal(size=(7, 28, 40, 2)) * 0.1).astype(np.float32)
    field[0] = 0.0
    for noise in (0.05, 0.12):
        agg = aggregate.aggregate_flow(field, mask, noise=noise)
        sums = field.reshape(7, -1).astype(np.float64) @ aggregate.flow_functionals(mask)
        assert np.allclose(agg.mean, sums[:, :2], rtol=0, atol=1e-7)
        assert np.allclose(agg.divergence, sums[:, 2], rtol=0, atol=1e-7)
        assert np.allclose(agg.curl, sums[:, 3], rtol=0, atol=1e-7)
        speed2 = (field[..., 0] * field[..., 0] + field[..., 1] * field[..., 1])[:, mask]
        assert np.array_equal(agg.confidence, (speed2 > np.float32(noise) ** 2).mean(axis=1))
        assert agg.confidence[0] == 0.0 and agg.mean.dtype == np.float64
    with pytest.raises(ValueError, match="mask"):
        aggregate.aggregate_flow(field, np.zeros((28, 40), bool))


@pytest.mark.parametrize("flags,levels", [(0, 3), (256, 3), (0, 1)])   # 256: OPTFLOW_FARNEBACK_GAUSSIAN
def test_farneback_between_empty_frames_is_skipped_and_exactly_zero(flags, levels):
    """The estimator skips Farnebäck between two empty frames; OpenCV gives exactly zero there,
    so a flow with the shortcut equals one without it, to the bit."""
    import cv2
    empty = np.zeros((28, 40), np.uint8)
    c = flow.FlowConfig(flags=flags, levels=levels)
    direct = cv2.calcOpticalFlowFarneback(empty, empty, None, c.pyr_scale, c.levels, c.winsize, c.iterations,
                                          c.poly_n, c.poly_sigma, c.flags)
    assert not direct.any()
    got = flow.FlowEstimator(c)(empty, empty)
    assert got.dtype == direct.dtype and got.shape == direct.shape and not got.any()
    pressed = empty.copy()
    pressed[10:16, 12:20] = 180                   # one empty frame of the two: computed, not skipped
    assert np.array_equal(flow.FlowEstimator(c)(empty, pressed),
                          cv2.calcOpticalFlowFarneback(empty, pressed, None, c.pyr_scale, c.levels, c.winsize,
                                                       c.iterations, c.poly_n, c.poly_sigma, c.flags))

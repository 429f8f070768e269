"""The whole chain from raw counts, and the errors a user meets with bad input."""

import numpy as np
import pytest

from tactile_flow.tactile import aggregate, signals, synthetic
from tactile_flow.tactile.pipeline import TactileConfig, TactileModel, activation_from_counts, process_view


def _counts_from_activation(activation, baseline_counts):
    """Invert Z = (4095/E − 1)·10 kΩ for a known activation on top of a baseline."""
    z = signals.counts_to_impedance(baseline_counts) + activation
    return np.rint(4095.0 / (1.0 + z / 10.0))


def test_raw_counts_to_flow_direction(model, rng):
    """Counts as a BioTac sends them (falling under pressure, 12-bit, noisy) → motion along −y."""
    baseline = rng.uniform(1700, 3500, 24)
    rest = np.zeros((30, 24))
    bump = synthetic.moving_bump(model.taxels, start=(0, 4, 0), velocity=(0, -10, 0), duration=0.8)
    counts = _counts_from_activation(np.concatenate([rest, bump]), baseline)
    counts = np.clip(counts + rng.normal(0, 5, counts.shape).round(), 0, 4095)
    assert np.all(counts[30:].min(0) <= counts[:30].max(0))           # pressure lowers counts
    act = activation_from_counts(counts, signals.baseline_from_rest(counts, 0, 30), model)
    result = process_view(model, act, "bottom")
    s = aggregate.window(result.dynamic, 31, len(act))
    vec = model.plans["bottom"].image_to_sensor([s["mean_col"], s["mean_row"]])
    angle = np.degrees(np.arctan2(vec[1], vec[0]))
    assert abs(angle - (-90)) < 10, f"motion along −y read as {angle:.1f}°"


def test_linear_renderer_equals_exact_without_displacement(model, rng):
    from dataclasses import replace
    flat_cfg = replace(model.config, scale=0.0)
    exact = replace(model, config=flat_cfg)
    linear = replace(model, config=replace(flat_cfg, render="linear"))
    act = rng.uniform(0, 4, (150, 24))                  # more than two of the linear renderer's blocks
    for view in model.plans:
        assert np.allclose(exact.render(act, view), linear.render(act, view), atol=1e-4)
        u8 = linear.render_uint8(act, view, (0.0, 4.0))
        assert u8.dtype == np.uint8 and u8.shape == (150,) + model.plans[view].shape
        assert np.abs(u8.astype(int) - exact.render_uint8(act, view, (0.0, 4.0))).max() <= 1


def test_bad_input_names_the_argument(model, cache_dir):
    with pytest.raises(ValueError, match="counts"):
        activation_from_counts(np.full((5, 24), 4096.0), np.ones(24), model)
    with pytest.raises(ValueError, match="counts"):
        activation_from_counts(np.full((5, 24), np.nan), np.ones(24), model)
    with pytest.raises(ValueError, match="activation"):
        process_view(model, np.zeros((10, 23)), "bottom")
    with pytest.raises(ValueError, match="activation"):
        process_view(model, np.zeros((0, 24)), "bottom")
    with pytest.raises(ValueError, match="activation"):
        process_view(model, np.full((3, 24), np.inf), "bottom")
    with pytest.raises(ValueError, match="view"):
        process_view(model, np.zeros((3, 24)), "top")
    with pytest.raises(ValueError, match="sigma"):
        TactileModel.build(TactileConfig(sigma=0.0), cache_dir=cache_dir)
    with pytest.raises(ValueError, match="size"):
        TactileModel.build(TactileConfig(size=(4, 40)), cache_dir=cache_dir)
    with pytest.raises(ValueError, match="render"):
        TactileModel.build(TactileConfig(render="fast"), cache_dir=cache_dir)
    with pytest.raises(ValueError, match="views"):
        TactileModel.build(TactileConfig(views=("bottom", "top")), cache_dir=cache_dir)
    with pytest.raises(ValueError, match="taxels: expected at least 6"):
        TactileModel.build(TactileConfig(), taxels=np.zeros((5, 3)), cache_dir=cache_dir)
    with pytest.raises(ValueError, match="points: expected points that are not all identical"):
        TactileModel.build(TactileConfig(), taxels=np.zeros((20, 3)), cache_dir=cache_dir)


def test_flow_aggregated_a_stretch_at_a_time_is_the_flow_aggregated_whole(model, rng, monkeypatch):
    """A long contact's dense fields are computed and aggregated FIELD_FRAMES at a time: the
    aggregates are those of the whole window, bit for bit, across the stretches' seams."""
    import dataclasses

    import tactile_flow.tactile.pipeline as tp
    act = np.clip(np.cumsum(rng.normal(0, 0.05, (300, 24)), axis=0), 0, None)
    refs = {"unloaded": None, "contact_onset": 40}
    whole = process_view(model, act, "bottom", references=refs, keep_fields=True)
    monkeypatch.setattr(tp, "FIELD_FRAMES", 37)
    pieces = process_view(model, act, "bottom", references=refs)
    assert pieces.dynamic_field is None
    for f in dataclasses.fields(aggregate.FlowAggregates):
        np.testing.assert_array_equal(getattr(pieces.dynamic, f.name), getattr(whole.dynamic, f.name))
        for r in refs:
            np.testing.assert_array_equal(getattr(pieces.statics[r], f.name), getattr(whole.statics[r], f.name))

"""The online (one frame at a time) pipeline against the offline one with the smoother off."""

import tracemalloc
from dataclasses import replace

import numpy as np
import pytest

from tactile_flow.tactile import signals, synthetic
from tactile_flow.tactile.online import AGGREGATES, OnlineFlow
from tactile_flow.tactile.pipeline import TactileModel, process_view

FINGERS = ("ff", "mf", "th")
REST = 20


@pytest.fixture(scope="module")
def model(sensor_model, cache_dir):
    """The online model of each shipped sensor (filter only)."""
    return TactileModel.build(replace(sensor_model.config, smooth=False), sensor=sensor_model.sensor,
                              cache_dir=cache_dir)


@pytest.fixture(scope="module")
def record(model):
    """(T, F, N) raw counts: a rest stretch, then a bump sliding a different way across the
    pad under each finger, 12-bit and noisy as a BioTac sends them; and the rest impedance (F, N)."""
    rng = np.random.default_rng(7)
    acts = []
    n = model.n_taxels
    pole = np.asarray(model.sensor.shape.pole) * [1, 1, 0]
    for f in range(len(FINGERS)):
        heading = 2 * np.pi * f / len(FINGERS)
        d = np.array([np.cos(heading), np.sin(heading), 0.0])
        bump = synthetic.moving_bump(model.taxels, pole - 8 * d, 8 * d, duration=1.6)
        acts.append(np.concatenate([np.zeros((REST, n)), bump]))
    act = np.stack(acts, axis=1)
    z = signals.counts_to_impedance(rng.uniform(1700, 3500, (len(FINGERS), n))) + act
    counts = np.clip(np.rint(4095.0 / (1.0 + z / 10.0)) + rng.normal(0, 4, z.shape).round(), 1, 4095)
    return counts, signals.baseline_from_rest(counts, 0, REST)


def offline(model, counts, baseline, view):
    """The offline pipeline (filter only) of one finger's (T, N) counts in one view."""
    act = model.smooth(signals.activation(signals.counts_to_impedance(counts), baseline))
    return process_view(model, act, view), signals.pdc_proxy(act)


def stream(online, counts, seqs=None, times=None, valid=None):
    """Push every frame; returns the step copies and, per (finger, view), the frames."""
    steps, frames = [], {}
    for i in range(len(counts)):
        seq = i if seqs is None else seqs[i]
        t = 0.01 * i if times is None else times[i]
        steps.append(online.push(seq, t, counts[i], None if valid is None else valid[i]).copy())
        for f, finger in enumerate(online.fingers):
            for view in online.views:
                frames.setdefault((finger, view), []).append(online.frame(finger, view).copy())
    return steps, frames


def field(steps, name, f, v):
    return np.array([getattr(s, name)[f, v] for s in steps])


def assert_matches_offline(model, online, steps, frames, counts, baseline, f, rows):
    """Finger f's results at ``rows`` of ``steps`` equal offline on ``counts[rows]``."""
    finger = online.fingers[f]
    assert all(steps[i].processed[f] for i in rows)
    for v, view in enumerate(online.views):
        result, total = offline(model, counts[rows, f], baseline[f], view)
        got = np.array(frames[(finger, view)])[rows]
        assert np.array_equal(got, result.frames), f"{finger}/{view}: frames differ"
        d = result.dynamic
        want = {"mean_col": d.mean[:, 0], "mean_row": d.mean[:, 1], "magnitude": d.magnitude,
                "direction": d.direction, "divergence": d.divergence, "curl": d.curl,
                "confidence": d.confidence}
        for name in AGGREGATES:
            np.testing.assert_allclose(field(steps, name, f, v)[rows], want[name], rtol=1e-6, atol=1e-12,
                                       err_msg=f"{finger}/{view}: {name}")
        assert d.magnitude.max() > 0.01                                # there is motion to compare
    np.testing.assert_allclose([steps[i].activation_total[f] for i in rows], total, rtol=1e-12, atol=1e-12)


def test_equals_offline_filter_pipeline_frame_by_frame(model, record):
    counts, baseline = record
    online = OnlineFlow(model, baseline, FINGERS)
    steps, frames = stream(online, counts)
    rows = np.arange(len(counts))
    for f in range(len(FINGERS)):
        assert_matches_offline(model, online, steps, frames, counts, baseline, f, rows)
    assert np.all(field(steps, "magnitude", 0, 0)[:1] == 0)           # first frame: zero flow
    assert online.counters()["th"] == {"processed": len(counts), "skipped_invalid": 0,
                                    "skipped_order": 0, "gaps": 0}


def test_a_subset_of_views_in_another_order(model, record):
    counts, baseline = record
    online = OnlineFlow(model, baseline[:2], FINGERS[:2], views=("right", "bottom"))
    steps, frames = stream(online, counts[:60, :2])
    assert steps[0].mean_col.shape == (2, 2)
    for f in range(2):
        assert_matches_offline(model, online, steps, frames, counts[:60, :2], baseline[:2], f, np.arange(60))


def test_other_flow_methods_match_offline(model, record):
    from tactile_flow.tactile.flow import FlowConfig
    counts, baseline = record
    dis = replace(model, config=replace(model.config, flow=FlowConfig(method="dis", dis_preset=0)))
    online = OnlineFlow(dis, baseline[:1], FINGERS[:1], views=("bottom",))
    rows = np.arange(REST, REST + 60)
    steps, frames = stream(online, counts[rows, :1])
    assert_matches_offline(dis, online, steps, frames, counts[rows, :1], baseline[:1], 0, np.arange(60))


def test_linear_renderer_matches_offline_up_to_blas_rounding(model, record):
    """``render="linear"``: offline renders a chunk of frames with one float32 BLAS product,
    whose rounding depends on the chunk; online renders one frame at a time. So a pixel
    may differ by one 8-bit level, rarely; wherever both frames of a pair agree the flow
    aggregates agree too."""
    counts, baseline = record
    linear = replace(model, config=replace(model.config, render="linear"))
    online = OnlineFlow(linear, baseline, FINGERS)
    steps, frames = stream(online, counts)
    for f, finger in enumerate(FINGERS):
        for v, view in enumerate(online.views):
            result, _ = offline(linear, counts[:, f], baseline[f], view)
            got = np.array(frames[(finger, view)])
            diff = np.abs(got.astype(int) - result.frames)
            assert diff.max() <= 1 and np.count_nonzero(diff) <= 1e-4 * diff.size
            same = np.all(diff == 0, axis=(1, 2))
            pairs = np.flatnonzero(same[1:] & same[:-1]) + 1
            np.testing.assert_allclose(field(steps, "curl", f, v)[pairs], result.dynamic.curl[pairs], rtol=1e-6,
                                       atol=1e-12)
            np.testing.assert_allclose(field(steps, "magnitude", f, v)[pairs], result.dynamic.magnitude[pairs],
                                       rtol=1e-6, atol=1e-12)


def test_invalid_samples_skip_that_finger_only_and_it_continues(model, record):
    counts, baseline = record
    counts = counts.copy()
    bad = {0: [30, 31, 32, 90], 2: [45, 46, 100, 101, 102, 103]}
    counts[30, 0, 3] = np.nan
    counts[31, 0, :] = np.inf
    counts[32, 0, 5] = 0                                     # a shorted channel
    counts[45, 2, 0] = 4096
    counts[46, 2, 7] = -12
    counts[90, 0, 0] = np.nan
    valid = np.ones(counts.shape[:2], bool)
    valid[100:104, 2] = False
    online = OnlineFlow(model, baseline, FINGERS, views=("bottom", "left"))
    steps, frames = stream(online, counts, valid=valid)
    for f in range(len(FINGERS)):
        good = np.setdiff1d(np.arange(len(counts)), bad.get(f, []))
        assert_matches_offline(model, online, steps, frames, counts, baseline, f, good)
        for i in bad.get(f, []):
            assert not steps[i].processed[f]
            assert np.isnan(steps[i].activation_total[f])
            assert all(np.all(np.isnan(getattr(steps[i], name)[f])) for name in AGGREGATES)
    s = online.counters()
    assert s["ff"]["skipped_invalid"] == 4 and s["mf"]["skipped_invalid"] == 0 and s["th"]["skipped_invalid"] == 6
    assert s["ff"]["gaps"] == 2 and s["mf"]["gaps"] == 0 and s["th"]["gaps"] == 2
    assert s["ff"]["processed"] == len(counts) - 4


def test_duplicate_late_and_unordered_frames_are_skipped_whole(model, record):
    counts, baseline = record
    n = 80
    order = list(range(40)) + [39, 20] + list(range(40, n))       # a duplicate, a late frame
    seqs = [1000 + i for i in order]
    times = [0.01 * i for i in order]
    times[50] = times[49]                                         # a frame whose time did not advance
    times[60] = np.nan                                            # and a frame with no valid time
    seqs[70:] = [s + 5 for s in seqs[70:]]                        # 5 frames lost in transport
    online = OnlineFlow(model, baseline[:2], FINGERS[:2], views=("bottom", "right"))
    steps, frames = stream(online, counts[order, :2], seqs=seqs, times=times)
    skipped = [40, 41, 50, 60]
    for i in skipped:
        assert not steps[i].processed.any() and np.isnan(steps[i].mean_col).all()
        assert steps[i].seq == seqs[i]
    kept = np.setdiff1d(np.arange(len(order)), skipped)
    for f in range(2):
        # offline on the frames that were accepted: the record minus the skipped frames
        assert_matches_offline(model, online, steps, frames, counts[order, :2], baseline[:2], f, kept)
    s = online.counters()
    assert s["ff"]["skipped_order"] == 4 and s["mf"]["skipped_order"] == 4
    assert s["ff"]["gaps"] == 3                                   # after 50, 60 and the transport loss
    assert s["ff"]["processed"] == len(kept)


def test_a_finger_that_stops_streaming_never_raises(model, record):
    counts, baseline = record
    n = 600
    rows = np.arange(n) % len(counts)
    c = counts[rows].copy()
    c[50:550, 1] = np.nan                                         # mf unplugged for 5 s
    c[200:210, 0] = 0                                             # ff: all zeros (a dead bridge)
    online = OnlineFlow(model, baseline, FINGERS, views=("bottom",))
    for i in range(n):
        step = online.push(i, i * 0.01, c[i])
        assert step.processed[1] == (not 50 <= i < 550)
    assert np.isfinite(step.mean_col).all()
    s = online.counters()
    assert s["mf"] == {"processed": 100, "skipped_invalid": 500, "skipped_order": 0, "gaps": 1}
    assert s["ff"]["skipped_invalid"] == 10 and s["th"]["processed"] == n


def test_reset_restarts_a_finger_and_the_sequence(model, record):
    counts, baseline = record
    online = OnlineFlow(model, baseline, FINGERS, views=("bottom",))
    steps, frames = stream(online, counts[:50])
    online.reset("mf")
    after, frames2 = stream(online, counts[50:100], seqs=range(50, 100), times=0.01 * np.arange(50, 100))
    rows = np.arange(50)
    assert_matches_offline(model, online, after, frames2, counts[50:100], baseline, 1, rows)
    assert after[0].magnitude[1, 0] == 0 and after[0].magnitude[0, 0] != 0
    assert online.push(3, 0.0, counts[0]).processed.sum() == 0    # seq went back: skipped
    online.reset()
    assert online.push(3, 0.0, counts[0]).processed.all()        # accepted after reset()
    assert online.counters()["mf"]["processed"] == 101
    with pytest.raises(ValueError, match="finger"):
        online.reset("xx")


def test_wrong_shapes_raise_value_error_naming_the_argument(model, record):
    counts, baseline = record
    online = OnlineFlow(model, baseline, FINGERS)
    n = model.n_taxels
    with pytest.raises(ValueError, match=rf"counts: expected shape \(3, {n}\)"):
        online.push(0, 0.0, counts[0, :, :n - 1])
    with pytest.raises(ValueError, match="counts"):
        online.push(0, 0.0, counts[0, 0])
    with pytest.raises(ValueError, match=r"valid: expected shape \(3,\)"):
        online.push(0, 0.0, counts[0], valid=[True, False])
    with pytest.raises(ValueError, match="seq"):
        online.push(0.5, 0.0, counts[0])
    with pytest.raises(ValueError, match="baseline_impedance"):
        OnlineFlow(model, baseline[:2], FINGERS)
    with pytest.raises(ValueError, match="baseline_impedance"):
        OnlineFlow(model, np.full((3, n), np.nan), FINGERS)
    with pytest.raises(ValueError, match="views"):
        OnlineFlow(model, baseline, FINGERS, views=("top",))
    with pytest.raises(ValueError, match="fingers"):
        OnlineFlow(model, baseline, ("ff", "ff", "th"))
    assert online.counters()["ff"]["processed"] == 0                # nothing was half-processed


def test_step_is_reused_and_copy_is_independent(model, record):
    counts, baseline = record
    online = OnlineFlow(model, baseline, FINGERS, views=("bottom",))
    a = online.push(0, 0.0, counts[REST + 10])
    kept = a.copy()
    b = online.push(1, 0.01, counts[REST + 20])
    assert a is b and kept.seq == 0 and b.seq == 1
    assert not np.array_equal(kept.activation_total, b.activation_total)


def test_memory_stays_flat_over_many_pushes(model, record):
    counts, baseline = record
    online = OnlineFlow(model, baseline, FINGERS, views=("bottom", "left"))
    n = len(counts)
    for i in range(100):                                          # warm up (compilation, caches)
        online.push(i, 0.01 * i, counts[i % n])
    tracemalloc.start()
    try:
        for i in range(100, 300):
            online.push(i, 0.01 * i, counts[i % n])
        before, _ = tracemalloc.get_traced_memory()
        tracemalloc.reset_peak()
        for i in range(300, 2300):
            online.push(i, 0.01 * i, counts[i % n])
        after, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert after - before < 4096, f"grew by {after - before} bytes over 2000 pushes"
    assert peak - before < 16384, f"a push held {peak - before} bytes at once"


def test_simulated_sweep_matches_offline(model):
    """A short simulated straws sweep (hardware.sim): the device's own seq, time and int16 counts."""
    from tactile_flow.hardware.sim import make_sim_lab
    from tactile_flow.hardware.sim.scenarios import biotac_arrays, straws_sweep

    lab = make_sim_lab({"seed": 3, "fingers": ["ff", "mf"]}, {"kind": "straws", "count": 2, "spacing_mm": 15.0},
                       sensor=model.sensor)
    with lab:
        b = biotac_arrays(straws_sweep(lab, speed=0.02)["biotac"])
    counts = b["electrodes"]
    baseline = signals.baseline_from_rest(counts, 0, 10)
    online = OnlineFlow(model, baseline, lab.biotac.fingers, views=("bottom",))
    steps, frames = [], []
    for seq, t, e in zip(b["seq"], b["device_time"], counts):
        steps.append(online.push(int(seq), t, e).copy())
        frames.append(online.frame("ff", "bottom").copy())
    result, total = offline(model, counts[:, 0].astype(float), baseline[0], "bottom")
    assert np.array_equal(np.array(frames), result.frames)
    np.testing.assert_allclose(field(steps, "curl", 0, 0), result.dynamic.curl, rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(field(steps, "mean_col", 0, 0), result.dynamic.mean[:, 0], rtol=1e-6, atol=1e-12)
    assert result.dynamic.magnitude.max() > 0.1 and online.counters()["ff"]["gaps"] == 0

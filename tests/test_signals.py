"""Tests for tactile.signals: counts → impedance → activation, baselines, Kalman + RTS."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tactile_flow.tactile.signals import (
    SensorCalibration,
    activation,
    baseline_from_rest,
    counts_to_activation,
    counts_to_impedance,
    kalman_filter,
    kalman_gains,
    kalman_smooth,
    pdc_proxy,
)

import pykalman  # noqa: E402  (a test dependency: the reference implementation)


# --------------------------------------------------------------------------- conversion

def test_impedance_known_values():
    # Z = (4095/E − 1)·10 kΩ
    z = counts_to_impedance([4095, 4095 / 2, 4095 / 4, 1, 2048, 1365])
    expected = [0.0, 10.0, 30.0, 40940.0, (4095 / 2048 - 1) * 10, (4095 / 1365 - 1) * 10]
    np.testing.assert_allclose(z, expected, rtol=1e-12, atol=1e-12)
    assert z[-1] == pytest.approx(20.0)  # 1365 = 4095/3


def test_impedance_shape_dtype_and_input_untouched():
    counts = np.array([[[3000, 2500], [2000, 1000]]], dtype=np.int16)
    before = counts.copy()
    z = counts_to_impedance(counts)
    assert z.shape == counts.shape and z.dtype == np.float64
    np.testing.assert_array_equal(counts, before)


def test_fewer_counts_mean_higher_impedance_and_positive_activation():
    counts = np.arange(4095, 0, -1)  # pressure rising → counts falling
    z = counts_to_impedance(counts)
    assert np.all(np.diff(z) > 0)
    rest = counts_to_impedance(np.full(24, 3000.0))
    pressed = np.full((1, 24), 3000.0)
    pressed[0, :5] = 2500.0
    a = counts_to_activation(pressed, rest)
    assert np.all(a[0, :5] > 0) and np.all(a[0, 5:] == 0)


@pytest.mark.parametrize("bad, fragment", [
    ([100, 4096, 200], "1 value(s) out of range"),
    ([-1, -2, 3000], "2 value(s) out of range"),
    ([100, np.nan, 200], "NaN"),
    ([100, np.inf, 200], "infinite"),
    ([100, 0, 0], "2 count(s) equal to 0"),
])
def test_bad_counts_rejected_naming_counts(bad, fragment):
    with pytest.raises(ValueError, match=r"^counts:") as info:
        counts_to_impedance(bad)
    assert fragment in str(info.value)
    if "range" in fragment:
        assert "0..4095" in str(info.value)


# --------------------------------------------------------------------------- baselines

def _record(rng, T=200, fingers=3, rest_until=50):
    """Counts (T, fingers, 24): rest noise, then a press lowering taxels 0–7 of each finger."""
    rest_counts = rng.uniform(2500, 3500, size=(fingers, 24))
    counts = rest_counts + rng.normal(0, 2, size=(T, fingers, 24))
    press = np.zeros((T, 1, 24))
    press[rest_until:, 0, :8] = np.linspace(0, 400, T - rest_until)[:, None]
    return counts - press, rest_counts


def test_baseline_from_rest_zero_on_rest_positive_under_pressure():
    rng = np.random.default_rng(1)
    counts, _ = _record(rng)
    base = baseline_from_rest(counts, start=0, stop=50)
    assert base.shape == (3, 24)
    a = counts_to_activation(counts, base)
    assert a.shape == counts.shape
    np.testing.assert_allclose(a[:50].mean(axis=0), 0.0, atol=1e-12)
    assert np.all(a[150:, :, :8] > 0.5)              # pressed taxels: clearly positive
    assert np.all(np.abs(a[150:, :, 8:]) < 0.1)     # untouched taxels: noise only


def test_first_samples_baseline_erases_pattern_of_record_starting_in_contact():
    # Why callers must choose the rest stretch: a cut-out that begins in contact.
    rng = np.random.default_rng(2)
    counts, rest_counts = _record(rng)
    cut = counts[150:]
    wrong = counts_to_activation(cut, baseline_from_rest(cut, 0, 10))
    right = counts_to_activation(cut, SensorCalibration(rest_counts[0], "ff").baseline_impedance)
    assert np.abs(wrong[:10, 0].mean(axis=0)).max() < 0.1   # pattern gone
    assert right[:10, 0, :8].mean() > 1.0                  # pattern kept


def test_baseline_axis_and_bad_stretch():
    rng = np.random.default_rng(3)
    counts, _ = _record(rng, T=60)
    b0 = baseline_from_rest(counts, 0, 20)
    b1 = baseline_from_rest(np.moveaxis(counts, 0, 1), 0, 20, axis=1)
    np.testing.assert_allclose(b0, b1)
    for start, stop in [(20, 20), (-1, 10), (0, 61), (30, 10)]:
        with pytest.raises(ValueError, match="start, stop"):
            baseline_from_rest(counts, start, stop)
    with pytest.raises(ValueError, match="^axis:"):
        baseline_from_rest(counts, 0, 10, axis=3)


def test_activation_rejects_baseline_that_does_not_fit():
    z = np.ones((10, 3, 24))
    with pytest.raises(ValueError, match="^baseline:"):
        activation(z, np.ones((5, 24)))
    with pytest.raises(ValueError, match="^baseline:"):
        activation(z, np.ones((2, 10, 3, 24)))   # would enlarge the result


def test_calibration_roundtrip_and_validation():
    rng = np.random.default_rng(4)
    counts, rest = _record(rng, fingers=1)
    cal = SensorCalibration.from_rest(counts[:, 0], sensor_id="BTSP-0042",
                                      source="session 3, tare 0:50", stop=50)
    back = SensorCalibration.from_dict(json.loads(json.dumps(cal.to_dict())))
    assert back == cal and hash(back) == hash(cal)
    np.testing.assert_array_equal(back.baseline_impedance, cal.baseline_impedance)
    np.testing.assert_allclose(cal.baseline_counts, rest[0], atol=1.0)
    with pytest.raises(ValueError):
        cal.baseline_counts[0] = 1.0                        # read-only
    with pytest.raises(ValueError, match="^baseline_counts:"):
        SensorCalibration(np.full((2, 24), 3000.0), "x")          # one count per taxel (the model says how many)
    assert SensorCalibration(np.full(19, 3000.0), "x").baseline_impedance.shape == (19,)
    with pytest.raises(ValueError, match="^baseline_counts:"):
        SensorCalibration(np.zeros(24), "x")
    with pytest.raises(ValueError, match="^sensor_id:"):
        SensorCalibration(np.full(24, 3000.0), "")
    with pytest.raises(ValueError, match="missing"):
        SensorCalibration.from_dict({"sensor_id": "x", "baseline_counts": [3000.0] * 24})


def test_pdc_proxy_sums_activation_over_taxels():
    a = np.zeros((4, 2, 24))
    a[2, 1, :3] = [1.0, 2.0, -0.5]
    p = pdc_proxy(a)
    assert p.shape == (4, 2)
    assert p[2, 1] == pytest.approx(2.5) and np.count_nonzero(p) == 1


# --------------------------------------------------------------------------- Kalman / RTS

def _random_walk(rng, T=300, fingers=3, q=0.00015, r=0.005):
    truth = np.cumsum(rng.normal(0, np.sqrt(q), size=(T, fingers, 24)), axis=0)
    truth += rng.normal(0, 1, size=(1, fingers, 24))
    return truth, truth + rng.normal(0, np.sqrt(r), size=truth.shape)


def _pykalman(z, R, Q, x0, P0, smooth):
    """Reference: one pykalman run per finger over its 24 channels."""
    out = np.empty_like(z)
    n = z.shape[-1]
    eye = np.eye(n)
    for f in range(z.shape[1]):
        kf = pykalman.KalmanFilter(
            transition_matrices=eye, observation_matrices=eye,
            transition_covariance=Q * eye, observation_covariance=R * eye,
            initial_state_mean=z[0, f] if x0 is None else x0[f],
            initial_state_covariance=(R if P0 is None else P0) * eye)
        out[:, f] = (kf.smooth if smooth else kf.filter)(z[:, f])[0]
    return out


@pytest.fixture(scope="module")
def walk():
    return _random_walk(np.random.default_rng(5))


@pytest.mark.parametrize("smooth", [True, False])
def test_matches_pykalman_default_params(walk, smooth):
    _, z = walk
    ours = kalman_smooth(z, smooth=smooth)
    ref = _pykalman(z, 0.005, 0.00015, None, None, smooth)
    np.testing.assert_allclose(ours, ref, rtol=0, atol=1e-9)
    if not smooth:
        np.testing.assert_array_equal(kalman_filter(z), ours)


@pytest.mark.parametrize("smooth", [True, False])
def test_matches_pykalman_other_params(walk, smooth):
    _, z = walk
    rng = np.random.default_rng(6)
    x0 = z[0] + rng.normal(0, 0.5, size=z.shape[1:])
    kw = dict(R=0.02, Q=0.001, x0=x0, P0=0.3)
    ours = kalman_smooth(z, smooth=smooth, **kw)
    ref = _pykalman(z, 0.02, 0.001, x0, 0.3, smooth)
    np.testing.assert_allclose(ours, ref, rtol=0, atol=1e-9)


def test_per_channel_params_equal_separate_runs(walk):
    _, z = walk
    R = np.array([0.005, 0.02, 0.1])[:, None]          # per finger, broadcast over taxels
    joint = kalman_smooth(z, R=R, Q=0.0005)
    for f in range(3):
        np.testing.assert_allclose(joint[:, f], kalman_smooth(z[:, f], R=R[f, 0], Q=0.0005),
                                   rtol=0, atol=1e-12)


def test_smoothing_reduces_noise(walk):
    truth, z = walk
    rms = lambda x: np.sqrt(np.mean((x - truth) ** 2))  # noqa: E731
    assert rms(kalman_filter(z)) < rms(z)
    assert rms(kalman_smooth(z)) < 0.6 * rms(z)
    assert rms(kalman_smooth(z)) < rms(kalman_filter(z))


def test_shapes_short_records_and_purity():
    rng = np.random.default_rng(7)
    z = rng.normal(size=(40, 24))
    before = z.copy()
    assert kalman_smooth(z).shape == z.shape
    assert kalman_smooth(z[:, 0]).shape == (40,)
    np.testing.assert_array_equal(z, before)
    np.testing.assert_array_equal(kalman_smooth(z[:1]), z[:1])     # x0 = z[0]
    assert kalman_smooth(z[:2]).shape == (2, 24)


def test_gain_sequences():
    K, P, C = kalman_gains(200, R=0.005, Q=0.00015)
    assert K.shape == P.shape == (200,) and C.shape == (199,)
    assert K[0] == pytest.approx(0.5)                     # P0 = R
    np.testing.assert_allclose(C, P[:-1] / (P[:-1] + 0.00015))
    # converges to the steady state of p⁻ = p + Q, p = p⁻R/(p⁻+R)
    p_pred = (0.00015 + np.sqrt(0.00015 ** 2 + 4 * 0.00015 * 0.005)) / 2
    assert K[-1] == pytest.approx(p_pred / (p_pred + 0.005), rel=1e-12)
    assert kalman_gains(5, R=np.ones((2, 3)), Q=1.0)[0].shape == (5, 2, 3)


@pytest.mark.parametrize("fn", [kalman_smooth, kalman_filter])
def test_kalman_rejects_bad_input(fn):
    with pytest.raises(ValueError, match="^z:"):
        fn(np.empty((0, 24)))
    with pytest.raises(ValueError, match="^z:"):
        fn(np.array([[1.0, np.nan]]))
    z = np.zeros((10, 24))
    for name, bad in [("R", 0.0), ("Q", -1e-3), ("P0", np.nan), ("R", np.inf)]:
        with pytest.raises(ValueError, match=f"^{name}:"):
            fn(z, **{name: bad})
    with pytest.raises(ValueError, match="^R:"):
        fn(z, R=np.full(5, 0.01))                        # does not fit 24 channels
    with pytest.raises(ValueError, match="^x0:"):
        fn(z, x0=np.zeros(3))


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 100_000), T=st.integers(1, 80), frames=st.sampled_from([1, 3, 5, 7, 9]))
def test_running_median_is_scipys_median_filter_with_the_edges_repeated(seed, T, frames):
    """The despiking median (numba) gives scipy's values exactly, ties and short records included."""
    from scipy.ndimage import median_filter

    from tactile_flow.tactile.signals import running_median
    x = np.random.default_rng(seed).integers(0, 5, (T, 2, 3)).astype(float)     # many ties
    np.testing.assert_array_equal(running_median(x, frames),
                                  median_filter(x, size=(frames, 1, 1), mode="nearest"))

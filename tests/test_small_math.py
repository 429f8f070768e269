"""Our own peak finder, Savitzky–Golay filter and rotation conversions against SciPy's.

The program no longer imports ``scipy.signal`` (SciPy 1.17 parses its docstrings and loads
``scipy.stats`` on import) nor ``scipy.spatial``; these tests hold the replacements to SciPy's
results: the same peak indices on every input, the same smoothing and the same rotations to
~1e-12. The tests themselves may import SciPy's (it stays a dependency).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import ndimage
from scipy import signal as sps
from scipy.spatial.transform import Rotation

from tactile_flow.analysis import segments as seg
from tactile_flow.analysis.signal1d import _savgol_coefficients, find_peaks, savgol_filter
from tactile_flow.hardware.transforms import matrix_to_rotvec, rotvec_to_matrix, rotvec_to_quaternion
from tactile_flow.tactile.aggregate import _eroded


def scipy_peaks(x, prominence, distance):
    return sps.find_peaks(x, prominence=prominence, distance=distance)[0]


# ----------------------------------------------------------------------------- peaks

@st.composite
def signals(draw):
    """1-D float signals: few distinct levels (ties, plateaus, flat stretches at the ends),
    runs of repeated values, or plain floats; any length from 0."""
    n = draw(st.integers(0, 300))
    kind = draw(st.sampled_from(["levels", "runs", "floats", "walk"]))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    if kind == "levels":
        return rng.integers(0, draw(st.integers(1, 5)), n).astype(float)
    if kind == "runs":
        values = rng.integers(-3, 4, n).astype(float)
        return np.repeat(values, rng.integers(1, 5, n))[:n]
    if kind == "floats":
        return rng.normal(0.0, 10.0 ** draw(st.integers(-3, 3)), n)
    return np.round(np.cumsum(rng.normal(size=n)), draw(st.integers(0, 3)))


@settings(max_examples=600, deadline=None)
@given(x=signals(), distance=st.one_of(st.none(), st.integers(1, 40), st.floats(1.0, 30.0)),
       prominence=st.one_of(st.none(), st.just(0.0), st.floats(0.0, 5.0)))
def test_find_peaks_gives_scipys_indices(x, distance, prominence):
    ours = find_peaks(x, prominence=prominence, distance=distance)
    assert ours.dtype.kind == "i"
    np.testing.assert_array_equal(ours, scipy_peaks(x, prominence, distance))


@pytest.mark.parametrize("x", [[], [1.0], [1.0, 2.0], [2.0, 1.0, 2.0], [0.0, 1.0, 0.0], [0.0, 1.0, 1.0],
                               [0.0, 1.0, 1.0, 0.0], [0.0, 2.0, 2.0, 2.0, 1.0, 2.0, 0.0], [5.0] * 7])
@pytest.mark.parametrize("distance", [None, 1, 2, 3])
def test_find_peaks_on_short_and_flat_signals(x, distance):
    x = np.array(x, float)
    np.testing.assert_array_equal(find_peaks(x, prominence=0.0, distance=distance), scipy_peaks(x, 0.0, distance))


def test_plateau_peaks_are_their_middle_and_ties_go_as_scipys():
    x = np.array([0, 3, 3, 3, 3, 0, 3, 0, 3, 3, 0, 3, 0], float)       # equal heights: argsort decides
    for d in (1, 2, 3, 4, 6):
        np.testing.assert_array_equal(find_peaks(x, prominence=1.0, distance=d), scipy_peaks(x, 1.0, d))
    assert find_peaks(x, prominence=1.0).tolist() == [2, 6, 8, 11]


@pytest.mark.parametrize("n", [10**5, 10**6])
def test_find_peaks_on_long_noisy_records(n):
    """An hour-long record's worth of samples (deep pyramids, many neighbouring peaks)."""
    rng = np.random.default_rng(n)
    x = np.cumsum(rng.normal(size=n)) * 0.05 + rng.normal(size=n) + np.round(rng.normal(size=n), 0)
    for prominence, distance in [(0.5, 5), (3.0, 50), (0.0, 1)]:
        np.testing.assert_array_equal(find_peaks(x, prominence=prominence, distance=distance),
                                      scipy_peaks(x, prominence, distance))


def test_find_peaks_rejects_what_scipy_rejects():
    with pytest.raises(ValueError, match="distance"):
        find_peaks(np.zeros(5), distance=0.5)
    with pytest.raises(ValueError, match="1-D"):
        find_peaks(np.zeros((5, 2)))


# ----------------------------------------------------------------------------- Savitzky–Golay

@settings(max_examples=200, deadline=None)
@given(window=st.integers(2, 40).map(lambda h: 2 * h + 1), extra=st.integers(0, 400),
       channels=st.sampled_from([(), (1,), (3,), (5, 3)]), scale=st.integers(-3, 4),
       polyorder=st.sampled_from([2, 2, 3]), seed=st.integers(0, 2**32 - 1))
def test_savgol_matches_scipy(window, extra, channels, scale, polyorder, seed):
    rng = np.random.default_rng(seed)
    x = np.cumsum(rng.normal(size=(window + extra, *channels)), axis=0) * 10.0 ** scale
    ours = savgol_filter(x, window, polyorder)
    ref = sps.savgol_filter(x, window, polyorder, axis=0)
    assert ours.shape == x.shape
    np.testing.assert_allclose(ours, ref, rtol=1e-12, atol=1e-12 * np.abs(x).max())


@settings(max_examples=200, deadline=None)
@given(window=st.integers(2, 40).map(lambda h: 2 * h + 1), extra=st.integers(0, 100),
       channels=st.sampled_from([(), (3,), (5, 3)]), polyorder=st.sampled_from([1, 2, 3, 4]),
       seed=st.integers(0, 2**32 - 1))
def test_savgol_interior_is_ndimage_convolve1d_to_the_bit(window, extra, channels, polyorder, seed):
    x = np.cumsum(np.random.default_rng(seed).normal(size=(window + extra, *channels)), axis=0)
    half = window // 2
    ref = ndimage.convolve1d(x, _savgol_coefficients(window, polyorder), axis=0, mode="constant")
    np.testing.assert_array_equal(savgol_filter(x, window, polyorder)[half:len(x) - half], ref[half:len(x) - half])


def test_savgol_keeps_a_parabola_and_the_input():
    t = np.arange(40.0)
    x = 0.5 * t**2 - 3 * t + 2
    before = x.copy()
    np.testing.assert_allclose(savgol_filter(x, 9, 2), x, rtol=1e-12, atol=1e-9)
    np.testing.assert_array_equal(x, before)


def test_smooth_of_a_short_signal_is_a_copy():
    x = np.arange(4.0)
    y = seg.smooth(x, 100.0, 0.05)
    np.testing.assert_array_equal(y, x)
    assert y is not x


def test_savgol_rejects_a_bad_window():
    with pytest.raises(ValueError, match="odd"):
        savgol_filter(np.zeros(10), 4, 2)
    with pytest.raises(ValueError, match="window"):
        savgol_filter(np.zeros(4), 5, 2)


# ----------------------------------------------------------------------------- rotations

@st.composite
def rotvecs(draw):
    """Rotation vectors whose angle is tiny, ordinary, near π, or past it."""
    axis = np.array(draw(st.lists(st.floats(-1, 1), min_size=3, max_size=3)))
    if np.linalg.norm(axis) < 1e-3:
        axis = np.array([0.3, -0.5, 0.8])
    axis /= np.linalg.norm(axis)
    near_pi = st.one_of(st.floats(-1e-3, 1e-3), st.floats(-1e-9, 1e-9)).map(lambda e: np.pi + e)
    angle = draw(st.one_of(st.just(0.0), st.floats(1e-12, 2e-3), st.floats(0.0, np.pi), near_pi,
                           st.floats(np.pi, 3 * np.pi)))
    return axis * angle


@settings(max_examples=500, deadline=None)
@given(rv=rotvecs())
def test_rotvec_to_matrix_matches_scipy(rv):
    R = rotvec_to_matrix(rv)
    assert R.shape == (3, 3)
    np.testing.assert_allclose(R, Rotation.from_rotvec(rv).as_matrix(), rtol=0, atol=1e-12)
    np.testing.assert_allclose(rotvec_to_quaternion(rv), Rotation.from_rotvec(rv).as_quat(), rtol=0, atol=1e-12)


@settings(max_examples=500, deadline=None)
@given(rv=rotvecs(), wobble=st.sampled_from([0.0, 1e-14, 1e-9]), seed=st.integers(0, 2**32 - 1))
def test_matrix_to_rotvec_matches_scipy(rv, wobble, seed):
    """Also on matrices a little off orthogonal (scipy projects those past 1e-12 onto SO(3))."""
    R = Rotation.from_rotvec(rv).as_matrix() + wobble * np.random.default_rng(seed).normal(size=(3, 3))
    ours = matrix_to_rotvec(R)
    assert ours.shape == (3,)
    np.testing.assert_allclose(ours, Rotation.from_matrix(R).as_rotvec(), rtol=0, atol=1e-12)
    assert np.linalg.norm(ours) <= np.pi + 1e-12


@pytest.mark.parametrize("R", [np.eye(3), np.diag([1.0, -1.0, -1.0]), np.diag([-1.0, 1.0, -1.0]),
                               np.diag([-1.0, -1.0, 1.0]), np.array([[0.0, 1, 0], [1, 0, 0], [0, 0, -1]])])
def test_matrix_to_rotvec_at_zero_and_half_turns(R):
    np.testing.assert_allclose(matrix_to_rotvec(R), Rotation.from_matrix(R).as_rotvec(), rtol=0, atol=1e-15)


def test_batches_of_rotations():
    rng = np.random.default_rng(3)
    rv = rng.normal(size=(50, 3)) * np.r_[1e-6, 1.0, np.pi][rng.integers(0, 3, 50), None]
    R = rotvec_to_matrix(rv)
    assert R.shape == (50, 3, 3)
    np.testing.assert_allclose(R, Rotation.from_rotvec(rv).as_matrix(), rtol=0, atol=1e-12)
    np.testing.assert_allclose(matrix_to_rotvec(R), Rotation.from_matrix(R).as_rotvec(), rtol=0, atol=1e-12)
    np.testing.assert_allclose(rotvec_to_quaternion(rv.reshape(5, 10, 3)),
                               Rotation.from_rotvec(rv).as_quat().reshape(5, 10, 4), rtol=0, atol=1e-12)
    for i in (0, 17, 49):                                  # one at a time = as a batch
        np.testing.assert_array_equal(rotvec_to_matrix(rv[i]), R[i])
        np.testing.assert_array_equal(matrix_to_rotvec(R[i]), matrix_to_rotvec(R)[i])


def test_bad_rotations_are_refused():
    with pytest.raises(ValueError, match="determinant"):
        matrix_to_rotvec(np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(ValueError, match=r"\(\.\.\., 3\)"):
        rotvec_to_matrix([1.0, 2.0])
    with pytest.raises(ValueError, match=r"\(\.\.\., 3, 3\)"):
        matrix_to_rotvec(np.eye(4))


# ----------------------------------------------------------------------------- erosion

@settings(max_examples=300, deadline=None)
@given(h=st.integers(1, 30), w=st.integers(1, 30), fill=st.floats(0.0, 1.0), seed=st.integers(0, 2**32 - 1))
def test_erosion_matches_scipy(h, w, fill, seed):
    mask = np.random.default_rng(seed).random((h, w)) < fill
    np.testing.assert_array_equal(_eroded(mask), ndimage.binary_erosion(mask, border_value=0))

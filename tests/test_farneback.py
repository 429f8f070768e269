"""The project's Farnebäck (each frame expanded once) against OpenCV's, bit for bit.

``tactile.flow`` uses it for every frame too small for a pyramid level, so every flow-based
estimate rests on it being OpenCV's flow exactly, not approximately.
"""

import csv
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tactile_flow.tactile import farneback, flow, signals
from tactile_flow.tactile.flow import FlowConfig

GRASPS = Path(__file__).resolve().parent / "data" / "biotac_sp_grasps"


def opencv_flow(prev, nxt, c: FlowConfig) -> np.ndarray:
    return cv2.calcOpticalFlowFarneback(prev, nxt, None, c.pyr_scale, c.levels, c.winsize, c.iterations,
                                        c.poly_n, c.poly_sigma, c.flags)


def assert_equal_to_opencv(frames, c: FlowConfig, reference: int = 0):
    dynamic = flow.dynamic_flow(frames, config=c)
    static = flow.static_flow(frames, reference, config=c)
    for t in range(len(frames)):
        if t:
            np.testing.assert_array_equal(dynamic[t], opencv_flow(frames[t - 1], frames[t], c),
                                          err_msg=f"dynamic flow {t - 1}→{t}")
        np.testing.assert_array_equal(static[t], opencv_flow(frames[reference], frames[t], c),
                                      err_msg=f"static flow {reference}→{t}")


def real_contact_frames(model, view: str) -> np.ndarray:
    """8-bit frames of real BioTac SP contact patterns (the index finger of successive real
    grasp readings, activation against the file's least-pressed counts, as
    ``test_real_contact`` takes them), from rest into the first pattern and on through the
    next ones, scaled to their peak as the analysis scales a contact: (T, H, W) uint8."""
    with open(GRASPS / "biotac-palmdown-grasps.csv") as f:
        rows = np.clip([[float(x) for x in r[2:26]] for r in list(csv.reader(f))[1:]], 1, 4094)
    act = signals.activation(signals.counts_to_impedance(rows),
                             signals.counts_to_impedance(np.percentile(rows, 95, axis=0)))
    pressed = act[np.argsort(act.sum(axis=1))[-4:]]                       # the four strongest readings
    keys = np.vstack([np.zeros(24), pressed])
    steps = np.linspace(0, 1, 6, endpoint=False)[:, None, None]
    seq = (keys[:-1] * (1 - steps) + keys[1:] * steps).transpose(1, 0, 2).reshape(-1, 24)
    return model.render_uint8(seq, view, (0.0, float(seq.max())))


@pytest.mark.parametrize("view", ["bottom", "left", "right"])
def test_flows_of_real_contact_frames_are_opencv_s_to_the_bit(model, view):
    frames = real_contact_frames(model, view)
    assert frames.any(axis=(1, 2)).sum() >= len(frames) - 1              # real patterns, not blanks
    c = FlowConfig()
    assert farneback.supports(frames.shape, c)
    assert_equal_to_opencv(frames, c, reference=len(frames) // 2)


@st.composite
def scenes(draw):
    """A few frames of moving, growing blobs over noise, and a Farnebäck configuration."""
    h = draw(st.integers(2, 40))
    w = draw(st.integers(2, 63))
    t = draw(st.integers(1, 4))
    seed = draw(st.integers(0, 2**31 - 1))
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w]
    frames = np.empty((t, h, w), np.uint8)
    cy, cx, r = rng.uniform(0, h), rng.uniform(0, w), rng.uniform(1, 8)
    vy, vx = rng.normal(0, 1.5, 2)
    noise = draw(st.sampled_from([0.0, 3.0, 40.0]))
    for k in range(t):
        blob = 230 * np.exp(-((yy - cy - k * vy) ** 2 + (xx - cx - k * vx) ** 2) / (2 * (r + 0.3 * k) ** 2))
        frames[k] = np.clip(blob + rng.normal(0, noise, (h, w)), 0, 255).astype(np.uint8)
    if draw(st.booleans()):
        frames[0] = 0                                                      # an empty frame
    c = FlowConfig(winsize=draw(st.sampled_from([1, 3, 5, 9, 15, 21])), iterations=draw(st.integers(1, 4)),
                   poly_n=draw(st.sampled_from([5, 7])), poly_sigma=draw(st.sampled_from([1.1, 1.2, 1.5])))
    return frames, c


@settings(max_examples=60, deadline=None)
@given(scenes())
def test_any_small_scene_and_configuration_gives_opencv_s_flow(scene):
    frames, c = scene
    assert farneback.supports(frames.shape, c)
    assert_equal_to_opencv(frames, c, reference=len(frames) - 1)


def test_frames_with_a_pyramid_level_or_a_gaussian_window_are_left_to_opencv():
    rng = np.random.default_rng(0)
    big = rng.integers(0, 255, (2, 64, 70), dtype=np.uint8)
    small = big[:, :28, :40].copy()
    assert not farneback.supports(big.shape, FlowConfig())                # 64 px · 0.5 ≥ 32: a pyramid
    assert not farneback.supports(small.shape, FlowConfig(flags=cv2.OPTFLOW_FARNEBACK_GAUSSIAN))
    assert not farneback.supports(small.shape, FlowConfig(method="dis"))
    for frames, c in ((big, FlowConfig()), (small, FlowConfig(flags=cv2.OPTFLOW_FARNEBACK_GAUSSIAN))):
        assert_equal_to_opencv(frames, c)


def test_each_frame_is_expanded_once_and_two_empty_frames_are_not_flowed():
    frames = np.zeros((4, 28, 40), np.uint8)
    frames[2:, 10:16, 12:20] = 200
    expanded = farneback.expand(frames, FlowConfig())
    assert expanded.values.shape == (4, 28, 40, 5) and expanded.empty.tolist() == [True, True, False, False]
    assert not expanded.values[:2].any()                                  # an empty frame expands to zero
    out = farneback.pair_flows(expanded, expanded, [[0, 1], [1, 2], [2, 3]], FlowConfig())
    assert not out[0].any()
    np.testing.assert_array_equal(out[1], opencv_flow(frames[1], frames[2], FlowConfig()))


def test_threads_that_flow_at_once_in_a_fresh_process_both_get_the_kernels():
    """The analysis's flow jobs start on several threads at once; the kernels' first load must
    not show one of them a half-loaded module (it did with a lazy module)."""
    import subprocess
    import sys
    code = """
import threading, numpy as np
from tactile_flow.tactile import flow
frames = np.zeros((3, 28, 40), np.uint8); frames[1:, 8:16, 10:20] = 200
errors = []
def job():
    try:
        flow.dynamic_flow(frames)
    except Exception as e:
        errors.append(repr(e))
threads = [threading.Thread(target=job) for _ in range(4)]
[t.start() for t in threads]; [t.join() for t in threads]
print(errors)
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"

"""Long records analysed in bounded memory (issue 13 item 15, issue 15 goal 7): a record longer
than ``analysis.memory.chunk_frames`` is prepared a stretch at a time and its electrodes stay in
the store, and it gives the results of the same record analysed whole."""

import json
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from long_record import make_store

from tactile_flow.analysis.chunking import ImpedanceReader, LazyActivation, smoother_reach, stretches
from tactile_flow.analysis.config import load_config
from tactile_flow.analysis.electrodes import StoredElectrodes
from tactile_flow.analysis.load import load_run
from tactile_flow.analysis.pipeline import analyse, get_model
from tactile_flow.analysis.preprocess import Envelope

ANALYZE = [sys.executable, "-c", "from tactile_flow.analysis.cli import main; main()"]
WHOLE = {"progress": False, "figures": False, "memory": {"chunk_frames": 100_000, "noise_sample_frames": 100_000}}
PIECES = {"progress": False, "figures": False, "memory": {"chunk_frames": 4_000, "noise_sample_frames": 100_000}}


@pytest.fixture(scope="module")
def long_store(tmp_path_factory):
    """Ten minutes of the real resting bag tiled, five fingers, a press every 100 s (60 000 frames)."""
    return make_store(tmp_path_factory.mktemp("long") / "run", 10 / 60, 100.0)


def _analysis(store, node):
    cfg = load_config(node)
    run = load_run(store, in_memory_frames=cfg.memory.chunk_frames)
    return run, analyse(run, cfg, get_model(cfg.tactile))


def test_a_record_analysed_in_pieces_gives_the_results_of_the_record_analysed_whole(long_store):
    run_w, whole = _analysis(long_store, WHOLE)
    run_p, pieces = _analysis(long_store, PIECES)
    assert isinstance(run_w.electrodes, np.ndarray) and isinstance(run_p.electrodes, StoredElectrodes)
    assert isinstance(pieces.prepared.activation, LazyActivation)
    assert run_w.input_sha256 == run_p.input_sha256
    # the six presses (press j at (j + 0.5)·100 s on finger j mod 5) are found where they are
    found = sorted((run_w.time[a], f) for f, ivs in whole.contacts.items() for a, _ in ivs)
    assert [f for _, f in found] == [run_w.fingers[j % 5] for j in range(6)]
    assert np.allclose([t for t, _ in found], [(j + 0.5) * 100 for j in range(6)], atol=0.5)
    assert pieces.contacts == whole.contacts and pieces.thresholds == pytest.approx(whole.thresholds, rel=1e-6)
    assert [(s.label, s.finger, s.start, s.stop) for s in pieces.segments] == \
        [(s.label, s.finger, s.start, s.stop) for s in whole.segments]
    np.testing.assert_array_equal(pieces.prepared.noise, whole.prepared.noise)
    np.testing.assert_array_equal(pieces.prepared.baseline.impedance, whole.prepared.baseline.impedance)
    for name in ("pressure", "proxy", "score", "fine_score"):       # float32 in pieces: its rounding only
        a, b = getattr(pieces.prepared, name), getattr(whole.prepared, name)
        assert a.dtype == np.float32 and b.dtype == np.float64
        np.testing.assert_allclose(a, b, rtol=2e-6, atol=2e-5 * np.abs(b).max())
    for f, ivs in whole.contacts.items():        # the activation of a window: to the last bit
        k = run_w.fingers.index(f)
        a, b = ivs[0]
        np.testing.assert_array_equal(pieces.prepared.activation[a - 300:b + 300, k],
                                      whole.prepared.activation[a - 300:b + 300, k])
    assert pieces.slips.keys() == whole.slips.keys() and pieces.slips
    for sid, est in whole.slips.items():
        assert pieces.slips[sid]["slip_class"] == est["slip_class"]
        for key in ("slip_direction_sensor_deg", "slip_displacement_mm", "rotation_deg", "slip_onset_s"):
            if est[key] is None:                   # a touch has no direction, a touch no onset
                assert pieces.slips[sid][key] is None, key
            else:
                assert pieces.slips[sid][key] == pytest.approx(est[key], rel=1e-6, abs=1e-9), key
    assert len(pieces.aggregates) == len(whole.aggregates)
    for p, w in zip(pieces.aggregates, whole.aggregates):
        np.testing.assert_allclose(p["cop"], w["cop"], rtol=1e-9)


def test_a_long_record_packed_is_read_in_pieces_from_the_zip_with_the_same_results(long_store, tmp_path):
    """A long import is packed (``run.zarr.zip``): the analysis reads its electrodes a stretch at
    a time from the zip (the chunks it needs, never the whole array) and finds what it finds in
    the directory store."""
    from tactile_flow.runstore import packed
    zipped = packed.pack(long_store, tmp_path / "run.zarr.zip")
    run_d, directory = _analysis(long_store, PIECES)
    run_z, zip_pieces = _analysis(zipped, PIECES)
    assert isinstance(run_z.electrodes, StoredElectrodes) and run_z.input_sha256 == run_d.input_sha256
    assert zip_pieces.contacts == directory.contacts and zip_pieces.slips.keys() == directory.slips.keys()
    assert [(s.label, s.finger, s.start, s.stop) for s in zip_pieces.segments] == \
        [(s.label, s.finger, s.start, s.stop) for s in directory.segments]


def test_tactile_analyze_streams_a_long_record_and_says_so_in_the_summary(long_store, tmp_path):
    """The command line: a record longer than chunk_frames is analysed, with figures, and the
    summary states how it was prepared."""
    r = subprocess.run(ANALYZE + [f"run={long_store}", "analysis.memory.chunk_frames=5000", "analysis.progress=false"],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    summary = json.loads((long_store.parent / "analysis" / "summary.json").read_text())
    assert summary["provenance"]["preparation"]["stretches"] == 12
    assert summary["headline"]["fingers_in_contact"] == 5
    assert len(list((long_store.parent / "analysis" / "figures").glob("*.png"))) >= 4


def test_the_smoothers_reach_covers_their_memory():
    """Past the reach, a step at a stretch's edge has faded below float64's last bit."""
    from tactile_flow.tactile import signals
    R, Q = 0.005, 0.00015
    reach = smoother_reach(R, Q, 5, 5)
    z = np.zeros(4 * reach)
    z[: reach] = 1000.0                                  # a huge step where the stretch begins
    assert signals.kalman_smooth(z[reach:], R=R, Q=Q)[reach:].max() == 0.0
    tail = signals.kalman_smooth(z, R=R, Q=Q)[2 * reach:]
    assert np.abs(tail).max() < 1e-12 * 1000.0
    assert smoother_reach(R, Q / 100, 5, 5) > reach      # a slower filter remembers longer


@settings(max_examples=40, deadline=None)
@given(T=st.integers(50, 400), frames=st.integers(10, 120), seed=st.integers(0, 10_000))
def test_stretches_cover_the_record_once_with_their_reach(T, frames, seed):
    reach = 1 + seed % 9
    parts = stretches(T, frames, reach)
    cores = [i for (a, b), _ in parts for i in range(a, b)]
    assert cores == list(range(T))
    for (a, b), (a0, b0) in parts:
        assert a0 == max(0, a - reach) and b0 == min(T, b + reach) and b - a <= max(frames, 4 * reach)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000), a=st.integers(0, 199), n=st.integers(1, 200))
def test_invalid_samples_are_bridged_alike_in_any_stretch(seed, a, n):
    """A finger's run of bad samples across a stretch boundary is bridged from its valid
    neighbours wherever they lie, as for the whole record."""
    rng = np.random.default_rng(seed)
    T = 200
    counts = rng.integers(1500, 2500, (T, 2, 24)).astype(float)
    valid = np.ones((T, 2), bool)
    for _ in range(rng.integers(1, 5)):
        s = rng.integers(0, T)
        valid[s:s + rng.integers(1, 40), 0] = False
    counts[~valid[:, 0], 0] = 0.0
    read = ImpedanceReader(counts, valid, [0, 1])
    b = min(T, a + n)
    whole = read(0, T)
    np.testing.assert_array_equal(read(a, b), whole[a:b])
    np.testing.assert_array_equal(read(a, b, 0), whole[a:b, 0])
    # the same from a store, through a screening that dropped frames (every 7th)
    import xarray as xr
    keep = np.arange(T + T // 6)
    keep = keep[keep % 7 != 3][:T]
    stored = np.zeros((keep[-1] + 1, 2, 24))
    stored[keep] = counts
    source = StoredElectrodes(xr.Variable(("time", "finger", "taxel"), stored), keep, RuntimeError)
    np.testing.assert_array_equal(ImpedanceReader(source, valid, [0, 1])(a, b), whole[a:b])


def test_the_envelope_of_stretches_is_the_envelope_of_the_whole():
    rng = np.random.default_rng(3)
    raw, act = rng.normal(size=(2, 5003, 2, 24))
    whole = Envelope.empty(5003, 2, bins=97)
    whole.add(0, raw, act)
    pieces = Envelope.empty(5003, 2, bins=97)
    for a in range(0, 5003, 777):
        pieces.add(a, raw[a:a + 777], act[a:a + 777])
    for name in ("raw_min", "raw_max", "act_min", "act_max", "peak"):
        np.testing.assert_array_equal(getattr(pieces, name), getattr(whole, name))
    e = whole.edges
    assert whole.act_max[5, 1, 3] == act[e[5]:e[6], 1, 3].max()
    raw[e[7] + 1, 0, 2] = np.nan                  # a NaN marks its stretch, as np.minimum would
    whole.add(0, raw, act)
    assert np.isnan(whole.raw_min[7, 0, 2]) and np.isnan(whole.raw_max[7, 0, 2])
    assert np.isfinite(whole.raw_min[[6, 8], 0, 2]).all()

"""The recorder and its clock model on real simulated devices and a real zarr store."""

import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest
import xarray as xr

from tactile_flow.hardware.biotac import BiotacFrame
from tactile_flow.hardware.device import WallClock
from tactile_flow.hardware.sim import make_sim_lab
from tactile_flow.hardware.sim.scenarios import pad_height_pose
from tactile_flow.runstore.clockmodel import (OnlineClockModel, fit_envelope, sequence_gaps, window_minima)
from tactile_flow.protocols.recorder import Recorder
from tactile_flow.protocols.store import RunStore, open_run


def sources(lab):
    return {"biotac": lab.biotac.read, "arm": lab.arm.read_states, "hand": lab.hand.read_states,
            "pump": lab.pump.read_states, "scale": lab.scale.read}


def sweep(lab, speed=0.02):
    """Sweep ff across every straw with blocking moves only (nothing here drains a device:
    the recorder must be the only reader)."""
    s = lab.surface
    u0 = s.features[0].u - s.features[0].width / 2 - 0.01
    u1 = s.features[-1].u + s.features[-1].width / 2 + 0.01
    start = pad_height_pose(lab, *(s.origin[:2] + u0 * s.across[:2]), 0.0015)
    end = pad_height_pose(lab, *(s.origin[:2] + u1 * s.across[:2]), 0.0015)
    above = start + np.array([0, 0, 0.02, 0, 0, 0])
    lab.arm.move_linear(above, 0.1, 1.0)
    lab.arm.move_linear(start, 0.02, 0.5)
    lab.arm.move_linear(end, speed, 0.5)
    lab.arm.move_linear(end + np.array([0, 0, 0.02, 0, 0, 0]), 0.05, 0.5)


def true_time(device, device_time, t0):
    """The simulator's sample time (s since t0) of a device timestamp: the sim's device
    clock is ``offset + t·rate`` (hardware/sim/devices.py)."""
    return (np.asarray(device_time) - device._clock_offset) / device._clock_rate - t0


# ------------------------------------------------------------------ clock model (pure)
def test_fit_envelope_recovers_offset_and_drift_under_heavy_latency():
    rng = np.random.default_rng(0)
    t = np.arange(0, 300, 0.01)                       # true host time of each sample
    offset_d, rate = 1234.5, 1 + 35e-6
    d = offset_d + t * rate
    lat = 0.002 + rng.exponential(0.003, t.size)      # min 2 ms, long tail
    lat[rng.random(t.size) < 0.01] += 0.5             # 1 % stalls
    h = t + lat
    _, dm, hm = window_minima(d, h, 1.0, d[0])
    fit = fit_envelope(dm, hm, min_latency_s=0.002)
    assert abs(fit.drift - (1 / rate - 1)) < 0.2e-6
    assert np.abs(fit(d) - t).max() < 0.2e-3


def test_fit_envelope_without_drift_span_fits_offset_only():
    d = np.array([10.0, 11.0])
    fit = fit_envelope(d, d + 5.0)
    assert fit.slope == 1.0 and fit(20.0) == pytest.approx(25.0)
    with pytest.raises(ValueError):
        fit_envelope([], [])


def test_online_model_maps_from_the_first_batch_and_refits():
    m = OnlineClockModel(window_s=1.0, min_drift_span_s=5.0)
    d = np.arange(0, 30, 0.01) + 7.0
    h = (d - 7.0) * (1 + 50e-6) + 100.0
    m.update(d[:10], h[:10])
    assert m.map(d[0]) == pytest.approx(h[0])
    m.update(d[10:], h[10:])
    assert np.abs(m.final()(d) - h).max() < 1e-6 and m.n_windows == 30


def test_sequence_gaps():
    assert sequence_gaps([1, 2, 3]) == []
    assert sequence_gaps([4, 5, 9, 10], previous=2) == [(0, 2, 1), (2, 5, 3)]
    assert sequence_gaps([5, 5]) == [(1, 5, -1)]


# ------------------------------------------------------------------ recorder on the sim
def test_sweep_records_every_frame_with_units_and_events(tmp_path):
    lab = make_sim_lab({"seed": 1, "fingers": ["ff", "mf", "th"]}, {"kind": "straws"})
    with lab:
        store = RunStore.create(tmp_path / "run.zarr", protocol="sweep_test", fingers=lab.biotac.fingers)
        with Recorder(store, sources(lab), lab.clock, flush_interval_s=0.2) as rec:
            rec.event("step_start", "sweep", {"speed_m_s": 0.02})
            sweep(lab)
            lab.clock.sleep(0.3)
            # readable mid-run: a committed, consistent prefix
            time.sleep(0.5)
            mid = xr.open_datatree(store.path, engine="zarr")
            assert 0 < mid["biotac"].sizes["time"] <= lab.biotac.seq
            rec.event("step_end", "sweep")
        truth_lab_seq = lab.biotac.seq
    dt = open_run(store.path)
    assert dt.attrs["status"] == "success" and dt.attrs["end_time"]
    seq = dt["biotac/seq"].values
    np.testing.assert_array_equal(seq, np.arange(1, truth_lab_seq + 1))      # every frame, in order
    assert dt["biotac_pac"].sizes["time_pac"] == 22 * seq.size
    assert dt["biotac/valid"].values.all()
    assert dt["biotac/electrodes"].shape == (seq.size, 3, 24)
    assert dt["biotac/pdc"].values.max() > dt["biotac/pdc"].values[0].max() + 100   # it touched
    assert np.all(np.diff(dt["biotac/time"].values) > 0)
    assert dt["arm"].sizes["time_arm"] > 4 * seq.size and dt["pour"].sizes["time_scale"] > 0
    kinds = list(dt["events/kind"].values)
    assert kinds[0] == "step_start" and "step_end" in kinds and "gap" not in kinds
    s = dt.attrs["streams"]
    assert s["biotac"]["samples"] == seq.size and s["biotac"]["gaps"] == 0
    assert abs(s["arm"]["clock_model"]["drift_ppm"]) < 25
    assert rec.stats()["biotac"]["samples"] == seq.size


def test_clock_model_matches_the_simulators_sample_times(tmp_path):
    """Device clocks with a random offset and up to ±40 ppm drift, ~1.5 ms latency jitter:
    the fitted time base agrees with the true sample time to < 2 ms (< 0.3 ms once the
    known minimum latency is subtracted)."""
    cfg = {"seed": 5, "fingers": ["ff"], "sensor": {"clock_drift_ppm": 40.0, "latency_s": 0.0015}}
    lab = make_sim_lab(cfg)
    with lab:
        store = RunStore.create(tmp_path / "run.zarr", protocol="clock", fingers=lab.biotac.fingers)
        rec = Recorder(store, sources(lab), lab.clock, min_latency_s={"biotac": 0.0015}).start()
        lab.clock.sleep(60.0)
        rec.stop("success")
    dt = open_run(store.path)
    checks = {"biotac": ("biotac", "time", "device_time"), "arm": ("arm", "time_arm", "controller_time"),
              "hand": ("hand", "time_hand", "device_time"), "pump": ("pour", "time_pump", "pump_device_time"),
              "scale": ("pour", "time_scale", "scale_device_time")}
    for stream, (group, tname, dname) in checks.items():
        dev = getattr(lab, stream)
        err = dt[f"{group}/{tname}"].values - true_time(dev, dt[f"{group}/{dname}"].values, rec.t0)
        bound = 0.3e-3 if stream == "biotac" else 2e-3
        assert np.abs(err).max() < bound, (stream, np.abs(err).max())
        cm = dt.attrs["streams"][stream]["clock_model"]
        assert cm["drift_ppm"] == pytest.approx((1 / dev._clock_rate - 1) * 1e6, abs=1.0), stream
        lo = 1.5 if stream == "biotac" else 0.0       # residual latency includes the known minimum
        assert lo <= cm["residual_latency"]["median_ms"] < lo + 0.5, stream


def test_dropout_gaps_and_corrupt_frames_are_counted_and_recorded(tmp_path):
    cfg = {"seed": 2, "fingers": ["ff"],
           "faults": {"biotac_dropout": [[1.0, 1.5], [2.0, 2.05]], "biotac_corrupt": [2.5]}}
    lab = make_sim_lab(cfg)
    with lab:
        store = RunStore.create(tmp_path / "run.zarr", protocol="faults", fingers=lab.biotac.fingers)
        with Recorder(store, sources(lab), lab.clock) as rec:
            lab.clock.sleep(3.0)
    st = rec.stats()["biotac"]
    assert st["gaps"] == 2 and st["missing"] == 50 + 5 and st["invalid"] == 1
    dt = open_run(store.path)
    ev = dt["events"]
    gaps = [(float(t), str(d)) for t, k, d in zip(ev["time"].values, ev["kind"].values, ev["detail"].values)
            if k == "gap"]
    assert len(gaps) == 2 and abs(gaps[0][0] - 1.5) < 0.02 and '"missing": 50' in gaps[0][1]
    assert list(ev["kind"].values).count("invalid") == 1
    assert (~dt["biotac/valid"].values).sum() == 1
    assert dt.attrs["streams"]["biotac"]["missing"] == 55


def test_device_error_becomes_a_fault_event_and_a_stale_stream(tmp_path):
    lab = make_sim_lab({"seed": 4, "fingers": ["ff"], "faults": {"disconnect": {"scale": 0.5}}})
    with lab:
        store = RunStore.create(tmp_path / "run.zarr", protocol="disconnect", fingers=lab.biotac.fingers)
        rec = Recorder(store, sources(lab), lab.clock).start()
        lab.clock.sleep(1.0)
        time.sleep(0.1)                                  # let the scale thread poll
        assert rec.stale_streams() == {"scale"}
        assert rec.last_sample_age("scale") > 0.4 and rec.last_sample_age("biotac") < 0.1
        assert rec.stale_streams(max_age_s=0.3) == {"scale"}
        rec.stop("failed")
    st = rec.stats()
    assert st["scale"]["faults"] == 1 and st["biotac"]["faults"] == 0
    dt = open_run(store.path)
    ev = dt["events"]
    faults = [str(n) for k, n in zip(ev["kind"].values, ev["name"].values) if k == "fault"]
    assert faults == ["scale"] and dt.attrs["status"] == "failed"
    assert dt["biotac"].sizes["time"] == 100


def test_exception_in_the_context_closes_the_store_as_failed(tmp_path):
    lab = make_sim_lab({"seed": 4, "fingers": ["ff"]})
    with lab:
        store = RunStore.create(tmp_path / "run.zarr", protocol="boom", fingers=lab.biotac.fingers)
        with pytest.raises(ZeroDivisionError):
            with Recorder(store, sources(lab), lab.clock):
                lab.clock.sleep(0.2)
                1 / 0
    dt = open_run(store.path)
    assert dt.attrs["status"] == "failed" and "ZeroDivisionError" in str(dt["events/detail"].values[-1])


# ------------------------------------------------------------------ SIGKILL
CHILD = textwrap.dedent("""
    import sys, time
    import numpy as np
    from tactile_flow.hardware.sim import make_sim_lab
    from tactile_flow.protocols.store import RunStore
    from tactile_flow.protocols.recorder import Recorder

    lab = make_sim_lab({"seed": 9, "realtime": True}, {"kind": "straws"})
    with lab:
        store = RunStore.create(sys.argv[1], protocol="sigkill", fingers=lab.biotac.fingers)
        rec = Recorder(store, {"biotac": lab.biotac.read, "arm": lab.arm.read_states,
                               "hand": lab.hand.read_states, "pump": lab.pump.read_states,
                               "scale": lab.scale.read}, lab.clock, flush_interval_s=0.5).start()
        home = np.array(lab.world.cfg.arm.home_pose)
        k = 0
        while True:
            if not lab.arm.is_moving():
                k += 1
                rec.event("step_start", f"move_{k}")
                lab.arm.move_linear(home + [0.05 * (k % 2), 0, 0, 0, 0, 0], 0.1, 1.0, asynchronous=True)
            lab.clock.sleep(0.02)
            newest = rec.newest_sample_time("biotac")
            print(f"{time.monotonic():.6f} {rec.now():.4f} {-1 if newest is None else newest:.4f}", flush=True)
""")


def test_sigkill_leaves_a_consistent_store_missing_at_most_one_second(tmp_path):
    script = tmp_path / "child.py"
    script.write_text(CHILD)
    path = tmp_path / "run.zarr"
    err = open(tmp_path / "child.err", "w")
    proc = subprocess.Popen([sys.executable, str(script), str(path)], stdout=subprocess.PIPE,
                            stderr=err, text=True)
    try:
        deadline = time.monotonic() + 60
        line = None
        while time.monotonic() < deadline:
            line = proc.stdout.readline()
            assert line, (tmp_path / "child.err").read_text()
            wall, run_t, newest = map(float, line.split())
            if run_t > 3.2:
                break
        os.kill(proc.pid, signal.SIGKILL)
        kill_wall = time.monotonic()
    finally:
        proc.kill()
        proc.wait()
        err.close()
    # realtime pacing: simulated time never runs ahead of the wall clock, so at the kill
    # the newest sample the child could have received is at most:
    newest_at_kill = newest + (kill_wall - wall)
    dt = xr.open_datatree(path, engine="zarr")
    assert dt.attrs["status"] == "running"
    stored = dt["biotac/host_time"].values
    lost_s = newest_at_kill - stored.max()
    print(f"SIGKILL: newest sample at kill <= {newest_at_kill:.3f} s, stored up to {stored.max():.3f} s, "
          f"lost <= {lost_s:.3f} s")
    assert lost_s <= 1.0
    seq = dt["biotac/seq"].values
    np.testing.assert_array_equal(seq, np.arange(1, seq.size + 1))           # nothing missing before
    assert dt["biotac_pac"].sizes["time_pac"] == 22 * seq.size
    for group in ("biotac", "arm", "hand", "pour", "events"):
        ds = dt[group].to_dataset()
        for name, var in ds.data_vars.items():
            for d in var.dims:
                assert var.sizes[d] == ds.sizes[d], (group, name)
        for name, var in ds.variables.items():                             # data actually readable
            assert np.asarray(var.values).shape == var.shape
    assert dt["arm"].sizes["time_arm"] > 0 and "step_start" in list(dt["events/kind"].values)


class JitteryBridge:
    """A BioTac bridge on the wall clock whose frames come with 22 PAC samples each and
    whose transport latency drops from 30 ms to 1 ms after 1.2 s (a congested link clearing):
    the online clock model then refits to an earlier offset mid-run, and frames now and then
    arrive 8 ms closer than their samples span (stamp jitter)."""

    def __init__(self):
        self.t0, self.seq = time.monotonic(), 0

    def read(self):
        frames, now = [], time.monotonic() - self.t0
        while (self.seq + 1) * 0.01 <= now:
            self.seq += 1
            t = self.seq * 0.01 - (0.008 if self.seq % 7 == 0 else 0.0)
            latency = 0.03 if t < 1.2 else 0.001
            frames.append(BiotacFrame(self.seq, 500.0 + t, self.t0 + t + latency, np.full((1, 24), 2000, np.int16),
                                      np.array([2000]), np.array([2000]), np.array([0]), np.zeros((1, 22), np.int16)))
        return frames


@pytest.mark.slow
def test_time_axes_increase_strictly_while_recording_and_after(tmp_path):
    """Issue 13 item 12, the recorder's part: committed times (what a reader, or a killed
    run, keeps) never go back across a flush when the clock model refits, nor at a frame
    boundary of the PAC samples; the final refit keeps them increasing."""
    store = RunStore.create(tmp_path / "run.zarr", protocol="jitter", fingers=("ff",))
    rec = Recorder(store, {"biotac": JitteryBridge().read}, WallClock(), flush_interval_s=0.2).start()
    time.sleep(3.0)
    mid = xr.open_datatree(store.path, engine="zarr")
    rec.stop("success")
    end = open_run(store.path)
    for tree in (mid, end):
        for group, axis in (("biotac", "time"), ("biotac_pac", "time_pac")):
            steps = np.diff(tree[group][axis].values)
            assert len(steps) > 100 and np.all(steps > 0), (group, axis, steps.min())

"""Faults injected from config behave as configured and are recorded in the truth."""

import numpy as np
import pytest

from tactile_flow.hardware.errors import DeviceDisconnectedError, NotConnectedError, ProtectiveStopError
from tactile_flow.hardware.sim import make_sim_lab
from tactile_flow.hardware.sim.scenarios import biotac_arrays


def test_dropout_window_leaves_a_gap_and_a_seq_jump():
    lab = make_sim_lab({"seed": 1, "faults": {"biotac_dropout": [[1.0, 1.5]]}})
    with lab:
        lab.clock.sleep(3.0)
        b = biotac_arrays(lab.biotac.read())
    t = b["time"]
    assert not np.any((t > 1.0 + 0.005) & (t < 1.5 - 0.005))
    jumps = np.diff(b["seq"])
    assert sorted(set(jumps)) == [1, 51]              # 50 frames lost in 0.5 s at 100 Hz
    assert len(b["seq"]) == 300 - 50


def test_corrupted_frames_are_delivered_and_countable():
    times = [0.5, 1.23, 2.0]
    lab = make_sim_lab({"seed": 1, "faults": {"biotac_corrupt": times}})
    with lab:
        lab.clock.sleep(3.0)
        frames = lab.biotac.read()
    bad = [f for f in frames if not f.is_valid()]
    assert len(bad) == 3
    assert np.allclose([f.host_time for f in bad], times, atol=0.01)
    assert np.all(np.diff([f.seq for f in frames]) == 1)      # nothing lost, just garbled
    assert list(lab.truth.to_dict()["faults"]["kind"]) == ["biotac_corrupt"] * 3


def test_protective_stop_stops_the_arm_and_refuses_motion_until_recover():
    lab = make_sim_lab({"seed": 1, "faults": {"protective_stop_s": 1.0}})
    with lab:
        start = lab.arm.tcp_pose()
        target = start + np.array([0.1, 0, 0, 0, 0, 0])
        with pytest.raises(ProtectiveStopError):
            lab.arm.move_linear(target, speed=0.05, accel=0.5)          # would take ~2.1 s
        assert lab.arm.is_protective_stopped()
        assert lab.clock.now() == pytest.approx(1.0, abs=0.01)
        lab.clock.sleep(0.5)
        stopped_at = lab.arm.tcp_pose()
        assert 0.01 < stopped_at[0] - start[0] < 0.05 and not lab.arm.is_moving()
        with pytest.raises(ProtectiveStopError):
            lab.arm.move_linear(target, speed=0.05, accel=0.5)
        with pytest.raises(ProtectiveStopError):
            lab.arm.speed_linear([0.01, 0, 0, 0, 0, 0], 0.5, 0.5)
        states = lab.arm.read_states()
        assert not states[0].protective_stopped and states[-1].protective_stopped
        lab.arm.recover()
        assert not lab.arm.is_protective_stopped()
        lab.arm.move_linear(target, speed=0.05, accel=0.5)
        np.testing.assert_allclose(lab.arm.tcp_pose(), target, atol=1e-9)
    assert "protective_stop" in lab.truth.to_dict()["faults"]["kind"]


def test_disconnect_at_t_raises_a_typed_error_on_that_device_only():
    lab = make_sim_lab({"seed": 1, "faults": {"disconnect": {"biotac": 2.0}}})
    with lab:
        lab.clock.sleep(1.0)
        assert len(lab.biotac.read()) == 100
        lab.clock.sleep(1.5)
        with pytest.raises(DeviceDisconnectedError, match="hardware.faults.disconnect.biotac"):
            lab.biotac.read()
        with pytest.raises(NotConnectedError):         # a disconnect is a NotConnectedError
            lab.biotac.read()
        assert not lab.biotac.is_connected
        with pytest.raises(DeviceDisconnectedError):
            lab.biotac.connect()
        assert len(lab.arm.read_states()) > 0          # the others carry on

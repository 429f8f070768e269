"""The device interfaces: what every driver (simulated or real) promises the run engine."""

import threading

import numpy as np
import pytest

from hardware.arm import Arm
from hardware.biotac import TactileSensors
from hardware.device import Clock, DeviceIdentity, WallClock
from hardware.errors import NotConnectedError
from hardware.hand import JOINT_NAMES, Hand
from hardware.pour import Pump, Scale
from hardware.sim import make_sim_lab


def test_sim_devices_implement_the_interfaces_and_report_identity():
    lab = make_sim_lab({"seed": 2})
    for dev, iface in [(lab.arm, Arm), (lab.hand, Hand), (lab.biotac, TactileSensors),
                       (lab.pump, Pump), (lab.scale, Scale)]:
        assert isinstance(dev, iface)
        assert isinstance(dev.identity, DeviceIdentity) and dev.identity.serial_or_address.startswith("sim://")
    assert isinstance(lab.clock, Clock) and isinstance(WallClock(), Clock)
    assert len(JOINT_NAMES) == 24 and JOINT_NAMES[0] == "rh_FFJ1" and JOINT_NAMES[-1] == "rh_WRJ2"


@pytest.mark.parametrize("call", [lambda l: l.arm.tcp_pose(), lambda l: l.biotac.read(),
                                  lambda l: l.hand.positions(), lambda l: l.pump.status(),
                                  lambda l: l.scale.mass()])
def test_calls_before_connect_raise_not_connected(call):
    lab = make_sim_lab({})
    with pytest.raises(NotConnectedError):
        call(lab)


def test_context_manager_connects_and_closes():
    lab = make_sim_lab({})
    with lab.biotac as b:
        assert b.is_connected
    assert not lab.biotac.is_connected
    with pytest.raises(NotConnectedError):
        lab.biotac.read()


def test_frames_carry_shapes_sequence_and_timestamps():
    lab = make_sim_lab({"seed": 2, "fingers": ["th", "ff"]})
    with lab:
        lab.clock.sleep(0.5)
        frames = lab.biotac.read()
        assert lab.biotac.read() == []                       # drained
    assert lab.biotac.fingers == ("ff", "th")               # Shadow order
    f = frames[0]
    assert f.electrodes.shape == (2, 24) and f.electrodes.dtype == np.int16
    assert f.pdc.shape == (2,) and f.pac.shape == (2, 22)
    seq = np.array([x.seq for x in frames])
    host = np.array([x.host_time for x in frames])
    dev = np.array([x.device_time for x in frames])
    assert np.all(np.diff(seq) == 1) and len(frames) == 50
    assert np.all(np.diff(host) > 0) and np.allclose(np.diff(dev), 0.01, rtol=1e-3)
    assert np.all(host - np.arange(1, 51) * 0.01 > 0)        # received after being produced


def test_hand_moves_joints_over_the_duration():
    with make_sim_lab({}) as lab:
        lab.hand.move_to({"rh_FFJ3": 1.0, "rh_THJ4": 0.5}, duration=1.0)
        assert lab.clock.now() == pytest.approx(1.0)
        q = lab.hand.positions()
        assert q["rh_FFJ3"] == pytest.approx(1.0) and q["rh_THJ4"] == pytest.approx(0.5)
        states = lab.hand.read_states()
        ffj3 = [s.position[JOINT_NAMES.index("rh_FFJ3")] for s in states]
        assert np.all(np.diff(ffj3) >= 0) and 95 <= len(states) <= 101


def test_only_the_driver_thread_advances_simulated_time():
    lab = make_sim_lab({})
    with lab:
        seen = []

        def poller():                     # a recorder's acquisition loop
            for _ in range(5):
                lab.clock.sleep(0.01)
                seen.append(lab.clock.now())

        th = threading.Thread(target=poller)
        th.start()
        th.join(5)
        assert lab.clock.now() == 0.0     # pollers waited, never stepped the world
        lab.clock.sleep(1.0)
        assert lab.clock.now() == pytest.approx(1.0)

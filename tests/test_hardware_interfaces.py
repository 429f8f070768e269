"""The device interfaces: what every driver (simulated or real) promises the run engine."""

import threading

import numpy as np
import pytest

from tactile_flow.hardware.arm import Arm
from tactile_flow.hardware.biotac import TactileSensors
from tactile_flow.hardware.device import Clock, DeviceIdentity, WallClock
from tactile_flow.hardware.errors import DeviceError, NotConnectedError
from tactile_flow.hardware.hand import JOINT_NAMES, Hand
from tactile_flow.hardware.pour import Pump, Scale
from tactile_flow.hardware.sim import make_sim_lab


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


# ------------------------------------------------------------------ every driver, real or simulated
def _drivers():
    from tactile_flow.hardware.serial_biotac import SerialBiotacs
    from tactile_flow.hardware.serial_pour import SerialPump, SerialScale
    from tactile_flow.hardware.shadow import RosbridgeBiotacs, ShadowHand
    from tactile_flow.hardware.sim import SimArm, SimBiotac, SimHand, SimPump, SimScale, SimStage
    from tactile_flow.hardware.stage import ObjectStage
    from tactile_flow.hardware.ur10 import UR10Arm
    return [(UR10Arm, Arm), (SimArm, Arm), (ShadowHand, Hand), (SimHand, Hand),
            (RosbridgeBiotacs, TactileSensors), (SerialBiotacs, TactileSensors), (SimBiotac, TactileSensors),
            (SerialPump, Pump), (SimPump, Pump), (SerialScale, Scale), (SimScale, Scale), (SimStage, ObjectStage)]


@pytest.mark.parametrize("driver, interface", _drivers(), ids=lambda c: getattr(c, "__name__", ""))
def test_every_driver_implements_its_whole_interface_and_declares_what_it_records(driver, interface):
    import inspect

    assert issubclass(driver, interface) and not inspect.isabstract(driver), inspect.getattr_static(
        driver, "__abstractmethods__", ())
    assert driver.kind == interface.kind and driver.sample_type is interface.sample_type
    streams = interface.sample_type.describe()
    assert streams and streams[0].name == interface.kind           # the store block is the device's name
    fields = set(interface.sample_type.__dataclass_fields__) | {"is_valid"}
    for stream in streams:
        for column in (stream.device_time, *stream.columns):
            assert (column.source or column.name) in fields, f"{stream.name}/{column.name}: no sample attribute"
            assert column.dims[0] == stream.time and column.units is not None


def test_what_a_device_declares_is_what_its_samples_give():
    """The columns a sample type declares, made from a real simulated device's samples, have
    the declared dtypes and the shapes of their dimensions."""
    with make_sim_lab({"seed": 2, "fingers": ["ff", "th"]}) as lab:
        lab.clock.sleep(0.2)
        streams, sources = lab.streams(), lab.sources()
        assert set(sources) == {"arm", "hand", "biotac", "pump", "scale"} | ({"stage"} if lab.stage else set())
        assert set(streams) == set(sources) | {"biotac_pac"}
        sizes = {"finger": 2, "taxel": 24, "axis6": 6, "joint": 24, "stage_axis": 3}
        for name, read in sources.items():
            samples = read()
            for stream in (s for s in streams.values() if s.source_name == name):
                cols = stream.to_columns(samples)
                n = len(cols[stream.device_time.name])
                assert n >= len(samples) > 0
                for column in stream.columns:
                    a = cols[column.name]
                    assert a.shape == (n, *(sizes[d] for d in column.dims[1:])), (stream.name, column.name)
                    assert a.dtype == np.dtype(column.dtype), (stream.name, column.name)


def test_hand_stop_holds_every_joint_where_it_is():
    with make_sim_lab({}) as lab:
        lab.hand.move_to({"rh_FFJ3": 1.0}, duration=1.0, wait=False)
        lab.clock.sleep(0.4)
        lab.hand.stop()
        held = lab.hand.positions()["rh_FFJ3"]
        lab.clock.sleep(0.6)
        assert 0.2 < held < 0.8                                  # stopped on the way
        assert lab.hand.positions()["rh_FFJ3"] == pytest.approx(held, abs=0.02)


def test_connecting_a_lab_reports_every_failing_device_and_leaves_nothing_open(tmp_path):
    from tactile_flow.hardware.lab_container import Lab
    from tactile_flow.hardware.serial_pour import SerialPump, SerialPumpConfig, SerialScale, SerialScaleConfig

    sim = make_sim_lab({})
    missing = tmp_path / "no-such-port"
    lab = Lab(arm=sim.arm, hand=sim.hand, biotac=sim.biotac, clock=sim.clock,
              pump=SerialPump(SerialPumpConfig(port=str(missing)), sim.clock),
              scale=SerialScale(SerialScaleConfig(port=str(missing)), sim.clock))
    with pytest.raises(DeviceError) as err:                    # the first failure's own type
        lab.connect()
    assert set(err.value.failures) == {"pump", "scale"}
    assert str(missing) in str(err.value) and "also failed to connect: scale: " in str(err.value)
    assert not any(d.is_connected for d in lab.devices.values())

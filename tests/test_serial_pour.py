"""Pump (EZO-PMP-like) and scale (A&D-like) drivers through pyserial against the emulators on ptys."""

import os
import threading
import time

import numpy as np
import pytest

from tactile_flow.hardware.emulators.serial_devices import SerialDevicesEmulator
from tactile_flow.hardware.errors import ConfigError, DeviceDisconnectedError, DeviceFaultError, NotConnectedError
from tactile_flow.hardware.serial_pour import (SerialPump, SerialPumpConfig, SerialScale, SerialScaleConfig, format_weight_line,
                                  parse_weight_line)


@pytest.fixture(scope="module")
def emu():
    with SerialDevicesEmulator(seed=5, pump_max_rate_ml_min=150.0) as e:
        yield e


@pytest.fixture
def pump(emu):
    with SerialPump(SerialPumpConfig(port=emu.ports["pump"], max_rate_ml_min=150.0)) as p:
        yield p
        p.stop()


@pytest.fixture
def scale(emu):
    with SerialScale(SerialScaleConfig(port=emu.ports["scale"])) as s:
        yield s


def test_weight_lines_parse_and_format():
    r = parse_weight_line("ST,GS,+  4.876kg", 1.5)
    assert (r.mass_g, r.stable, r.host_time) == (4876.0, True, 1.5)
    assert parse_weight_line("US,NT,-  12.30 g").mass_g == -12.3 and not parse_weight_line("US,NT,-  12.30 g").stable
    assert format_weight_line(4876.0, True, net=False, unit="kg") == "ST,GS,+  4.876kg"
    for bad in ("", "ST,GS,+  4.876lb", "XX,GS,+ 1.0 g", "ST,GS,4.876kg", "garbage"):
        assert parse_weight_line(bad) is None


def test_pump_identifies_and_round_trips_every_command(pump, emu):
    assert pump.identity.firmware == "2.4-emulated"
    pump.set_rate(90.0)
    s = pump.status()
    assert s.running and s.rate_ml_min == pytest.approx(90.0)
    pump.stop()
    s = pump.status()
    assert not s.running and s.rate_ml_min == 0.0
    d0 = s.dispensed_ml
    pump.dispense(1.5, 120.0)                 # 0.75 s at 2 ml/s
    assert pump.status().running
    time.sleep(1.2)
    s = pump.status()
    assert not s.running and s.dispensed_ml - d0 == pytest.approx(1.5, abs=0.01)
    assert pump.done_count >= 1               # the pump's *DONE message
    states = pump.read_states()
    assert len(states) >= 8 and any(st.running for st in states)       # 10 Hz status polling


def test_pump_refuses_a_wrong_rate_before_sending_and_reports_device_errors(emu):
    commands = emu.stats()["pump"]["commands"]
    with SerialPump(SerialPumpConfig(port=emu.ports["pump"], max_rate_ml_min=150.0, poll_hz=1.0)) as pump:
        for bad in (-1.0, 151.0, float("nan")):
            with pytest.raises(ValueError, match=r"outside \[0, hardware.pump.max_rate_ml_min=150.0\]"):
                pump.set_rate(bad)
        with pytest.raises(ValueError, match="volume_ml"):
            pump.dispense(0.0)
    assert emu.stats()["pump"]["commands"] - commands <= 3       # `i` and at most a status poll: nothing sent
    # a driver configured beyond what the pump accepts: the pump's *ER becomes a typed error
    with SerialPump(SerialPumpConfig(port=emu.ports["pump"], max_rate_ml_min=500.0)) as loose:
        with pytest.raises(DeviceFaultError, match=r"refused 'DC,400.000,\*' \(\*ER\)"):
            loose.set_rate(400.0)
        assert not loose.status().running
    with pytest.raises(ConfigError, match="hardware.pump.poll_hz"):
        SerialPumpConfig(port="loop://", poll_hz=0)


def test_scale_streams_tares_and_follows_the_pump(scale, pump):
    time.sleep(0.35)
    readings = scale.read()
    assert len(readings) >= 2 and all(r.stable for r in readings[-2:])
    scale.tare()
    time.sleep(0.25)
    assert abs(scale.mass()) < 0.3
    pump.dispense(3.0, 150.0)                 # 1.2 s; water leaves the reservoir on the scale
    time.sleep(0.6)
    assert not scale.stable
    time.sleep(1.3)
    assert scale.mass() == pytest.approx(-3.0, abs=0.3)
    assert len(scale.read()) >= 15


def test_calls_before_connect_and_a_missing_port_are_clear_errors(tmp_path):
    p = SerialPump(SerialPumpConfig(port="loop://"))
    with pytest.raises(NotConnectedError, match="not connected"):
        p.status()
    t0 = time.monotonic()
    with pytest.raises(NotConnectedError, match=r"scale: cannot open serial port .*hint: check hardware.scale.port"):
        SerialScale(SerialScaleConfig(port=str(tmp_path / "ttyUSB7"))).connect()
    assert time.monotonic() - t0 < 1.0


def test_a_pump_that_never_answers_times_out():
    """``loop://`` echoes our own command back: not a pump."""
    p = SerialPump(SerialPumpConfig(port="loop://", timeout_s=0.3))
    t0 = time.monotonic()
    with pytest.raises(Exception, match="(no reply to 'i'|not a pump)"):
        p.connect()
    assert time.monotonic() - t0 < 1.5 and not p.is_connected


def test_disconnect_of_pump_and_scale_is_detected():
    with SerialDevicesEmulator() as e:
        pump = SerialPump(SerialPumpConfig(port=e.ports["pump"], max_rate_ml_min=150.0))
        scale = SerialScale(SerialScaleConfig(port=e.ports["scale"]))
        pump.connect()
        scale.connect()
        e.command("disconnect pump")
        e.command("disconnect scale")
        t0 = time.monotonic()
        with pytest.raises(DeviceDisconnectedError, match="pump: serial link .* lost"):
            while time.monotonic() - t0 < 2:
                pump.read_states()
                time.sleep(0.005)
        # each port's reader thread notices on its own: the scale's may come a little later
        with pytest.raises(DeviceDisconnectedError, match="scale: serial link .* lost"):
            while time.monotonic() - t0 < 2:
                scale.read()
                time.sleep(0.005)
        pump.close()
        scale.close()


def test_weight_lines_read_together_get_strictly_increasing_times():
    """Issue 13 item 12: lines that reach the host in one read shared one receipt time, so
    ``pour/time_scale`` repeated a time. A real pty; five lines written at once."""
    master, slave = os.openpty()
    scale = SerialScale(SerialScaleConfig(port=os.ttyname(slave), rate_hz=10.0))
    line = format_weight_line(99.0, True, False).encode() + b"\r\n"
    try:
        writer = threading.Timer(0.2, os.write, (master, line))
        writer.start()
        scale.connect()                                   # waits for the first line
        scale.read()
        os.write(master, b"".join(format_weight_line(100.0 + i, True, False).encode() + b"\r\n" for i in range(5)))
        got, deadline = [], time.monotonic() + 5
        while len(got) < 5 and time.monotonic() < deadline:
            got += scale.read()
            time.sleep(0.05)
    finally:
        scale.close()
        os.close(master)
        os.close(slave)
    t = np.array([r.device_time for r in got])
    assert [r.mass_g for r in got] == [100.0, 101.0, 102.0, 103.0, 104.0]
    assert np.all(np.diff(t) > 0) and np.all(np.diff(t) <= 0.1 + 1e-9), t      # at most the line period apart

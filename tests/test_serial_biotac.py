"""The serial BioTac frame format and reader: the parser on bytes, then the real pyserial
driver against the BioTac bridge emulator on a pty (a separate process)."""

import os
import time

import numpy as np
import pytest

from tactile_flow.hardware.emulators.serial_devices import SerialDevicesEmulator
from tactile_flow.hardware.errors import ConfigError, DeviceDisconnectedError, DeviceFaultError, NotConnectedError
from tactile_flow.hardware.serial_biotac import (HEADER_SIZE, FrameParser, SerialBiotacConfig, SerialBiotacs, crc16,
                                    encode_frame)

FINGERS3 = ("ff", "mf", "th")


def _frame(seq, fingers=FINGERS3, n_pac=22, rng=np.random.default_rng(0)):
    F = len(fingers)
    return encode_frame(seq, seq * 10_000, fingers, rng.integers(0, 4096, (F, 24)), rng.integers(0, 4096, F),
                        rng.integers(0, 4096, F), rng.integers(0, 4096, F), rng.integers(0, 4096, (F, n_pac)))


# ----------------------------------------------------------------------------- frame format
def test_crc_is_ccitt_false_and_a_frame_round_trips():
    assert crc16(b"123456789") == 0x29B1                  # the CRC-16/CCITT-FALSE check value
    e = np.arange(72, dtype=np.int16).reshape(3, 24)
    raw = encode_frame(7, 123_456, FINGERS3, e, [1, 2, 3], [4, 5, 6], [7, 8, 9], np.full((3, 22), 2000))
    assert raw[:2] == b"\xA5\x5A" and len(raw) == HEADER_SIZE + 3 * (27 + 22) * 2 + 2
    (f,) = FrameParser().feed(raw)
    assert (f.seq, f.device_time_us, f.fingers) == (7, 123_456, FINGERS3)
    assert np.array_equal(f.electrodes, e) and list(f.pdc) == [1, 2, 3] and list(f.tac) == [7, 8, 9]
    assert f.pac.shape == (3, 22)


def test_resync_after_garbage_loses_no_valid_frame():
    rng = np.random.default_rng(1)
    frames = [_frame(s) for s in range(1, 201)]
    stream = bytearray()
    for i, raw in enumerate(frames):
        if i % 3 == 0:
            junk = rng.integers(0, 256, int(rng.integers(1, 300)), dtype=np.uint8).tobytes()
            stream += junk + (b"\xA5\x5A\x01" if i % 6 == 0 else b"")     # include false syncs
        stream += raw
    p = FrameParser()
    got = []
    for k in range(0, len(stream), 97):                   # arbitrary read boundaries
        got += p.feed(bytes(stream[k:k + 97]))
    assert [f.seq for f in got] == list(range(1, 201))
    assert p.stats.dropped == 0 and p.stats.garbage_bytes > 0


def test_truncated_and_corrupt_frames_are_counted_and_the_next_frame_kept():
    stream = _frame(1) + _frame(2)[:100] + _frame(3)      # 2 cut short: 3 starts inside its length
    bad = bytearray(_frame(4))
    bad[50] ^= 0xFF                                       # 4 corrupt: CRC fails
    stream += bytes(bad) + _frame(5) + _frame(8)          # 6, 7 never sent: dropped
    p = FrameParser()
    assert [f.seq for f in p.feed(stream)] == [1, 3, 5, 8]
    assert (p.stats.truncated, p.stats.corrupt, p.stats.dropped) == (1, 1, 4)


def test_byte_by_byte_feeding_and_loop_url(tmp_path):
    p = FrameParser()
    out = []
    for b in _frame(1) + _frame(2):
        out += p.feed(bytes([b]))
    assert [f.seq for f in out] == [1, 2]
    import serial
    port = serial.serial_for_url("loop://", timeout=0.1)
    port.write(_frame(9))
    assert [f.seq for f in FrameParser().feed(port.read(4096))] == [9]


# ----------------------------------------------------------------------------- driver vs emulator
@pytest.fixture(scope="module")
def emu():
    with SerialDevicesEmulator(seed=3) as e:
        yield e


@pytest.fixture
def biotacs(emu):
    bt = SerialBiotacs(SerialBiotacConfig(port=emu.ports["biotac"], fingers=("ff", "mf", "th")))
    bt.connect()
    yield bt
    bt.close()


def test_streams_at_100_hz_with_resting_counts(biotacs):
    biotacs.read()
    t0 = time.monotonic()
    time.sleep(1.5)
    frames = biotacs.read()
    rate = len(frames) / (time.monotonic() - t0)
    assert 75 <= rate <= 125, rate                              # host receipt rate, loaded CI
    f = frames[-1]
    assert f.electrodes.shape == (3, 24) and f.pac.shape == (3, 22) and f.is_valid()
    assert 1500 < np.median(f.electrodes) < 3500                   # BioTac SP at rest
    seqs = [fr.seq for fr in frames]
    assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))
    dev = np.array([fr.device_time for fr in frames])
    assert np.all(np.diff(dev) > 0) and abs(np.median(np.diff(dev)) - 0.01) < 0.002
    assert biotacs.latest() is frames[-1] or biotacs.latest().seq >= frames[-1].seq


def test_garbage_truncation_and_corruption_on_the_wire(emu, biotacs):
    biotacs.read()
    before = dict(biotacs.stats)
    emu.command("garbage 700")
    emu.command("truncate 3")
    emu.command("garbage 50")
    emu.command("corrupt 2")
    time.sleep(0.4)
    frames = biotacs.read()
    st = emu.stats()
    first = frames[0].seq
    whole = [s for s in st["whole"] if first <= s <= frames[-1].seq]
    assert [f.seq for f in frames] == whole                     # every valid frame received, in order
    assert set(st["truncated"][-3:]).isdisjoint(f.seq for f in frames)
    after = biotacs.stats
    assert after["truncated"] - before["truncated"] == 3
    assert after["corrupt"] - before["corrupt"] == 2
    assert after["dropped"] - before["dropped"] == 5             # the 5 damaged frames
    assert after["garbage_bytes"] - before["garbage_bytes"] >= 750


def test_configured_finger_missing_from_the_bridge_is_refused():
    with SerialDevicesEmulator(fingers=("ff", "mf")) as e:
        bt = SerialBiotacs(SerialBiotacConfig(port=e.ports["biotac"], fingers=("ff", "th")))
        with pytest.raises(DeviceFaultError, match=r"sends fingers \['ff', 'mf'\], not \['th'\]"):
            bt.connect()
        assert not bt.is_connected
        bt = SerialBiotacs(SerialBiotacConfig(port=e.ports["biotac"], fingers=("ff",)))
        with bt:
            time.sleep(0.1)
            assert bt.read()[-1].electrodes.shape == (1, 24)
        e.command("disconnect biotac")                   # the pty is gone: reconnecting fails at once
        t0 = time.monotonic()
        with pytest.raises(NotConnectedError, match="cannot open serial port"):
            SerialBiotacs(SerialBiotacConfig(port=e.ports["biotac"], fingers=("ff",))).connect()
        assert time.monotonic() - t0 < 3.0


def test_disconnect_is_detected_quickly():
    with SerialDevicesEmulator() as e:
        bt = SerialBiotacs(SerialBiotacConfig(port=e.ports["biotac"]))
        bt.connect()
        e.command("disconnect biotac")
        t0 = time.monotonic()
        with pytest.raises(DeviceDisconnectedError, match="serial link .* lost"):
            while time.monotonic() - t0 < 2.0:
                bt.read()
                time.sleep(0.002)
        assert time.monotonic() - t0 < 1.0                   # its reader thread notices within a read
        assert not bt.is_connected
        bt.close()
        with pytest.raises(NotConnectedError):
            bt.read()


def test_a_port_that_does_not_exist_is_a_clear_error(tmp_path):
    missing = str(tmp_path / "ttyACM9")
    t0 = time.monotonic()
    with pytest.raises(NotConnectedError, match=r"biotac: cannot open serial port .*ttyACM9.*hint: check hardware.biotac.port"):
        SerialBiotacs(SerialBiotacConfig(port=missing)).connect()
    assert time.monotonic() - t0 < 1.0
    with pytest.raises(ConfigError, match=r"hardware.biotac.fingers\[1\]"):
        SerialBiotacConfig(port="loop://", fingers=("ff", "xx"))
    with pytest.raises(ConfigError, match="hardware.biotac.rate_hz"):
        SerialBiotacConfig(port="loop://", rate_hz=0)


def test_a_silent_port_times_out_at_connect():
    r, w = os.openpty()
    try:
        bt = SerialBiotacs(SerialBiotacConfig(port=os.ttyname(w), first_frame_timeout_s=0.3))
        t0 = time.monotonic()
        with pytest.raises(Exception, match="no valid frame .* within 0.3 s"):
            bt.connect()
        assert time.monotonic() - t0 < 1.5 and not bt.is_connected
    finally:
        os.close(r)
        os.close(w)


# ----------------------------------------------------------------------------- sensor models
def test_a_frame_of_19_electrodes_round_trips_with_the_classic_model():
    e = np.arange(57, dtype=np.int16).reshape(3, 19)
    raw = encode_frame(3, 30_000, FINGERS3, e, [1, 2, 3], [4, 5, 6], [7, 8, 9], np.full((3, 22), 2000))
    assert len(raw) == HEADER_SIZE + 3 * (19 + 3 + 22) * 2 + 2
    (f,) = FrameParser(19).feed(raw)
    assert np.array_equal(f.electrodes, e) and list(f.pdc) == [1, 2, 3] and f.pac.shape == (3, 22)
    parser = FrameParser()                                 # a BioTac SP's: the frame does not fit
    assert parser.feed(raw) == [] and parser.other_count == 19


@pytest.mark.parametrize("name, n", [("biotac_sp", 24), ("biotac", 19)])
def test_the_bridge_emulator_and_the_driver_speak_the_models_electrode_count(name, n):
    from tactile_flow.tactile.sensor import builtin_sensor
    sensor = builtin_sensor(name)
    with SerialDevicesEmulator(seed=4, sensor=name) as e:
        with SerialBiotacs(SerialBiotacConfig(port=e.ports["biotac"], fingers=FINGERS3), sensor=sensor) as bt:
            time.sleep(0.2)
            frames = bt.read()
            assert frames and frames[-1].electrodes.shape == (3, n) and frames[-1].is_valid()
            assert 1000 < np.median(frames[-1].electrodes) < 3900
            assert {s.name for s in bt.describe()} == {"biotac", "biotac_pac"}
            assert bt.describe()[0].coords[1].values[-1] == n
        other = builtin_sensor("biotac" if name == "biotac_sp" else "biotac_sp")
        bt = SerialBiotacs(SerialBiotacConfig(port=e.ports["biotac"], fingers=FINGERS3, first_frame_timeout_s=0.5),
                           sensor=other)
        with pytest.raises(DeviceFaultError, match=rf"sends {n} electrodes per sensor; the sensor model "
                                                   rf"{other.name} has {other.n_taxels}"):
            bt.connect()

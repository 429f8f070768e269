"""The whole real lab against its emulators: ``hardware=lab_emulated`` runs the straws
protocol to success through ur_rtde, roslibpy and pyserial, and leaves a run store with the
schema of a simulated run. The test starts every emulator itself (separate processes) and
passes their addresses as overrides."""

from __future__ import annotations

import os
import socket
import time
from contextlib import ExitStack
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from hydra import compose, initialize_config_dir

pytest.importorskip("rtde_control")

from tactile_flow.hardware.emulators.process import free_loopback as emulated_loopback  # noqa: E402
from tactile_flow.hardware.emulators.rosbridge_server import RosbridgeEmulator  # noqa: E402
from tactile_flow.hardware.emulators.serial_devices import SerialDevicesEmulator  # noqa: E402
from tactile_flow.hardware.emulators.ur_controller import URControllerProcess  # noqa: E402
from tactile_flow.hardware.rosbridge import RosbridgeUnreachableError  # noqa: E402
from tactile_flow.protocols.run import run_protocol  # noqa: E402
from tactile_flow.protocols.schema import register  # noqa: E402

register()
CONF_DIR = Path(__file__).resolve().parents[1] / "conf"
HOME = (0.3, 0.0, 0.2, 3.141592653589793, 0.0, 0.0)          # hardware.arm.home_pose of lab.yaml
FAST = ["protocol.sweep_speed=40", "protocol.travel_speed=100", "protocol.approach_speed=10",
        "progress=false", "analyze=false"]


def free_loopback() -> str:
    """A 127.0.x.y whose RTDE port is free, x per xdist worker (parallel runs need their own address)."""
    worker = os.environ.get("PYTEST_XDIST_WORKER", "gw0")
    return emulated_loopback(60 + int(worker[2:] or 0)) or pytest.skip("no free loopback address for the UR emulator")


@pytest.fixture(scope="module")
def emulated_lab():
    """UR controller, rosbridge and serial emulators; yields the Hydra overrides that point
    ``hardware=lab_emulated`` at them."""
    host = free_loopback()
    with URControllerProcess(host, initial_pose=HOME), RosbridgeEmulator() as ros, SerialDevicesEmulator() as ser:
        yield [f"hardware.arm.host={host}", f"hardware.rosbridge.url={ros.url}",
               f"hardware.biotac.port={ser.ports['biotac']}", f"hardware.pump.port={ser.ports['pump']}",
               f"hardware.scale.port={ser.ports['scale']}"]


@pytest.fixture(scope="module")
def sim_schema(tmp_path_factory):
    """The schema of the same protocol run on the simulated lab (ground truth aside), configured
    as the lab: no object stage, no stored calibration."""
    sim = run_protocol(_cfg("hardware=sim", "protocol=straws_sweep", "hardware.stage=null",
                            "hardware.biotac_calibration=null", *FAST), tmp_path_factory.mktemp("sim"),
                       console=lambda *a: None)
    assert sim.status == "success"
    return _schema(sim.store)


def _cfg(*overrides):
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base=None):
        return compose("config", overrides=list(overrides))


def _schema(store: Path, skip=("truth",)) -> dict:
    """Groups → variables → (dims, dtype, attribute names), and each group's attribute names."""
    tree = xr.open_datatree(store, engine="zarr")
    out = {}
    for node in tree.subtree:
        if node.path.strip("/").split("/")[0] in skip:
            continue
        out[node.path] = ({k: (v.dims, str(v.dtype), sorted(v.attrs)) for k, v in node.ds.variables.items()},
                          sorted(node.attrs))
    return out


@pytest.mark.parametrize("biotac_source", ["rosbridge", "serial"])
def test_straws_protocol_runs_to_success_with_the_schema_of_a_sim_run(emulated_lab, sim_schema, biotac_source,
                                                                     tmp_path):
    cfg = _cfg("hardware=lab_emulated", "protocol=straws_sweep", f"hardware.biotac.source={biotac_source}",
               *emulated_lab, *FAST)
    t0 = time.monotonic()
    result = run_protocol(cfg, tmp_path / "lab", console=lambda *a: None)
    elapsed = time.monotonic() - t0
    assert result.status == "success", result.error
    assert elapsed < 3 * result.plan.duration + 10

    assert _schema(result.store) == sim_schema

    tree = xr.open_datatree(result.store, engine="zarr")
    bt = tree["biotac"].ds
    span = float(bt.time[-1] - bt.time[0])
    # rates are measured in the driver tests; here only "streamed throughout", robust to a loaded machine
    assert 70 < bt.sizes["time"] / span < 115                                # BioTac at ~100 Hz
    assert bool(bt.valid.all()) and list(bt.finger.values) == ["ff", "mf", "rf", "lf", "th"]
    assert tree["arm"].ds.sizes["time_arm"] / span > 50                     # RTDE at 125 Hz (CB3)
    assert tree["hand"].ds.sizes["time_hand"] > 0 and tree["pour"].ds.sizes["time_scale"] > 0
    kinds = list(tree["events"].ds.kind.values)
    assert kinds.count("step_start") == kinds.count("step_end") == len(result.plan.steps)
    assert (tmp_path / "lab" / "run.json").exists()


@pytest.mark.parametrize("biotac_source", ["rosbridge", "serial"])
def test_the_live_monitor_keeps_up_with_the_real_drivers(emulated_lab, biotac_source, tmp_path):
    """Live tactile flow through the real BioTac drivers, on the wall clock: every frame the
    recorder stored while the engine ran is processed online, in order, none dropped."""
    cfg = _cfg("hardware=lab_emulated", "protocol=straws_sweep", f"hardware.biotac.source={biotac_source}",
               "live.enabled=true", "live.fingers=[ff,th]", *emulated_lab, *FAST)
    result = run_protocol(cfg, tmp_path / "lab", console=lambda *a: None)
    assert result.status == "success", result.error
    tree = xr.open_datatree(result.store, engine="zarr")
    live, seqs = tree["live"].ds, tree["biotac"].ds.seq.values
    assert tree.attrs["live"]["tap_overflows"] == 0
    first, last = live.seq.values[0], live.seq.values[-1]      # the recorder drains on after the engine ends
    assert np.array_equal(live.seq.values, seqs[(seqs >= first) & (seqs <= last)])
    assert float(live.time_live[-1] - live.time_live[0]) > 4.0
    assert bool(live.processed.all())
    # receipt to verdict on the wall clock: not timed here (a shared machine); only that it
    # does not fall behind for good (the lag at the end is that of one engine period or a few)
    lag = live.processed_time.values - live.time_live.values
    assert float(np.median(lag[-100:])) < 0.5, np.percentile(lag, [50, 99])
    assert not bool(live.slip_fired.any())


def test_unreachable_rosbridge_fails_fast_and_leaves_nothing_half_written(emulated_lab, tmp_path):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        dead = f"ws://127.0.0.1:{s.getsockname()[1]}"
    overrides = [o for o in emulated_lab if not o.startswith("hardware.rosbridge.url=")]
    cfg = _cfg("hardware=lab_emulated", *overrides, f"hardware.rosbridge.url={dead}", *FAST)
    t0 = time.monotonic()
    with pytest.raises(RosbridgeUnreachableError, match=rf"unreachable rosbridge at {dead}: .*hint"):
        run_protocol(cfg, tmp_path / "run", console=lambda *a: None)
    assert time.monotonic() - t0 < 10
    assert not (tmp_path / "run" / "run.zarr").exists() and not (tmp_path / "run" / "run.json").exists()


TIME_AXES = {"biotac": "time", "biotac_pac": "time_pac", "arm": "time_arm", "hand": "time_hand",
             "pour": ("time_pump", "time_scale")}


@pytest.mark.slow
def test_every_time_axis_of_an_emulated_run_is_strictly_increasing(emulated_lab, tmp_path):
    """Issue 13 item 12: PAC times went back at frame boundaries (a frame's 22 samples span
    10 ms; frame stamps jitter, frames came closer) and the scale repeated a time (lines read
    together shared one receipt time)."""
    cfg = _cfg("hardware=lab_emulated", "protocol=pour_grasp", "protocol.steps.3.hold.duration=3",
               *emulated_lab, *FAST)
    result = run_protocol(cfg, tmp_path / "lab", console=lambda *a: None)
    assert result.status == "success", result.error
    tree = xr.open_datatree(result.store, engine="zarr")
    for group, axes in TIME_AXES.items():
        for axis in (axes,) if isinstance(axes, str) else axes:
            t = tree[group][axis].values
            steps = np.diff(t)
            assert len(t) > 10 and np.all(steps > 0), (f"{group}/{axis}: {int(np.sum(steps <= 0))} of {len(t)} "
                                                        f"steps not increasing, worst {steps.min():.4g} s")


@pytest.mark.slow
def test_a_rehearsal_on_tactile_emulate_presses_finds_segments_and_leaves_no_links(tmp_path):
    """``tactile-emulate`` then the command it prints: the emulated BioTacs press on the board
    following the emulated arm, so the rehearsal's analysis finds the crossings; stopped, the
    emulated lab removes its links."""
    import json
    import shlex
    import signal
    import subprocess
    import sys

    links = tmp_path / "links"
    emu = subprocess.Popen([sys.executable, "-c", "import sys; from tactile_flow.hardware.emulators.cli import main; "
                            "sys.exit(main())", "--host", free_loopback(), "--rosbridge-port", "0",
                            "--link-dir", str(links)], stdout=subprocess.PIPE, text=True, cwd=tmp_path)
    try:
        command = None
        for line in emu.stdout:
            if line.startswith("In another terminal:"):
                command = line.split(":", 1)[1].strip()
                break
        assert command is not None and (links / "biotac").is_symlink()
        words = shlex.split(command)
        env = {**os.environ, **dict(w.split("=", 1) for w in words if w.startswith("TACTILE_EMULATE_DIR="))}
        args = [w for w in words if not w.startswith("TACTILE_EMULATE_DIR=")][1:]
        run = subprocess.run([sys.executable, "-c", "from tactile_flow.protocols.cli import main; main()", *args,
                              "progress=false", "analysis.progress=false", "analysis.figures=false",
                              "analysis.views=[bottom]"],
                             cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
        assert run.returncode == 0, run.stderr
        (summary,) = (tmp_path / "outputs").glob("*/*/summary.json")
        labels = [s["label"] for s in json.loads(summary.read_text())["segments"]]
        assert labels.count("during") == 3, labels                # every straw crossed, as in simulation
    finally:
        emu.send_signal(signal.SIGTERM)
        assert emu.wait(timeout=60) == 0
    assert not links.exists()                                      # links and pose file removed


@pytest.fixture(scope="module")
def emulated_worlds(tmp_path_factory):
    """The emulated lab with its simulated world (``hardware/emulators/touch.py``): the bottle
    between ff, mf and th, filled by the emulated pump. ``get(gain)`` starts (once per gain)
    the emulators with the BioTacs' shear gain ``gain`` kΩ/N (``None``: the simulator's
    default) and returns the overrides and the rosbridge and serial emulators (for their
    ``stats``)."""
    from tactile_flow.hardware.emulators.touch import POSE_FILE
    worlds, stack = {}, ExitStack()

    def get(gain=None):
        if gain not in worlds:
            world = tmp_path_factory.mktemp("world")
            host = free_loopback()
            stack.enter_context(URControllerProcess(host, initial_pose=HOME, pose_file=str(world / POSE_FILE)))
            ros = stack.enter_context(RosbridgeEmulator(world_dir=str(world), surface="flat", shear_kohm_per_n=gain))
            ser = stack.enter_context(SerialDevicesEmulator(world_dir=str(world), surface="flat",
                                                            pump_max_rate_ml_min=600.0, shear_kohm_per_n=gain))
            worlds[gain] = ([f"hardware.arm.host={host}", f"hardware.rosbridge.url={ros.url}",
                             f"hardware.biotac.port={ser.ports['biotac']}", f"hardware.pump.port={ser.ports['pump']}",
                             f"hardware.scale.port={ser.ports['scale']}"], ros, ser)
        return worlds[gain]

    with stack:
        yield get


@pytest.fixture(scope="module")
def emulated_world(emulated_worlds):
    """The emulated world at the realistic shear gain, 3 kΩ/N (one of the reactive pour's)."""
    return emulated_worlds(3.0)


def _released_bottle(emulator, before: int) -> dict:
    """The bottle the run poured into, once the emulator's world has taken it away (it does so
    at its first frame after the hand opened)."""
    end = time.monotonic() + 3.0
    while True:
        bottles = emulator.stats()["world"]["bottles"]
        if len(bottles) > before:
            return bottles[-1]
        assert time.monotonic() < end, "the world never saw the hand let the bottle go"
        time.sleep(0.05)


@pytest.mark.slow
@pytest.mark.parametrize("gain", [
    pytest.param(3.0, marks=pytest.mark.xfail(
        strict=False, reason="issue 33, known: at gain 3 the thumb's first give is 15-17 % over 4 frames, about 7 "
                             "times its own 4-frame noise, so it reaches 0.7-1.1 of the release threshold (the noise "
                             "term decides, not release_drop); held in 9 of 24 runs (docs/live.md)")),
    12.0])
@pytest.mark.parametrize("biotac_source", ["rosbridge", "serial"])
def test_the_emulated_reactive_pour_catches_the_slip_and_holds_the_bottle(emulated_worlds, biotac_source, gain,
                                                                          tmp_path):
    """Issue 36, part 4: the reflex through rosbridge and the serial links. The emulated pump
    fills the bottle of the emulators' world; the world's grasp slips as in the simulated lab;
    the run's live monitor sees it in the recorded BioTac driver's frames and the tighten
    trajectory reaches the hand emulator, whose world then grips harder: the bottle is held.
    Issue 33: at the realistic shear gain (3 kΩ/N, the real BioTac SP's bound:
    docs/simulator.md) as at the simulator's 12 — at 3 the thumb's light contact gives only
    ~15 % over 3 frames, caught against its own fall's noise (tactile/slip.py)."""
    overrides, ros, ser = emulated_worlds(gain)
    emulator = ros if biotac_source == "rosbridge" else ser
    before = len(emulator.stats()["world"]["bottles"])
    cfg = _cfg("hardware=lab_emulated", "protocol=pour_grasp_reactive", "protocol.pour_rate=600",
               "protocol.steps.3.hold.duration=2", f"hardware.biotac.source={biotac_source}", *overrides, *FAST)
    result = run_protocol(cfg, tmp_path / "lab", console=lambda *a: None)
    assert result.status == "success", result.error
    bottle = _released_bottle(emulator, before)
    commands = ros.stats()["hand_command_times"]

    onset = bottle["slip_onset"]
    assert onset is not None and bottle["held"] and bottle["full_slip"] is None, bottle
    assert 40 < bottle["water_ml"] < 60, bottle              # caught at its first give (~45 ml), the pump stopped
    tree = xr.open_datatree(result.store, engine="zarr")
    ev = tree["events"].ds
    kinds, names = list(ev.kind.values), list(ev.name.values)
    assert kinds.count("slip") == 1 and ("reaction", "tighten") in zip(kinds, names)
    # the tighten trajectory reached the hand emulator after the world's onset, not before:
    # the reflex answered this slip, not noise (its latency is bench_reflex.py's to measure)
    reacted = [t for t in commands if t >= onset]
    assert reacted and reacted[0] - onset < 0.5, (onset, commands)
    assert all(t < onset - 1.0 or t >= onset for t in commands)       # nothing commanded just before it
    detection = tree.attrs["live"]["detection"]
    assert detection["seq"] in tree["live"].ds.seq.values


@pytest.mark.slow
def test_without_the_reflex_the_emulated_bottle_slips_out(emulated_world, tmp_path):
    """The contrast: plain ``pour_grasp`` on the same emulated world: nothing tightens the grip
    and the bottle leaves the hand, as in the simulated lab."""
    overrides, ros, _ = emulated_world
    before = len(ros.stats()["world"]["bottles"])
    cfg = _cfg("hardware=lab_emulated", "protocol=pour_grasp", "protocol.pour_rate=600",
               "protocol.steps.3.hold.duration=40", *overrides, *FAST)
    result = run_protocol(cfg, tmp_path / "lab", console=lambda *a: None)
    assert result.status == "success", result.error
    bottle = _released_bottle(ros, before)
    assert not bottle["held"] and bottle["full_slip"] is not None, bottle
    assert bottle["slip_onset"] < bottle["downward"] < bottle["full_slip"]

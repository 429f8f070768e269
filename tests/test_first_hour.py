"""A new user's first hour (issue 34, items 12 and 13): the README's own examples work, a
Ctrl-C while a command starts is one line, two commands do not want the same port, and what a
command writes to a log file is text, not terminal control."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

BIN = Path(sys.executable).parent


def start(command: str, *args, cwd) -> subprocess.Popen:
    return subprocess.Popen([str(BIN / command), *args], cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env={**os.environ, "MPLBACKEND": "Agg"})


def numpy_loaded(proc) -> bool:
    """Whether ``proc`` is past Python's start and loading its libraries (numpy's extension mapped)."""
    try:
        return "_multiarray_umath" in Path(f"/proc/{proc.pid}/maps").read_text()
    except OSError:
        return True


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/maps").exists(), reason="reads /proc (Linux)")
@pytest.mark.parametrize("when", ["numpy loading", "0.5 s"])
@pytest.mark.parametrize("command", ["tactile-demo", "tactile-view"])
def test_a_ctrl_c_as_a_command_starts_is_one_line_and_exit_3(tmp_path, command, when):
    """Issue 34, item 13: a KeyboardInterrupt traceback before (``tactile-demo`` always,
    ``tactile-view`` while it imported Rerun)."""
    args = ["--figure", str(tmp_path / "demo.png")] if command == "tactile-demo" else \
        [str(tmp_path), "--save", str(tmp_path / "x.rrd")]
    proc = start(command, *args, cwd=tmp_path)
    if when == "0.5 s":
        time.sleep(0.5)
    else:
        end = time.monotonic() + 30
        while not numpy_loaded(proc) and proc.poll() is None and time.monotonic() < end:
            time.sleep(0.001)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 3, (proc.returncode, err)
    assert [line for line in err.splitlines() if line.strip()] in (["interrupted"], [f"{command}: interrupted"]), err
    assert not list(tmp_path.glob("*.png")) and not list(tmp_path.glob("*.rrd*")) and not list(tmp_path.glob(".*"))


@pytest.mark.slow
def test_a_ctrl_c_while_the_demo_computes_leaves_no_figure(tmp_path):
    proc = start("tactile-demo", "--figure", str(tmp_path / "demo.png"), cwd=tmp_path)
    assert proc.stdout.readline().startswith("building the sensor model")       # past its imports
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode in (0, 3), err
    assert "Traceback" not in err
    if proc.returncode == 3:
        assert err.strip() == "interrupted" and not list(tmp_path.iterdir())


def test_the_web_viewer_and_the_emulator_do_not_want_the_same_port():
    from tactile_flow.hardware.emulators.cli import build_parser
    from tactile_flow.viewer.cli import parse_args
    viewer = parse_args(["run", "--web"]).port
    rosbridge = build_parser().parse_args([]).rosbridge_port
    assert viewer != rosbridge == 9090


# ----------------------------------------------------------------------------- item 12
@pytest.mark.slow
def test_the_readmes_same_sweep_on_another_board_succeeds(tmp_path):
    """``tactile-run protocol=straws_sweep surface=sticks`` ended ``aborted (interlock
    electrode_saturation ...)``: the straws' 1.5 mm depth flattens the pad on a stick's flat top.
    The shipped sweeps take the depth from the board (``surface.sweep_depth_mm``)."""
    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    assert "tactile-run protocol=straws_sweep surface=sticks" in readme
    proc = subprocess.run([str(BIN / "tactile-run"), "protocol=straws_sweep", "surface=sticks", "progress=false"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    analysis, last = proc.stdout.strip().splitlines()[-2:]
    assert last.endswith(": success") and "targets met" in analysis, proc.stdout[-1000:]
    assert "\r" not in proc.stdout + proc.stderr          # item 13: no progress-bar clutter off a terminal


def test_an_emulated_lab_on_another_board_is_said_before_the_run(tmp_path):
    from hydra import compose, initialize_config_dir

    from tactile_flow.hardware.emulators.cli import remove_links, write_board
    from tactile_flow.protocols.backends import board_warning
    from tactile_flow.protocols.cli import CONF_DIR
    from tactile_flow.protocols.schema import register
    from tactile_flow.protocols.settings import run_settings
    register()

    def settings(*overrides):
        with initialize_config_dir(config_dir=str(CONF_DIR), version_base=None):
            return run_settings(compose("config", overrides=["hardware=lab_emulated", f"hardware.emulator={tmp_path}",
                                                             *overrides]))
    assert board_warning(settings()) is None                                  # no emulator running there
    write_board(tmp_path, "straws")
    assert board_warning(settings()) is None                                  # straws_sweep on straws
    said = board_warning(settings("surface=sticks"))
    assert said.startswith("warning: the emulated lab") and "'straws'" in said and "'sticks'" in said
    assert "tactile-emulate --surface sticks" in said
    assert "other values" in board_warning(settings("surface.spacing_mm=30"))
    remove_links(tmp_path)
    assert not tmp_path.exists()


@pytest.mark.slow
def test_the_warning_comes_before_anything_connects(tmp_path):
    from tactile_flow.hardware.emulators.cli import write_board
    write_board(tmp_path / "lab", "straws")
    proc = subprocess.run([str(BIN / "tactile-run"), "hardware=lab_emulated", f"hardware.emulator={tmp_path / 'lab'}",
                           "hardware.arm.host=127.0.0.254", "protocol=sticks_sweep", "progress=false"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=120)
    lines = proc.stdout.splitlines()
    assert lines and lines[0].startswith("warning: the emulated lab") and "--surface sticks" in lines[0], proc.stdout
    assert proc.returncode == 1                                               # nothing to connect to, after it


# ----------------------------------------------------------------------------- item 13: skipped
@pytest.mark.slow
def test_a_reactive_pour_does_not_count_phases_it_never_reached_as_skipped(tmp_path):
    import json
    proc = subprocess.run([str(BIN / "tactile-run"), "protocol=pour_grasp_reactive", "progress=false",
                           "hydra.run.dir=run", "analysis.figures=false"], cwd=tmp_path, capture_output=True,
                          text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr[-2000:]
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert not [s for s in summary["skipped"] if s["what"].startswith("phase ")]     # 9 of the 12 before
    held = summary["estimates"]["pour"]["not_reached"]
    assert set(held) == {"ff", "mf", "th"} and all(set(v) == {"rotation", "downward", "full_slip"}
                                                   for v in held.values())
    assert f"{summary['headline']['skipped']} skipped" in proc.stdout

"""Faults a lab run meets, injected for real: SIGTERM, an exception inside a step, a full disk.
Each asserts the exit status, the recorded reason and that the data up to the fault are intact."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from hydra import compose, initialize_config_dir

from conftest import tmpfs, wait_for_store

from tactile_flow.hardware.sim import make_sim_lab
from tactile_flow.protocols.engine import FAILED, RunEngine
from tactile_flow.protocols.plan import make_plan
from tactile_flow.protocols.recorder import Recorder
from tactile_flow.protocols.schema import register
from tactile_flow.protocols.steps import Wait
from tactile_flow.protocols.store import RunStore

register()
CONF_DIR = Path(__file__).resolve().parents[1] / "conf"
CLI = [sys.executable, "-c", "from tactile_flow.protocols.cli import main; main()", "analyze=false", "progress=false"]


def test_sigterm_stops_safely_like_ctrl_c(tmp_path):
    proc = subprocess.Popen([*CLI, "hardware.realtime=true"], cwd=tmp_path, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    wait_for_store(tmp_path)
    time.sleep(7.0)
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 3, err
    (store,) = list(tmp_path.rglob("run.zarr"))
    tree = xr.open_datatree(store, engine="zarr")
    assert tree.attrs["status"] == "aborted"
    assert {"abort", "retract"} <= set(tree["events"]["kind"].values)
    assert np.all(np.diff(tree["biotac"]["seq"].values) == 1)


def test_an_exception_inside_a_step_fails_the_run_with_the_error_recorded(tmp_path, monkeypatch):
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base=None):
        cfg = compose("config", overrides=["protocol=pour_grasp"])
    plan = make_plan(cfg)
    lab = make_sim_lab(cfg.hardware, cfg.surface)

    def broken(self, ctx):
        raise RuntimeError("gripper firmware said no")
    monkeypatch.setattr(Wait, "run", broken)
    with lab:
        store = RunStore.create(tmp_path / "run.zarr", protocol=plan.protocol, fingers=lab.biotac.fingers)
        rec = Recorder(store, {"biotac": lab.biotac.read, "pump": lab.pump.read_states}, lab.clock).start()
        outcome = RunEngine(lab, rec, cfg, plan, log=lambda *a: None).run()
        delivered = lab.biotac.seq
        pump_running = lab.pump.status().running
        rec.stop(outcome.status, attrs={"error": outcome.error})
    assert outcome.status == FAILED and "gripper firmware said no" in outcome.error
    assert not pump_running
    tree = xr.open_datatree(tmp_path / "run.zarr", engine="zarr")
    assert tree.attrs["status"] == "failed" and "gripper firmware" in tree.attrs["error"]
    errors = [json.loads(d) for k, d in zip(tree["events"]["kind"].values, tree["events"]["detail"].values)
              if k == "error"]
    assert errors and "gripper firmware" in errors[0]["error"]
    assert tree["biotac"].sizes["time"] == delivered            # every frame delivered is stored


@pytest.fixture
def small_disk(tmp_path):
    with tmpfs(tmp_path / "disk", "3m") as mount:
        yield mount


@pytest.mark.slow
def test_a_full_disk_stops_the_run_and_keeps_what_was_committed(tmp_path, small_disk):
    """Issue 34, item 11: the store stayed ``running`` without a ``run.json`` until
    ``tactile-recover`` was run on a disk with room; the room to close is now held from the start."""
    proc = subprocess.run([*CLI, "protocol=pour_grasp", f"hydra.run.dir={small_disk}/run"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 1 and "Traceback" not in proc.stderr
    (line,) = [x for x in proc.stdout.splitlines() if x.startswith("run ")]
    assert ": failed (recording failed" in line and "No space left on device" in line
    assert "interlock recording_failed" in line and "tactile-recover" not in line       # nothing left to recover
    store = small_disk / "run" / "run.zarr"
    tree = xr.open_datatree(store, engine="zarr")             # what was committed opens
    seq = tree["biotac"]["seq"].values
    assert len(seq) > 100 and np.all(np.diff(seq) == 1) and seq[0] == 1
    assert tree.attrs["status"] == "failed" and "No space left on device" in tree.attrs["recorder_error"]
    assert json.loads((store.parent / "run.json").read_text())["status"] == "failed"
    assert not list((small_disk / "run").glob(".*room"))       # the room was given back, for the close
    os.statvfs(small_disk)                                     # the mount is still usable for cleanup


@pytest.mark.slow
def test_recovering_a_killed_run_on_a_full_disk_uses_the_room_it_kept(tmp_path, small_disk):
    """A run killed (SIGKILL) leaves its store ``running`` and its room held; with the rest of
    the disk filled, ``tactile-recover`` frees that room and closes the store ``crashed``."""
    proc = subprocess.Popen([*CLI, "hardware.realtime=true", f"hydra.run.dir={small_disk}/run"], cwd=tmp_path,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    store = small_disk / "run" / "run.zarr"
    wait_for_store(small_disk)
    time.sleep(2.0)
    proc.kill()
    proc.wait(30)
    assert list((small_disk / "run").glob(".*room"))
    committed = len(xr.open_datatree(store, engine="zarr")["biotac"]["seq"])
    try:                                                       # the rest of the disk (under load the run
        with open(small_disk / "filler", "wb") as f:           # may have filled it before it was killed:
            while True:                                        # then not even the file can be made)
                f.write(b"x" * 65536)
    except OSError:
        pass
    disk = os.statvfs(small_disk)
    assert disk.f_bavail * disk.f_frsize < 65536                # full, but for the room the run held
    from tactile_flow.runstore.recover import main as recover_main
    assert recover_main([str(store)]) == 0
    tree = xr.open_datatree(store, engine="zarr")
    assert tree.attrs["status"] == "crashed" and len(tree["biotac"]["seq"]) == committed
    assert json.loads((store.parent / "run.json").read_text())["status"] == "crashed"
    assert not list((small_disk / "run").glob(".*room"))


@pytest.fixture
def tiny_disk(tmp_path):
    with tmpfs(tmp_path / "tiny", "1m") as mount:
        yield mount


@pytest.mark.slow
def test_a_run_that_could_not_record_is_never_a_success(tmp_path, tiny_disk):
    """Issue 13 item 6: a disk full from the start (1 MB) closed the store ``success`` with 0
    frames. Since issue 34 item 11 a run first takes the room to close it: on a disk without it
    the run is refused before anything is recorded, in one line."""
    proc = subprocess.run([*CLI, f"hydra.run.dir={tiny_disk}/run"], cwd=tmp_path, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 1 and "Traceback" not in proc.stderr, proc.stderr
    (line,) = [x for x in proc.stderr.splitlines() if x.strip()]
    assert line.startswith("run failed: no room on the disk of") and "to close the run" in line, line
    assert "success" not in proc.stdout
    assert not list(tiny_disk.rglob("run.zarr")) and not list(tiny_disk.rglob("*room"))


def test_a_store_whose_electrodes_are_all_saturated_says_so(tmp_path):
    """Issue 34, item 11: every electrode at 4095 gave "0 valid tactile frame(s)", not why."""
    from tactile_flow.analysis.load import AnalysisInputError
    from tactile_flow.analysis.run import analyze_run
    from tactile_flow.importers.importer import ImportSettings, import_source
    source = tmp_path / "saturated.csv"
    source.write_text(",".join(f"e{k}" for k in range(1, 25)) + "\n" + ("4095," * 23 + "4095\n") * 300)
    (result,) = import_source(source, tmp_path / "imported", ImportSettings(rate_hz=100.0, fingers=["ff"]))
    with pytest.raises(AnalysisInputError) as err:
        analyze_run(result.store, {"progress": False, "figures": False}, console=lambda *a: None)
    message = str(err.value)
    assert "0 valid tactile frame(s)" in message and "300 frame(s) dropped" in message
    assert "4095: saturated" in message and len(message.splitlines()) == 1

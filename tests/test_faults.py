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
    proc = subprocess.run([*CLI, "protocol=pour_grasp", f"hydra.run.dir={small_disk}/run"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 1 and "Traceback" not in proc.stderr
    (line,) = [x for x in proc.stdout.splitlines() if x.startswith("run ")]
    assert ": failed (recording failed" in line and "No space left on device" in line
    assert "interlock recording_failed" in line and "tactile-recover" in line
    store = small_disk / "run" / "run.zarr"
    tree = xr.open_datatree(store, engine="zarr")             # what was committed opens
    seq = tree["biotac"]["seq"].values
    assert len(seq) > 100 and np.all(np.diff(seq) == 1) and seq[0] == 1
    assert tree.attrs["status"] == "running"                  # it could not even be closed: recovery's job

    # tactile-recover on the still-full disk: one line, exit 1, nothing lost; with room, it closes the run
    from tactile_flow.runstore.recover import main as recover_main
    rec = subprocess.run([sys.executable, "-c", "from tactile_flow.runstore.recover import main; import sys; sys.exit(main())",
                          str(store)], capture_output=True, text=True, timeout=120)
    assert rec.returncode == 1 and "Traceback" not in rec.stderr and len(rec.stderr.strip().splitlines()) == 1
    assert "could not be written" in rec.stderr and "nothing was lost" in rec.stderr
    subprocess.run(["mount", "-o", "remount,size=8m", str(small_disk)], check=True)     # the disk has room
    assert recover_main([str(store)]) == 0
    tree = xr.open_datatree(store, engine="zarr")
    assert tree.attrs["status"] == "crashed" and len(tree["biotac"]["seq"]) == len(seq)
    assert json.loads((store.parent / "run.json").read_text())["status"] == "crashed"
    os.statvfs(small_disk)                                     # the mount is still usable for cleanup


@pytest.fixture
def tiny_disk(tmp_path):
    with tmpfs(tmp_path / "tiny", "1m") as mount:
        yield mount


@pytest.mark.slow
def test_a_run_that_could_not_record_is_never_a_success(tmp_path, tiny_disk):
    """Issue 13 item 6: a disk full from the start (1 MB) closed the store ``success`` with 0 frames."""
    proc = subprocess.run([*CLI, f"hydra.run.dir={tiny_disk}/run"], cwd=tmp_path, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert "success" not in proc.stdout and ": failed (recording failed" in proc.stdout, proc.stdout
    tree = xr.open_datatree(tiny_disk / "run" / "run.zarr", engine="zarr")
    run_json = tiny_disk / "run" / "run.json"
    if tree.attrs["status"] == "running":               # the disk did not even take the close: recovery's job
        assert "tactile-recover" in proc.stdout
    else:
        assert tree.attrs["status"] == "failed" and "No space left on device" in tree.attrs["recorder_error"]
    assert not run_json.exists() or json.loads(run_json.read_text())["status"] == "failed"

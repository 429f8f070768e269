"""tactile-run end to end: a real Hydra run in a subprocess, multirun, bad input, SIGKILL."""

import json
import signal
import subprocess
import sys
import time
from datetime import datetime
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from conftest import wait_for_store

FAST = ["analyze=false", "progress=false"]


def tactile_run(tmp_path, *args, timeout=240):
    return subprocess.run([sys.executable, "-c", "from tactile_flow.protocols.cli import main; main()", *args],
                          cwd=tmp_path, capture_output=True, text=True, timeout=timeout)


def run_dirs(root: Path):
    return sorted(p.parent for p in root.rglob("run.json"))


def test_default_run_leaves_a_complete_store(tmp_path):
    proc = tactile_run(tmp_path, *FAST)
    assert proc.returncode == 0, proc.stderr
    (run,) = run_dirs(tmp_path / "outputs")
    assert f"run {run}: success" in proc.stdout
    tree = xr.open_datatree(run / "run.zarr", engine="zarr")
    assert {"biotac", "biotac_pac", "arm", "hand", "pour", "events", "truth"} <= set(tree.children)
    assert tree.attrs["status"] == "success" and tree.attrs["protocol"] == "straws_sweep"
    for group in ("biotac", "arm", "hand"):
        for name, var in tree[group].data_vars.items():
            assert var.attrs.get("units") is not None and var.attrs.get("long_name"), (group, name)
    info = json.loads((run / "run.json").read_text())
    for key in ("run_id", "config", "overrides", "git", "python", "packages", "host", "hardware", "calibration", "seed",
                "start_time", "end_time", "status"):
        assert key in info, key
    assert info["run_id"] == tree.attrs["run_id"]
    assert (run / ".hydra" / "config.yaml").exists()


def test_plan_only_prints_the_timeline_and_touches_nothing(tmp_path):
    proc = tactile_run(tmp_path, "plan_only=true", "protocol=pour_grasp")
    assert proc.returncode == 0, proc.stderr
    assert "protocol pour_grasp" in proc.stdout and "hold" in proc.stdout
    assert not list(tmp_path.rglob("run.zarr"))


def test_plan_only_does_not_build_the_lab(monkeypatch):
    from hydra import compose, initialize_config_dir

    import tactile_flow.protocols.run as run
    from tactile_flow.protocols.schema import register
    register()
    monkeypatch.setattr(run, "make_lab", lambda cfg: pytest.fail("plan_only built the lab"))
    conf = Path(run.__file__).resolve().parents[1] / "conf"
    with initialize_config_dir(config_dir=str(conf), version_base=None):
        cfg = compose("config", overrides=["plan_only=true"])
    assert run.run_protocol(cfg, "/nonexistent", console=lambda *a: None).status == "planned"


@pytest.mark.parametrize("override, key", [
    ("protocol.steps.0.move_to.at=before:feature_7", "protocol.steps[0].move_to.at"),
    ("protocol.steps.5.lift.height=900", "hardware.workspace.max_m[2]"),
    ("hardware.fingers=[ff,xx]", "hardware.fingers"),
])
def test_bad_input_is_one_line_naming_the_key_and_nothing_moves(tmp_path, override, key):
    proc = tactile_run(tmp_path, override, *FAST)
    assert proc.returncode == 2, proc.stderr
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and key in lines[0], proc.stderr
    assert "Traceback" not in proc.stderr
    assert not list(tmp_path.rglob("run.zarr"))


def test_unknown_keys_and_protocols_are_refused(tmp_path):
    for override in ("protocol.sweep_sped=3", "protocol=swirl"):
        proc = tactile_run(tmp_path, override, *FAST)
        assert proc.returncode == 2 and ("sweep_sped" in proc.stderr or "swirl" in proc.stderr), proc.stderr
        assert "Traceback" not in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
    assert not list(tmp_path.rglob("run.zarr"))


def test_multirun_two_by_two_gives_four_runs_and_a_summary(tmp_path):
    proc = tactile_run(tmp_path, "-m", "protocol=straws_sweep,sticks_sweep", "protocol.sweep_speed=10,20",
                       f"hydra.sweep.dir={tmp_path}/sweep", *FAST)
    assert proc.returncode == 0, proc.stderr
    runs = run_dirs(tmp_path / "sweep")
    assert len(runs) == 4
    assert all(json.loads((r / "run.json").read_text())["status"] == "success" for r in runs)
    table = (tmp_path / "sweep" / "summary.csv").read_text().splitlines()
    assert len(table) == 5 and table[0].startswith("job,protocol,protocol.sweep_speed,status")   # a column each
    assert {row.split(",")[2] for row in table[1:]} == {"10", "20"}


def test_sigkill_leaves_a_store_with_all_but_the_last_second(tmp_path):
    proc = subprocess.Popen([sys.executable, "-c", "from tactile_flow.protocols.cli import main; main()",
                             "hardware.realtime=true", *FAST], cwd=tmp_path,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wait_for_store(tmp_path)
    time.sleep(6.0)                               # mid-protocol: the sweep runs from ~5 s to ~13 s
    killed_at = datetime.now().astimezone()
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=10)
    (store,) = list(tmp_path.rglob("run.zarr"))
    tree = xr.open_datatree(store, engine="zarr")
    assert tree.attrs["status"] == "running"       # nobody closed it: recovery marks it later
    started = datetime.fromisoformat(tree.attrs["recording_start_time"].replace("Z", "+00:00"))
    elapsed = (killed_at - started).total_seconds()
    last = float(tree["biotac"]["time"].values[-1])
    assert last >= elapsed - 1.0 - 0.3, f"store ends at {last:.2f} s, kill at {elapsed:.2f} s"
    assert np.all(np.diff(tree["biotac"]["seq"].values) == 1)
    assert tree["arm"].sizes["time_arm"] > 0 and len(tree["events"]["kind"]) >= 3

    # tactile-recover closes it as crashed; it then opens like any other run.
    from tactile_flow.runstore.recover import main as recover_main
    assert recover_main([str(store)]) == 0
    tree = xr.open_datatree(store, engine="zarr")
    assert tree.attrs["status"] == "crashed" and tree.attrs["last_sample_s"] == pytest.approx(last, abs=0.05)
    assert tree["biotac"].sizes["time"] == len(tree["biotac"]["seq"])
    assert json.loads((store.parent / "run.json").read_text())["status"] == "crashed"
    assert recover_main([str(store)]) == 0                  # idempotent
    assert recover_main([str(tmp_path)]) == 2               # not a run store


def _start_realtime_run(tmp_path):
    proc = subprocess.Popen([sys.executable, "-c", "from tactile_flow.protocols.cli import main; main()",
                             "hardware.realtime=true", *FAST], cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    wait_for_store(tmp_path)
    time.sleep(7.0)                               # in the sweep
    return proc


@pytest.mark.parametrize("presses, retract", [(1, True), (2, False)])
def test_ctrl_c_stops_safely_once_and_at_once_twice(tmp_path, presses, retract):
    proc = _start_realtime_run(tmp_path)
    for _ in range(presses):
        proc.send_signal(signal.SIGINT)
        time.sleep(0.05)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 3, err
    assert ": aborted" in out
    (store,) = list(tmp_path.rglob("run.zarr"))
    tree = xr.open_datatree(store, engine="zarr")
    assert tree.attrs["status"] == "aborted"
    kinds = list(tree["events"]["kind"].values)
    assert "abort" in kinds and ("retract" in kinds) == retract
    assert json.loads((store.parent / "run.json").read_text())["status"] == "aborted"


def test_resumed_sweep_skips_successes_reruns_the_rest_and_refuses_a_changed_config(tmp_path):
    sweep = ["-m", "protocol.sweep_speed=10,20", f"hydra.sweep.dir={tmp_path}/sweep", *FAST]
    assert tactile_run(tmp_path, *sweep).returncode == 0
    first, second = run_dirs(tmp_path / "sweep")
    ids = {d: json.loads((d / "run.json").read_text())["run_id"] for d in (first, second)}
    info = json.loads((second / "run.json").read_text())
    (second / "run.json").write_text(json.dumps({**info, "status": "failed"}))   # as if it had failed

    proc = tactile_run(tmp_path, *sweep, "resume=true")
    assert proc.returncode == 0, proc.stderr
    assert "skipped" in proc.stdout and proc.stdout.count(": success") == 1
    assert json.loads((first / "run.json").read_text())["run_id"] == ids[first]        # kept
    assert json.loads((second / "run.json").read_text())["run_id"] != ids[second]      # re-run
    assert (second / "previous" / "0" / "run.zarr").exists()
    assert len((tmp_path / "sweep" / "summary.csv").read_text().splitlines()) == 3

    proc = tactile_run(tmp_path, *sweep, "resume=true", "protocol.sweep_depth=1.0")
    assert proc.returncode == 2 and "another config" in proc.stderr and "sweep_depth" in proc.stderr


def test_runs_started_in_the_same_second_get_distinct_directories(tmp_path):
    cmd = [sys.executable, "-c", "from tactile_flow.protocols.cli import main; main()", "analyze=false", "progress=false",
           "protocol.steps=[{wait: {duration: 0.05}}]"]             # a run: a plan alone leaves no directory
    procs = [subprocess.Popen(cmd, cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
             for _ in range(3)]
    assert all(p.wait(timeout=120) == 0 for p in procs)
    dirs = [p for p in (tmp_path / "outputs").glob("*/*") if p.is_dir()]
    assert len(dirs) == 3 and len({d.name for d in dirs}) == 3

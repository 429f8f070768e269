"""tactile-recover: a store left by a killed run is trimmed to its last commit and closed
as crashed, and then opens with consistent lengths even without consolidated metadata."""

import json
import signal
import subprocess
import sys

import numpy as np
import pytest
import xarray as xr
import zarr

from tactile_flow.runstore.recover import main, recover
from tactile_flow.protocols.store import RunStore

from test_store import F, arm_rows, biotac_rows


def test_recover_trims_uncommitted_rows_and_marks_crashed(tmp_path):
    store = RunStore.create(tmp_path / "run.zarr", protocol="unit_test", provenance={"seed": 3})
    store.append("biotac", biotac_rows(40))
    store.append("arm", arm_rows(10))
    store.commit()
    store.append("biotac", biotac_rows(25, start=40))       # the kill comes before the commit
    raw = zarr.open_group(str(store.path), mode="r+", use_consolidated=False)
    raw["biotac/electrodes"].resize((90, F, 24))

    result = recover(store.path)
    assert result["action"] == "recovered" and result["trimmed"]["biotac/seq"] == 25
    assert result["trimmed"]["biotac/electrodes"] == 50
    # Every array's own metadata now agrees with the commit: it opens even unconsolidated.
    for consolidated in (True, False):
        tree = xr.open_datatree(store.path, engine="zarr", consolidated=consolidated)
        assert tree["biotac"].sizes["time"] == 40 and tree["biotac/electrodes"].shape[0] == 40
        assert tree.attrs["status"] == "crashed"
    assert tree.attrs["last_sample_s"] == np.float64(0.39)
    info = json.loads((tmp_path / "run.json").read_text())
    assert info["status"] == "crashed" and info["run_id"] == tree.attrs["run_id"]


def test_closed_runs_are_left_alone(tmp_path):
    store = RunStore.create(tmp_path / "run.zarr", protocol="unit_test")
    store.close("success")
    assert recover(store.path)["action"].startswith("none")
    assert xr.open_datatree(store.path, engine="zarr").attrs["status"] == "success"


def test_not_a_run_store_is_a_clear_error(tmp_path, capsys):
    assert main([str(tmp_path)]) == 2
    assert "not a run store" in capsys.readouterr().err


INTERRUPTED_AT = """
import os, signal, sys
import zarr
from tactile_flow.runstore import recover

step, sig = sys.argv[2], int(sys.argv[3])
target = {"trim": zarr.Array, "close": zarr.Group, "run_json": recover}[step]
name = {"trim": "resize", "close": "update_attributes", "run_json": "write_run_json"}[step]
original = getattr(target, name)

def interrupted(*args, **kwargs):          # the signal lands as this step begins
    os.kill(os.getpid(), sig)
    return original(*args, **kwargs)

setattr(target, name, interrupted)
sys.argv = ["tactile-recover", sys.argv[1]]
recover.command()
"""


@pytest.mark.parametrize("step", ["trim", "close", "run_json"])
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_recovery_interrupted_at_any_step_says_so_and_the_next_one_finishes_it(tmp_path, step, sig):
    """Found by probing ``tactile-recover`` with Ctrl-C: a ``KeyboardInterrupt`` traceback,
    exit -2. Now one line naming the store and exit 3; every step can be done again, so a
    second ``tactile-recover`` leaves the store closed as crashed with its ``run.json``."""
    store = RunStore.create(tmp_path / "run.zarr", protocol="unit_test")
    store.append("biotac", biotac_rows(40))
    store.commit()
    zarr.open_group(str(store.path), mode="r+", use_consolidated=False)["biotac/seq"].resize((55,))
    proc = subprocess.run([sys.executable, "-c", INTERRUPTED_AT, str(store.path), step, str(int(sig))],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 3 and proc.stderr.startswith(f"interrupted: {store.path} is as it was or recovered")
    assert len(proc.stderr.splitlines()) == 1, proc.stderr
    assert main([str(store.path)]) == 0
    tree = xr.open_datatree(store.path, engine="zarr")
    assert tree.attrs["status"] == "crashed" and tree["biotac"].sizes["time"] == 40
    assert json.loads((tmp_path / "run.json").read_text())["status"] == "crashed"

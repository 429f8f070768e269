"""tactile-recover: a store left by a killed run is trimmed to its last commit and closed
as crashed, and then opens with consistent lengths even without consolidated metadata."""

import json

import numpy as np
import xarray as xr
import zarr

from runstore.recover import main, recover
from protocols.store import RunStore

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

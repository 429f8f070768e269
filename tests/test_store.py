"""The run store on real zarr v3 on disk, read back through xarray."""

import json

import numpy as np
import pytest
import xarray as xr
import zarr

from tactile_flow.hardware.biotac import FINGERS
from tactile_flow.hardware.hand import JOINT_NAMES
from tactile_flow.protocols.store import AXIS6, RunStore, open_run, run_schema

F = len(FINGERS)


def biotac_rows(n, start=0):
    t = (start + np.arange(n)) * 0.01
    return {"time": t, "device_time": t + 100.0, "host_time": t + 0.0015, "seq": start + 1 + np.arange(n),
            "valid": np.ones(n, bool), "electrodes": np.full((n, F, 24), 2000, np.int16),
            "pdc": np.full((n, F), 1800, np.int16), "tdc": np.zeros((n, F), np.int16),
            "tac": np.zeros((n, F), np.int16)}


def arm_rows(n):
    t = np.arange(n) * 0.002
    return {"time_arm": t, "controller_time": t + 5.0, "host_time": t, "tcp_pose": np.zeros((n, 6)),
            "tcp_speed": np.zeros((n, 6)), "tcp_wrench": np.ones((n, 6)), "protective_stopped": np.zeros(n, bool)}


@pytest.fixture
def store(tmp_path):
    return RunStore.create(tmp_path / "run.zarr", protocol="unit_test", provenance={"seed": 3, "x": [1, 2]})


def test_new_store_opens_with_every_group_units_and_attrs(store):
    dt = xr.open_datatree(store.path, engine="zarr")
    assert set(dt.children) == {"biotac", "biotac_pac", "arm", "hand", "pour", "events"}
    a = dt.attrs
    assert a["status"] == "running" and a["protocol"] == "unit_test" and a["schema_version"]
    assert len(a["run_id"]) == 36 and a["start_time"].endswith("Z") and a["end_time"] is None
    assert a["provenance"] == {"seed": 3, "x": [1, 2]}
    for node in dt.subtree:
        for name, var in node.variables.items():
            assert "units" in var.attrs and var.attrs.get("long_name"), f"{node.path}/{name}"
    b = dt["biotac"]
    assert b["electrodes"].dims == ("time", "finger", "taxel") and b["electrodes"].dtype == np.int16
    assert b["pdc"].dims == ("time", "finger") and b["seq"].dims == ("time",)
    assert list(b["finger"].values) == list(FINGERS) and list(b["taxel"].values) == list(range(1, 25))
    assert list(dt["arm/axis6"].values) == list(AXIS6)
    assert list(dt["hand/joint"].values) == list(JOINT_NAMES)
    assert dt["hand/position"].attrs["units"] == "rad" and dt["pour/mass"].attrs["units"] == "g"
    assert dt["pour/pump_rate"].dims == ("time_pump",) and dt["pour/mass"].dims == ("time_scale",)
    assert dt["biotac_pac/pac"].dims == ("time_pac", "finger")


def test_appends_are_invisible_until_commit_then_readable(store):
    store.append("biotac", biotac_rows(30))
    assert open_run(store.path)["biotac"].sizes["time"] == 0
    store.commit()
    store.append("biotac", biotac_rows(20, start=30))
    store.append("arm", arm_rows(7))
    store.append("events", {"time": [0.5], "kind": ["info"], "name": ["ünïcode"],
                            "detail": [json.dumps({"a": [1, 2], "b": "x"})]})
    store.commit()
    dt = open_run(store.path)
    assert dt["biotac"].sizes["time"] == 50
    np.testing.assert_array_equal(dt["biotac/seq"].values, np.arange(1, 51))
    assert dt["arm"].sizes["time_arm"] == 7
    ev = dt["events"]
    assert str(ev["name"].values[0]) == "ünïcode" and json.loads(str(ev["detail"].values[0]))["b"] == "x"


def test_append_checks_names_and_lengths(store):
    rows = biotac_rows(3)
    with pytest.raises(ValueError, match="expected variables"):
        store.append("biotac", {k: v for k, v in rows.items() if k != "pdc"})
    rows["pdc"] = rows["pdc"][:2]
    with pytest.raises(ValueError, match="different lengths"):
        store.append("biotac", rows)
    assert store.length("biotac") == 0


def test_reader_sees_last_commit_when_array_metadata_is_ahead(store):
    """As after a SIGKILL between appending and committing: some arrays of a group already
    have a longer zarr.json than the consolidated metadata. Readers must see the commit."""
    store.append("biotac", biotac_rows(40))
    store.append("arm", arm_rows(10))
    store.commit()
    store.append("biotac", biotac_rows(25, start=40))       # appended, never committed
    raw = zarr.open_group(str(store.path), mode="r+", use_consolidated=False)
    raw["biotac/electrodes"].resize((90, F, 24))             # one array further still
    raw["arm/tcp_pose"].resize((33, 6))
    assert raw["biotac/seq"].shape[0] == 65                  # per-array metadata is ahead
    dt = xr.open_datatree(store.path, engine="zarr")         # exactly as a user opens it
    assert dt["biotac"].sizes["time"] == 40 and dt["arm"].sizes["time_arm"] == 10
    for name, var in dt["biotac"].data_vars.items():
        assert var.sizes["time"] == 40, name
    np.testing.assert_array_equal(dt["biotac/seq"].values, np.arange(1, 41))
    assert (dt["biotac/electrodes"].values == 2000).all()


def test_attribute_update_keeps_the_store_consolidated(store):
    store.append("biotac", biotac_rows(5))
    store.commit()
    store.set_attrs(note="x")
    store.append("biotac", biotac_rows(5, start=5))
    store.commit()
    root = json.loads((store.path / "zarr.json").read_text())
    assert root["consolidated_metadata"] is not None and root["attributes"]["note"] == "x"
    assert open_run(store.path)["biotac"].sizes["time"] == 10


def test_close_sets_status_and_end_time_and_refuses_writes(store):
    store.close("aborted", reason="operator")
    dt = open_run(store.path)
    assert dt.attrs["status"] == "aborted" and dt.attrs["end_time"].endswith("Z")
    assert dt.attrs["reason"] == "operator"
    with pytest.raises(RuntimeError, match="closed"):
        store.append("biotac", biotac_rows(1))
    with pytest.raises(ValueError, match="status"):
        RunStore.create(store.path.parent / "b.zarr", protocol="p").close("fine")


def test_create_refuses_an_existing_store(store):
    with pytest.raises(FileExistsError):
        RunStore.create(store.path, protocol="again")


def test_rewrite_replaces_a_time_coordinate(store):
    store.append("biotac", biotac_rows(12))
    store.rewrite("biotac", "time", np.arange(12) * 0.02)
    store.commit()
    np.testing.assert_allclose(open_run(store.path)["biotac/time"].values, np.arange(12) * 0.02)
    with pytest.raises(ValueError):
        store.rewrite("biotac", "time", np.zeros(3))


def test_truth_tree_round_trips(store):
    truth = {"contacts": {"finger": np.array(["ff", "mf"]), "start": np.array([1.0, 2.0]),
                          "end": np.array([1.5, np.nan])},
             "sweeps": {"finger": np.array([], dtype=str), "start": np.zeros(0),
                        "dir_world": np.zeros((0, 3))},
             "features": {"kind": "straws", "name": np.array(["feature_0"]), "centre_m": np.zeros((1, 3)),
                          "width_m": np.array([0.006])},
             "pour": {"slip_onset": 3.25, "full_slip": float("nan")}}
    store.write_tree("truth", truth, attrs={"long_name": "ground truth"})
    store.close("success")
    dt = open_run(store.path)
    c = dt["truth/contacts"]
    assert c["start"].dims == ("contacts",) and list(c["finger"].values) == ["ff", "mf"]
    assert c["start"].attrs["units"] == "s" and np.isnan(c["end"].values[1])
    assert dt["truth/features/centre_m"].shape == (1, 3) and dt["truth/features/width_m"].attrs["units"] == "m"
    assert str(dt["truth/features/kind"].values) == "straws"
    assert dt["truth/sweeps"].sizes["sweeps"] == 0
    assert float(dt["truth/pour/slip_onset"]) == 3.25


def test_chunks_hold_seconds_of_data():
    s = run_schema(chunk_s=5.0)
    assert s["biotac"].chunk == 500 and s["biotac_pac"].chunk == 11000 and s["arm"].chunk == 2500
    assert s["pump"].group == s["scale"].group == "pour"


def test_failed_append_leaves_the_block_consistent(store):
    store.append("biotac", biotac_rows(4))
    store.commit()
    bad = biotac_rows(3)
    bad["electrodes"] = np.zeros((3, F, 23), np.int16)        # wrong shape: zarr refuses
    with pytest.raises(Exception):
        store.append("biotac", bad)
    assert store.length("biotac") == 4
    store.commit()                                            # lengths consistent again
    assert open_run(store.path)["biotac"].sizes["time"] == 4

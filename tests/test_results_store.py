"""analysis.zarr as written by runstore.labelled.write_tree: the same files as xarray's own
consolidated writer, readable by xarray with every group in the root's consolidated metadata,
and written without importing xarray."""

import json
import subprocess
import sys
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from tactile_flow.runstore import RunStore
from tactile_flow.runstore.labelled import Dataset, Variable, to_xarray, write_tree
from test_store import biotac_rows

ROOT = Path(__file__).resolve().parents[1]


def _tree():
    """Every kind of array analysis.zarr holds: float64 with NaN, float32 and uint8 fields,
    int64, bool, fixed-length strings, an empty dimension, a group below a group with no data."""
    mm = {"units": "mm", "long_name": "width"}
    return {
        "/": Dataset(attrs={"analysis_id": "abc", "provenance": {"config": {"a": 1}, "code": None}}),
        "/segments": Dataset({"start": Variable(("segment",), np.array([0.5, 1.5]), {"units": "s", "long_name": "s"}),
                              "label": Variable(("segment",), np.array(["before", "during"])),
                              "moved": Variable(("segment",), np.array([True, False]))},
                             coords={"segment": np.arange(2)}),
        "/aggregates": Dataset({"magnitude": Variable(("segment", "view"), np.arange(6.0).reshape(2, 3),
                                                      {"units": "mm/s"})},
                               coords={"segment": np.arange(2), "view": np.array(["bottom", "left", "right"]),
                                       "axis3": np.array(["x", "y", "z"])}),
        "/estimates/crossings": Dataset({"width": Variable(("crossing",), np.array([2.0, np.nan]), mm),
                                         "rank": Variable(("crossing",), np.array([1, -1], np.int64))}),
        "/estimates/none": Dataset({"width": Variable(("crossing",), np.zeros(0), mm),
                                    "finger": Variable(("crossing",), np.array([], dtype=str))},
                                   coords={"crossing": np.arange(0, dtype=np.int64)}),
        "/fields/ff_0_bottom": Dataset(
            {"frames": Variable(("time", "row", "col"), np.arange(2 * 3 * 4, dtype=np.uint8).reshape(2, 3, 4)),
             "dynamic": Variable(("time", "row", "col", "component"), np.full((2, 3, 4, 2), 0.25, np.float32))},
            coords={"time": np.array([0.0, 0.01])}, attrs={"finger": "ff", "view": "bottom"}),
        "/fields/th_1_left": Dataset({"dynamic": Variable(("time", "row", "col", "component"), _long_field())},
                                     coords={"time": np.arange(301) * 0.01}),
    }


def _long_field():
    """A field zarr splits into chunks along every axis, with edge chunks and chunks that hold
    only NaN (which are not written)."""
    field = np.random.default_rng(0).normal(size=(301, 28, 40, 2)).astype(np.float32)
    field[:151, :14] = np.nan                  # chunks of (151, 14, 20, 2): two hold only NaN
    return field


def _files(root):
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def test_write_tree_writes_what_xarrays_consolidated_writer_writes(tmp_path):
    tree = _tree()
    (tmp_path / "ours").mkdir()
    write_tree(tree, tmp_path / "ours" / "analysis.zarr")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        to_xarray(tree).to_zarr(str(tmp_path / "xarray.zarr"), mode="w", zarr_format=3, consolidated=True)
    ours, theirs = _files(tmp_path / "ours" / "analysis.zarr"), _files(tmp_path / "xarray.zarr")
    assert ours.keys() == theirs.keys()
    assert [k for k in ours if ours[k] != theirs[k]] == []

    root = json.loads(ours["zarr.json"])
    assert {"segments", "aggregates", "estimates/crossings"} <= set(root["consolidated_metadata"]["metadata"])
    back = xr.open_datatree(str(tmp_path / "ours" / "analysis.zarr"), engine="zarr").load()
    assert back["aggregates"]["magnitude"].attrs["units"] == "mm/s"
    assert back["segments"]["label"].values.tolist() == ["before", "during"]
    assert np.isnan(back["estimates/crossings"]["width"].values[1])
    assert back["estimates/none"].sizes["crossing"] == 0
    assert back["fields/ff_0_bottom"]["dynamic"].dtype == np.float32
    np.testing.assert_array_equal(back["fields/th_1_left"]["dynamic"].values, _long_field())
    assert len([k for k in ours if k.startswith("fields/th_1_left/dynamic/c/")]) == 2 * 2 * 2 - 2
    assert back.attrs["provenance"] == {"config": {"a": 1}, "code": None}


def test_write_tree_packed_is_the_same_members_in_one_zip_that_xarray_opens_by_a_string(tmp_path):
    """``analysis.zarr.zip``: the directory store's files as the members of one zip (metadata
    deflated, chunks stored), read back by xarray through its ``zip::`` URL and by the opener."""
    from tactile_flow.runstore import open_run
    tree = _tree()
    write_tree(tree, tmp_path / "analysis.zarr")
    write_tree(tree, tmp_path / "analysis.zarr.zip")
    with zipfile.ZipFile(tmp_path / "analysis.zarr.zip") as z:
        members = {i.filename: (z.read(i), i.compress_type) for i in z.infolist()}
    assert {k: v[0] for k, v in members.items()} == _files(tmp_path / "analysis.zarr")
    assert {k for k, v in members.items() if v[1] == zipfile.ZIP_DEFLATED} == {k for k in members
                                                                              if k.endswith("zarr.json")}
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []   # no temporary file left
    for back in (xr.open_datatree(f"zip::{tmp_path / 'analysis.zarr.zip'}", engine="zarr").load(),
                 open_run(tmp_path / "analysis.zarr.zip").load()):
        np.testing.assert_array_equal(back["fields/th_1_left"]["dynamic"].values, _long_field())
        assert back["segments"]["label"].values.tolist() == ["before", "during"]
    with pytest.raises(FileExistsError):                               # written once, never over a store
        write_tree(tree, tmp_path / "analysis.zarr.zip")


def _store(path: Path) -> Path:
    s = RunStore.create(path, protocol="t")
    s.append("biotac", biotac_rows(5))
    s.commit()
    s.close("success")
    return path


def test_the_analysis_refuses_a_store_of_a_newer_major_schema_version(tmp_path):
    from tactile_flow.analysis.load import AnalysisInputError, load_run
    store = _store(tmp_path / "run.zarr")
    meta = json.loads((store / "zarr.json").read_text())
    meta["attributes"]["schema_version"] = "2.0"
    (store / "zarr.json").write_text(json.dumps(meta))
    with pytest.raises(AnalysisInputError, match=r"schema_version '2.0' is newer than this reader's"):
        load_run(store)


def test_writing_an_analysis_and_reading_its_run_import_no_xarray(tmp_path):
    """xarray (with pandas, ~0.6 s on one core) is for users reading the stores; the analysis
    reads run.zarr and writes analysis.zarr without it."""
    store = _store(tmp_path / "run.zarr")
    code = ("import sys\n"
            "from pathlib import Path\n"
            "from tactile_flow.runstore.labelled import Dataset, Variable, write_tree\n"
            "from tactile_flow.analysis.load import load_run\n"
            f"run = load_run({str(store)!r})\n"
            "tree = {'/x': Dataset({'t': Variable(('time',), run.time)})}\n"
            f"write_tree(tree, Path({str(tmp_path / 'analysis.zarr')!r}))\n"
            "print(len(run.time), sorted(m for m in ('xarray', 'pandas') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["5", "[]"]

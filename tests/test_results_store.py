"""analysis.zarr as written by analysis.results.write_store: the same files as xarray's own
consolidated writer, readable by xarray with every group in the root's consolidated metadata."""

import json
import warnings

import numpy as np
import xarray as xr

from analysis import results


def _tree() -> xr.DataTree:
    seg = xr.Dataset({"start": ("segment", np.array([0.5, 1.5])), "label": ("segment", np.array(["before", "during"]))},
                     coords={"segment": np.arange(2)})
    agg = xr.Dataset({"magnitude": (("segment", "view"), np.arange(6.0).reshape(2, 3), {"units": "mm/s"})},
                     coords={"segment": np.arange(2), "view": np.array(["bottom", "left", "right"])})
    crossings = xr.Dataset({"width": ("crossing", np.array([2.0, np.nan]), {"units": "mm"})})
    return xr.DataTree.from_dict({"/": xr.Dataset(attrs={"analysis_id": "abc"}), "/segments": seg,
                                  "/aggregates": agg, "/estimates/crossings": crossings})


def _files(root):
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def test_write_store_writes_what_xarrays_consolidated_writer_writes(tmp_path):
    tree = _tree()
    (tmp_path / "ours").mkdir()
    results.write_store(tree, tmp_path / "ours" / "analysis.zarr")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tree.to_zarr(str(tmp_path / "xarray.zarr"), mode="w", zarr_format=3, consolidated=True)
    ours, theirs = _files(tmp_path / "ours" / "analysis.zarr"), _files(tmp_path / "xarray.zarr")
    assert ours.keys() == theirs.keys()
    assert [k for k in ours if ours[k] != theirs[k]] == []

    root = json.loads(ours["zarr.json"])
    assert {"segments", "aggregates", "estimates/crossings"} <= set(root["consolidated_metadata"]["metadata"])
    back = xr.open_datatree(str(tmp_path / "ours" / "analysis.zarr"), engine="zarr").load()
    assert back["aggregates"]["magnitude"].attrs["units"] == "mm/s"
    assert back["segments"]["label"].values.tolist() == ["before", "during"]
    assert np.isnan(back["estimates/crossings"]["width"].values[1])

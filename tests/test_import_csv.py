"""tactile-import on CSV files (made from the real resting recording's counts), and baselines."""

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from tactile_flow.runstore import store_url
from tactile_flow.importers import ImportSettings, import_source, read_bag, select_fingers
from tactile_flow.tactile.signals import SensorCalibration
from tactile_flow.analysis.run import analyze_run
from conftest import DATA

BAG = DATA / "biotac_rest_untouched.bag"


@pytest.fixture(scope="module")
def rest():
    """The real recording's connected fingers (ff, mf, th): 977 frames of real counts."""
    rec, _ = select_fingers(read_bag(BAG))
    return rec


def write_csv(path: Path, rec, fingers=None, prefixed=True, channels=("pdc",), time=None, rows=None,
              drop=(), extra=()) -> Path:
    """A CSV of ``rec``'s counts: per-finger or unprefixed names, optional channels and time column."""
    fingers = fingers or list(rec.fingers)
    sl = slice(None) if rows is None else rows
    names, cols = [], []
    if time is not None:
        names.append("time")
        cols.append(np.asarray(time)[:, None])
    for f in fingers:
        k = rec.fingers.index(f)
        p = f"{f}_" if prefixed else ""
        names += [f"{p}e{i}" for i in range(1, 25)]
        cols.append(rec.electrodes[sl, k])
        for c in channels:
            names.append(f"{p}{c}")
            cols.append(getattr(rec, c)[sl, k:k + 1])
    for name in extra:
        names.append(name)
        cols.append(np.zeros((cols[-1].shape[0], 1)))
    data = np.hstack([np.asarray(c, float) for c in cols])
    keep = [i for i, n in enumerate(names) if n not in drop]
    path.write_text(",".join(names[i] for i in keep) + "\n"
                    + "\n".join(",".join(f"{v:g}" for v in row[keep]) for row in data) + "\n")
    return path


def test_per_finger_prefixes_with_time_column(rest, tmp_path):
    t = 5.0 + np.arange(rest.n_frames) / 100.0
    src = write_csv(tmp_path / "hand.csv", rest, channels=("pdc", "tdc", "tac"), time=t)
    (res,) = import_source(src, tmp_path / "out")
    assert res.fingers == ["ff", "mf", "th"] and res.rate_hz == pytest.approx(100.0)
    dt = xr.open_datatree(store_url(res.store), engine="zarr")
    b = dt["biotac"]
    np.testing.assert_array_equal(b["electrodes"].values, rest.electrodes)
    np.testing.assert_array_equal(b["pdc"].values, rest.pdc)
    np.testing.assert_array_equal(b["tac"].values, rest.tac)
    np.testing.assert_allclose(b["time"].values, t - 5.0, atol=1e-9)
    np.testing.assert_allclose(b["device_time"].values, t)
    assert np.isnan(b["host_time"].values).all()                       # a CSV has no receipt times
    np.testing.assert_array_equal(b["seq"].values, np.arange(rest.n_frames))
    assert set(dt.children) == {"biotac", "events"}      # a CSV has no PAC, arm, hand, pour: no empty groups
    assert dt.attrs["import"]["reader"]["rate_source"] == "time column"
    assert dt.attrs["provenance"]["importer"]["reader"] == "tactile_flow.importers.csv.read_csv"


def test_electrode_only_file_with_rate(rest, tmp_path):
    src = write_csv(tmp_path / "th_only.csv", rest, fingers=["th"], prefixed=False, channels=())
    (res,) = import_source(src, tmp_path / "out", ImportSettings(rate_hz=100, fingers=("th",)))
    dt = xr.open_datatree(store_url(res.store), engine="zarr")
    b = dt["biotac"]
    assert list(b["finger"].values) == ["th"]
    assert "pdc" not in b and "tdc" not in b and "tac" not in b        # not recorded: not stored
    np.testing.assert_array_equal(b["electrodes"].values[:, 0], rest.electrodes[:, 2])
    assert b["time"].values[1] == pytest.approx(0.01)
    assert dt.attrs["import"]["channels"] == []


def test_electrode_only_file_analyses(rest, tmp_path):
    src = write_csv(tmp_path / "ff.csv", rest, fingers=["ff"], prefixed=False, channels=())
    (res,) = import_source(src, tmp_path / "out", ImportSettings(rate_hz=100))
    s = analyze_run(res.store, {"progress": False, "figures": False}, console=lambda *a: None)
    assert s["provenance"]["pressure_signal"] == "proxy"                # no pdc stored → electrode proxy
    assert s["headline"]["status"] == "no_contact"


def test_directory_imports_one_store_per_file_with_estimated_baseline(rest, tmp_path):
    d = tmp_path / "session"
    d.mkdir()
    write_csv(d / "a.csv", rest, rows=slice(0, 400))
    # b starts in contact: ff pressed through its first 2 s (counts fall under load)
    pressed = rest.electrodes.copy()
    pressed[400:600, 0] -= 400
    write_csv(d / "b.csv", replace(rest, electrodes=pressed), rows=slice(400, 977))
    (d / "notes.txt").write_text("not imported")
    res = import_source(d, tmp_path / "out", ImportSettings(rate_hz=100, baseline="estimate"))
    assert [Path(r.run_dir).name for r in res] == ["a", "b"] and [r.frames for r in res] == [400, 577]
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["a", "b"]
    early = np.concatenate([rest.electrodes[0:100], pressed[400:500]]).astype(float)     # first 1 s of each
    est = np.percentile(early, 95, axis=0)                                              # (3, 24)
    rest_level = rest.electrodes[:, 0].mean(axis=0)
    assert np.abs(est[0] - rest_level).max() < 15                  # the unloaded level, not the pressed one
    for r in res:
        dt = xr.open_datatree(store_url(r.store), engine="zarr")
        assert dt.attrs["baseline"]["method"] == "estimated"
        assert dt.attrs["baseline"]["details"]["files"] == [str(d / "a.csv"), str(d / "b.csv")]
        assert dt["biotac"]["baseline"].dims == ("finger", "taxel")
        np.testing.assert_allclose(dt["biotac"]["baseline"].values, est)               # counts
        cal = SensorCalibration.from_dict(dt.attrs["calibration"]["mf"])
        np.testing.assert_allclose(cal.baseline_counts, est[1])
        assert json.loads((Path(r.run_dir) / "run.json").read_text())["baseline"]["method"] == "estimated"


def test_calibration_file_per_finger(rest, tmp_path):
    src = write_csv(tmp_path / "two.csv", rest, fingers=["ff", "mf"], time=np.arange(rest.n_frames) / 100)
    cals = {f: SensorCalibration.from_rest(rest.electrodes[:, k], f"SN-{f}", "bench, 2026-01-01").to_dict()
            for k, f in enumerate(rest.fingers)}
    cal_file = tmp_path / "cal.json"
    cal_file.write_text(json.dumps(cals))
    (res,) = import_source(src, tmp_path / "out", ImportSettings(calibration=str(cal_file)))
    dt = xr.open_datatree(store_url(res.store), engine="zarr")
    assert dt.attrs["baseline"]["method"] == "calibration_file"
    assert dt.attrs["baseline"]["details"]["sha256"] and sorted(dt.attrs["calibration"]) == ["ff", "mf"]
    np.testing.assert_allclose(dt["biotac"]["baseline"].values,
                               [cals["ff"]["baseline_counts"], cals["mf"]["baseline_counts"]])
    assert dt.attrs["provenance"]["calibration"]["ff"]["sensor_id"] == "SN-ff"


def test_single_sensor_calibration_file(rest, tmp_path):
    src = write_csv(tmp_path / "one.csv", rest, fingers=["mf"], prefixed=False, channels=())
    cal = SensorCalibration.from_rest(rest.electrodes[:, 1], "SN-42", "bench")
    cal_file = tmp_path / "sn42.json"
    cal_file.write_text(json.dumps(cal.to_dict()))
    (res,) = import_source(src, tmp_path / "out", ImportSettings(rate_hz=100, fingers=("mf",),
                                                                 calibration=str(cal_file)))
    dt = xr.open_datatree(store_url(res.store), engine="zarr")
    assert SensorCalibration.from_dict(dt.attrs["calibration"]["mf"]) == cal


def test_recording_that_starts_in_contact_keeps_its_pressure_with_a_stored_calibration(rest, tmp_path):
    """The analysis takes an import's stored baseline, not the record's own first samples: a
    record pressed from its first frame to its last still shows its contact."""
    from tactile_flow.analysis import run as analysis_run

    pressed = replace(rest, electrodes=rest.electrodes.copy())
    pressed.electrodes[:, 1, 18:24] -= 400                     # mf's pad pressed throughout
    src = write_csv(tmp_path / "pressed.csv", pressed, fingers=["mf"], prefixed=False, channels=())
    cal = SensorCalibration.from_rest(rest.electrodes[:, 1], "SN-mf", "bench, at rest")
    cal_file = tmp_path / "mf.json"
    cal_file.write_text(json.dumps(cal.to_dict()))
    (res,) = import_source(src, tmp_path / "out", ImportSettings(rate_hz=100, fingers=("mf",),
                                                                 calibration=str(cal_file)))
    summary = analysis_run.analyze_run(res.store, {"progress": False, "figures": False}, console=lambda *a: None)
    assert "stored baseline" in json.dumps(summary)
    labels = {s["label"] for s in summary["segments"]}
    assert "contact" in labels, labels

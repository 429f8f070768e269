"""Recordings of other sensor models and in the layouts labs publish: the classic BioTac's 19
electrodes in CSV files (``ele1..ele19``, ``electrode_1..``, per-finger prefixes, a seconds or
nanoseconds time column, PAC as ``pac1..pacN``, baseline-relative values) and in ROS1 bags of
``BiotacAll``; the sensor model chosen by the electrode count (or asked for) and recorded, a
store of one model refused with another, and a count no model has refused listing the models."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from tactile_flow.runstore import store_url
from tactile_flow.analysis.run import analyze_run
from tactile_flow.importers import ImportSettings, import_source
from tactile_flow.importers.csv import read_csv
from tactile_flow.importers.recording import ImportInputError
from tactile_flow.tactile.sensor import SensorModelError, builtin_sensor

from sensor_record import press_record, write_csv, write_ros1_bag

QUIET = {"progress": False, "figures": False}


@pytest.fixture(scope="module", params=["biotac", "biotac_sp"])
def press(request):
    return request.param, press_record(builtin_sensor(request.param))


@pytest.fixture(scope="module")
def classic():
    return press_record(builtin_sensor("biotac"))


@pytest.mark.slow                       # analyses the import
def test_a_csv_of_either_biotac_imports_with_its_model_from_the_electrode_count(press, tmp_path):
    name, rec = press
    src = write_csv(tmp_path / "press.csv", rec, lambda i: f"ele{i}")
    lines = []
    (res,) = import_source(src, tmp_path / "out", console=lines.append)
    n = builtin_sensor(name).n_taxels
    assert res.sensor == f"{name} (inferred from {n} electrodes per sensor)" and f"sensor {res.sensor}" in lines[0]
    dt = xr.open_datatree(store_url(res.store), engine="zarr")
    assert dt.attrs["sensor"]["name"] == name and dt.attrs["sensor"]["sha256"] == builtin_sensor(name).sha256
    b = dt["biotac"]
    assert b["electrodes"].shape == (len(rec.time), 1, n)
    np.testing.assert_array_equal(b["electrodes"].values[:, 0], rec.electrodes[:, 0])
    np.testing.assert_allclose(b["time"].values, rec.time, atol=1e-9)
    summary = analyze_run(res.store, QUIET, console=lambda *a: None)
    contact = summary["contacts"]["ff"]
    truth = rec.time[rec.contact]
    assert len(contact) == 1 and abs(contact[0][0] - truth[0]) < 0.3 and abs(contact[0][1] - truth[-1]) < 0.3, contact
    assert summary["provenance"]["sensor"]["name"] == name


@pytest.mark.parametrize("names", [lambda i: f"e{i}", lambda i: f"electrode_{i}", lambda i: f"E{i:02d}",
                                   lambda i: f"taxel-{i}"])
def test_the_conventions_labs_name_electrodes_by(classic, tmp_path, names):
    src = write_csv(tmp_path / "c.csv", classic, names)
    rec = read_csv(src)
    assert rec.meta["electrodes"] == 19
    np.testing.assert_array_equal(rec.electrodes[:, 0], classic.electrodes[:, 0])


def test_per_finger_prefixes_pac_samples_and_a_nanosecond_time_column(classic, tmp_path):
    src = write_csv(tmp_path / "hand.csv", classic, lambda i: f"ele{i}", finger_prefix=True, pac=True,
                    time_name="timestamp", time_scale=1e9)
    lines = []
    (res,) = import_source(src, tmp_path / "out", console=lines.append)
    assert res.fingers == ["ff", "th"] and res.rate_hz == pytest.approx(100.0)
    assert "time column in ns (guessed from its median step 1e+07 (100 Hz in ns)" in lines[0]
    dt = xr.open_datatree(store_url(res.store), engine="zarr")
    pac = dt["biotac_pac"]
    assert pac.sizes["time_pac"] == 22 * len(classic.time)
    np.testing.assert_array_equal(pac["pac"].values[:22, 1], classic.pac[0, 1])
    np.testing.assert_allclose(np.diff(pac["time_pac"].values[:22]), 1 / 2200, atol=1e-7)
    assert pac["time_pac"].values[21] == pytest.approx(dt["biotac"]["time"].values[0])   # a batch ends at its frame


def test_a_time_unit_named_or_given_is_not_guessed(classic, tmp_path):
    rec = read_csv(write_csv(tmp_path / "a.csv", classic, lambda i: f"e{i}", time_name="time_ms", time_scale=1e3))
    assert rec.meta["time_unit"] == "ms" and rec.meta["time_unit_source"] == "the column's name"
    np.testing.assert_allclose(rec.device_time, classic.time, atol=1e-9)
    rec = read_csv(write_csv(tmp_path / "b.csv", classic, lambda i: f"e{i}", time_name="stamp", time_scale=1e6),
                   time_unit="us")
    assert rec.meta["time_unit_source"] == "time_unit=us"
    np.testing.assert_allclose(rec.device_time, classic.time, atol=1e-9)


@pytest.mark.slow                       # analyses the import
def test_baseline_relative_values_are_detected_and_said(classic, tmp_path):
    rest = classic.electrodes[:50].mean(axis=0).round()                    # (2, 19): each electrode's rest
    src = write_csv(tmp_path / "rel.csv", classic, lambda i: f"ele{i}", relative_to=rest)
    lines = []
    (res,) = import_source(src, tmp_path / "out", console=lines.append)
    assert "electrode values relative to rest (electrode values relative to rest (first rows: median" in lines[0]
    assert res.baseline == "relative"
    b = xr.open_datatree(store_url(res.store), engine="zarr")["biotac"]
    np.testing.assert_array_equal(b["electrodes"].values[:, 0], classic.electrodes[:, 0] - rest[0] + 2500)
    np.testing.assert_array_equal(b["baseline"].values, np.full((1, 19), 2500.0))
    summary = analyze_run(res.store, QUIET, console=lambda *a: None)
    assert len(summary["contacts"]["ff"]) == 1
    raw = import_source(write_csv(tmp_path / "raw.csv", classic, lambda i: f"ele{i}"), tmp_path / "o2")[0]
    assert raw.baseline == "none"                                           # raw counts: not relative


def test_column_renames_for_names_no_convention_covers(classic, tmp_path):
    src = write_csv(tmp_path / "odd.csv", classic, lambda i: f"BT_{i}", time_name="clock")
    with pytest.raises(ImportInputError, match="unexpected columns: clock, BT_1, BT_2"):
        import_source(src, tmp_path / "o1")
    columns = {"clock": "time", **{f"BT_{i}": f"e{i}" for i in range(1, 20)}}
    (res,) = import_source(src, tmp_path / "o2", ImportSettings(columns=columns))
    assert res.frames == len(classic.time)


@pytest.mark.slow                       # analyses the import
def test_a_ros1_bag_of_19_electrode_biotacall_messages(classic, tmp_path):
    bag = write_ros1_bag(tmp_path / "classic.bag", classic)
    (res,) = import_source(bag, tmp_path / "out", ImportSettings(rate_hz=100))
    assert res.fingers == ["ff", "th"] and res.sensor.startswith("biotac (inferred from 19")
    dt = xr.open_datatree(store_url(res.store), engine="zarr")
    np.testing.assert_array_equal(dt["biotac"]["electrodes"].values, classic.electrodes)
    np.testing.assert_array_equal(dt["biotac"]["pdc"].values, classic.pdc)
    assert dt["biotac_pac"].sizes["time_pac"] == 22 * len(classic.time)
    summary = analyze_run(res.store, QUIET, console=lambda *a: None)
    assert len(summary["contacts"]["ff"]) == 1 and summary["contacts"].get("th", []) == []
    # the same store, asked to be read as a BioTac SP: refused in one line naming both models
    with pytest.raises(SensorModelError) as info:
        analyze_run(res.store, QUIET, console=lambda *a: None, sensor=builtin_sensor("biotac_sp"))
    msg = str(info.value)
    assert "\n" not in msg and "was recorded with sensor model biotac (19 taxels" in msg
    assert "sensor=biotac_sp is biotac_sp (24 taxels" in msg


def test_a_requested_model_must_have_the_files_electrodes(classic, tmp_path):
    bag = write_ros1_bag(tmp_path / "classic.bag", classic)
    with pytest.raises(ImportInputError, match=r"message 0 has \[19\] electrodes per sensor; sensor=biotac_sp has 24"):
        import_source(bag, tmp_path / "o1", ImportSettings(sensor=builtin_sensor("biotac_sp")))
    csv = write_csv(tmp_path / "c.csv", classic, lambda i: f"ele{i}")
    with pytest.raises(ImportInputError, match="missing columns: ele20, ele21, ele22, ele23, ele24"):
        import_source(csv, tmp_path / "o2", ImportSettings(sensor=builtin_sensor("biotac_sp")))


def test_an_electrode_count_of_no_model_is_one_line_listing_the_models(classic, tmp_path):
    cut = press_record(builtin_sensor("biotac"), seconds=0.5)
    cut.electrodes = cut.electrodes[:, :, :16]
    src = write_csv(tmp_path / "sixteen.csv", cut, lambda i: f"e{i}")
    with pytest.raises(ImportInputError) as info:
        import_source(src, tmp_path / "out")
    assert str(info.value) == (f"{src}: 16 electrodes match no sensor model; the models and their electrode counts: "
                               f"biotac (19), biotac_sp (24); give sensor=FILE.yaml for another model")
    assert not (tmp_path / "out").exists()

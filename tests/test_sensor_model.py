"""Sensors as data (tactile.sensor): the shipped models read, match their published tables, and
every kind of bad sensor file is one line naming the file, the field and what was expected."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import yaml

from tactile_flow.tactile import frames
from tactile_flow.tactile.pipeline import TactileConfig, TactileModel
from tactile_flow.tactile.sensor import (SensorModelError, builtin_sensor, builtin_sensors, load_sensor,
                                         load_sensor_file, sensor_for_taxels)

from conftest import DATA

SENSORS = ("biotac_sp", "biotac")
FLAT = DATA / "conf" / "sensor" / "flat_pad.yaml"


def table(name):
    return np.loadtxt(DATA / name, delimiter=",", skiprows=1, usecols=(1, 2, 3))


def test_both_biotacs_ship_and_match_their_published_tables():
    assert {"biotac_sp", "biotac"} <= set(builtin_sensors())
    sp, bt = builtin_sensor("biotac_sp"), builtin_sensor("biotac")
    np.testing.assert_array_equal(sp.taxels, table("biotac_sp_taxels.csv"))
    np.testing.assert_array_equal(bt.taxels, table("biotac_taxels.csv"))
    assert (sp.n_taxels, bt.n_taxels) == (24, 19)
    assert bt.taxel_names[0] == "E1" and bt.taxel_names[-1] == "E19"
    # the manual's axes: tip electrodes E7-E10 lean towards +x, the pad faces -z, E1-E6 at y < 0 mirror E11-E16
    assert (bt.normals[6:10, 0] > 0.4).all() and (bt.normals[:, 2] < 0).all()
    np.testing.assert_allclose(bt.taxels[:6] * [1, -1, 1], bt.taxels[10:16])
    np.testing.assert_allclose(np.linalg.norm(bt.normals, axis=1), 1.0)
    assert bt.normals_source == "file" and sp.normals_source == "surface"


def test_the_classic_biotac_surface_is_pinned_by_its_normals():
    bt = builtin_sensor("biotac")
    s = bt.shape
    # fitted to positions and normals, the equator sits at the side electrodes (z ~ 0), not 6.7 mm above them
    assert s.kind == "ellipsoid" and abs(s.centre[2]) < 1.0 and s.rms_mm < 0.3
    assert 14 < s.extent[0] < 17 and 5 < s.extent[1] < 6 and 5 < s.extent[2] < 6
    from tactile_flow.tactile.sensor import _surface_normals
    angle = np.degrees(np.arccos(np.clip(np.sum(_surface_normals(s, bt.taxels) * bt.normals, axis=1), -1, 1)))
    assert np.median(angle) < 10 and angle.max() < 30


def test_the_checksum_is_of_the_content_not_the_text(tmp_path):
    sp = builtin_sensor("biotac_sp")
    text = sp.file and open(sp.file).read()
    (tmp_path / "a.yaml").write_text("# another comment\n" + text.replace("# E1 (side)", "# first"))
    assert load_sensor_file(tmp_path / "a.yaml").sha256 == sp.sha256
    data = yaml.safe_load(text)
    data["taxels"]["positions_mm"][3][0] += 0.01
    assert load_sensor(data).sha256 != sp.sha256
    assert len({m.sha256 for m in map(builtin_sensor, SENSORS)}) == 2


def test_a_model_is_chosen_by_its_electrode_count_or_refused_listing_them():
    assert sensor_for_taxels(19).name == "biotac" and sensor_for_taxels(24).name == "biotac_sp"
    with pytest.raises(SensorModelError) as e:
        sensor_for_taxels(16)
    assert str(e.value) == ("sensor: 16 electrodes match no sensor model; the models and their electrode counts: "
                            "biotac (19), biotac_sp (24)")


def test_the_flat_pad_is_a_plane_with_one_view():
    m = load_sensor_file(FLAT)
    assert m.n_taxels == 16 and m.views == ("bottom",) and m.shape.kind == "plane"
    np.testing.assert_allclose(m.shape.extent, [16, 16])
    assert m.pressure is None and m.channel_names() == {}


def bad(tmp_path, mutate, base=None):
    data = yaml.safe_load(open(base or builtin_sensor("biotac_sp").file))
    mutate(data)
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(SensorModelError) as e:
        load_sensor_file(path)
    text = str(e.value)
    assert "\n" not in text and text.startswith(f"{path}: sensor.")
    return text.removeprefix(f"{path}: ")


@pytest.mark.parametrize("mutate, expected", [
    (lambda d: d.pop("name"), "sensor.name: missing; expected this key"),
    (lambda d: d["taxels"].pop("positions_mm"), "sensor.taxels.positions_mm: missing; expected a list of [x, y, z]"),
    (lambda d: d["surface"].pop("kind"), "sensor.surface.kind: missing; expected one of ellipsoid, plane"),
    (lambda d: d.pop("views"), "sensor.views: missing"),
    (lambda d: d["taxels"]["positions_mm"].__setitem__(5, [1.0, 2.0]),
     "sensor.taxels.positions_mm[5]: got [1.0, 2.0]; expected [x, y, z] in mm"),
    (lambda d: d["taxels"]["positions_mm"].__setitem__(7, [1.0, float("nan"), -3.0]),
     "sensor.taxels.positions_mm[7][1]: got nan; expected a finite number"),
    (lambda d: d["taxels"]["positions_mm"].__setitem__(9, copy.copy(d["taxels"]["positions_mm"][2])),
     "sensor.taxels.positions_mm[9]: [2.21927, -7.16233, -3.26548] is the position of [2] too; expected distinct"),
    (lambda d: d["taxels"]["positions_mm"][4].__setitem__(2, -12.0),
     "sensor.taxels.positions_mm[4]: [-0.47307, -2.41094, -12.0] is 4.78 mm off the ellipsoid surface "
     "(positions); expected every taxel within surface.tolerance_mm = 1 mm of it"),
    (lambda d: d["taxels"].__setitem__("normals", [[0.0, 0.0, -1.0]] * 23 + [[0.0, 0.0, 0.0]]),
     "sensor.taxels.normals[23]: [0.0, 0.0, 0.0] has zero length"),
    (lambda d: d["taxels"].__setitem__("normals", [[0.0, 0.0, -1.0]] * 20),
     "sensor.taxels.normals: got 20 normals; expected one per taxel position (24)"),
    (lambda d: d["taxels"].__setitem__("names", ["A"] * 24), "sensor.taxels.names: 'A' is given twice"),
    (lambda d: d.__setitem__("views", ["bottom", "top"]), "sensor.views[1]: unknown view 'top'"),
    (lambda d: d["surface"].__setitem__("fit", "given"), "sensor.surface.centre_mm: missing; expected it with fit: given"),
    (lambda d: d["electrodes"].__setitem__("reference_khom", 10.0),
     "sensor.electrodes.reference_khom: unknown key; expected one of"),
    (lambda d: d["limits"].__setitem__("electrode_counts", [1, 5000]),
     "sensor.limits.electrode_counts: got [1.0, 5000.0]; expected [low, high] with 0 <= low < high <= "),
])
def test_a_bad_sensor_file_is_one_line_naming_file_field_and_expectation(tmp_path, mutate, expected):
    assert bad(tmp_path, mutate).startswith(expected)


def test_taxels_not_on_the_given_surface_or_above_its_rim_are_refused(tmp_path):
    def given(d):
        d["surface"].update(fit="given", centre_mm=[0.0, 0.0, -0.8], axes_mm=[12.0, 7.8, 9.0])
    assert "mm off the ellipsoid surface (given)" in bad(tmp_path, given)

    def plane_off(d):
        d["taxels"]["positions_mm"][3][2] = -4.0
    assert bad(tmp_path, plane_off, FLAT).startswith("sensor.taxels.positions_mm[3]: [-6.0, 6.0, -4.0] is 1.88 mm "
                                                     "off the plane surface (positions)")


@pytest.mark.parametrize("name", SENSORS)
def test_a_press_over_a_taxel_peaks_over_it_for_every_sensor(name, cache_dir):
    """The model built from a sensor file: the frame of a single pressed taxel is brightest
    at that taxel's place in the bottom view (the image's cols run along +x, rows along +y)."""
    sensor = builtin_sensor(name)
    model = TactileModel.build(TactileConfig(views=("bottom",)), cache_dir=cache_dir, sensor=sensor)
    assert model.n_taxels == sensor.n_taxels and model.weights.shape[1] == sensor.n_taxels
    pad = int(np.argmin(sensor.taxels[:, 2]))                     # the lowest taxel: on the pad
    act = np.zeros((1, sensor.n_taxels))
    act[0, pad] = 3.0
    img = model.render(act, "bottom")[0]
    plan = model.plans["bottom"]
    r, c = np.unravel_index(np.argmax(img), img.shape)
    peak = plan.origin + plan.mm_per_px * np.array([c, r])         # (cols, rows) = (x, y), mm
    assert np.linalg.norm(peak - sensor.taxels[pad, :2]) < 1.5


def test_views_outside_the_sensors_are_refused(cache_dir):
    flat = load_sensor_file(FLAT)
    with pytest.raises(ValueError, match=r"views: unknown view\(s\) \['left'\] of sensor flat_pad"):
        TactileModel.build(TactileConfig(views=("bottom", "left")), cache_dir=cache_dir, sensor=flat)
    model = TactileModel.build(TactileConfig(views=("bottom",)), cache_dir=cache_dir, sensor=flat)
    assert model.fit is None and model.mesh.kind == "plane" and model.plans["bottom"].mask.mean() > 0.3
    assert set(frames.DEFAULT_VIEWS) >= set(builtin_sensor("biotac").views)


@pytest.mark.parametrize("mutate, expected", [
    (lambda d: d["surface"].__setitem__("pad_radius_mm", 0.5), "sensor.surface.pad_radius_mm: 0.5 mm holds no taxel"),
    (lambda d: d.__setitem__("frame_size", [4, 40]), "sensor.frame_size: got [4, 40]; expected [H, W] of at least 8"),
    (lambda d: d.__setitem__("live_slip", {"curl_mni": 0.002}), "sensor.live_slip.curl_mni: unknown threshold; "),
])
def test_the_pad_frames_and_live_thresholds_are_checked_too(tmp_path, mutate, expected):
    assert bad(tmp_path, mutate).startswith(expected)


def test_the_analysis_takes_the_sensors_views_frames_and_pad_unless_told():
    from tactile_flow.analysis.config import AnalysisConfigError, for_sensor, load_config
    bt, sp, flat = builtin_sensor("biotac"), builtin_sensor("biotac_sp"), load_sensor_file(FLAT)
    cfg = for_sensor(load_config(None), bt)
    assert cfg.views == ("bottom", "left", "right") and cfg.tactile.size == (24, 48)
    assert for_sensor(load_config(None), sp).tactile.size == (28, 40)
    assert for_sensor(load_config({"tactile": {"size": [20, 30]}}), bt).tactile.size == (20, 30)
    assert for_sensor(load_config(None), flat).views == ("bottom",)
    with pytest.raises(AnalysisConfigError, match=r"analysis.views\[1\]: unknown view of sensor flat_pad; expected one of bottom"):
        for_sensor(load_config({"views": ["bottom", "left"]}), flat)
    assert bt.pad.sum() == 9 and sp.pad is None                       # the SP: every taxel
    assert [bt.taxel_names[i] for i in np.flatnonzero(bt.pad)] == ["E3", "E4", "E5", "E13", "E14", "E15", "E17",
                                                                    "E18", "E19"]


def test_the_live_slip_test_takes_the_sensors_thresholds_where_the_run_keeps_the_default():
    from tactile_flow.protocols.live import LiveConfig
    from tactile_flow.protocols.run import for_sensor_slip
    from tactile_flow.tactile.slip import SlipConfig
    live = for_sensor_slip(LiveConfig(), builtin_sensor("biotac"))
    assert live.slip.curl_min == 0.002 and for_sensor_slip(LiveConfig(), builtin_sensor("biotac_sp")).slip.curl_min == 0.001
    own = LiveConfig(slip=SlipConfig(curl_min=0.003))
    assert for_sensor_slip(own, builtin_sensor("biotac")).slip.curl_min == 0.003


@pytest.mark.parametrize("name", SENSORS)
def test_an_object_resting_on_the_pad_is_at_the_pad_centre(name):
    """The reference of the slip estimate's unloaded centre of pressure, the centroid of the pad's
    taxels, is where the taxels put a press at the pad's lowest point (within 0.5 mm); the whole
    centroid is that too on the SP (its pad is every taxel) but 3.2 mm off on the classic BioTac."""
    from tactile_flow.tactile import aggregate, synthetic
    s = builtin_sensor(name)
    pole = np.asarray(s.shape.pole) * [1, 1, 0]
    act = synthetic.moving_bump(s.taxels, start=pole, velocity=(0, 0, 0), duration=0.1)
    cop, _ = aggregate.centre_of_pressure(act, s.taxels)
    assert np.linalg.norm((cop[0] - s.pad_centre)[:2]) < 0.5
    off = np.linalg.norm((s.taxels.mean(axis=0) - cop[0])[:2])
    assert off > 3.0 if name == "biotac" else off < 0.5

"""Contact, baselines and the slip estimate on real BioTac SP data (``tests/data``).

Real contact frames (grasps of 41 objects, another lab) and a real resting recording; the
records that begin in contact are made of a real contact pattern held under the real
sensor's own resting noise (glitches included), as imported data are: electrode-only CSVs
without a time column, no tare, a baseline estimated across the import.
"""

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from tactile_flow.analysis.config import load_config
from tactile_flow.analysis.load import load_run
from tactile_flow.analysis.pipeline import analyse
from tactile_flow.analysis.preprocess import despike
from tactile_flow.analysis.run import analyze_run
from tactile_flow.importers import ImportSettings, import_source, read_bag, select_fingers
from tactile_flow.tactile import aggregate as tagg
from tactile_flow.tactile import contact, signals
from tactile_flow.tactile.pipeline import TactileConfig, TactileModel, process_view

DATA = Path(__file__).resolve().parent / "data"
GRASPS = sorted((DATA / "biotac_sp_grasps").glob("*.csv"))
CFG = load_config({"figures": False, "progress": False})


def grasp_rows(path: Path) -> np.ndarray:
    """(N, 3, 24) raw counts of ff, mf, th, one row per grasp reading."""
    with open(path) as f:
        rows = list(csv.reader(f))[1:]
    return np.array([[float(x) for x in r[2:]] for r in rows]).reshape(-1, 3, 24)


@pytest.fixture(scope="module")
def rest():
    """The real resting recording's connected fingers ff, mf, th: (977, 3, 24) counts."""
    rec, _ = select_fingers(read_bag(DATA / "biotac_rest_untouched.bag"))
    return rec.electrodes.astype(float)


def rest_noise(rest: np.ndarray) -> np.ndarray:
    """(3, 24) white noise of ln Z of the real sensors at rest, measured as the analysis does."""
    z = signals.counts_to_impedance(rest)
    base = z.mean(axis=0)
    smooth = base + signals.kalman_smooth(despike(z - base, 5), R=0.005, Q=0.00015)
    return contact.residual_noise(np.log(z), np.log(smooth))


@pytest.mark.parametrize("path", GRASPS, ids=lambda p: p.name)
def test_every_real_grasp_reading_is_in_contact(path, rest):
    """Every row of the real grasp data touches with at least one finger: each is found in
    contact against a baseline estimated across the file (as ``baseline=estimate`` pools an
    import) and the real sensors' resting noise."""
    rows = np.clip(grasp_rows(path), 1, 4094)
    base = signals.counts_to_impedance(np.percentile(rows, 95, axis=0))
    change = contact.relative_change(signals.counts_to_impedance(rows), base)
    score = contact.contact_score(change, rest_noise(rest))             # (N, 3)
    threshold = CFG.contact.threshold_sigma
    assert (score.max(axis=1) > threshold).all(), f"rows not in contact: {np.flatnonzero(score.max(1) <= threshold)}"
    # the pressed electrodes fall (impedance up) by far more than the far ones rise
    pressed = change.max(axis=2)
    rise = -change.min(axis=2)
    assert np.median(pressed[score > threshold]) > 3 * np.median(rise[score > threshold])


def test_real_resting_recording_has_no_contact(rest, tmp_path, model):
    """The real resting bag, imported without and with an estimated baseline: no contact on any
    finger, and its contact score stays far below the threshold."""
    for baseline in ("none", "estimate"):
        (res,) = import_source(DATA / "biotac_rest_untouched.bag", tmp_path / baseline,
                               ImportSettings(baseline=baseline))
        a = analyse(load_run(res.store), CFG, model)
        assert a.contacts == {}, (baseline, a.contacts)
        assert a.contact_method == "pattern"
        assert a.prepared.score.max() < CFG.contact.threshold_sigma / 2


def _write_record(path: Path, counts: np.ndarray) -> None:
    """An electrode-only CSV (``ff_e1``…``ff_e24``), no time column."""
    header = ",".join(f"ff_e{k}" for k in range(1, 25))
    path.write_text(header + "\n" + "\n".join(",".join(str(int(v)) for v in row) for row in counts) + "\n")


@pytest.fixture(scope="module")
def in_contact_import(rest, tmp_path_factory):
    """Eight records that begin (and stay) in contact: real ff grasp patterns from four files,
    each held for 2.7 s under a stretch of the real ff sensor's resting noise; imported as a
    directory with ``rate_hz=100 baseline=estimate`` and analysed with ``tactile-analyze``'s
    defaults."""
    tmp = tmp_path_factory.mktemp("in_contact")
    rng = np.random.default_rng(7)
    noise = rest[:, 0] - np.median(rest[:, 0], axis=0)
    src = tmp / "csvs"
    src.mkdir()
    for i, path in enumerate(GRASPS[:4]):
        rows = grasp_rows(path)[:, 0]
        for j in range(2):
            pattern = rows[rng.integers(len(rows))]
            s = int(rng.integers(0, len(noise) - 270))
            _write_record(src / f"rec{i}{j}.csv", np.clip(np.rint(pattern + noise[s:s + 270]), 1, 4094))
    results = import_source(src, tmp / "imported", ImportSettings(rate_hz=100.0, baseline="estimate"))
    return [analyze_run(r.store, {"figures": False, "progress": False}, console=lambda *_: None) for r in results]


def test_records_that_begin_in_contact_are_found_in_contact_with_a_slip_estimate(in_contact_import):
    for summary in in_contact_import:
        assert summary["headline"]["status"] == "ok"
        assert summary["begins_in_contact"] == {"ff": True}
        (start, end), = summary["contacts"]["ff"]
        assert start == 0.0 and end > 2.6
        assert summary["provenance"]["baseline_kind"] == "stored"
        slip = summary["estimates"]["slip"]["ff"]
        assert slip["reference"] == "first_settled" and slip["begins_in_contact"] and slip["reference_s"] < 0.2
        # a real pattern held still is a touch, wherever it sits on the pad: no direction, no onset
        assert slip["slip_class"] == "none" and 0.0 <= slip["confidence"] <= 1.0, slip["evidence"].get("motion")
        assert slip["slip_direction_sensor_deg"] is None and slip["slip_onset_s"] is None
        assert slip["slip_displacement_mm"] < 0.5 and abs(slip["rotation_deg"]) < 0.9
        # the unloaded flow (negated) and the centre of pressure agree on where it sits
        ev = slip["evidence"]
        a, b = ev["cop_unloaded"]["direction_deg"], ev["static_unloaded"]["direction_deg"] + 180.0
        assert abs((a - b + 180.0) % 360.0 - 180.0) < 60.0
        assert set(ev) >= {"static_unloaded", "static_onset", "dynamic", "cop_unloaded", "cop_onset", "motion",
                           "rotation"}


def test_flow_from_the_unloaded_sensor_points_away_from_real_patterns():
    """The documented sign (analysis/slip.py): the static flow from an empty frame to a real
    contact pattern points away from its centre of pressure."""
    model = TactileModel.build(TactileConfig(views=("bottom",)))
    plan = model.plans["bottom"]
    rows = grasp_rows(DATA / "biotac_sp_grasps" / "palm_down_test.csv")
    rest_counts = np.percentile(rows, 99, axis=0)
    signs = []
    for row in rows[::8]:
        for f in (0, 2):
            act = (signals.counts_to_impedance(np.clip(row[f], 1, 4094))
                   - signals.counts_to_impedance(rest_counts[f]))[None]
            cop, _ = tagg.centre_of_pressure(act, model.taxels)
            offset = (cop[0] - model.taxels.mean(axis=0))[:2]
            r = process_view(model, act, "bottom", references={"unloaded": None}, intensity_range=(0, act.max()))
            flow = plan.image_to_sensor(r.statics["unloaded"].mean[0])[:2]
            if np.hypot(*offset) > 0.5:
                signs.append(np.sign(flow @ offset))
    assert len(signs) > 40 and np.mean(np.array(signs) < 0) >= 0.95


def test_contact_intensity_keeps_a_light_contact_s_flow():
    """Why frames are scaled per contact: a light blob sliding across the pad gives the same
    flow as a firm one with ``intensity_range: contact``, and a fraction of it with the fixed
    0–8 kΩ scale."""
    model = TactileModel.build(TactileConfig(views=("bottom",)))
    tx = model.taxels
    t = np.arange(60)
    centre = -4.0 + 0.15 * t                                     # mm along x, 15 mm/s at 100 Hz
    shape = np.exp(-((tx[None, :, 0] - centre[:, None]) ** 2 + tx[None, :, 1] ** 2) / (2 * 3.0 ** 2))
    speeds = {}
    for peak in (4.0, 0.2):
        act = peak * shape
        for name, rng in (("contact", (0.0, act.max())), ("fixed", (0.0, 8.0))):
            r = process_view(model, act, "bottom", intensity_range=rng)
            speeds[peak, name] = float(r.dynamic.mean[1:, 0].mean())
    assert speeds[0.2, "contact"] == pytest.approx(speeds[4.0, "contact"], rel=0.05)
    assert speeds[0.2, "fixed"] < 0.5 * speeds[4.0, "fixed"]


def _csv_of(rest: np.ndarray, path: Path, edit=None) -> Path:
    counts = rest.copy()
    if edit is not None:
        edit(counts)
    names = [f"{f}_e{k}" for f in ("ff", "mf", "th") for k in range(1, 25)]
    path.write_text(",".join(names) + "\n" + "\n".join(",".join(str(int(v)) for v in row.ravel()) for row in counts)
                    + "\n")
    return path


@pytest.mark.parametrize("case, finger, reason", [
    ("dead", "mf", "only 200 of 977 frames"),
    ("saturated", "th", "reads 4095"),
])
def test_one_bad_finger_never_holds_back_the_others(case, finger, reason, rest, tmp_path, model):
    """A finger that goes dead (reads 0 from 2 s on) or is saturated throughout is skipped with
    the reason; the sound finger's contact is analysed as if the bad one were not there."""
    k = ("ff", "mf", "th").index(finger)

    def edit(c):
        if case == "dead":
            c[200:, k] = 0
        else:
            c[:, k] = 4095
        c[300:500, 0, 20:24] -= 400                              # ff pressed for 2 s
    src = _csv_of(rest, tmp_path / "hand.csv", edit)
    (res,) = import_source(src, tmp_path / "out", ImportSettings(rate_hz=100.0, fingers=("ff", "mf", "th")))
    a = analyse(load_run(res.store), CFG, model)
    assert finger in a.prepared.unusable and reason in a.prepared.unusable[finger]
    assert any(s["what"] == "finger" and s["finger"] == finger for s in a.skipped)
    assert list(a.contacts) == ["ff"]
    (start, stop), = a.contacts["ff"]
    assert abs(start - 300) <= 5 and abs(stop - 500) <= 5


def test_short_record_and_a_sensor_at_rest(rest, tmp_path, model):
    """A record of 0.3 s (shorter than the baseline's fallback window) and sensors at rest:
    analysed, no contact, nothing raised."""
    src = _csv_of(rest[:30], tmp_path / "short.csv")
    (res,) = import_source(src, tmp_path / "out", ImportSettings(rate_hz=100.0))
    a = analyse(load_run(res.store), CFG, model)
    assert a.contacts == {} and a.segments == []
    assert any("no finger in contact" in s["reason"] for s in a.skipped)


def test_summary_reports_the_baseline_and_how_sure(in_contact_import):
    s = in_contact_import[0]
    assert "stored baseline" in s["provenance"]["baseline"]
    assert "uncertain by" in s["provenance"]["baseline"]
    assert s["provenance"]["contact_method"] == "pattern"
    json.dumps(s)


def _rewrite_store(src: Path, dst: Path, edit) -> Path:
    """A copy of the run store ``src`` with its arrays edited by ``edit(dict of datasets)``."""
    import warnings

    import xarray as xr

    from tactile_flow.runstore import open_run
    tree = open_run(src).load()                  # a recording's directory store or an import's packed one
    d = edit({node.path: node.to_dataset() for node in tree.subtree})
    dst.mkdir()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        xr.DataTree.from_dict(d).to_zarr(str(dst / "run.zarr"), zarr_format=3, consolidated=True)
    return dst / "run.zarr"


@pytest.fixture(scope="module")
def pressed_store(rest, tmp_path_factory):
    """The real resting recording with ff pressed from 3 to 5 s, imported (no tare)."""
    tmp = tmp_path_factory.mktemp("pressed")

    def edit(c):
        c[300:500, 0, 20:24] -= 400
    (res,) = import_source(_csv_of(rest, tmp / "hand.csv", edit), tmp / "out", ImportSettings(rate_hz=100.0))
    return Path(res.store)


def test_shuffled_time_axis_is_refused(pressed_store, tmp_path):
    from tactile_flow.analysis.load import AnalysisInputError

    def shuffle(d):
        b = d["/biotac"]
        t = b["time"].values.copy()
        np.random.default_rng(0).shuffle(t)
        d["/biotac"] = b.assign_coords(time=t)
        return d
    with pytest.raises(AnalysisInputError, match="goes backwards at .* steps"):
        load_run(_rewrite_store(pressed_store, tmp_path / "s", shuffle))


def test_a_chunk_read_back_as_zeros_is_dropped_and_said(pressed_store, tmp_path, model):
    """A deleted chunk reads back as zeros (time and counts): those frames are dropped, named in
    ``skipped``, and the rest is analysed as before."""
    def zero_chunk(d):
        b = d["/biotac"]
        t = b["time"].values.copy()
        e = b["electrodes"].values.copy()
        t[600:700], e[600:700] = 0.0, 0
        d["/biotac"] = b.assign_coords(time=t).assign(electrodes=(b["electrodes"].dims, e, b["electrodes"].attrs))
        return d
    run = load_run(_rewrite_store(pressed_store, tmp_path / "z", zero_chunk))
    assert len(run.time) == 877 and run.dropped_invalid == 100
    a = analyse(run, CFG, model)
    assert any("out of order or repeated" in s["reason"] and s["frames"] == 100 for s in a.skipped)
    (start, stop), = a.contacts["ff"]
    assert abs(run.time[start] - 3.0) < 0.05 and abs(run.time[stop - 1] - 5.0) < 0.05


def test_electrodes_stuck_at_full_scale_set_the_finger_aside(pressed_store, tmp_path, model):
    def stuck(d):
        b = d["/biotac"]
        e = b["electrodes"].values.copy()
        e[:, 1, 3] = 4095                                       # mf's taxel 4 saturated throughout
        d["/biotac"] = b.assign(electrodes=(b["electrodes"].dims, e, b["electrodes"].attrs))
        return d
    a = analyse(load_run(_rewrite_store(pressed_store, tmp_path / "st", stuck)), CFG, model)
    assert "taxel(s) 4 outside 1..4094 counts throughout" in a.prepared.unusable["mf"]
    assert list(a.contacts) == ["ff"]

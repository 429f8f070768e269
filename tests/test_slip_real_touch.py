"""Real touches read as touches, and contacts the record cannot show well enough are not decided.

Real BioTac SP contact frames (``tests/data/biotac_sp_grasps``) held still under the real resting
recording's noise (``tests/real_touch.py``), as electrode-only CSVs imported and analysed as the
held-out records are: wherever a touch sits on the pad, however its sensor drifts, it is
``slip_class: none`` — the first thing the round-1 estimate got wrong on real data (26 of 44 real
touches read as translations, from where they sat). And the bad input of a slip estimate: a
contact too short to decide, a finger saturated or dead, a record with a gap in time: the slip
fields are null with the reason, and the other fingers are analysed.
"""

from __future__ import annotations

import numpy as np
import pytest

import real_touch as rt
from tactile_flow.analysis.config import load_config
from tactile_flow.analysis.load import load_run
from tactile_flow.analysis.pipeline import analyse
from tactile_flow.analysis.headline import whole_contact_slips
from tactile_flow.importers import ImportSettings, import_source

CFG = load_config({"figures": False, "progress": False})


@pytest.fixture(scope="module")
def touches(tmp_path_factory):
    """Two grasp files × 3 fingers × 4 frames, held from the first frame and reached from rest:
    48 records, each read by ``tactile-analyze``'s defaults."""
    tmp = tmp_path_factory.mktemp("real_touch")
    dirs = rt.write_records(tmp / "csv", per_finger=4, files=rt.GRASPS[2:4])
    return {kind: [row for d in ds for row in rt.read_as_touch(d, tmp / "imported" / kind, rt.BASELINE[kind])]
            for kind, ds in dirs.items()}


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["first", "rest"])
def test_real_contact_frames_held_still_read_as_touch(touches, kind):
    rows = touches[kind]
    assert len(rows) == 24
    read = [(r["record"], (r["slip"] or {}).get("slip_class")) for r in rows]
    touch = [name for name, cls in read if cls == "none"]
    assert len(touch) >= 0.95 * len(rows), [x for x in read if x[1] != "none"]
    for r in rows:
        s = r["slip"]
        if s and s["slip_class"] == "none":
            assert s["slip_onset_s"] is None and s["slip_direction_sensor_deg"] is None


def _pressed(counts, finger, a, b, drop=400):
    counts[a:b, finger, 20:24] -= drop


@pytest.fixture(scope="module")
def noise():
    return rt.rest_noise()


def _store(tmp_path, counts, time=None, fingers=("ff", "mf", "th")):
    """An electrode-only CSV of ``counts`` (T, F, 24) with an optional time column, imported."""
    names = [f"{f}_e{k}" for f in fingers for k in range(1, 25)]
    head = ("time," if time is not None else "") + ",".join(names)
    lines = [(f"{time[i]:.4f}," if time is not None else "") + ",".join(str(int(v)) for v in row.ravel())
             for i, row in enumerate(counts)]
    path = tmp_path / "rec.csv"
    path.write_text(head + "\n" + "\n".join(lines) + "\n")
    settings = ImportSettings(fingers=tuple(fingers)) if time is not None else ImportSettings(rate_hz=100.0,
                                                                                               fingers=tuple(fingers))
    (res,) = import_source(path, tmp_path / "out", settings)
    return load_run(res.store)


def _rest(noise, n):
    base = np.array([[3000.0] * 24] * 3)
    reps = int(np.ceil(n / len(noise)))
    return np.clip(base[None] + np.concatenate([noise] * reps)[:n], 1, 4094)


def test_a_contact_too_short_to_decide_says_so(noise, tmp_path, model):
    counts = _rest(noise, 400)
    _pressed(counts, 0, 200, 222)                  # 0.22 s: found (≥ 0.1 s), too short to decide
    a = analyse(_store(tmp_path, counts), CFG, model)
    slip = whole_contact_slips(a)["ff"]
    assert slip["slip_class"] is None and slip["confidence"] is None
    assert "too short to decide" in slip["reason"]


def test_a_gap_in_time_inside_a_contact_is_not_decided_across(noise, tmp_path, model):
    counts = _rest(noise, 500)
    _pressed(counts, 0, 100, 450)
    t = np.arange(500) * 0.01
    t[300:] += 0.25                                 # 0.25 s missing in the middle of the contact
    a = analyse(_store(tmp_path, counts, time=t), CFG, model)
    slip = whole_contact_slips(a)["ff"]
    assert slip["slip_class"] is None and "gap of 0.26" in slip["reason"]


def test_a_dead_or_saturated_finger_has_a_null_slip_and_the_others_are_read(noise, tmp_path, model):
    counts = _rest(noise, 500)
    _pressed(counts, 0, 100, 450)
    counts[:, 1] = 4095                              # mf saturated throughout
    counts[150:, 2] = 0                              # th dead from 1.5 s
    a = analyse(_store(tmp_path, counts), CFG, model)
    slips = whole_contact_slips(a)
    assert slips["ff"]["slip_class"] == "none" and slips["ff"]["reason"] is None
    for f in ("mf", "th"):
        assert slips[f]["slip_class"] is None and slips[f]["reason"].startswith("finger not analysed")

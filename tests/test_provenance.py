"""Provenance: what is collected, run.json written atomically, the same summary in the store."""

import json
import re
import threading

import numpy as np
import pytest

from tactile_flow.hardware.sim import make_sim_lab
from tactile_flow.runstore.provenance import collect, git_state, summary, write_run_json
from tactile_flow.protocols.store import RunStore, open_run

CONFIG = "protocol:\n  name: straws_sweep\n  sweep_speed: 10.0\nhardware:\n  backend: sim\n  seed: 3\n"


@pytest.fixture(scope="module")
def prov():
    lab = make_sim_lab({"seed": 3, "fingers": ["ff", "th"]})
    calibration = {"taxel_positions_mm": np.arange(72.0).reshape(24, 3),
                   "baselines": {f: b for f, b in lab.biotac.calibration.items()}}
    return collect(CONFIG, ["protocol.sweep_speed=10"], lab.identities(), calibration, seed=3,
                   protocol="straws_sweep")


def test_collect_has_every_required_field(prov):
    for key in ("run_id", "protocol", "start_time", "config_yaml", "config", "overrides", "git", "python",
                "packages", "host", "platform", "hardware", "calibration", "seed"):
        assert key in prov, key
    assert re.fullmatch(r"[0-9a-f-]{36}", prov["run_id"]) and prov["start_time"].endswith("Z")
    assert prov["config_yaml"] == CONFIG and prov["config"]["protocol"]["sweep_speed"] == 10.0
    assert prov["overrides"] == ["protocol.sweep_speed=10"] and prov["seed"] == 3
    assert {"numpy", "zarr", "xarray"} <= set(prov["packages"]) and prov["python"]["version"].count(".") == 2
    assert prov["hardware"]["biotac"]["model"].startswith("SimBiotac")
    assert len(prov["calibration"]["baselines"]["th"]) == 24
    assert np.array(prov["calibration"]["taxel_positions_mm"]).shape == (24, 3)
    json.dumps(prov, allow_nan=False)                       # plain JSON all the way down


def test_git_state_of_this_checkout_and_of_a_non_repository(prov, tmp_path):
    g = prov["git"]
    if g["commit"] != "unknown":                            # the project is a git checkout here
        assert re.fullmatch(r"[0-9a-f]{40}", g["commit"]) and isinstance(g["dirty"], bool)
        assert re.fullmatch(r"[0-9a-f]{64}", g["diff_sha256"])
    assert set(git_state(tmp_path).values()) == {"unknown"}


def test_run_json_is_written_atomically_beside_the_store(prov, tmp_path):
    path = write_run_json(tmp_path, prov, "running")
    assert path == tmp_path / "run.json"
    stop = threading.Event()
    bad = []

    def reader():
        while not stop.is_set():
            try:
                json.loads(path.read_text())
            except (ValueError, FileNotFoundError) as e:    # a torn or missing file
                bad.append(e)

    t = threading.Thread(target=reader)
    t.start()
    for i in range(100):
        write_run_json(path, dict(prov, note="x" * (i * 500)), "running")
    stop.set()
    t.join()
    assert not bad
    doc = json.loads(write_run_json(path, prov, "success", "2026-01-01T00:00:00Z").read_text())
    assert doc["status"] == "success" and doc["end_time"] == "2026-01-01T00:00:00Z"
    assert doc["run_id"] == prov["run_id"]
    with pytest.raises(TypeError):
        write_run_json(path, dict(prov, bad=object()), "failed")
    assert json.loads(path.read_text())["status"] == "success"     # the old file is intact
    assert [p.name for p in tmp_path.iterdir()] == ["run.json"]     # no temporary left


def test_store_root_attrs_carry_the_same_provenance(prov, tmp_path):
    store = RunStore.create(tmp_path / "run.zarr", protocol=prov["protocol"], provenance=summary(prov))
    store.close("failed")
    write_run_json(tmp_path, prov, "failed", extra={"error": "boom", "store": "run.zarr"})
    a = open_run(store.path).attrs
    assert a["run_id"] == prov["run_id"] and a["provenance"] == prov
    doc = json.loads((tmp_path / "run.json").read_text())
    assert doc["git"] == a["provenance"]["git"] and doc["error"] == "boom" and doc["status"] == "failed"


def test_same_code_asks_git_and_the_packages_once_and_gives_the_same_answers(monkeypatch):
    """A dataset's import or analysis collects provenance for every run: within
    ``same_code()`` git and the installed packages are asked once (the code a process loaded
    does not change under it), the answers are those asked fresh, and a caller changing its
    copy changes nobody else's."""
    from tactile_flow.runstore import provenance as prov
    fresh = collect("a: 1", [], {}, {}, 0)
    calls = []
    real = prov._git
    monkeypatch.setattr(prov, "_git", lambda *a: calls.append(a) or real(*a))
    with prov.same_code():
        first = collect("a: 1", [], {}, {}, 0)
        n = len(calls)
        first["packages"]["numpy"] = "changed"
        second = collect("a: 1", [], {}, {}, 0)
        assert len(calls) == n                                   # git asked once
    assert second["git"] == fresh["git"] and second["packages"] == fresh["packages"]
    collect("a: 1", [], {}, {}, 0)
    assert len(calls) > n or fresh["git"]["commit"] == "unknown"  # outside the block: asked again

"""An import's store made in memory and packed at once is the store streamed into a directory
and then packed: the same members, byte for byte (``runstore.inmemory``).

A file of at most one import chunk (``chunk_frames``) takes the in-memory way; the same file
imported with smaller chunks is streamed into a directory store and packed (the way of a long
file). Every member of the two zips is compared: the chunks and every node's ``zarr.json``
byte for byte, the root's too (the consolidated metadata of every node) once the attributes
that name the import itself or its ``chunk_frames`` are set aside.
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np
import pytest

from tactile_flow.importers import ImportSettings, import_source, read_bag, select_fingers
from tactile_flow.importers import writer as writer_mod
from tactile_flow.runstore import open_group
from conftest import DATA
from test_import_bag import _write_ros2_bag
from test_import_csv import write_csv

BAG = DATA / "biotac_rest_untouched.bag"
#: root attributes that name the import itself (run id, times, provenance) or depend on its
#: chunk_frames setting (the import's options, what its first chunk showed, the baseline's details)
OWN = ("run_id", "start_time", "end_time", "provenance", "import", "baseline")


def members(store: Path) -> dict[str, bytes]:
    with zipfile.ZipFile(store) as z:
        return {i.filename: z.read(i) for i in z.infolist()}


def without_own(root: bytes) -> tuple[list, str]:
    """The root ``zarr.json``: its attributes' names, and the rest without :data:`OWN`."""
    meta = json.loads(root)
    names = list(meta["attributes"])
    for k in OWN:
        meta["attributes"].pop(k)
    return names, json.dumps(meta)


def import_both(tmp_path: Path, source: Path, frames: int, monkeypatch, **settings) -> tuple[list, list]:
    """``source`` imported in memory (one chunk) and streamed (chunks of half of it); the
    stores of each, in order."""
    ways = {}
    calls = []
    real = writer_mod.write_import_store

    def spy(prepared, store_path, *a, **k):
        calls.append(store_path.name)
        return real(prepared, store_path, *a, **k)

    monkeypatch.setattr(writer_mod, "write_import_store", spy)
    for name, chunk in (("memory", frames), ("streamed", max(1, frames // 2))):
        calls.clear()
        res = import_source(source, tmp_path / name, ImportSettings(chunk_frames=chunk, **settings))
        ways[name] = [Path(r.store) for r in res]
        assert set(calls) == {"run.zarr.zip" if name == "memory" else "run.zarr"}, calls
    return ways["memory"], ways["streamed"]


def assert_same_members(a: Path, b: Path) -> None:
    ma, mb = members(a), members(b)
    assert list(ma) == list(mb)                                   # the same keys, in the same order
    assert without_own(ma.pop("zarr.json")) == without_own(mb.pop("zarr.json"))
    different = [k for k in ma if ma[k] != mb[k]]
    assert not different, different
    with zipfile.ZipFile(a) as za, zipfile.ZipFile(b) as zb:
        assert [(i.filename, i.compress_type) for i in za.infolist()] == \
               [(i.filename, i.compress_type) for i in zb.infolist()]


def test_real_bag_three_fingers_with_vibration_and_host_times(tmp_path, monkeypatch):
    frames = read_bag(BAG).n_frames
    (mem,), (streamed,) = import_both(tmp_path, BAG, frames, monkeypatch)
    assert_same_members(mem, streamed)
    g = open_group(mem)
    assert g["biotac_pac"]["pac"].shape[1] == 3 and np.isfinite(g["biotac"]["host_time"][:]).all()


def test_ros2_bag(tmp_path, monkeypatch):
    _write_ros2_bag(tmp_path / "r2", n=150)
    (mem,), (streamed,) = import_both(tmp_path, tmp_path / "r2", 150, monkeypatch)
    assert_same_members(mem, streamed)


@pytest.mark.parametrize("kind", ["time_and_pressure", "electrodes_only_one_finger", "estimated_baseline"])
def test_csv_files(tmp_path, monkeypatch, kind):
    rec, _ = select_fingers(read_bag(BAG))
    d = tmp_path / "src"
    d.mkdir()
    n = 300
    settings = {}
    if kind == "time_and_pressure":
        write_csv(d / "a.csv", rec, rows=slice(0, n), time=np.arange(n) * 0.01 + 5.0)
        source = d / "a.csv"
    elif kind == "electrodes_only_one_finger":                      # no pdc, tdc, tac: removed
        write_csv(d / "a.csv", rec, fingers=["mf"], prefixed=False, channels=(), rows=slice(0, n))
        source, settings = d / "a.csv", {"rate_hz": 100}
    else:
        write_csv(d / "a.csv", rec, channels=(), rows=slice(0, n))
        write_csv(d / "b.csv", rec, channels=(), rows=slice(n, 2 * n))
        source, settings = d, {"rate_hz": 100, "baseline": "estimate"}
    mem, streamed = import_both(tmp_path, source, n, monkeypatch, **settings)
    assert len(mem) == len(streamed) >= 1
    for a, b in zip(mem, streamed):
        assert_same_members(a, b)
    if kind == "estimated_baseline":
        assert "biotac/baseline/zarr.json" in members(mem[0])
    if kind == "electrodes_only_one_finger":
        assert "pressure" not in open_group(mem[0])["biotac"] and "biotac/pressure/zarr.json" not in members(mem[0])

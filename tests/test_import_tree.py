"""Imports of whole dataset trees, and input that used to fail open (issue 13, item 16; issue
12's subfolders): a CSV tree imported and analysed in one call, bad files left out and
named, implausible rates and time jumps refused, a killed import's staging removed."""

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from conftest import DATA
from tactile_flow.runstore import store_url
from tactile_flow.importers import ImportInputError, ImportSettings, import_source, read_bag, select_fingers
from tactile_flow.importers.importer import ImportIncomplete
from test_import_csv import write_csv

IMPORT = [sys.executable, "-c", "from tactile_flow.importers.cli import main; main()"]
ANALYZE = [sys.executable, "-c", "from tactile_flow.analysis.cli import main; main()"]


@pytest.fixture(scope="module")
def rest():
    rec, _ = select_fingers(read_bag(DATA / "biotac_rest_untouched.bag"))
    return rec


def pressed(rec, start: int, stop: int, depth: int = 500):
    """``rec`` with ff pressed between frames ``start`` and ``stop`` (its counts fall under load)."""
    from dataclasses import replace
    e = rec.electrodes.copy()
    e[start:stop, 0, 8:16] -= depth
    return replace(rec, electrodes=e)


def dataset(root: Path, rest) -> list[str]:
    """A tree as published datasets lay it out: one folder per object, electrode-only CSVs
    without a time column (rate given), two of them called take1.csv."""
    files = {"bottle/take1.csv": pressed(rest, 300, 600), "bottle/take2.csv": rest,
             "sponge/take1.csv": pressed(rest, 200, 700, 300), "sponge/soft/take3.csv": rest, "top.csv": rest}
    for rel, rec in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        write_csv(root / rel, rec, prefixed=True, channels=())
    (root / "README.txt").write_text("not a recording")
    (root / ".hidden").mkdir()
    write_csv(root / ".hidden" / "skip.csv", rest, channels=())
    return sorted(files)


@pytest.mark.slow
def test_a_tree_of_csv_folders_imports_in_one_call_and_analyses(rest, tmp_path):
    rels = dataset(tmp_path / "data", rest)
    out = tmp_path / "imported"
    proc = subprocess.run([*IMPORT, f"source={tmp_path / 'data'}", f"out={out}", "rate_hz=100", "baseline=estimate"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    stores = sorted(p.relative_to(out).as_posix() for p in out.rglob("run.zarr.zip"))
    assert stores == sorted(str(Path(r).with_suffix("") / "run.zarr.zip") for r in rels)  # the tree, mirrored, packed
    files = [str(tmp_path / "data" / r) for r in ["top.csv", "bottle/take1.csv", "bottle/take2.csv",
                                                  "sponge/take1.csv", "sponge/soft/take3.csv"]]
    for rel in rels:
        run_dir = out / Path(rel).with_suffix("")
        sub = Path(rel).parent.as_posix() if "/" in rel else ""
        tree = xr.open_datatree(f"zip::{run_dir / 'run.zarr.zip'}", engine="zarr")   # by a string, as users do
        assert tree.attrs["import"]["subfolder"] == sub
        assert tree.attrs["import"]["source"] == str(tmp_path / "data" / rel)
        assert sorted(tree.attrs["baseline"]["details"]["files"]) == sorted(files)          # one pool for all
        assert tree.attrs["baseline"]["method"] == "estimated" and tree.attrs["import"]["rate_hz"] == pytest.approx(100)
        assert json.loads((run_dir / "run.json").read_text())["import"]["subfolder"] == sub
    analysed = subprocess.run([*ANALYZE, f"run={out}", "analysis.figures=false"], cwd=tmp_path,
                              capture_output=True, text=True, timeout=900)
    assert analysed.returncode == 0, analysed.stderr
    assert len([s for s in out.rglob("run.zarr.zip") if (s.parent / "analysis" / "summary.json").is_file()]) == len(rels)
    for pressed_take in ("bottle/take1", "sponge/take1"):           # issue 12: every record, the slip fields
        summary = json.loads((out / pressed_take / "analysis" / "summary.json").read_text())
        assert summary["headline"]["fingers_in_contact"] >= 1
        slip = summary["estimates"]["slip"]["ff"]
        assert slip["slip_class"] in ("translation", "rotation", "none") and 0 <= slip["confidence"] <= 1
        assert {"slip_direction_sensor_deg", "slip_displacement_mm", "rotation_deg", "evidence"} <= set(slip)


def test_bad_files_of_a_directory_are_named_and_the_good_ones_imported(rest, tmp_path):
    d = tmp_path / "session"
    write_csv((d / "a").mkdir(parents=True) or d / "a" / "good.csv", rest, channels=())
    write_csv(d / "b.csv", rest, channels=(), drop=("ff_e3",))
    (d / "c.csv").write_text("ff_e1\n1\n")
    write_csv(d / "d.csv", rest, channels=())
    with pytest.raises(ImportIncomplete) as info:
        import_source(d, tmp_path / "out", ImportSettings(rate_hz=100))
    failures = dict(info.value.failures)
    assert sorted(Path(p).name for p in failures) == ["b.csv", "c.csv"]
    assert "missing columns: ff_e3" in failures[str(d / "b.csv")]
    assert [Path(r.run_dir).relative_to(tmp_path / "out").as_posix() for r in info.value.results] == ["d", "a/good"]
    assert (tmp_path / "out" / "a" / "good" / "run.json").exists() and (tmp_path / "out" / "d" / "run.json").exists()
    assert not (tmp_path / "out" / "b").exists() and not (tmp_path / "out" / "c").exists()


@pytest.mark.slow
def test_the_cli_lists_every_bad_file_and_exits_2(rest, tmp_path):
    d = tmp_path / "session"
    d.mkdir()
    write_csv(d / "a.csv", rest, channels=())
    write_csv(d / "b.csv", rest, channels=(), extra=("oops",))
    write_csv(d / "c.csv", rest, channels=(), drop=("ff_e1",))
    proc = subprocess.run([*IMPORT, f"source={d}", "out=out", "rate_hz=100"], cwd=tmp_path, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    errors = [x for x in proc.stderr.splitlines() if x.startswith("import error: ")]
    assert len(errors) == 2 and "b.csv" in errors[0] and "c.csv" in errors[1]
    assert "1 of 3 files imported" in proc.stderr and "imported " in proc.stdout
    assert (tmp_path / "out" / "a" / "run.json").exists()


@pytest.mark.parametrize("rate", ["1e-308", "1e308", "0.01", "1e6", "inf"])
def test_implausible_rates_are_refused(rest, tmp_path, rate):
    src = write_csv(tmp_path / "x.csv", rest, channels=())
    with pytest.raises(ImportInputError, match=r"rate_hz=.*expected .*Hz in \[0.1, 10000\]") as info:
        import_source(src, tmp_path / "out", ImportSettings(rate_hz=float(rate)))
    assert len(str(info.value)) < 160 and not (tmp_path / "out").exists()


def with_time(path: Path, rec, t) -> Path:
    """A CSV of ``rec`` with a ``time`` column written to the microsecond."""
    lines = write_csv(path, rec, channels=()).read_text().splitlines()
    path.write_text("\n".join(["time," + lines[0]] + [f"{x:.6f},{row}" for x, row in zip(t, lines[1:])]) + "\n")
    return path


def test_a_jump_of_the_time_column_is_refused_and_a_gap_is_said(rest, tmp_path):
    t = np.arange(977) * 0.01
    t[500:] += 1e6
    src = with_time(tmp_path / "jump.csv", rest, t)
    with pytest.raises(ImportInputError, match=r"jump.csv line 502, column time: .* more than 3600 s"):
        import_source(src, tmp_path / "out", ImportSettings())
    t = np.arange(977) * 0.01
    t[500:] += 5.0
    src = with_time(tmp_path / "gap.csv", rest, t)
    lines = []
    (res,) = import_source(src, tmp_path / "out", ImportSettings(), console=lines.append)
    assert res.warnings == ["time column: 1 gap(s) longer than 10 x the median step, the largest 5.01 s at line 502"]
    assert "WARNING: time column: 1 gap(s)" in lines[0]
    assert xr.open_datatree(store_url(res.store), engine="zarr").attrs["import"]["reader"]["time_gaps"]["at_line"] == 502


@pytest.mark.slow
def test_a_killed_import_leaves_staging_that_the_next_import_removes(rest, tmp_path):
    big = np.tile(rest.electrodes, (60, 1, 1))                      # ~58 000 rows: seconds to import
    from dataclasses import replace
    n = len(big)
    rec = replace(rest, electrodes=big, seq=np.arange(n), device_time=np.arange(n) * 0.01, host_time=None)
    write_csv(tmp_path / "big.csv", rec, channels=())
    proc = subprocess.Popen([*IMPORT, f"source={tmp_path / 'big.csv'}", "out=out", "rate_hz=100"], cwd=tmp_path,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while not list((tmp_path / "out").glob(".big.importing-*")) and proc.poll() is None:
        assert time.monotonic() < deadline
        time.sleep(0.01)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    assert list((tmp_path / "out").glob(".big.importing-*"))
    import_source(write_csv(tmp_path / "small.csv", rest, channels=()), tmp_path / "out", ImportSettings(rate_hz=100))
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["small"]

"""Every analysis of a run kept, named, one of them current (issue 32, part 2).

Fast tests drive ``runstore.analyses`` on analysis directories written by hand; the slow ones
run ``tactile-analyze`` on a recorded run (sweeps on the joblib launcher, ``name=``,
``analysis.figures=false``, several processes at once).
"""

import errno
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import record_run
from tactile_flow.runstore import analyses

ANALYZE = [sys.executable, "-c", "from tactile_flow.analysis.cli import main; main()"]
RUN = [sys.executable, "-c", "from tactile_flow.protocols.cli import main; main()", "progress=false"]
QUIET = ("analysis.progress=false",)


def fake_analysis(directory: Path, analysis_id: str, score: bool = True) -> Path:
    """The files of an analysis as the analysis writes them (ids only)."""
    (directory / "analysis.zarr").mkdir(parents=True)
    (directory / "analysis.zarr" / "zarr.json").write_text(json.dumps({"attributes": {"analysis_id": analysis_id}}))
    (directory / "summary.json").write_text(json.dumps({"analysis_id": analysis_id, "headline": {"segments": 1}}))
    if score:
        (directory / "score.json").write_text(json.dumps({"analysis_id": analysis_id}))
    (directory / "figures").mkdir()
    (directory / "figures" / "pressure.png").write_bytes(b"png " + analysis_id.encode())
    return directory


def make(run: Path, name: str, analysis_id: str, **kw) -> Path:
    with analyses.staging(run) as staged:
        fake_analysis(staged, analysis_id)
        return analyses.commit(run, staged, name, {"analysis_id": analysis_id, "created": analysis_id, "key": name},
                               **kw)


def test_each_analysis_is_kept_and_the_pointer_chooses_the_current_one(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    assert analyses.state(run) == "missing" and analyses.current_dir(run) is None
    make(run, "farneback-aaa", "1" * 32)
    make(run, "dis-bbb", "2" * 32)
    assert os.readlink(run / "analysis") == "analyses/dis-bbb" and analyses.current_name(run) == "dis-bbb"
    assert json.loads((run / "summary.json").read_text())["analysis_id"] == "2" * 32     # the paths before 0.2
    assert (run / "figures" / "pressure.png").read_bytes() == b"png " + b"2" * 32
    assert [(a["name"], a["current"]) for a in analyses.listing(run)] == [("farneback-aaa", False), ("dis-bbb", True)]
    analyses.make_current(run, "farneback-aaa")
    assert analyses.current_name(run) == "farneback-aaa"
    assert json.loads((run / "score.json").read_text())["analysis_id"] == "1" * 32
    events = [json.loads(x)["event"] for x in (run / analyses.HISTORY).read_text().splitlines()]
    assert events == ["made", "made", "reused"]


def test_a_reproduction_is_compared_with_the_runs_analysis_of_the_same_settings(tmp_path):
    """The run was re-analysed with DIS after its Farneback analysis; its reproduction (on
    newer code, so its analysis's name differs) is analysed with Farneback: the comparison
    reads the run's Farneback analysis, not its current (DIS) one."""
    from tactile_flow.runstore.reproduce import _like

    def made(run, name, method, created):
        run.mkdir(exist_ok=True)
        with analyses.staging(run) as staged:
            fake_analysis(staged, created * 32)
            return analyses.commit(run, staged, name, {"analysis_id": created * 32, "created": created, "key": name,
                                                       "config": {"flow": {"method": method}, "figures": True}})

    run, new = tmp_path / "run", tmp_path / "new"
    made(run, "farneback-aaa", "farneback", "1")
    made(run, "dis-bbb", "dis", "2")
    assert analyses.current_name(run) == "dis-bbb"
    assert _like(run, made(new, "farneback-ccc", "farneback", "3")) == run / "analyses" / "farneback-aaa"
    assert _like(run, made(new, "dis-bbb", "dis", "4")) == run / "analyses" / "dis-bbb"       # same name
    assert _like(tmp_path / "never-analysed", new / "analyses" / "dis-bbb") is None


def test_links_planted_where_the_current_analysis_is_read_are_replaced_never_written_through(tmp_path):
    """``RUN/summary.json`` and ``RUN/analysis.zarr.zip`` planted as links to a file outside
    the run: the next analysis points the first at itself and removes the second (this
    analysis has no packed store); the file outside is never touched."""
    run = tmp_path / "run"
    run.mkdir()
    make(run, "farneback-aaa", "1" * 32)
    victim = tmp_path / "outside.zip"
    victim.write_bytes(b"precious")
    for name in ("summary.json", "analysis.zarr.zip"):
        (run / name).unlink(missing_ok=True)
        (run / name).symlink_to(victim)
    make(run, "dis-bbb", "2" * 32)
    assert os.readlink(run / "summary.json") == "analysis/summary.json"
    assert json.loads((run / "summary.json").read_text())["analysis_id"] == "2" * 32
    assert not os.path.lexists(run / "analysis.zarr.zip")
    assert victim.read_bytes() == b"precious" and not list(run.glob(".*.link"))


def test_a_process_killed_just_after_pointing_at_its_analysis_leaves_the_paths_that_read_it(tmp_path, monkeypatch):
    """The run's first analysis, its process ended right after the rename that makes it
    current (a worker killed by a Ctrl-C of the whole dataset's analysis): wherever
    ``RUN/analysis`` is, ``RUN/summary.json`` reads it (found missing on CI before)."""
    run = tmp_path / "run"
    run.mkdir()
    replace = os.replace

    def killed_after_pointing(src, dst, **kw):
        replace(src, dst, **kw)
        if dst == analyses.CURRENT:
            raise KeyboardInterrupt
    monkeypatch.setattr(os, "replace", killed_after_pointing)
    with pytest.raises(KeyboardInterrupt):
        make(run, "farneback-aaa", "1" * 32)
    assert os.readlink(run / "analysis") == "analyses/farneback-aaa"
    assert json.loads((run / "summary.json").read_text())["analysis_id"] == "1" * 32
    assert (run / "figures" / "pressure.png").exists() and (run / "score.json").exists()


def test_a_forced_replacement_exchanges_the_directories_and_keeps_the_old(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    make(run, "mine", "1" * 32)
    make(run, "mine", "2" * 32, replace=True)
    assert analyses.current_name(run) == "mine"
    assert json.loads((run / "analysis" / "summary.json").read_text())["analysis_id"] == "2" * 32
    kept = run / "analyses" / f"mine~{'1' * 8}"
    assert json.loads((kept / "summary.json").read_text())["analysis_id"] == "1" * 32


def test_a_file_system_without_links_gets_a_pointer_file(tmp_path, monkeypatch):
    run = tmp_path / "run"
    run.mkdir()

    def no_links(*a, **k):
        raise OSError(errno.EPERM, "Operation not permitted")
    monkeypatch.setattr(os, "symlink", no_links)
    make(run, "a", "1" * 32)
    make(run, "b", "2" * 32)
    assert (run / "analysis").read_text() == "analyses/b\n" and not os.path.lexists(run / "summary.json")
    assert analyses.current_dir(run) == run / "analyses" / "b"


def test_a_run_copied_with_its_links_followed_still_reads_and_takes_new_analyses(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    make(run, "a", "1" * 32)
    copy = tmp_path / "copy"
    shutil.copytree(run, copy, symlinks=False)                     # cp -rL: links became files
    assert not (copy / "analysis").is_symlink() and analyses.current_dir(copy) == copy / "analysis"
    assert analyses.is_complete(copy / "analysis") and analyses.current_name(copy) == "a"
    make(copy, "b", "2" * 32)
    assert os.readlink(copy / "analysis") == "analyses/b" and analyses.current_name(copy) == "b"


def test_debris_of_dead_analyses_is_removed_and_a_live_one_is_left_alone(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    make(run, "a", "1" * 32)
    dead = run / "analyses" / ".staging-dead"
    fake_analysis(dead, "9" * 32)
    (dead / ".lock").write_text("")                              # its process gone: the lock free
    (run / ".analysis-staging-1234").mkdir()                      # the layout before 0.2
    with analyses.staging(run) as live:
        removed = analyses.remove_debris(run)
        assert live.exists() and sorted(removed) == [".analysis-staging-1234", ".staging-dead"]
    assert analyses.current_name(run) == "a"


def test_a_pointer_that_leaves_analyses_is_not_followed(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    make(run, "a", "1" * 32)
    elsewhere = fake_analysis(tmp_path / "elsewhere", "6" * 32)
    os.unlink(run / "analysis")
    (run / "analysis").symlink_to(elsewhere)
    assert analyses.current_dir(run) == run / "analyses" / "a"


# ----------------------------------------------------------------------------- real analyses
@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    return record_run(tmp_path_factory.mktemp("rec"))


@pytest.fixture
def run(recorded, tmp_path):
    shutil.copytree(recorded, tmp_path / "run", ignore=shutil.ignore_patterns(".tactile.lock"))
    return tmp_path / "run"


@pytest.mark.slow
def test_a_sweep_over_flow_methods_on_joblib_keeps_both_analyses_and_names_each_row(run, tmp_path):
    """``tactile-analyze -m run=X analysis.flow.method=farneback,dis`` with the joblib launcher
    (before: one job failed on the run directory's lock, exit 1; both wrote the same outputs)."""
    proc = subprocess.run([*ANALYZE, "-m", f"run={run}", "analysis.flow.method=farneback,dis", *QUIET,
                           "analysis.figures=false", "hydra/launcher=joblib", "hydra.launcher.n_jobs=2",
                           f"hydra.sweep.dir={tmp_path / 'sweep'}"], cwd=tmp_path, capture_output=True, text=True,
                          timeout=600)
    assert proc.returncode == 0, proc.stderr
    kept = {a["name"]: a for a in analyses.listing(run)}
    assert sorted(n.split("-")[0] for n in kept) == ["dis", "farneback"]
    assert {a["config"]["tactile"]["flow"]["method"] for a in kept.values()} == {"dis", "farneback"}
    table = (tmp_path / "sweep" / "analysis_summary.csv").read_text().splitlines()
    header = table[0].split(",")
    rows = [dict(zip(header, line.split(","))) for line in table[1:]]
    assert sorted(r["analysis"] for r in rows) == sorted(kept) and all(r["result"] == "analysed" for r in rows)


@pytest.mark.slow
def test_an_analysis_without_figures_leaves_the_earlier_figures_in_place(run):
    """Before: a batch with ``analysis.figures=false`` deleted every run's figures."""
    first = subprocess.run([*ANALYZE, f"run={run}", *QUIET, "analysis.max_segment_figures=1"], capture_output=True,
                           text=True, timeout=300)
    assert first.returncode == 0, first.stderr
    figures = {p.name: p.read_bytes() for p in (run / "analysis" / "figures").iterdir()}
    earlier = analyses.current_name(run)
    second = subprocess.run([*ANALYZE, f"run={run}", *QUIET, "analysis.figures=false"], capture_output=True,
                            text=True, timeout=300)
    assert second.returncode == 0, second.stderr
    assert analyses.current_name(run) != earlier and len(figures) >= 4
    assert {p.name: p.read_bytes() for p in (run / "analyses" / earlier / "figures").iterdir()} == figures


@pytest.mark.slow
def test_names_a_user_gives(run):
    """``name=``: kept under that name; a name taken by another config is refused in one line
    (exit 2, nothing written) unless ``force=true``; a name that leaves analyses/ is refused."""
    def analyze(*args):
        return subprocess.run([*ANALYZE, f"run={run}", *QUIET, "analysis.figures=false", *args], capture_output=True,
                              text=True, timeout=300)
    assert analyze("name=baseline").returncode == 0
    assert analyses.current_name(run) == "baseline"
    before = sorted(p.name for p in (run / "analyses").iterdir())
    taken = analyze("name=baseline", "analysis.flow.method=dis")
    assert taken.returncode == 2 and "name=baseline" in taken.stderr and "force=true" in taken.stderr, taken.stderr
    assert len(taken.stderr.strip().splitlines()) == 1 and sorted(p.name for p in (run / "analyses").iterdir()) == before
    for bad in ("../../escaped", "a/b", ".hidden"):
        refused = analyze(f"name={bad}")
        assert refused.returncode == 2 and "name:" in refused.stderr, refused.stderr
    assert not (run.parent / "escaped").exists()
    forced = analyze("name=baseline", "analysis.flow.method=dis", "force=true")
    assert forced.returncode == 0, forced.stderr
    meta = analyses.read_meta(run / "analyses" / "baseline")
    assert meta["config"]["tactile"]["flow"]["method"] == "dis" and meta["forced"]
    assert [p.name.split("~")[0] for p in (run / "analyses").iterdir() if "~" in p.name] == ["baseline"]


@pytest.mark.slow
def test_analyses_of_one_run_in_several_processes_at_once_are_all_kept(run):
    """Three ``tactile-analyze`` processes on one run at once, each another method or name:
    none fails on the lock, each analysis is kept whole, the journal has a line for each."""
    procs = [subprocess.Popen([*ANALYZE, f"run={run}", *QUIET, "analysis.figures=false", *extra],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for extra in (["analysis.flow.method=dis"], ["analysis.flow.method=farneback"], ["name=third"])]
    for p in procs:
        out, err = p.communicate(timeout=300)
        assert p.returncode == 0, err
    kept = analyses.listing(run)
    assert len(kept) == 3 and all(analyses.is_complete(a["path"]) for a in kept)
    assert len((run / analyses.HISTORY).read_text().splitlines()) == 3
    assert analyses.current_dir(run) is not None

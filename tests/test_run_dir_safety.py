"""Run directories stay where they belong and are written one way (issue 34, items 1-3).

- a path made from a config value (``protocol.name=../../X``, on the command line or as
  ``name:`` in a protocol file) never leaves its root (``runstore.paths``);
- no file of a run directory is ever written through a link planted in it: the lock,
  ``analysis_history.jsonl``, ``analysis_summary.md``... (``runstore.files``);
- a second ``tactile-run`` aimed at a finished run's directory is refused before anything in
  it changes: ``.hydra/*`` and the log keep their bytes.

The unit tests call the functions every command writes with; the slow ones run the real
commands in subprocesses.
"""

import logging
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import record_run
from tactile_flow.runstore import files, paths, rundir

RUN = [sys.executable, "-c", "from tactile_flow.protocols.cli import main; main()", "progress=false"]
ANALYZE = [sys.executable, "-c", "from tactile_flow.analysis.cli import main; main()", "analysis.progress=false",
           "analysis.figures=false"]


def snapshot(directory: Path) -> dict:
    """Every file below ``directory`` (links as their target's text) and its bytes."""
    out = {}
    for p in sorted(directory.rglob("*")):
        rel = str(p.relative_to(directory))
        if p.is_symlink():
            out[rel] = "-> " + os.readlink(p)
        elif p.is_file():
            out[rel] = p.read_bytes()
    return out


# ----------------------------------------------------------------------------- paths
@pytest.mark.parametrize("name", ["../../X", "a/b", "..", ".", "", ".hidden", "x\x00y", "x" * 200, "a\\b"])
def test_a_name_that_is_not_one_plain_component_is_refused_in_one_line(name):
    with pytest.raises(paths.PathOutsideRoot) as err:
        paths.component(name, "protocol.name")
    assert str(err.value).startswith("protocol.name: ") and "\n" not in str(err.value)


@pytest.mark.parametrize("text", ["../../../../X", "a/../../b", "..", "x" * 500, "é/ü", "-rf", ".ssh"])
def test_a_slug_is_always_one_component_that_cannot_climb(text, tmp_path):
    s = paths.slug(text)
    assert "/" not in s and ".." not in s and not s.startswith((".", "-")) and 0 < len(s) <= paths.MAX_COMPONENT
    assert paths.within(tmp_path, tmp_path / s, "x").parent == tmp_path.resolve()
    assert paths.slug("x" * 500) != paths.slug("x" * 499 + "y")        # long names stay apart


def test_within_follows_links_and_dot_dots(tmp_path):
    root = tmp_path / "outputs"
    root.mkdir()
    (root / "link").symlink_to(tmp_path)
    assert paths.within(root, root / "a" / "b", "d") == (root / "a" / "b").resolve()
    for escaping in (root / ".." / "x", root / "link" / "x", Path("/etc")):
        with pytest.raises(paths.PathOutsideRoot):
            paths.within(root, escaping, "hydra.run.dir")
    assert paths.template_root("outputs/${now:%Y}/${now:%H}_${tf_name:${protocol.name}}") == "outputs"
    assert paths.template_root("/data/runs/x") == "/data/runs/x"
    assert paths.template_root("${oc.env:HOME}/x") == "."


# ----------------------------------------------------------------------------- files
@pytest.fixture
def planted(tmp_path):
    """A run directory and, outside it, a victim file that links in the directory point at."""
    run = tmp_path / "run"
    run.mkdir()
    victim = tmp_path / "victim.txt"
    victim.write_text("precious\n")
    return run, victim


def test_the_lock_never_truncates_a_file_a_planted_link_points_at(planted):
    run, victim = planted
    (run / rundir.LOCK_NAME).symlink_to(victim)
    with pytest.raises(files.UnsafePath) as err:
        rundir.acquire(run)
    assert victim.read_text() == "precious\n" and "symbolic link" in str(err.value)
    assert rundir.holder(run) is None


def test_an_append_never_goes_through_a_link(planted):
    run, victim = planted
    (run / "analysis_history.jsonl").symlink_to(victim)
    with pytest.raises(files.UnsafePath):
        files.append_text(run, "analysis_history.jsonl", "{}\n")
    assert victim.read_text() == "precious\n"


def test_a_whole_file_write_replaces_a_planted_link_and_never_writes_its_target(planted):
    from tactile_flow.analysis.cli import write_table
    run, victim = planted
    (run / "analysis_summary.md").symlink_to(victim)
    (run / "analysis_summary.csv").symlink_to(victim)
    write_table(run, [{"run": "a", "result": "analysed"}, {"run": "b", "result": "analysed"}])
    assert victim.read_text() == "precious\n"
    assert not (run / "analysis_summary.md").is_symlink() and "| a | analysed |" in (run / "analysis_summary.md").read_text()


def test_directories_below_a_run_directory_are_never_entered_through_a_link(planted, tmp_path):
    run, victim = planted
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (run / ".hydra").symlink_to(elsewhere)
    with pytest.raises(files.UnsafePath):
        files.write_text(run, ".hydra/config.yaml", "x: 1\n")
    with pytest.raises(files.UnsafePath):
        files.make_dirs(run, ".hydra/sub")
    assert list(elsewhere.iterdir()) == []
    with pytest.raises(paths.PathOutsideRoot):
        files.write_text(run, "../escaped.txt", "x")
    assert not (tmp_path / "escaped.txt").exists()


def test_a_finished_runs_record_is_never_rewritten(planted):
    run, _ = planted
    files.write_text(run, ".hydra/config.yaml", "a: 1\n", record=True)
    files.write_text(run, "run.json", "{}\n")
    with pytest.raises(files.UnsafePath):
        files.write_text(run, ".hydra/config.yaml", "a: 2\n", record=True)
    with pytest.raises(rundir.RunFinished):
        rundir.refuse_finished(run)
    assert (run / ".hydra" / "config.yaml").read_text() == "a: 1\n"


def test_the_run_log_never_appends_to_a_finished_runs_log_nor_through_a_link(planted):
    run, victim = planted
    (run / "run.json").write_text("{}\n")
    (run / "tactile-run.log").write_text("the run's own lines\n")
    handler = rundir.RunLog(str(run / "tactile-run.log"))
    handler.emit(logging.LogRecord("x", logging.INFO, __file__, 1, "a second command's line", None, None))
    handler.close()
    assert (run / "tactile-run.log").read_text() == "the run's own lines\n"

    fresh = run.parent / "fresh"
    fresh.mkdir()
    (fresh / "tactile-run.log").symlink_to(victim)
    handler = rundir.RunLog(str(fresh / "tactile-run.log"))
    handler.emit(logging.LogRecord("x", logging.INFO, __file__, 1, "a line", None, None))
    handler.close()
    assert victim.read_text() == "precious\n"


# ----------------------------------------------------------------------------- the commands
EVIL_PROTOCOL = """# @package _global_
defaults:
  - /surface: straws
protocol:
  name: ../../../../escaped_by_file
  labels: [approach, before, during, after, lift]
  finger: ff
  sweep_speed: 10.0
  sweep_depth: 1.5
  steps:
    - move_to: {at: "before:first", height: 10.0}
    - approach: {depth: 1.5, until: {force: 15.0}}
    - sweep: {to: "after:last", speed: 10.0}
    - lift: {height: 20.0}
"""


@pytest.mark.slow
@pytest.mark.parametrize("how", ["command line", "protocol file", "sweep"])
def test_a_protocol_name_that_climbs_out_of_outputs_is_refused_and_makes_nothing_outside(tmp_path, how):
    """``protocol.name=../../../../X`` (before: the run directory landed at ``<cwd>/../X``, exit 0)."""
    work = tmp_path / "a" / "b" / "work"
    work.mkdir(parents=True)
    args = {"command line": ["protocol.name=../../../../escaped_by_cli"],
            "protocol file": [f"hydra.searchpath=[file://{tmp_path / 'shared'}]", "protocol=evil"],
            "sweep": ["protocol.name=../../../../escaped_by_sweep,straws_sweep", "protocol.sweep_speed=10"]}[how]
    (tmp_path / "shared" / "protocol").mkdir(parents=True)
    (tmp_path / "shared" / "protocol" / "evil.yaml").write_text(EVIL_PROTOCOL)
    before = {p for p in tmp_path.rglob("*") if "work" not in p.parts}
    command = [*RUN[:3], *(["-m"] if how == "sweep" else []), *RUN[3:], "analyze=false", *args]
    proc = subprocess.run(command, cwd=work, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2, (proc.stdout, proc.stderr)
    assert "protocol.name: '../../../../escaped_by" in proc.stderr and "Traceback" not in proc.stderr
    assert {p for p in tmp_path.rglob("*") if "work" not in p.parts} == before       # nothing made outside
    assert not list(tmp_path.rglob("escaped_by*"))
    made = [p for p in work.rglob("*") if p.is_dir() and p.parent.name != ".hydra"]
    for p in made:                                   # whatever was made is inside its root
        assert p.resolve().is_relative_to(work / ("multirun" if how == "sweep" else "outputs")), p
    if how == "sweep":                               # the other job ran; the refused one left no directory
        (job,) = [p.parent.name for p in work.glob("multirun/*/*/*/run.json")]
        assert job.startswith("1_straws_sweep_on_straws_"), job


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    return record_run(tmp_path_factory.mktemp("finished"))


@pytest.mark.slow
def test_a_second_run_aimed_at_a_finished_run_is_refused_before_anything_there_changes(finished, tmp_path):
    """Before: refused with one line, but only after Hydra had rewritten ``.hydra/config.yaml``,
    ``overrides.yaml`` and ``hydra.yaml`` and appended a traceback to the log."""
    run = tmp_path / "run"
    shutil.copytree(finished, run)
    before = snapshot(run)
    assert {".hydra/config.yaml", ".hydra/overrides.yaml", ".hydra/hydra.yaml", "tactile-run.log"} <= set(before)
    proc = subprocess.run([*RUN, "analyze=false", "protocol.sweep_speed=20", f"hydra.run.dir={run}"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "holds a finished run" in proc.stderr, proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1
    after = snapshot(run)
    after.pop(rundir.LOCK_NAME, None)
    before.pop(rundir.LOCK_NAME, None)
    assert after == before


@pytest.mark.slow
def test_an_analysis_refuses_links_planted_in_the_run_directory_and_writes_nothing_through_them(finished, tmp_path):
    """Before: the lock's target was truncated to the analysis's pid, a record appended to
    ``analysis_history.jsonl``'s target, ``analysis_summary.md``'s target overwritten."""
    runs = tmp_path / "runs"
    for name in ("a", "b"):
        shutil.copytree(finished, runs / name, ignore=shutil.ignore_patterns(rundir.LOCK_NAME))
    victims = {}
    for link, where in ((rundir.LOCK_NAME, runs / "a"), ("analysis_history.jsonl", runs / "b"),
                        ("analysis_summary.md", runs)):
        victim = tmp_path / f"victim_{link.strip('.')}"
        victim.write_text("precious\n")
        (where / link).symlink_to(victim)
        victims[link] = victim
    proc = subprocess.run([*ANALYZE, f"run={runs}"], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2, (proc.stdout, proc.stderr)
    assert all(v.read_text() == "precious\n" for v in victims.values())
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 2 and all("symbolic link" in x for x in lines), lines
    assert not (runs / "analysis_summary.md").is_symlink()          # the table replaced the link, not its target


@pytest.mark.slow
def test_a_sweep_aimed_at_an_earlier_sweep_is_refused_and_resuming_it_never_touches_the_finished_jobs(tmp_path):
    """Without ``resume=true`` a sweep directory holding runs is refused; with it, the jobs that
    succeeded are skipped and their ``.hydra/`` and log keep their bytes (before: Hydra rewrote
    every job's ``.hydra/*`` and the log got the skip line)."""
    sweep = [*RUN[:3], "-m", "progress=false", "analyze=false", "protocol.sweep_speed=10,20",
             f"hydra.sweep.dir={tmp_path / 'sweep'}"]
    assert subprocess.run(sweep, cwd=tmp_path, capture_output=True, text=True, timeout=300).returncode == 0
    jobs = sorted(p.parent for p in (tmp_path / "sweep").glob("*/run.json"))
    assert len(jobs) == 2
    before = {j.name: snapshot(j) for j in jobs}
    again = subprocess.run(sweep, cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert again.returncode == 2 and "holds the runs of an earlier sweep" in again.stderr, again.stderr
    resumed = subprocess.run([*sweep, "resume=true"], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert resumed.returncode == 0 and resumed.stdout.count("skipped") == 2, (resumed.stdout, resumed.stderr)
    for j in jobs:
        after = snapshot(j)
        for volatile in (rundir.LOCK_NAME, "job_result.json"):
            after.pop(volatile, None)
            before[j.name].pop(volatile, None)
        assert after == before[j.name], j

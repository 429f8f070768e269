"""Sweeps on Hydra's launchers (issue 15, goal 6): every job leaves its result on disk, so the
sweep's exit status and table come back from worker processes (joblib) and separate processes
(submitit) alike; ``tactile-analyze -m`` makes one job per run (or ``batch=N`` runs) from a
directory or a pattern; a job whose process dies is named and counts as failed."""

import csv
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from hydra._internal.core_plugins.basic_sweeper import BasicSweeper
from hydra.core.override_parser.overrides_parser import OverridesParser

from tactile_flow.analysis.cli import find_stores, quoted, run_specs, runs_as_jobs
import tactile_flow.cliapp.jobresults as jobresults

ANALYZE = "from tactile_flow.analysis.cli import main; main()"
RUN = "from tactile_flow.protocols.cli import main; main()"
QUIET = ("analysis.progress=false", "analysis.figures=false")
#: paths Hydra's override grammar would split or misread if they were not quoted
NASTY = ["a b", "c,d", "e=f", "g'h", "i\\", "j\\'k", "[l]", "m\"n", "${o}"]


def command(code, *args, cwd, timeout=300):
    return subprocess.run([sys.executable, "-c", code, *args], cwd=cwd, capture_output=True, text=True,
                          timeout=timeout)


def table(sweep_root: Path) -> list[dict]:
    (path,) = sweep_root.glob("multirun/*/*_analyze/analysis_summary.csv")
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def fake_store(path: Path) -> Path:
    path.mkdir(parents=True)
    (path / "zarr.json").write_text("{}")
    return path


# ----------------------------------------------------------------------------- fast
def test_every_path_survives_hydras_override_grammar_quoted():
    from omegaconf import OmegaConf
    for text in NASTY + ["/data/run 1/run.zarr", "plain"]:
        value = OverridesParser.create().parse_override(f"run={quoted(text)}").value()
        assert OmegaConf.create({"run": value}).run == text, text          # as the job reads it
        assert run_specs([f"run={quoted(text)}"]) == [text]
    assert run_specs([f"run=[{quoted('a,b')},{quoted('c d')}],[{quoted('e=f')}]"]) == ["a,b", "c d", "e=f"]


def test_packed_stores_are_found_beside_directory_stores(tmp_path):
    """An import's run store is one file, ``run.zarr.zip``: a directory, a pattern and the file
    itself name it as they name a recording's ``run.zarr``; nothing inside a store is a run."""
    recorded = fake_store(tmp_path / "day" / "a" / "run.zarr")
    imported = tmp_path / "day" / "b" / "run.zarr.zip"
    imported.parent.mkdir(parents=True)
    imported.write_bytes(b"PK")
    (tmp_path / "day" / "b" / "analyses" / "x").mkdir(parents=True)
    (tmp_path / "day" / "b" / "analyses" / "x" / "analysis.zarr.zip").write_bytes(b"PK")
    assert find_stores(str(tmp_path / "day")) == [recorded, imported]
    assert find_stores(str(tmp_path / "**" / "run.zarr.zip")) == [imported]
    assert find_stores(str(imported)) == [imported] and find_stores(str(imported.parent)) == [imported]


def test_runs_become_jobs_from_directories_patterns_and_lists(tmp_path):
    stores = [fake_store(tmp_path / "day" / name / "run.zarr") for name in NASTY + ["p", "q"]]
    expected = sorted(str(s) for s in stores)
    assert [str(s) for s in find_stores(str(tmp_path / "day"))] == expected
    assert [str(s) for s in find_stores(str(tmp_path / "**" / "run.zarr"))] == expected
    assert [str(s) for s in find_stores(str(tmp_path / "d?y" / "*"))] == expected      # each match searched below

    def jobs(*args):
        (run,) = [a for a in runs_as_jobs(["-m", *args]) if a.startswith("run=")]
        batches = BasicSweeper.split_arguments(OverridesParser.create().parse_overrides([run]), None)[0]
        return [run_specs(job) for job in batches]

    assert jobs(f"run={tmp_path / 'day'}") == [[s] for s in expected]
    assert jobs(f"run={tmp_path / '**' / 'run.zarr'}", "batch=4") == [expected[:4], expected[4:8], expected[8:]]
    one, two = quoted(expected[1]), quoted(expected[0])          # named twice (and below the directory): once
    assert jobs(f"run={one},{two},{quoted(str(tmp_path / 'day'))}", "batch=3") == \
        [[expected[1], expected[0], expected[2]], expected[3:6], expected[6:9], expected[9:]]
    assert runs_as_jobs([f"run={tmp_path}"]) == [f"run={tmp_path}"]                  # no -m: one process


def test_job_results_on_disk_make_the_sweeps_exit_code(tmp_path):
    for job, code in [(0, 0), (1, 2), (2, None)]:
        (tmp_path / str(job)).mkdir()
        (tmp_path / str(job) / jobresults.RESULT_FILE).write_text(json.dumps({"job": job, "code": code,
                                                                              "overrides": [f"x={job}"]}))
    (tmp_path / "3").mkdir()
    (tmp_path / "3" / jobresults.RESULT_FILE).write_text('{"job": 3, "co')           # cut short: no result
    results = jobresults.collect(tmp_path)
    assert [(r["job"], r["code"]) for r in results] == [(0, 0), (1, 2), (2, None), ("3", None)]
    assert jobresults.sweep_code(results) == 2 and jobresults.sweep_code(results[:1]) == 0
    assert jobresults.sweep_code([results[0], results[2]]) == 1                      # no result: failed
    assert jobresults.sweep_code([{"code": 3}, {"code": 2}, {"code": None}]) == 3    # interrupted stays
    assert jobresults.describe(results[1]) == "job 1 (x=1)"


# ----------------------------------------------------------------------------- processes
@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """Two short simulated runs (tactile-run -m, no analysis)."""
    cwd = tmp_path_factory.mktemp("recorded")
    proc = command(RUN, "-m", "protocol.steps=[{wait: {duration: 0.2}}]", "hardware.seed=1,2", "analyze=false",
                   "progress=false", cwd=cwd)
    assert proc.returncode == 0, proc.stderr
    stores = sorted(cwd.glob("multirun/*/*/*/run.zarr"))
    assert len(stores) == 2
    return stores


def runs_dir(recorded, root: Path, names, bad: str | None = None) -> Path:
    """``root/runs/<name>/run.zarr`` copies of the recorded runs, and with ``bad`` a run.zarr
    that is no store (its zarr.json is not JSON)."""
    for i, name in enumerate(names):
        shutil.copytree(recorded[i % len(recorded)], root / "runs" / name / "run.zarr")
    if bad:
        (root / "runs" / bad / "run.zarr").mkdir(parents=True)
        (root / "runs" / bad / "run.zarr" / "zarr.json").write_text("not json")
    return root / "runs"


@pytest.mark.slow
def test_analysis_sweep_on_joblib_exits_with_the_worst_job_and_tables_every_run(recorded, tmp_path):
    runs = runs_dir(recorded, tmp_path, ["one, two", "x=y z's ${HOME}"], bad="broken")
    proc = command(ANALYZE, "-m", f"run={runs}", "hydra/launcher=joblib", "hydra.launcher.n_jobs=2", *QUIET,
                   cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr                  # the bad run's job: bad input
    error, named = [line for line in proc.stderr.splitlines() if line.strip()]
    assert error == (f"error: {runs / 'broken' / 'run.zarr'}: cannot be read as a run store (JSONDecodeError: "
                     f"Expecting value: line 1 column 1 (char 0))")
    assert named.startswith("job 0 (") and named.endswith("): refused (bad input)")   # the sweep names its job
    rows = table(tmp_path)
    assert [(r["run"], r["result"].split(":")[0]) for r in rows] == [
        (str(runs / "broken" / "run.zarr"), "error"), (str(runs / "one, two" / "run.zarr"), "analysed"),
        (str(runs / "x=y z's ${HOME}" / "run.zarr"), "analysed")]
    assert (runs / "one, two" / "analysis" / "summary.json").is_file() and not (runs / "broken" / "analysis" / "summary.json").exists()

    shutil.rmtree(tmp_path / "multirun")
    shutil.rmtree(runs / "broken")
    proc = command(ANALYZE, "-m", f"run={tmp_path / '**' / 'run.zarr'}", "batch=2", "hydra/launcher=joblib",
                   "hydra.launcher.n_jobs=2", *QUIET, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert [r["result"] for r in table(tmp_path)] == ["analysed", "analysed"]
    (job,) = tmp_path.glob("multirun/*/*_analyze/*/job_result.json")               # two runs, one job
    assert json.loads(job.read_text())["code"] == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["multirun", "runs"]      # nothing else written here


@pytest.mark.slow
def test_a_job_whose_process_dies_is_named_and_fails_the_sweep(recorded, tmp_path):
    """SIGKILL a joblib worker in the middle of its job: the launcher stops the sweep; the job
    is named in one line, every run is in the table, exit status 1, no traceback."""
    runs = runs_dir(recorded, tmp_path, [f"r{i}" for i in range(6)])
    proc = subprocess.Popen([sys.executable, "-c", ANALYZE, "-m", f"run={runs}", "batch=3", "hydra/launcher=joblib",
                             "hydra.launcher.n_jobs=2", *QUIET], cwd=tmp_path, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        started = [json.loads(p.read_text()) for p in tmp_path.glob("multirun/*/*/1/job_result.json")]
        if started and started[0]["code"] is None:              # job 1 began: its first run takes seconds
            os.kill(started[0]["pid"], signal.SIGKILL)
            break
        time.sleep(0.02)
    else:
        pytest.fail("job 1 never started, or the sweep ended first")
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 1, err
    assert "Traceback" not in err
    named = [line for line in err.splitlines() if line.startswith("job 1 (")]
    assert len(named) == 1 and "no result" in named[0] and f"pid {started[0]['pid']}" in named[0], err
    rows = table(tmp_path)
    assert sorted(r["run"] for r in rows) == [str(runs / f"r{i}" / "run.zarr") for i in range(6)]
    assert all(r["result"].startswith("failed: its job (1)") for r in rows if r["run"].split("/")[-2] >= "r3")


@pytest.mark.slow
def test_analysis_sweep_on_submitit_local(recorded, tmp_path):
    pytest.importorskip("hydra_plugins.hydra_submitit_launcher", reason="the [cluster] extra is not installed")
    runs = runs_dir(recorded, tmp_path, ["a", "b"])
    proc = command(ANALYZE, "-m", f"run={runs}", "hydra/launcher=submitit_local", *QUIET, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    rows = table(tmp_path)
    assert [(r["run"], r["result"]) for r in rows] == [(str(runs / n / "run.zarr"), "analysed") for n in "ab"]
    assert (runs / "b" / "analysis" / "analysis.zarr.zip").is_file()


@pytest.mark.slow
def test_simulated_sweep_on_joblib_exits_non_zero_when_a_job_fails(tmp_path):
    proc = command(RUN, "-m", "protocol.steps=[{wait: {duration: 0.2}}],[{wait: {duration: -1}}]", "analyze=false",
                   "progress=false", "hydra/launcher=joblib", "hydra.launcher.n_jobs=2", cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    assert "error: protocol.steps[0].wait.duration: expected a number > 0" in proc.stderr     # not blamed on a file
    (sweep,) = tmp_path.glob("multirun/*/*")
    (job,) = [p.name for p in sweep.iterdir() if p.is_dir()]                             # the bad job left none
    assert job.startswith("0_straws_sweep_on_straws_protocol.steps"), job
    rows = (sweep / "summary.csv").read_text().splitlines()[1:]
    assert len(rows) == 2 and ",success," in rows[0] and ",refused (bad input)," in rows[1]   # named, not hidden

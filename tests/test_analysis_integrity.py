"""A killed analysis leaves neither debris nor stale results, and resuming a sweep finishes it
(issue 13, item 9). Real runs, real ``tactile-analyze``/``tactile-run`` processes, SIGKILL."""

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tactile_flow.analysis.run import analyze_run
from tactile_flow.protocols.resume import analysis_state

pytestmark = pytest.mark.slow
RUN = [sys.executable, "-c", "from tactile_flow.protocols.cli import main; main()", "progress=false"]
ANALYZE = [sys.executable, "-c", "from tactile_flow.analysis.cli import main; main()"]
FAST = {"progress": False, "figures": False}


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    root = tmp_path_factory.mktemp("rec")
    proc = subprocess.run([*RUN, "analyze=false", "hydra.run.dir=run"], cwd=root, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr
    return root / "run" / "run.zarr"


@pytest.fixture
def store(recorded, tmp_path):
    shutil.copytree(recorded.parent, tmp_path / "run", ignore=shutil.ignore_patterns(".tactile.lock"))
    return tmp_path / "run" / "run.zarr"


def test_a_killed_analysis_leaves_debris_that_the_next_one_removes(store):
    proc = subprocess.Popen([*ANALYZE, f"run={store}", "analysis.figures=true"], cwd=store.parent,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 240
    while not list(store.parent.glob(".analysis-staging-*")) and proc.poll() is None:
        assert time.monotonic() < deadline
        time.sleep(0.005)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    assert list(store.parent.glob(".analysis-staging-*")) and analysis_state(store.parent) == "missing"

    lines = []
    analyze_run(store, FAST, console=lines.append)
    assert any("removed what a killed analysis left" in x for x in lines), lines
    assert not list(store.parent.glob(".analysis-*")) and analysis_state(store.parent) == "complete"


def _children(pid: int) -> set[int]:
    out = set()
    for t in Path(f"/proc/{pid}/task").glob("*/children"):
        try:
            out.update(int(c) for c in t.read_text().split())
        except (FileNotFoundError, ProcessLookupError):  # a thread just ended
            pass
    return out


def _cmdline(pid: int) -> bytes:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes()
    except (FileNotFoundError, ProcessLookupError):      # a short-lived child (git) just ended
        return b""


def _alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except (FileNotFoundError, ProcessLookupError):
        return False


def _analysis_with_figure_workers(store: Path) -> tuple[subprocess.Popen, set[int]]:
    """``tactile-analyze`` (figures on, 2 workers) in a session of its own, once its figure
    workers (forked: the same command line) are running."""
    proc = subprocess.Popen([*ANALYZE, f"run={store}", "analysis.figures=true", "analysis.workers=2",
                             "analysis.progress=false"], cwd=store.parent, start_new_session=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline, workers = time.monotonic() + 240, set()
    while not workers and proc.poll() is None:
        assert time.monotonic() < deadline
        workers = {c for c in _children(proc.pid) if _cmdline(c) == _cmdline(proc.pid)}
        time.sleep(0.002)
    assert workers, proc.communicate()
    return proc, workers


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="reads /proc (Linux)")
def test_ctrl_c_while_the_figure_workers_draw_stops_the_analysis_cleanly(store):
    """Ctrl-C at the terminal (SIGINT to the whole process group) while the figures are drawn:
    the workers ignore it, the analysis stops them, exits as interrupted and leaves nothing."""
    proc, workers = _analysis_with_figure_workers(store)
    os.killpg(proc.pid, signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 3 and "interrupted" in err, (proc.returncode, err)
    assert not list(store.parent.glob(".analysis-*")) and analysis_state(store.parent) == "missing"
    assert not any(_alive(c) for c in workers)


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="reads /proc (Linux)")
def test_an_analysis_killed_while_its_figure_workers_draw_leaves_no_worker(store):
    """The figures' forked workers end with their parent, even when it is SIGKILLed (they would
    otherwise wait for work forever)."""
    proc, workers = _analysis_with_figure_workers(store)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    deadline = time.monotonic() + 5
    try:
        while any(_alive(c) for c in workers):
            assert time.monotonic() < deadline, "figure workers outlived their killed analysis"
            time.sleep(0.05)
    finally:
        for c in filter(_alive, workers):
            os.kill(c, signal.SIGKILL)


def test_a_ctrl_c_as_the_figure_workers_start_leaves_no_worker_for_the_exit_to_wait_on(recorded, tmp_path,
                                                                                        monkeypatch):
    """Seen in CI: Ctrl-C landed while the pool was being started, inside ``FigureWriter()``
    (so no ``__exit__`` stopped it); the workers waited for work and the process's exit waited
    for them, forever, with Ctrl-C ignored by then. The interrupt lands after the first
    figure is queued (all workers forked): the workers are gone when it propagates."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    from tactile_flow.analysis import figures
    from tactile_flow.analysis.config import load_config
    from tactile_flow.analysis.load import load_run
    from tactile_flow.analysis.pipeline import analyse, get_model

    cfg = load_config({"progress": False})
    model = get_model(cfg.tactile)
    a = analyse(load_run(recorded), cfg, model)
    submit, calls = ProcessPoolExecutor.submit, []

    def interrupted(self, *args):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return submit(self, *args)
    monkeypatch.setattr(ProcessPoolExecutor, "submit", interrupted)
    before = set(multiprocessing.active_children())
    with pytest.raises(KeyboardInterrupt):
        figures.FigureWriter(a, model, tmp_path / "figures", cfg, workers=2)
    assert set(multiprocessing.active_children()) == before


def test_a_signal_while_the_figure_workers_fork_waits_for_them_and_never_reaches_them():
    """Around the workers' start SIGINT is noted, then raised once they are all known; a
    worker forked meanwhile inherits the noting handler, so a Ctrl-C at the terminal before it
    ignores SIGINT itself is dropped there, not a ``KeyboardInterrupt`` and a traceback."""
    from tactile_flow.analysis.figures import _signals_deferred

    with pytest.raises(KeyboardInterrupt):
        with _signals_deferred():
            pid = os.fork()
            if pid == 0:                       # the worker, before its own handlers
                code = 1
                try:
                    signal.raise_signal(signal.SIGINT)
                    code = 0
                finally:
                    os._exit(code)             # never back into pytest in a forked copy
            signal.raise_signal(signal.SIGINT)  # noted only
            assert os.waitpid(pid, 0)[1] == 0
            noted = True
    assert noted


def test_an_analysis_stopped_between_its_renames_is_incomplete_never_stale(store, monkeypatch):
    """The previous analysis's ``summary.json`` never stands beside another analysis's outputs:
    it goes first, the new one comes last (the renames are interrupted after the first)."""
    first = analyze_run(store, FAST, console=lambda *a: None)
    calls, replace = [], os.replace

    def interrupted(src, dst, *args, **kwargs):
        if any(p.parent.name.startswith(".analysis-") for p in (Path(src), Path(dst))):    # swap_in's renames
            calls.append(Path(dst).name)
            if len(calls) == 3:                # the old summary and analysis.zarr moved aside, the new ones not in
                raise KeyboardInterrupt
        return replace(src, dst, *args, **kwargs)
    monkeypatch.setattr(os, "replace", interrupted)         # zarr renames too: only swap_in's are stopped
    with pytest.raises(KeyboardInterrupt):
        analyze_run(store, FAST, console=lambda *a: None)
    monkeypatch.setattr(os, "replace", replace)
    assert calls == ["summary.json", "analysis.zarr", "analysis.zarr"]
    assert not (store.parent / "summary.json").exists()
    assert analysis_state(store.parent) in ("incomplete", "missing")

    second = analyze_run(store, FAST, console=lambda *a: None)
    assert second["analysis_id"] != first["analysis_id"] and analysis_state(store.parent) == "complete"


def test_outputs_of_two_analyses_side_by_side_are_incomplete(store, tmp_path):
    """What the previous code could leave (a kill between its renames): an old
    ``summary.json`` beside a new ``analysis.zarr``. The ids tell them apart."""
    analyze_run(store, FAST, console=lambda *a: None)
    old_summary = (store.parent / "summary.json").read_text()
    analyze_run(store, FAST, console=lambda *a: None)
    (store.parent / "summary.json").write_text(old_summary)
    assert analysis_state(store.parent) == "incomplete"


def test_resuming_a_sweep_analyses_a_run_whose_analysis_was_killed(tmp_path):
    sweep = ["-m", "protocol.sweep_speed=10,20", f"hydra.sweep.dir={tmp_path}/sweep"]
    proc = subprocess.run([*RUN[:3], *sweep, "progress=false"], cwd=tmp_path, capture_output=True, text=True,
                          timeout=600)
    assert proc.returncode == 0, proc.stderr
    jobs = sorted(p.parent for p in (tmp_path / "sweep").glob("*/run.json"))
    assert [analysis_state(j) for j in jobs] == ["complete", "complete"]
    (jobs[1] / "summary.json").unlink()                       # as a kill during its analysis leaves it
    run_id = json.loads((jobs[1] / "run.json").read_text())["run_id"]

    proc = subprocess.run([*RUN[:3], *sweep, "progress=false", "resume=true"], cwd=tmp_path, capture_output=True,
                          text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    assert "skipped" in proc.stdout and "analysing it again" in proc.stdout
    assert json.loads((jobs[1] / "run.json").read_text())["run_id"] == run_id      # not recorded again
    assert [analysis_state(j) for j in jobs] == ["complete", "complete"]
    table = (tmp_path / "sweep" / "summary.csv").read_text().splitlines()
    assert len(table) == 3 and all(",complete," in row for row in table[1:]), table

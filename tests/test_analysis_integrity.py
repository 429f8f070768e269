"""A killed analysis leaves neither debris nor stale results, and resuming a sweep finishes it
(issue 13, item 9); every analysis is kept and one is current, whatever moment a kill comes
(issue 32). Real runs, real ``tactile-analyze``/``tactile-run`` processes, SIGKILL."""

import json
import os
import shutil
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import pytest

from conftest import record_run
from tactile_flow.analysis.run import analyze_run
from tactile_flow.protocols.resume import analysis_state
from tactile_flow.runstore import analyses
from tactile_flow.runstore.packed import read_member

pytestmark = pytest.mark.slow
RUN = [sys.executable, "-c", "from tactile_flow.protocols.cli import main; main()", "progress=false"]
ANALYZE = [sys.executable, "-c", "from tactile_flow.analysis.cli import main; main()"]
FAST = {"progress": False, "figures": False}


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    return record_run(tmp_path_factory.mktemp("rec")) / "run.zarr"


@pytest.fixture
def store(recorded, tmp_path):
    shutil.copytree(recorded.parent, tmp_path / "run", ignore=shutil.ignore_patterns(".tactile.lock"))
    return tmp_path / "run" / "run.zarr"


def test_a_killed_analysis_leaves_debris_that_the_next_one_removes(store):
    proc = subprocess.Popen([*ANALYZE, f"run={store}", "analysis.figures=true"], cwd=store.parent,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 240
    while not list(store.parent.glob("analyses/.staging-*")) and proc.poll() is None:
        assert time.monotonic() < deadline
        time.sleep(0.005)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    assert list(store.parent.glob("analyses/.staging-*")) and analysis_state(store.parent) == "missing"

    lines = []
    analyze_run(store, FAST, console=lines.append)
    assert any("removed what a killed analysis left" in x for x in lines), lines
    assert not list(store.parent.glob("analyses/.staging-*")) and analysis_state(store.parent) == "complete"


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
    assert not (store.parent / "analyses").exists() and analysis_state(store.parent) == "missing"
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
    from tactile_flow.cliapp.workers import signals_deferred

    with pytest.raises(KeyboardInterrupt):
        with signals_deferred():
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


def whole_current(run_dir: Path) -> str:
    """The current analysis's name, after checking it is whole and the only one the run's paths
    show: ``summary.json``, its store (``analysis.zarr.zip``, or ``analysis.zarr`` of an analysis
    by 0.2.0 and before) and ``score.json`` of one analysis (one id),
    through ``analysis/`` and the paths of the layout before 0.2 alike; every kept analysis
    whole; nothing half-made visible."""
    current = analyses.current_dir(run_dir)
    assert current is not None and analyses.is_complete(current), current
    summary = json.loads((run_dir / "analysis" / "summary.json").read_text())
    assert summary == json.loads((run_dir / "summary.json").read_text())
    packed_now = (run_dir / "analysis" / analyses.PACKED_STORE).is_file()
    for link in ("analysis.zarr", analyses.PACKED_STORE):                 # no store link dangles
        assert not os.path.lexists(run_dir / link) or (run_dir / link).exists(), link
    zarr_json = read_member(run_dir / (analyses.PACKED_STORE if packed_now else "analysis.zarr"), "zarr.json")
    zattrs = json.loads(zarr_json)["attributes"]
    assert zattrs["analysis_id"] == summary["analysis_id"] == json.loads((run_dir / "score.json").read_text())["analysis_id"]
    for kept in analyses.listing(run_dir):
        assert analyses.is_complete(kept["path"]), kept
    return analyses.current_name(run_dir)


@pytest.mark.parametrize("force", [False, True])
def test_an_analysis_stopped_between_the_steps_of_its_commit_leaves_a_whole_current_analysis(store, monkeypatch,
                                                                                              force):
    """Interrupted at each step of its commit (``analysis.json`` written, renamed into
    ``analyses/``, the pointer changed, the journal), as a new analysis and as a forced
    replacement of the current one: the current analysis is always whole, the earlier one or
    the new one, and the next analysis finishes the job."""
    first = analyze_run(store, FAST, console=lambda *a: None)
    config = FAST if force else {**FAST, "flow": {"method": "dis"}}
    real_write, real_rename, real_point = analyses.files.write_text, os.rename, analyses._point

    def write(directory, name, *a, **k):
        if name == analyses.META:
            raise KeyboardInterrupt
        return real_write(directory, name, *a, **k)

    def rename(src, dst, *a, **k):
        real_rename(src, dst, *a, **k)
        if Path(dst).parent.name == analyses.ANALYSES:
            raise KeyboardInterrupt

    def point(*a):
        real_point(*a)
        raise KeyboardInterrupt

    def journal(*a):
        raise KeyboardInterrupt
    seen = set()
    for target, stop in ((analyses.files, ("write_text", write)), (os, ("rename", rename)),
                         (analyses, ("_point", point)), (analyses, ("_journal", journal))):
        monkeypatch.setattr(target, *stop)
        with pytest.raises(KeyboardInterrupt):
            analyze_run(store, config, force=force, console=lambda *a: None)
        monkeypatch.undo()
        seen.add(whole_current(store.parent))
        assert not list(store.parent.glob("analyses/.staging-*")) or stop[0] != "write_text"
    assert (first["analysis"] in seen) and (force or len(seen) == 2), seen
    final = analyze_run(store, config, console=lambda *a: None)
    assert whole_current(store.parent) == final["analysis"]
    assert (final["analysis"] == first["analysis"]) == force


def test_a_run_analysed_before_0_2_reads_as_it_is_and_is_adopted_by_the_next_analysis(store):
    """The layout before 0.2 (outputs as files in the run directory) reads as the current
    analysis; the next analysis moves it into analyses/legacy-<id>/ (kept) and goes beside it.
    Outputs of two analyses side by side (a kill in the old code's renames) are incomplete."""
    made = analyze_run(store, FAST, console=lambda *a: None)
    run = store.parent
    for name in ("summary.json", "analysis.zarr", "analysis.zarr.zip", "score.json", "figures"):  # the old layout
        if os.path.lexists(run / name):
            os.unlink(run / name)
    for item in (run / "analyses" / made["analysis"]).iterdir():
        if item.name == analyses.PACKED_STORE:                   # the store was a directory then
            with zipfile.ZipFile(item) as z:
                z.extractall(run / "analysis.zarr")
        elif item.name != "analysis.json":
            os.rename(item, run / item.name)
    shutil.rmtree(run / "analyses")
    os.unlink(run / "analysis")
    (run / "analysis_history.jsonl").unlink()
    assert analyses.state(run) == "complete" and analyses.current_dir(run) == run
    assert analyses.current_name(run) == "legacy"
    assert [a["name"] for a in analyses.listing(run)] == ["legacy"]

    dis = analyze_run(store, {**FAST, "flow": {"method": "dis"}}, console=lambda *a: None)
    kept = {a["name"]: a for a in analyses.listing(run)}
    assert set(kept) == {f"legacy-{made['analysis_id'][:8]}", dis["analysis"]} and kept[dis["analysis"]]["current"]
    assert json.loads((run / "analyses" / f"legacy-{made['analysis_id'][:8]}" / "summary.json").read_text())[
        "analysis_id"] == made["analysis_id"]
    assert whole_current(run) == dis["analysis"]

    old = run / "old"                                             # two analyses' outputs side by side
    old.mkdir()
    for name in ("summary.json", analyses.PACKED_STORE, "score.json"):
        shutil.copy(run / "analyses" / dis["analysis"] / name, old / name)
    shutil.copy(run / "analyses" / f"legacy-{made['analysis_id'][:8]}" / "summary.json", old / "summary.json")
    assert analyses.state(old) == "incomplete"


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="reads /proc (Linux)")
def test_sigkill_at_any_moment_leaves_the_previous_or_the_new_analysis_whole(store, tmp_path):
    """``tactile-analyze`` SIGKILLed at moments spread over its life (its length measured once)
    and at the steps of its commit (the staging directory made, the new analysis renamed into
    analyses/, the pointer changed): the run shows the earlier analysis or the new one, whole,
    never a mix; the next analysis removes the debris and the result is the same."""
    first = analyze_run(store, FAST, console=lambda *a: None)
    command = [*ANALYZE, "analysis.progress=false", "analysis.figures=true", "analysis.max_segment_figures=2",
               "analysis.flow.method=dis"]

    def attempt(run: Path, at=None, when=None):
        proc = subprocess.Popen([*command, f"run={run / 'run.zarr'}"], cwd=tmp_path, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True)
        t0 = time.monotonic()
        if when is not None:
            while not when(run) and proc.poll() is None:
                time.sleep(0.0005)
        elif at is not None:
            time.sleep(at)
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=60)
        return time.monotonic() - t0

    runs = []

    def copy(tag):
        run = tmp_path / f"run-{tag}"
        shutil.copytree(store.parent, run, symlinks=True, ignore=shutil.ignore_patterns(".tactile.lock"))
        runs.append(run)
        return run

    full = copy("full")
    proc = subprocess.run([*command, f"run={full / 'run.zarr'}"], cwd=tmp_path, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr
    took_name = whole_current(full)
    t0 = time.monotonic()
    subprocess.run([*command, f"run={copy('timed') / 'run.zarr'}"], cwd=tmp_path, capture_output=True, timeout=300)
    took = time.monotonic() - t0
    for i in range(6):
        attempt(copy(f"at{i}"), at=took * (i + 0.5) / 6)
    moments = {"staging": lambda r: any(r.glob("analyses/.staging-*")),
               "renamed": lambda r: (r / "analyses" / took_name).exists(),
               "pointed": lambda r: os.path.islink(r / "analysis") and os.readlink(r / "analysis").endswith(took_name)}
    for tag, when in moments.items():
        attempt(copy(tag), when=when)
    outcomes = set()
    for run in runs[2:]:
        name = whole_current(run)
        assert name in (first["analysis"], took_name), (run, name)
        outcomes.add(name)
        after = analyze_run(run / "run.zarr", {**FAST, "figures": True, "max_segment_figures": 2,
                                               "flow": {"method": "dis"}}, console=lambda *a: None)
        assert after["analysis"] == took_name and whole_current(run) == took_name
        assert not list(run.glob("analyses/.staging-*"))
    assert outcomes == {first["analysis"], took_name}, outcomes      # the kills fell on both sides of the commit


def test_resuming_a_sweep_analyses_a_run_whose_analysis_was_killed(tmp_path):
    sweep = ["-m", "protocol.sweep_speed=10,20", f"hydra.sweep.dir={tmp_path}/sweep"]
    proc = subprocess.run([*RUN[:3], *sweep, "progress=false"], cwd=tmp_path, capture_output=True, text=True,
                          timeout=600)
    assert proc.returncode == 0, proc.stderr
    jobs = sorted(p.parent for p in (tmp_path / "sweep").glob("*/run.json"))
    assert [analysis_state(j) for j in jobs] == ["complete", "complete"]
    shutil.rmtree(jobs[1] / "analyses")                       # as a kill during its only analysis leaves it
    (jobs[1] / "analysis").unlink()
    run_id = json.loads((jobs[1] / "run.json").read_text())["run_id"]

    proc = subprocess.run([*RUN[:3], *sweep, "progress=false", "resume=true"], cwd=tmp_path, capture_output=True,
                          text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    assert "skipped" in proc.stdout and "analysing it again" in proc.stdout
    assert json.loads((jobs[1] / "run.json").read_text())["run_id"] == run_id      # not recorded again
    assert [analysis_state(j) for j in jobs] == ["complete", "complete"]
    table = (tmp_path / "sweep" / "summary.csv").read_text().splitlines()
    assert len(table) == 3 and all(",complete," in row for row in table[1:]), table

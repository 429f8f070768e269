"""Conventional command lines (issue 16, items 2, 7, 8, 9): one line and exit 2 on bad input
in every command, nothing written to the working directory, no empty run directories, help
that says what a command does, with examples, exit codes and the config groups that apply."""

import subprocess
import sys
from pathlib import Path

import pytest

from tactile_flow.protocols.listing import listing, summary
from tactile_flow.runstore.recover import describe
from tactile_flow.validation.cli import ArgumentParser

ROOT = Path(__file__).resolve().parents[1]
COMMANDS = {
    "tactile-run": "from tactile_flow.protocols.cli import main; main()",
    "tactile-analyze": "from tactile_flow.analysis.cli import main; main()",
    "tactile-import": "from tactile_flow.importers.cli import main; main()",
    "tactile-recover": "import sys; from tactile_flow.runstore.recover import main; sys.exit(main())",
    "tactile-view": "import sys; from tactile_flow.viewer.cli import main; sys.exit(main())",
    "tactile-emulate": "import sys; from tactile_flow.hardware.emulators.cli import main; sys.exit(main())",
    "tactile-demo": "import sys; from tactile_flow.tactile.demo import main; sys.exit(main())",
}


def command(name, *args, cwd, timeout=240):
    return subprocess.run([sys.executable, "-c", COMMANDS[name], *args], cwd=cwd, capture_output=True,
                          text=True, timeout=timeout)


def lines(text):
    return [line for line in text.splitlines() if line.strip()]


# ----------------------------------------------------------------------------- fast
def test_argument_errors_are_one_line_and_exit_2(capsys):
    parser = ArgumentParser(prog="tactile-x")
    parser.add_argument("path")
    with pytest.raises(SystemExit) as e:
        parser.parse_args(["a", "--bogus"])
    err = capsys.readouterr().err
    assert e.value.code == 2 and lines(err) == ["tactile-x: error: unrecognized arguments: --bogus; "
                                                "see tactile-x --help"]


def test_the_list_names_every_protocol_surface_and_hardware_in_one_line_each():
    text = listing(ROOT / "conf")
    for group in ("protocol", "surface", "hardware", "experiment"):
        for f in (ROOT / "conf" / group).glob("*.yaml"):
            (line,) = [x for x in text.splitlines() if x.strip().split(" ")[0] == f.stem]
            assert len(line) < 140 and len(line.split(f.stem, 1)[1].strip()) > 10, line
    assert summary(ROOT / "conf" / "surface" / "bump.yaml") == "Bump: a spherical cap on the board."
    assert summary(ROOT / "conf" / "hardware" / "sim.yaml") == "the simulated lab."


def test_recover_says_what_it_did_in_a_sentence():
    done = describe({"path": "r/run.zarr", "status": "crashed", "last_sample_s": 12.345, "trimmed": {"a": 3, "b": 2},
                     "dropped_unpublished": ["truth"], "action": "recovered"})
    assert done == ("r/run.zarr: recovered as crashed; its data ends at 12.35 s of run time; 5 rows written after "
                    "the last commit were dropped; 1 unpublished groups or arrays deleted; run.json written")
    assert describe({"path": "r/run.zarr", "status": "success", "action": "none: the run was closed"}) == \
        "r/run.zarr: nothing to do, the run was closed (success)"


def test_gitignore_covers_the_output_roots():
    ignored = (ROOT / ".gitignore").read_text().split()
    assert {"outputs/", "multirun/", "imported/"} <= set(ignored)


# ----------------------------------------------------------------------------- processes
@pytest.mark.slow
@pytest.mark.parametrize("name, args, words", [
    ("tactile-run", ["protocol=nope"], "protocol=nope"),
    ("tactile-run", ["protocol.sweep_sped=10"], "did you mean `sweep_speed`?"),
    ("tactile-run", ["pour_grasp"], "pour_grasp: expected key=value; did you mean protocol=pour_grasp?"),
    ("tactile-analyze", ["run=x", "analysis.flow.methd=dis"], "did you mean `method`?"),
    ("tactile-analyze", [], "run: expected run=PATH"),
    ("tactile-analyze", ["-m", "run=glob(outputs/*/*)"], "glob() selects config options, not files"),
    ("tactile-analyze", ["."], ".: a run is named by run=PATH; expected: tactile-analyze run=."),
    ("tactile-analyze", ["-m", "run=.", "hydra/launcher=joblib"], "run=.: no run.zarr found"),
    ("tactile-analyze", ["-m", "run=x/run.zarr", "batch=0"], "batch=0: expected the number of runs per job"),
    ("tactile-import", [], "source: missing; expected source=PATH"),
    ("tactile-import", ["sorce=a.bag"], "did you mean `source`?"),
    ("tactile-recover", [], "the following arguments are required: paths"),
    ("tactile-recover", ["nowhere"], "not a run store"),
    ("tactile-view", ["run", "--bogus"], "unrecognized arguments"),
    ("tactile-emulate", ["--seed", "x"], "invalid int value"),
    ("tactile-emulate", ["--shear-kohm-per-n", "-1"], "expected a number of kΩ per N >= 0, got -1"),
    ("tactile-demo", ["--speed", "fast"], "invalid float value"),
])
def test_bad_input_is_one_line_and_exit_2_in_every_command(tmp_path, name, args, words):
    proc = command(name, *args, cwd=tmp_path, timeout=120)
    err = lines(proc.stderr)
    assert proc.returncode == 2 and len(err) == 1 and words in err[0], (proc.returncode, proc.stderr)
    assert "Traceback" not in proc.stderr and "To append" not in proc.stderr
    assert list(tmp_path.iterdir()) == []                          # nothing written, not even a log


def test_a_missing_protocol_names_the_ones_there_are(tmp_path):
    from tactile_flow.cliapp.runner import error_line
    from hydra.errors import MissingConfigException
    exc = MissingConfigException("In 'config': Could not find 'protocol/nope'\nAvailable options in 'protocol':"
                                 "\n\tpour_grasp\n\tstraws_sweep\nConfig search path:\n\tprovider=hydra",
                                 missing_cfg_file="protocol/nope")
    assert error_line(exc) == "protocol=nope: no such protocol; expected one of pour_grasp, straws_sweep"


@pytest.mark.slow
@pytest.mark.parametrize("name, first, must", [
    ("tactile-run", "tactile-run: run a protocol", ["examples:", "exit status:", "config groups", "protocol:",
                                                   "--list", "plan_only=true"]),
    ("tactile-analyze", "tactile-analyze: (re-)analyse recorded runs", ["examples:", "exit status:",
                                                                        "analysis: default"]),
    ("tactile-import", "tactile-import: bring a ROS bag or CSV", ["examples:", "exit status:", "source=PATH"]),
    ("tactile-recover", "usage: tactile-recover", ["close a run store left open", "examples:", "exit status:"]),
    ("tactile-view", "usage: tactile-view", ["a recorded run in the Rerun viewer", "Exit status:"]),
    ("tactile-emulate", "usage: tactile-emulate", ["the whole emulated lab", "hardware=lab_emulated",
                                                   "exit status:"]),
    ("tactile-demo", "usage: tactile-demo", ["tactile flow of a synthetic contact", "examples:", "exit status:"]),
])
def test_help_says_what_a_command_does_with_examples_and_exit_codes(tmp_path, name, first, must):
    proc = command(name, "--help", cwd=tmp_path, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith(first), proc.stdout[:200]
    for word in must:
        assert word in proc.stdout, (word, proc.stdout)
    assert len(proc.stdout.splitlines()) < 70 and "cli" not in proc.stdout.split("\n", 1)[0]
    assert "Powered by Hydra" not in proc.stdout and "sweep_speed: 10.0" not in proc.stdout   # no config dump
    if name == "tactile-analyze":
        assert "protocol:" not in proc.stdout and "hardware:" not in proc.stdout   # groups that do not apply
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_tactile_run_list(tmp_path):
    proc = command("tactile-run", "--list", cwd=tmp_path, timeout=60)
    assert proc.returncode == 0 and "straws_sweep" in proc.stdout and "lab_emulated" in proc.stdout
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_plan_only_and_a_failed_connection_leave_no_run_directory(tmp_path):
    proc = command("tactile-run", "plan_only=true", cwd=tmp_path)
    assert proc.returncode == 0 and "sweep" in proc.stdout
    proc = command("tactile-run", "hardware=lab", "hardware.arm.host=127.0.0.1", "+hardware.arm.connect_timeout_s=0.5",
                   "hardware.rosbridge.url=ws://127.0.0.1:9", "analyze=false", "progress=false", cwd=tmp_path)
    assert proc.returncode == 1 and len(lines(proc.stderr)) == 1 and "not reachable" in proc.stderr, proc.stderr
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_nothing_is_written_to_the_working_directory(tmp_path):
    """A sweep, the analysis of its directory and of a list of runs (-m), and an import: every
    file under outputs/ or multirun/ (or out=), none in the working directory."""
    proc = command("tactile-run", "-m", "protocol.steps=[{wait: {duration: 0.2}}]", "hardware.seed=1,2",
                   "analyze=false", "progress=false", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    (sweep,) = (tmp_path / "multirun").glob("*/*")
    proc = command("tactile-analyze", f"run={sweep}", "analysis.progress=false", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert (sweep / "analysis_summary.md").is_file() and (sweep / "analysis_summary.csv").is_file()
    stores = ",".join(str(p) for p in sorted(sweep.glob("*/run.zarr")))
    proc = command("tactile-analyze", "-m", f"run={stores}", "analysis.progress=false", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    (analyze_sweep,) = (tmp_path / "multirun").glob("*/*_analyze")
    assert (analyze_sweep / "analysis_summary.md").is_file() and (analyze_sweep / "multirun.yaml").is_file()
    proc = command("tactile-import", f"source={ROOT / 'tests' / 'data' / 'biotac_rest_untouched.bag'}", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "outputs" / "imported" / "biotac_rest_untouched" / "run.zarr.zip").is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["multirun", "outputs"]


# ----------------------------------------------------------------------------- item 6
class _Terminal:
    """A terminal's stream as tqdm sees it: text in, ``isatty`` true."""

    def __init__(self):
        self.text = ""

    def write(self, s):
        self.text += s

    def flush(self):
        pass

    def isatty(self):
        return True


def test_the_live_line_shows_under_the_progress_bars_on_a_terminal():
    from types import SimpleNamespace

    from tactile_flow.protocols.run import ProgressConsole
    term = _Terminal()
    screen = ProgressConsole(term)
    bar = screen.bar(SimpleNamespace(duration=4.0, index=3, step=SimpleNamespace(kind="hold")))
    show = screen.live_line()
    bar.update(1.0)
    show("ff ↓ 0.016 | th · 0.002 | slip: -")
    bar.update(1.0)
    show("ff ↓ 0.031 | th ↓ 0.020 | slip: ff release at 2.10 s")
    assert "step 03 hold" in term.text
    # the live line on the line under the bar (down one line, draw, back up), not over it
    assert "\n\rff ↓ 0.031 | th ↓ 0.020 | slip: ff release at 2.10 s\x1b[A" in term.text, repr(term.text)
    bar.close()
    screen.close()
    assert ProgressConsole(SimpleNamespace(isatty=lambda: False)).live_line() is None   # a pipe: bars only


@pytest.mark.slow
def test_a_simulated_sweep_runs_on_the_joblib_launcher(tmp_path):
    proc = command("tactile-run", "-m", "hydra/launcher=joblib", "hydra.launcher.n_jobs=2", "analyze=false",
                   "progress=false", "protocol.sweep_speed=10,20", cwd=tmp_path, timeout=300)
    assert proc.returncode == 0, proc.stderr
    [summary] = tmp_path.glob("multirun/*/*/summary.csv")
    rows = summary.read_text().splitlines()[1:]
    assert len(rows) == 2 and all(",success," in r for r in rows), rows


@pytest.mark.parametrize("entry", ["tactile_flow.protocols.entry", "tactile_flow.analysis.entry"])
def test_help_into_a_closed_pipe_is_no_error(entry):
    """``tactile-run --help | head -1``: the reader goes away first; no traceback, exit 0."""
    proc = subprocess.Popen([sys.executable, "-c", f"from {entry} import main; main()", "--help"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.close()                                   # before the child has written anything
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=60) == 0 and err == "", err


def test_a_caller_that_goes_on_after_an_app_keeps_its_garbage_collector():
    # The apps skip the collector's work at interpreter exit (everything is frozen then, from
    # an atexit handler); a process that calls one and goes on must still collect its cycles.
    code = ("import gc\n"
            "from tactile_flow.cliapp.runner import run_app\n"
            "run_app(lambda: None, argv=[])\n"
            "run_app(lambda: None, argv=[])\n"
            "a = []; a.append(a); del a\n"
            "print(gc.get_freeze_count(), gc.collect() > 0, gc.isenabled())\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["0", "True", "True"]

import signal
import subprocess
import sys
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

#: the real recordings the tests read (shipped with the project; attribution in DATA / "README.md")
DATA = Path(__file__).resolve().parent / "data"

# ----------------------------------------------------------------------------- test tiers
# `pytest` runs the fast tier (`-m 'not soak and not slow'`, pyproject.toml); `-m "not soak"`
# everything (CI, .ci/run, runs it in two parts: the `realtime` tests alone, the rest with `-n auto`). `realtime` tests wait on wall-clock emulators in other
# processes (they are also `slow`); `slow` ones run subprocesses, whole simulated runs with their
# analysis, or take more than a few seconds. Marks in a test module add to these tables.
#: test modules against the wall-clock emulators (UR controller, rosbridge, serial devices)
REALTIME_MODULES = {"test_ur10.py", "test_lab_emulated.py", "test_rosbridge.py", "test_serial_pour.py",
                    "test_serial_biotac.py"}
#: test modules of whole runs, analyses and command-line processes
SLOW_MODULES = {"test_reactive.py", "test_slip_in_place.py", "test_analysis_runs.py", "test_import_hostile.py",
                "test_cli.py", "test_faults.py", "test_hostile_input.py", "test_real_contact.py"}
#: single slow tests of otherwise fast modules (node id prefixes)
SLOW_TESTS = ("tests/test_geometry.py::test_accurate_geodesic_matches_principal_section_arc",
              "tests/test_long_records.py::test_a_record_analysed_in_pieces",
              "tests/test_long_records.py::test_tactile_analyze_streams_a_long_record",
              "tests/test_recorder.py::test_clock_model_matches_the_simulators_sample_times",
              "tests/test_recorder.py::test_sigkill_leaves_a_consistent_store_missing_at_most_one_second",
              "tests/test_guides.py::test_first_session_runs_plan_without_hardware",
              "tests/test_guides.py::test_the_copied_protocol_plans_as_the_guide_shows",
              "tests/test_guides.py::test_step_table_matches_the_code",
              "tests/test_guides.py::test_a_board_of_your_own_plans",
              "tests/test_interlocks.py::test_protective_stop_mid_sweep_aborts_or_recovers_per_config",
              "tests/test_interlocks.py::test_a_short_dropout_under_the_stale_limit_does_not_stop_the_run",
              "tests/test_protocols.py::test_pour_holds_until_the_bottle_has_slipped_out",
              "tests/test_sim_contact.py::test_the_shipped_calibration_is_what_the_script_derives_from_the_test_data",
              "tests/test_sim_determinism.py::test_same_seed_is_bit_identical_and_other_seeds_differ",
              "tests/test_online.py::test_memory_stays_flat_over_many_pushes",
              "tests/test_import_csv.py::test_recording_that_starts_in_contact_keeps_its_pressure_with_a_stored_calibration",
              "tests/test_viewer.py::test_bad_input_is_one_line_and_exit_2",
              "tests/test_viewer.py::test_the_core_packages_never_import_rerun",
              "tests/test_architecture.py::test_importing_a_package_loads_nothing_above_it",
              "tests/test_architecture.py::test_a_run_and_its_analysis_load_neither_scipy_signal_nor_spatial",
              "tests/test_recover.py::test_a_recovery_interrupted_at_any_step")


def pytest_configure(config):
    """The signal tests press Ctrl-C as a terminal does. A test run started in the background
    (``pytest &`` in a script, ``nohup``) inherits SIGINT ignored, and so would every program
    the tests start: give them Python's own handler back. The runs the tests make register in
    a catalogue of the test session's own (runstore/catalogue.py), never the user's."""
    if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    import os
    import tempfile
    os.environ["TACTILE_CATALOGUE"] = os.path.join(tempfile.mkdtemp(prefix="tactile-catalogue-"), "runs.sqlite")


@pytest.hookimpl(tryfirst=True)              # before `-m` deselects
def pytest_collection_modifyitems(config, items):
    for item in items:
        if item.path.name in REALTIME_MODULES or item.get_closest_marker("realtime"):
            item.add_marker(pytest.mark.realtime)
            item.add_marker(pytest.mark.slow)
        elif item.path.name in SLOW_MODULES or item.nodeid.startswith(SLOW_TESTS):
            item.add_marker(pytest.mark.slow)


@pytest.fixture(scope="session")
def cache_dir(tmp_path_factory):
    """A geodesic cache shared by the whole test session (built once, like a user's)."""
    return tmp_path_factory.mktemp("tactile-cache")


@pytest.fixture(scope="session")
def model(cache_dir):
    from tactile_flow.tactile.pipeline import TactileConfig, TactileModel
    return TactileModel.build(TactileConfig(), cache_dir=cache_dir)


#: the sensor models every per-sensor test runs for
SENSORS = ("biotac_sp", "biotac")


@pytest.fixture(scope="session", params=SENSORS)
def sensor_model(request, cache_dir):
    """The tactile model of each shipped BioTac (its views, its frame size), for the per-sensor
    tests; ``model.sensor.shape.pole`` is where its pad touches."""
    from tactile_flow.tactile.pipeline import TactileConfig, TactileModel
    from tactile_flow.tactile.sensor import builtin_sensor
    sensor = builtin_sensor(request.param)
    return TactileModel.build(TactileConfig(size=sensor.frame_size or (28, 40)), cache_dir=cache_dir, sensor=sensor)


@pytest.fixture
def rng():
    return np.random.default_rng(1234)


class EventLog:
    """The part of the recorder the run engine talks to, kept in memory: events, the run's
    time origin and the recording's health. Engine tests that need no store use it."""

    t0 = 0.0

    def __init__(self):
        self.events = []

    def event(self, kind, name, detail=None):
        self.events.append((kind, name, detail))

    def write_failure(self, max_age_s):
        return None

    def keep_up(self):
        pass

    def kinds(self):
        return [k for k, _, _ in self.events]


@contextmanager
def tmpfs(mount: Path, size: str):
    """A tmpfs of ``size`` (mount's syntax: ``3m``, ``2900k``) mounted at ``mount``: a small disk
    that fills up for real (the tests run as root, as CI does; otherwise they are skipped)."""
    import subprocess
    mount.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(mount)],
                      capture_output=True).returncode != 0:
        pytest.skip("needs root to mount a small tmpfs")
    try:
        yield mount
    finally:
        subprocess.run(["umount", "-l", str(mount)], capture_output=True)


def wait_for_store(directory: Path, timeout_s: float = 60.0) -> None:
    """Wait until a run started in ``directory`` has its ``run.zarr`` (or ``timeout_s``). The
    store is made in a hidden directory and renamed into place, so a walk of the tree can
    meet a directory that is gone a moment later: that walk just looks again."""
    import time
    deadline = time.time() + timeout_s
    while time.time() < deadline:
        try:
            if any(directory.rglob("run.zarr")):
                return
        except FileNotFoundError:
            pass
        time.sleep(0.1)


TACTILE_RUN = [sys.executable, "-c", "from tactile_flow.protocols.cli import main; main()", "progress=false"]


def record_run(root: Path) -> Path:
    """The default protocol recorded on the simulated lab, not analysed, by a real
    ``tactile-run`` process into ``root/run``; returns that run directory."""
    proc = subprocess.run([*TACTILE_RUN, "analyze=false", "hydra.run.dir=run"], cwd=root, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    return root / "run"

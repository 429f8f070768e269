"""Docs as tests (issue 34): every command README.md and the guides (``docs/*.md``) show runs in
a test, and the numbers they quote are the commands' own.

:func:`documented` extracts every command: each line of a fenced block that starts with a
command (``tactile-*``, ``python``, ``pytest``, ``pip``), and each inline ``code span`` that
does with at least one argument. :data:`TESTED` says, for each, where it runs:

- ``HERE``: run here, as written, from a scratch directory (exit 0);
- ``Variant(command, why)``: run here in a form a test machine can run (a placeholder filled,
  ``plan_only=true`` for the real robot or a 72-run grid, ``--save`` for a display), ``why`` says
  what differs;
- ``Options(why)``: a benchmark or a long job (its figures come from running it by hand, in
  ``docs/performance.md``): its ``--help`` is run here and every option the docs give must be in it;
- ``"tests/x.py::test"``: the test that runs it (or its concrete form, for a placeholder).

A command added to the docs without an entry here, an entry whose command left the docs, a
test that no longer exists, or a program or module that does not: each fails the fast test.
"""

from __future__ import annotations

import importlib.util
import json
import re
import shlex
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
WORDS = r"(?:tactile-[a-z]+|python3?|pytest|pip)"


def normal(command: str) -> str:
    """A command as one line: continuations joined, a trailing ``# comment`` and extra spaces dropped."""
    command = re.sub(r"\\\n\s*", " ", command.strip())
    return " ".join(re.sub(r"\s+#\s.*$", "", command).split())


def documented() -> dict[str, set[str]]:
    """Every command README.md and docs/*.md show → the files that show it."""
    out: dict[str, set[str]] = {}
    for path in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
        text = path.read_text()
        for block in re.findall(r"```[a-z]*\n(.*?)```", text, re.S):
            for line in re.sub(r"\\\n\s*", " ", block).splitlines():
                line = line.strip().removeprefix("$ ")
                if re.match(WORDS + r"\b", line):
                    out.setdefault(normal(line), set()).add(path.name)
        prose = re.sub(r"```.*?```", "", text, flags=re.S)
        for span in re.findall(r"`(" + WORDS + r" [^`]+)`", prose):
            out.setdefault(normal(span), set()).add(path.name)
    return out


@dataclass(frozen=True)
class Variant:
    command: str
    why: str


@dataclass(frozen=True)
class Options:
    why: str


HERE = "here"
BENCH = Options("a benchmark: minutes of measuring; figures from running it by hand, in docs/performance.md")
NUMBERS = "tests/test_docs_commands.py::test_the_measured_table_is_what_the_runs_give"
NO_DISPLAY = "no display on a test machine: the same replay written with --save"

TESTED: dict[str, object] = {
    # ------------------------------------------------------------------ install, the test suite
    'pip install -e . && tactile-run': "tests/test_cli.py::test_default_run_leaves_a_complete_store",
    'pip install -e ".[test]" && pytest -m "realtime and not soak" && pytest -m "not soak and not realtime" -n auto':
        "tests/test_docs_commands.py::test_the_suites_tiers_are_the_ones_the_docs_name",
    'pip install -e ".[cluster]"': "tests/test_launchers.py::test_analysis_sweep_on_submitit_local",
    'pip install -e ".[view]"': "tests/test_packaging.py::test_every_command_runs_from_an_empty_directory_with_the_checkouts_results",
    'pip install -e ".[view]" && tactile-view outputs/<date>/<time>_straws_sweep_on_straws --web':
        "tests/test_viewer.py::test_web_serves_the_viewer_on_this_machine_only_until_stopped",
    'pip install dist/tactile_flow-0.2.0-py3-none-any.whl':
        "tests/test_packaging.py::test_every_command_runs_from_an_empty_directory_with_the_checkouts_results",
    'pip install ur-rtde==1.6.5': "tests/test_ur10.py::test_connect_identity_and_interface",
    'python -m build': "tests/test_packaging.py::test_the_wheel_holds_one_top_level_name_its_configs_data_and_licence",
    'pytest -m "not soak"': "tests/test_docs_commands.py::test_the_suites_tiers_are_the_ones_the_docs_name",
    'pytest -m soak -s tests/test_soak.py': "tests/test_soak.py::test_one_hour_of_sweeps_loses_nothing_with_flat_memory",
    # ------------------------------------------------------------------ python modules and scripts
    'python -X importtime -c "import tactile_flow.protocols.cli, tactile_flow.protocols.run, tactile_flow.analysis.run"':
        HERE,
    'python -X importtime': Variant('python -X importtime -c "import tactile_flow.protocols.cli, '
                                    'tactile_flow.protocols.run, tactile_flow.analysis.run"', "the run's modules, as "
                                    "docs/performance.md gives them further down"),
    'python -m tactile_flow.hardware.sim.calibrate_contact tests/data/biotac_sp_grasps '
    'hardware/sim/biotac_contact_calibration.json':
        Variant("python -m tactile_flow.hardware.sim.calibrate_contact tests/data/biotac_sp_grasps {tmp}/contact.json",
                "the output to a scratch file, not over the shipped one"),
    'python -m tactile_flow.hardware.emulators.ur_controller --host 127.0.0.2 [--unlock-delay-s 5]':
        Options("a server that runs until stopped (tests/test_ur10.py drives it)"),
    'python -m tactile_flow.hardware.sim.calibrate BAG OUT.json':
        Variant("python -m tactile_flow.hardware.sim.calibrate tests/data/biotac_rest_untouched.bag {tmp}/rest.json",
                "the placeholders filled with the real bag shipped in tests/data"),
    'python -m tactile_flow.hardware.sim.calibrate_contact':
        Variant("python -m tactile_flow.hardware.sim.calibrate_contact tests/data/biotac_sp_grasps {tmp}/contact.json",
                "its arguments, as docs/simulator.md gives them"),
    'python -m tactile_flow.hardware.sim.contact_check': HERE,
    'python -m tactile_flow.tactile.warmup GROUP':
        "tests/test_warmup.py::test_a_first_analysis_compiles_in_children_and_then_nothing_itself",
    'python benchmarks/bench_analysis.py': BENCH,
    'python benchmarks/bench_catalogue.py': BENCH,
    'python benchmarks/bench_widths.py': BENCH,
    'python benchmarks/bench_widths.py --sensor biotac --gains 3 12 --seeds 0 --electrodes': BENCH,
    'python benchmarks/bench_import.py': BENCH,
    'python benchmarks/bench_kill.py': BENCH,
    'python benchmarks/bench_kill.py --trials 10': BENCH,
    'python benchmarks/bench_launchers.py --runs 8': BENCH,
    'python benchmarks/bench_launchers.py --runs 8 --repeat 2 --kind straws': BENCH,
    'python benchmarks/bench_launchers.py --runs 8 --repeat 3 --kind wait': BENCH,
    'python benchmarks/bench_link_loss.py --trials 5': BENCH,
    'python benchmarks/bench_long_analysis.py --hours 0.1 0.5 2 8': BENCH,
    'python benchmarks/bench_online.py': BENCH,
    'python benchmarks/bench_pipeline.py': BENCH,
    'python benchmarks/bench_pipeline.py --seconds 20 --naive-frames 10 --render exact': BENCH,
    'python benchmarks/bench_pipeline.py --seconds 20 --naive-frames 10 --render exact linear': BENCH,
    'python benchmarks/bench_recorder.py': BENCH,
    'python benchmarks/bench_store_files.py': BENCH,
    'python benchmarks/bench_recorder.py --sim-s 20 --repeat 2': BENCH,
    'python benchmarks/bench_recorder.py --sim-s 20 --repeat 3': BENCH,
    'python benchmarks/bench_sim.py': BENCH,
    'python benchmarks/bench_sim_vs_real.py': BENCH,
    'python benchmarks/bench_slip.py': BENCH,
    'python benchmarks/bench_slip.py --override hardware.sensor.shear_kohm_per_n=3': BENCH,
    'python benchmarks/bench_reflex.py': BENCH,
    'python benchmarks/bench_slip_direction.py': BENCH,
    'python benchmarks/bench_slip_direction.py --grid classic': BENCH,
    'python benchmarks/bench_slip_direction.py --grid varied': BENCH,
    'python benchmarks/bench_slip_direction.py --sensor biotac_sp --seeds 3 --real-touch 0': BENCH,
    'python benchmarks/bench_slip_direction.py --sensor biotac_sp --real-touch 0 --out DIR': BENCH,
    'python benchmarks/bench_slip_direction.py --sensor biotac_sp --real-touch 0 --set hardware.sensor.shear_kohm_per_n=3 '
    '--out /tmp/shear3': BENCH,
    'python benchmarks/bench_rotation_evidence.py --out /tmp/shear3 --set hardware.sensor.shear_kohm_per_n=3 '
    '--real-touch 6': BENCH,
    'python benchmarks/bench_rotation_evidence.py --out /tmp/shear3 --set hardware.sensor.shear_kohm_per_n=3 '
    '--seeds 2 --real-touch 6': BENCH,
    'python benchmarks/bench_speed.py': BENCH,
    'python benchmarks/bench_speed.py --only analysis': BENCH,
    'python benchmarks/bench_speed.py --only analysis --repeat 3': BENCH,
    'python benchmarks/bench_speed.py --only dis': BENCH,
    'python benchmarks/bench_speed.py --only farneback --repeat 3': BENCH,
    'python benchmarks/bench_speed.py --only firstrun --repeat 2': BENCH,
    'python benchmarks/bench_speed.py --only startup': BENCH,
    'python benchmarks/bench_speed.py --only workers --repeat 3': BENCH,
    'python benchmarks/bench_view.py': BENCH,
    'python benchmarks/probe_interrupts.py --copy RUN_DIR --at 0.3,0.9,1.5,2.1 --repeat 3 -- tactile-analyze run={dir} analysis.progress=false':
        BENCH,
    'python docs/make_figures.py': "tests/test_guides.py::test_gallery_script_makes_the_figures",
    'python docs/make_viewer_screenshot.py': Options("needs a browser with WebGL (docs/viewer.md)"),
    'python docs/protocol_tables.py': "tests/test_guides.py::test_step_table_matches_the_code",
    'python examples/first_touch.py outputs/<date>/<time>_first_touch':
        "tests/test_guides.py::test_first_touch_on_the_simulated_lab_finds_the_board",
    'python examples/open_run.py RUN_DIR': "tests/test_guides.py::test_open_run_example_prints_what_analysis_zarr_holds",
    # ------------------------------------------------------------------ tactile-analyze
    'tactile-analyze --help': HERE,
    "tactile-analyze -m 'run=outputs/**/run.zarr' batch=8 hydra/launcher=submitit_slurm hydra.launcher.partition=cpu "
    "hydra.launcher.timeout_min=30": "tests/test_launchers.py::test_analysis_sweep_on_submitit_local",
    'tactile-analyze -m run=...':
        "tests/test_launchers.py::test_analysis_sweep_on_joblib_exits_with_the_worst_job_and_tables_every_run",
    'tactile-analyze -m run=outputs hydra/launcher=joblib hydra.launcher.n_jobs=4':
        "tests/test_launchers.py::test_analysis_sweep_on_joblib_exits_with_the_worst_job_and_tables_every_run",
    'tactile-analyze -m run=outputs/2026-01-01 hydra/launcher=joblib hydra.launcher.n_jobs=2':
        "tests/test_launchers.py::test_analysis_sweep_on_joblib_exits_with_the_worst_job_and_tables_every_run",
    'tactile-analyze analysis.workers=2': "tests/test_analysis_runs.py::test_workers_give_identical_results",
    'tactile-analyze run=<default dry run> analysis.progress=false':
        "tests/test_analysis_runs.py::test_the_same_analysis_is_reused_and_a_forced_one_is_identical_and_keeps_the_old",
    'tactile-analyze run=OUT': "tests/test_import_tree.py::test_a_tree_of_csv_folders_imports_in_one_call_and_analyses",
    'tactile-analyze run=PATH [analysis.xxx=...]': "tests/test_analysis_runs.py::test_the_same_analysis_is_reused_and_a_forced_one_is_identical_and_keeps_the_old",
    'tactile-analyze run=outputs/imported/ds':
        "tests/test_import_tree.py::test_a_tree_of_csv_folders_imports_in_one_call_and_analyses",
    'tactile-analyze run=outputs/imported/rest/run.zarr.zip':
        "tests/test_import_bag.py::test_real_resting_recording_analyses_to_no_contact",
    'tactile-analyze run=…': "tests/test_analysis_runs.py::test_the_same_analysis_is_reused_and_a_forced_one_is_identical_and_keeps_the_old",
    'tactile-analyze run=… analysis.tactile.render=exact|linear': "tests/test_analysis_runs.py::test_sweep_labels_estimates_and_score",
    # ------------------------------------------------------------------ the others
    'tactile-emulate':
        "tests/test_lab_emulated.py::test_a_rehearsal_on_tactile_emulate_presses_finds_segments_and_leaves_no_links",
    'tactile-emulate --surface straws':
        "tests/test_lab_emulated.py::test_a_rehearsal_on_tactile_emulate_presses_finds_segments_and_leaves_no_links",
    'tactile-import calibration=': "tests/test_import_csv.py::test_calibration_file_per_finger",
    'tactile-import source=PATH': "tests/test_import_csv.py::test_electrode_only_file_with_rate",
    'tactile-import source=csvs/ rate_hz=100 baseline=estimate out=outputs/imported/session3':
        "tests/test_import_csv.py::test_directory_imports_one_store_per_file_with_estimated_baseline",
    'tactile-import source=dataset/ rate_hz=100 baseline=estimate out=outputs/imported/ds':
        "tests/test_import_tree.py::test_a_tree_of_csv_folders_imports_in_one_call_and_analyses",
    'tactile-import source=lab/rest.bag': "tests/test_import_bag.py::test_real_bag_keeps_three_fingers_drops_two",
    'tactile-import source=press.csv calibration=cal/mf.json fingers=[mf]':
        "tests/test_import_csv.py::test_single_sensor_calibration_file",
    'tactile-recover RUN_DIR': "tests/test_recover.py::test_recover_trims_uncommitted_rows_and_marks_crashed",
    'tactile-view --save': "tests/test_viewer.py::test_a_straws_sweep_replays_every_stream_on_the_run_timeline",
    'tactile-view RUN_DIR': "tests/test_viewer.py::test_without_a_display_tactile_view_asks_for_web_or_save",
    'tactile-view RUN_DIR --fps 100': Variant("tactile-view {run} --fps 100 --save {tmp}/run.rrd", NO_DISPLAY),
    'tactile-view RUN_DIR --save run.rrd': Variant("tactile-view {run} --save {tmp}/run.rrd", "the run filled in"),
    'tactile-view RUN_DIR --web': "tests/test_viewer.py::test_web_serves_the_viewer_on_this_machine_only_until_stopped",
    'tactile-analyze -m run=X analysis.flow.method=farneback,dis':
        "tests/test_analyses_kept.py::test_a_sweep_over_flow_methods_on_joblib_keeps_both_analyses_and_names_each_row",
    'tactile-analyze ... name=NAME': "tests/test_analyses_kept.py::test_names_a_user_gives",
    # ------------------------------------------------------------------ tactile-runs
    'tactile-runs diff': "tests/test_catalogue.py::test_show_and_diff_tell_what_a_run_is_whatever_its_name",
    'tactile-runs diff RUN_A RUN_B': "tests/test_catalogue.py::test_show_and_diff_tell_what_a_run_is_whatever_its_name",
    'tactile-runs index [PATH ...]': "tests/test_catalogue.py::test_index_notices_new_changed_moved_and_deleted_runs",
    'tactile-runs index outputs multirun': "tests/test_catalogue.py::test_index_notices_new_changed_moved_and_deleted_runs",
    'tactile-runs list [FILTER ...]': "tests/test_catalogue.py::test_the_issues_filter_and_every_kind_of_key",
    "tactile-runs list protocol=straws_sweep 'protocol.sweep_speed>=10' 'score.width_error_mm_median<1' "
    "since=2026-11-01": "tests/test_catalogue.py::test_the_issues_filter_and_every_kind_of_key",
    'tactile-runs list protocol=straws_sweep protocol.sweep_speed>=10 score.width_error_mm_median<1 status=success '
    'since=2026-11-01': "tests/test_catalogue.py::test_the_issues_filter_and_every_kind_of_key",
    'tactile-runs list|show|diff|index': "tests/test_catalogue.py::test_every_option_is_in_the_help",
    'tactile-runs reproduce': "tests/test_reproduce.py::test_a_run_from_a_search_path_folder_reproduces_bit_identical_after_the_folder_is_gone",
    'tactile-runs reproduce RUN --out elsewhere --allow-code-change':
        "tests/test_reproduce.py::test_a_run_on_an_edited_tree_is_refused_once_the_edit_is_gone_and_reproduces_with_its_diff",
    'tactile-runs reproduce RUN_DIR': "tests/test_reproduce.py::test_a_run_from_a_search_path_folder_reproduces_bit_identical_after_the_folder_is_gone",
    'tactile-runs reproduce multirun/2026-11-27/10-02-11-000000':
        "tests/test_docs_commands.py::test_a_sweeps_directory_reproduces_every_job",
    'tactile-runs reproduce outputs/2026-11-27/11-15-07-687911_straws_sweep_on_straws':
        "tests/test_reproduce.py::test_a_run_from_a_search_path_folder_reproduces_bit_identical_after_the_folder_is_gone",
    'tactile-runs show': "tests/test_catalogue.py::test_show_and_diff_tell_what_a_run_is_whatever_its_name",
    'tactile-runs show RUN': "tests/test_catalogue.py::test_show_and_diff_tell_what_a_run_is_whatever_its_name",
    # ------------------------------------------------------------------ tactile-run
    'tactile-run --help': HERE,
    'tactile-run --list': HERE,
    'tactile-run --version': HERE,
    "tactile-run 'hydra.searchpath=[file://./examples/conf]' protocol=first_touch":
        "tests/test_guides.py::test_first_touch_on_the_simulated_lab_finds_the_board",
    "tactile-run 'hydra.searchpath=[file://./examples/conf]' protocol=first_touch hardware=lab":
        "tests/test_guides.py::test_first_session_runs_plan_without_hardware",
    "tactile-run 'hydra.searchpath=[file://./examples/conf]' protocol=first_touch hardware=lab plan_only=true":
        "tests/test_guides.py::test_first_session_runs_plan_without_hardware",
    "tactile-run 'hydra.searchpath=[file://./my_conf]' hardware=our_lab plan_only=true":
        "tests/test_guides.py::test_first_session_search_path_of_two_directories",
    "tactile-run 'hydra.searchpath=[file://./my_conf]' protocol=sticks_sweep surface=ridges":
        "tests/test_guides.py::test_the_new_surface_kind_applies_plans_and_runs",
    "tactile-run 'hydra.searchpath=[file://./my_conf]' protocol=sticks_sweep surface=ridges plan_only=true":
        "tests/test_guides.py::test_the_new_surface_kind_applies_plans_and_runs",
    "tactile-run 'hydra.searchpath=[file://./my_conf]' protocol=sticks_sweep surface=tall_sticks":
        "tests/test_guides.py::test_a_board_of_your_own_runs_and_meets_the_targets",
    "tactile-run 'hydra.searchpath=[file://./my_conf]' protocol=sticks_sweep surface=tall_sticks plan_only=true":
        "tests/test_guides.py::test_a_board_of_your_own_plans",
    "tactile-run 'hydra.searchpath=[file://./my_conf]' protocol=straws_there_and_back":
        "tests/test_guides.py::test_the_copied_protocol_runs_and_ends_with_two_lines",
    "tactile-run 'hydra.searchpath=[file://./my_conf]' protocol=straws_there_and_back plan_only=true":
        "tests/test_guides.py::test_the_copied_protocol_plans_as_the_guide_shows",
    "tactile-run 'hydra.searchpath=[file://./my_conf]' protocol=straws_three_lines":
        "tests/test_guides.py::test_the_new_step_kind_plans_runs_and_enters_the_table",
    "tactile-run 'hydra.searchpath=[file://./my_conf]' protocol=straws_three_lines plan_only=true":
        "tests/test_guides.py::test_the_new_step_kind_plans_runs_and_enters_the_table",
    'tactile-run -m +experiment=slip_in_place_grid':
        Variant("tactile-run -m +experiment=slip_in_place_grid plan_only=true hydra.sweep.dir={tmp}/grid",
                "72 runs, an hour: every job composed and planned (the recorded grid: benchmarks/bench_slip_direction.py)"),
    'tactile-run -m +experiment=speeds_by_surface':
        Variant("tactile-run -m +experiment=speeds_by_surface plan_only=true hydra.sweep.dir={tmp}/speeds",
                "6 whole runs: every job composed and planned (a recorded sweep: tests/test_cli.py)"),
    'tactile-run -m ...': "tests/test_cli.py::test_multirun_two_by_two_gives_four_runs_and_a_summary",
    'tactile-run -m hydra/launcher=joblib hydra.launcher.n_jobs=2 protocol.sweep_speed=10,20':
        "tests/test_command_lines.py::test_a_simulated_sweep_runs_on_the_joblib_launcher",
    'tactile-run -m protocol=straws_sweep,sticks_sweep protocol.sweep_speed=5,10,20':
        Variant("tactile-run -m protocol=straws_sweep,sticks_sweep protocol.sweep_speed=5,10,20 plan_only=true "
                "hydra.sweep.dir={tmp}/sweep", "6 whole runs: every job composed and planned"),
    'tactile-run -m protocol=straws_sweep,sticks_sweep protocol.sweep_speed=5,10,20 hardware.sensor.shear_kohm_per_n=3 '
    'analysis.figures=false':
        Variant("tactile-run -m protocol=straws_sweep,sticks_sweep protocol.sweep_speed=5,10,20 "
                "hardware.sensor.shear_kohm_per_n=3 analysis.figures=false plan_only=true hydra.sweep.dir={tmp}/sweep3",
                "6 whole runs: every job composed and planned (their figures in docs/analysis.md, measured by hand)"),
    'tactile-run "hardware.fingertips.ff=[0,0,0,2.902453,-1.202235,0]" hardware.sensor.shear_kohm_per_n=G':
        Variant('tactile-run "hardware.fingertips.ff=[0,0,0,2.902453,-1.202235,0]" hardware.sensor.shear_kohm_per_n=3 '
                "plan_only=true", "G filled with 3, composed and planned (the turned tip's run: "
                "tests/test_direction_off_axis.py; the figures in docs/analysis.md, measured by hand)"),
    'tactile-run ... live.viewer=rerun': "tests/test_viewer.py::test_the_live_viewer_shows_every_frame_the_monitor_processed",
    'tactile-run ... protocol.sweep_speed=20': Variant("tactile-run protocol.sweep_speed=20 progress=false analyze=false",
                                                         "the default protocol for the '...'"),
    'tactile-run [overrides] analysis.figures=false':
        "tests/test_first_hour.py::test_a_reactive_pour_does_not_count_phases_it_never_reached_as_skipped",
    'tactile-run analyze=false hardware.seed=3': HERE,
    'tactile-run hardware.realtime=true': "tests/test_faults.py::test_sigterm_stops_safely_like_ctrl_c",
    'tactile-run hardware=lab': Variant("tactile-run hardware=lab plan_only=true", "no robot here: checked and planned"),
    'tactile-run hardware=lab protocol=straws_sweep plan_only=true': HERE,
    'tactile-run hardware=lab protocol=straws_sweep protocol.sweep_speed=5 progress=false live.enabled=true':
        Variant("tactile-run hardware=lab protocol=straws_sweep protocol.sweep_speed=5 progress=false "
                "live.enabled=true plan_only=true", "no robot here: checked and planned"),
    'tactile-run hardware=lab_emulated':
        "tests/test_lab_emulated.py::test_a_rehearsal_on_tactile_emulate_presses_finds_segments_and_leaves_no_links",
    'tactile-run hardware=lab_emulated ...':
        "tests/test_lab_emulated.py::test_a_rehearsal_on_tactile_emulate_presses_finds_segments_and_leaves_no_links",
    'tactile-run hardware=lab_emulated protocol=pour_grasp_reactive protocol.pour_rate=600':
        "tests/test_lab_emulated.py::test_the_emulated_reactive_pour_catches_the_slip_and_holds_the_bottle",
    'tactile-run live.viewer=rerun': "tests/test_viewer.py::test_the_live_viewer_shows_every_frame_the_monitor_processed",
    'tactile-run progress=false': "tests/test_cli.py::test_default_run_leaves_a_complete_store",
    'tactile-run protocol.sweep_speed=20 hardware.seed=3': HERE,
    'tactile-run protocol=P analyze=false': "tests/test_cli.py::test_default_run_leaves_a_complete_store",
    'tactile-run protocol=P protocol.sweep_speed=V analysis.figures=false':
        Variant("tactile-run protocol=sticks_sweep protocol.sweep_speed=20 analysis.figures=false progress=false",
                "P and V filled with one of the runs docs/analysis.md tables"),
    'tactile-run protocol=pour_grasp': NUMBERS,
    'tactile-run protocol=pour_grasp plan_only=true': HERE,
    'tactile-run protocol=pour_grasp hardware.sensor.shear_kohm_per_n=3':
        Variant("tactile-run protocol=pour_grasp hardware.sensor.shear_kohm_per_n=3 plan_only=true",
                "composed and planned (a 60 s run; its figures in docs/analysis.md, measured by hand)"),
    'tactile-run protocol=pour_grasp_reactive':
        "tests/test_first_hour.py::test_a_reactive_pour_does_not_count_phases_it_never_reached_as_skipped",
    'tactile-run protocol=pour_grasp_reactive hardware.sensor.shear_kohm_per_n=3 hardware.seed=1':
        "tests/test_reactive.py::test_at_a_realistic_shear_gain_the_reflex_still_holds_the_bottle",
    'tactile-run protocol=pour_grasp_reactive live.viewer=rerun':
        "tests/test_viewer.py::test_a_reactive_pour_replays_every_stream_and_the_live_verdicts",
    'tactile-run protocol=slip_in_place protocol.motion=rotate protocol.tare=false surface=cylinder': HERE,
    'tactile-run protocol=sticks_sweep': NUMBERS,
    'tactile-run protocol=straws_sweep hardware=sim': NUMBERS,
    'tactile-run protocol=straws_sweep live.enabled=true': HERE,
    'tactile-run protocol=straws_sweep surface=sticks':
        "tests/test_first_hour.py::test_the_readmes_same_sweep_on_another_board_succeeds",
    # ------------------------------------------------------------------ sensor models (docs/sensors.md)
    'python docs/make_sensor_figures.py':
        Variant("python docs/make_sensor_figures.py --out {tmp}/sensors", "the figures to a scratch folder"),
    'python docs/make_sensor_figures.py --sensor my_pad.yaml --out /tmp/check':
        Variant("python docs/make_sensor_figures.py --sensor tests/data/conf/sensor/flat_pad.yaml --out {tmp}/check",
                "the test suite's own new model for the guide's my_pad.yaml"),
    'tactile-run sensor=biotac': Variant("tactile-run sensor=biotac progress=false analysis.figures=false",
                                         "without figures: the targets are what is checked"),
    'tactile-run sensor=biotac protocol=pour_grasp':
        Variant("tactile-run sensor=biotac protocol=pour_grasp plan_only=true", "composed and planned (a 60 s run)"),
    'tactile-run -m +experiment=slip_in_place_grid sensor=NAME':
        Variant("tactile-run -m +experiment=slip_in_place_grid sensor=biotac plan_only=true hydra.sweep.dir={tmp}/grid",
                "72 runs: every job composed and planned for the classic BioTac"),
    'tactile-run hardware=lab_emulated sensor=biotac':
        Variant("tactile-run hardware=lab_emulated sensor=biotac plan_only=true",
                "no emulators running here: checked and planned"),
    'tactile-run hydra.searchpath=[file://<your configs>] sensor=<name>':
        "tests/test_flat_pad.py::test_the_flat_pad_runs_end_to_end_from_its_yaml_alone",
    'tactile-run --cfg job': HERE,
    'tactile-emulate --sensor biotac': Options("the emulators run until stopped (tests/test_rosbridge.py starts them "
                                               "with the classic model)"),
    'tactile-emulate --shear-kohm-per-n G': Options("the emulators run until stopped (tests/test_lab_emulated.py "
                                                   "starts them at gains 3 and 12)"),
    'tactile-emulate --sensor <your configs>/sensor/<name>.yaml':
        Options("the emulators run until stopped; --sensor takes a file as sensor= does"),
    'tactile-import source=lab/classic.csv':
        "tests/test_import_sensors.py::test_a_csv_of_either_biotac_imports_with_its_model_from_the_electrode_count",
    'tactile-import source=press.csv hydra.searchpath=[file://my_conf] sensor=my_pad':
        "tests/test_flat_pad.py::test_the_flat_pad_runs_end_to_end_from_its_yaml_alone",
    'tactile-analyze run=outputs/imported/classic/run.zarr.zip':
        "tests/test_sensor_cli.py::test_the_analysis_reads_a_store_with_its_model_and_refuses_another",
}


def program_exists(command: str) -> str | None:
    """Why the program of ``command`` does not exist (None if it does): a ``tactile-*`` script
    not declared, a ``python -m`` module not found, a ``python`` script not in the tree."""
    import tomllib
    words = shlex.split(command.split(" && ")[-1]) if "'" in command or '"' in command else command.split()
    first = words[0]
    if first.startswith("tactile-"):
        scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
        return None if first in scripts else f"{first} is not a command of pyproject.toml"
    if first in ("python", "python3"):
        rest = [w for w in words[1:] if not w.startswith("-X") and w != "importtime"]
        if words[1:2] == ["-m"]:
            return None if importlib.util.find_spec(words[2]) else f"no module {words[2]}"
        if rest and rest[0].endswith(".py"):
            return None if (ROOT / rest[0]).is_file() else f"no file {rest[0]}"
        if "-c" in words:
            code = words[words.index("-c") + 1]
            missing = [m for m in re.findall(r"import ([\w.]+)", code.replace(", ", " import "))
                       if importlib.util.find_spec(m.split(".")[0]) is None or importlib.util.find_spec(m) is None]
            return f"no module {missing[0]}" if missing else None
    return None


# ----------------------------------------------------------------------------- fast: the list is the docs'
def test_every_documented_command_has_its_test_and_every_entry_is_documented():
    docs = documented()
    missing = sorted(set(docs) - set(TESTED))
    assert not missing, "documented commands without a test (add them to TESTED):\n" + "\n".join(
        f"  {c!r} ({', '.join(sorted(docs[c]))})" for c in missing)
    stale = sorted(set(TESTED) - set(docs))
    assert not stale, "TESTED lists commands the docs no longer show:\n" + "\n".join(f"  {c!r}" for c in stale)


@pytest.mark.parametrize("command", sorted(TESTED))
def test_each_command_names_a_program_that_exists_and_a_test_that_does(command):
    assert program_exists(command) is None, program_exists(command)
    how = TESTED[command]
    if isinstance(how, str) and how != HERE:
        path, _, name = how.partition("::")
        assert re.search(rf"^def {re.escape(name)}\(", (ROOT / path).read_text(), re.M), f"{how}: no such test"


def test_the_suites_tiers_are_the_ones_the_docs_name():
    """``pytest -m "realtime and not soak"`` and ``-m "not soak and not realtime"``: the markers exist."""
    import tomllib
    markers = " ".join(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["pytest"]["ini_options"]["markers"])
    assert all(m in markers for m in ("slow", "soak", "realtime"))


# ----------------------------------------------------------------------------- slow: run them
@pytest.fixture(scope="module")
def a_run(tmp_path_factory) -> Path:
    """A short recorded run, for the commands that take one."""
    cwd = tmp_path_factory.mktemp("a-run")
    proc = subprocess.run([str(BIN / "tactile-run"), "progress=false", "hydra.run.dir=run", "analysis.figures=false"],
                          cwd=cwd, capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return cwd / "run"


def _argv(command: str, tmp: Path, run: Path | None = None) -> list[str]:
    words = shlex.split(command.format(tmp=tmp, run=run))
    head = BIN / words[0] if words[0].startswith("tactile-") else sys.executable if words[0] == "python" else words[0]
    if words[0] == "python" and len(words) > 1 and (ROOT / words[1]).is_file():   # a script of the checkout's
        words[1] = str(ROOT / words[1])
    return [str(head), *words[1:]]


RUN_HERE = sorted(c for c, how in TESTED.items() if how == HERE or isinstance(how, Variant))


@pytest.mark.slow
@pytest.mark.parametrize("command", RUN_HERE)
def test_the_command_runs(command, tmp_path, request):
    how = TESTED[command]
    line = how.command if isinstance(how, Variant) else command
    run = request.getfixturevalue("a_run") if "{run}" in line else None
    proc = subprocess.run(_argv(line, tmp_path, run), cwd=ROOT if "tests/data" in line else tmp_path,
                          capture_output=True, text=True, timeout=1800, env={**__import__("os").environ,
                                                                            "MPLBACKEND": "Agg"})
    assert proc.returncode == 0, f"{line}: exit {proc.returncode}\n{proc.stdout[-1500:]}\n{proc.stderr[-1500:]}"
    assert "Traceback" not in proc.stderr
    if "tests/data" in line:
        shutil.rmtree(tmp_path, ignore_errors=True)


@pytest.mark.slow
@pytest.mark.parametrize("command", sorted(c for c, how in TESTED.items() if isinstance(how, Options)))
def test_a_long_commands_options_are_its_own(command):
    words = shlex.split(command)
    if words[0].startswith("tactile-"):
        argv = [str(BIN / words[0])]
    else:
        argv = [sys.executable, *words[1:3]] if words[1] == "-m" else [sys.executable, words[1]]
    proc = subprocess.run([*argv, "--help"], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-1500:]
    for option in re.findall(r"(?<![\w-])(--[a-z][\w-]*)", command.split(" -- ")[0]):
        assert option in proc.stdout, f"{command}: {option} is not an option of {argv[-1]}"


# ----------------------------------------------------------------------------- the numbers the docs quote
MEASURED = {"straws_sweep": "protocol=straws_sweep", "sticks_sweep": "protocol=sticks_sweep",
            "pour_grasp": "protocol=pour_grasp"}


@pytest.mark.slow
def test_the_measured_table_is_what_the_runs_give(tmp_path):
    """docs/analysis.md's "Measured" table and its pour phase errors are the commands' own
    (seed 0): ``tactile-run protocol=straws_sweep hardware=sim``, ``protocol=sticks_sweep``,
    ``protocol=pour_grasp``."""
    text = " ".join((ROOT / "docs" / "analysis.md").read_text().split())
    scores = {}
    for name, arg in MEASURED.items():
        proc = subprocess.run([str(BIN / "tactile-run"), arg, "hardware=sim", "progress=false",
                               f"hydra.run.dir={name}", "analysis.figures=false"], cwd=tmp_path,
                              capture_output=True, text=True, timeout=1800)
        assert proc.returncode == 0, proc.stderr[-2000:]
        scores[name] = json.loads((tmp_path / name / "score.json").read_text())
    for name in ("straws_sweep", "sticks_sweep"):
        s = scores[name]["summary"]
        row = (f"| {name} | {s['crossings_matched']}/{s['crossings_true']} (max {s['direction_error_deg_max']:.2f}°) "
               f"| {s['width_error_mm_median']:.2f} mm | {s['boundary_error_ms_median']:.1f} ms | – |")
        assert row in text, f"docs/analysis.md should read {row}"
    s, phases = scores["pour_grasp"]["summary"], scores["pour_grasp"]["pour"]
    row = (f"| pour_grasp | – | – | {s['boundary_error_ms_median']:.1f} ms (all five phases; max "
           f"{s['boundary_error_ms_max']:.1f} ms) | {s['slip_onset_error_ms']:+.1f} ms |")
    assert row in text, f"docs/analysis.md should read {row}"
    said = ", ".join(f"{n.replace('_', ' ')} {phases[n]['error_ms']:+.1f}".replace("-", "−")
                     for n in ("pour", "initial_slip", "rotation", "downward", "full_slip")) + " ms"
    assert f"(seed 0, `tactile-run protocol=pour_grasp`): {said}" in text, said


@pytest.mark.slow
def test_a_sweeps_directory_reproduces_every_job(tmp_path):
    """``tactile-runs reproduce multirun/...`` (docs/reproducibility.md): a recorded sweep's
    directory, every job done again and compared."""
    env = {**__import__("os").environ, "MPLBACKEND": "Agg"}
    sweep = subprocess.run([str(BIN / "tactile-run"), "-m", "protocol.sweep_speed=10,20", "analyze=false",
                            "progress=false", "hydra.sweep.dir=sweep"], cwd=tmp_path, capture_output=True, text=True,
                           timeout=900, env=env)
    assert sweep.returncode == 0, sweep.stderr[-1500:]
    again = subprocess.run([str(BIN / "tactile-runs"), "reproduce", "sweep"], cwd=tmp_path, capture_output=True,
                           text=True, timeout=900, env=env)
    assert again.returncode == 0, again.stderr[-1500:]
    assert again.stdout.count("reproduced: identical") == 2, again.stdout[-1500:]

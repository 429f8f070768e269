"""One check of the whole composed config before anything is written or moves (issue 34, items
5-7): the safety limits and the analysis are checked also with ``plan_only``, a misspelt label
cannot switch the analysis's scheme, and a bad key is the same one line whether it was typed on
the command line or written in a YAML file (then with the file and the line), with the nearest
known key. Fast checks call :func:`protocols.settings.run_settings`; the rest are real
``tactile-run`` processes."""

import subprocess
import sys

import pytest
from hydra import compose, initialize_config_dir

from tactile_flow.analysis.config import AnalysisConfig
from tactile_flow.hardware.config import SimConfig
from tactile_flow.protocols.cli import CONF_DIR
from tactile_flow.protocols.schema import register
from tactile_flow.protocols.settings import RunSettings, run_settings
from tactile_flow.validation import ConfigError

register()
RUN = [sys.executable, "-c", "from tactile_flow.protocols.entry import main; main()"]
SWEEP = (CONF_DIR / "protocol" / "straws_sweep.yaml").read_text()


def _cfg(*overrides):
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base=None):
        return compose("config", overrides=["analyze=false", "progress=false", *overrides])


def refused_key(*overrides) -> ConfigError:
    with pytest.raises(ConfigError) as info:
        run_settings(_cfg(*overrides))
    return info.value


def tactile_run(cwd, *args, timeout=120):
    return subprocess.run([*RUN, *args], cwd=cwd, capture_output=True, text=True, timeout=timeout)


def one_line(proc, code=2) -> str:
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert proc.returncode == code, proc.stderr + proc.stdout
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    return lines[0]


def user_conf(tmp_path, group: str, name: str, text: str) -> str:
    folder = tmp_path / "my_conf" / group
    folder.mkdir(parents=True, exist_ok=True)
    (folder / f"{name}.yaml").write_text(text)
    return "hydra.searchpath=[file://./my_conf]"


# ----------------------------------------------------------------------------- one typed config
def test_the_composed_config_becomes_one_typed_settings_object():
    settings = run_settings(_cfg("protocol.sweep_speed=20"))
    assert isinstance(settings, RunSettings) and run_settings(settings) is settings
    assert isinstance(settings.hardware, SimConfig) and isinstance(settings.analysis, AnalysisConfig)
    assert settings.protocol.sweep_speed == 20.0 and settings.protocol.steps[0].kind == "move_to"
    assert settings.safety.pdc_max == 3900.0 and settings.live.views == ["bottom"]
    assert "sweep_speed: 20.0" in settings.config_yaml


def test_the_real_lab_is_typed_too_without_building_a_driver():
    settings = run_settings(_cfg("hardware=lab"))
    assert settings.hardware.arm.max_speed_m_s == 0.25 and settings.hardware.arm.driver.host == "192.168.1.10"
    assert settings.hardware.pump.max_rate_ml_min == 105.0 and settings.hardware.stage is None


# ----------------------------------------------------------------------------- item 5: safety
@pytest.mark.parametrize("override, key", [
    ("safety.force_max=nan", "safety.force_max"), ("safety.force_max=inf", "safety.force_max"),
    ("safety.force_max=-1", "safety.force_max"), ("safety.recording_stall_s=nan", "safety.recording_stall_s"),
    ("safety.pdc_max=-1", "safety.pdc_max"), ("safety.stale_periods=0", "safety.stale_periods"),
    ("safety.electrode_min=5000", "safety.electrode_min"), ("safety.on_protective_stop=ignore", "safety.on_protective_stop")])
def test_every_safety_limit_is_a_finite_number_within_its_bounds(override, key):
    for plan_only in ("plan_only=true", "plan_only=false"):
        assert refused_key(override, plan_only).key == key


@pytest.mark.slow
@pytest.mark.parametrize("args", [("safety.force_max=nan", "plan_only=true"), ("safety.force_max=-1", "plan_only=true"),
                                  ("safety.pdc_max=-1",), ("safety.recording_stall_s=nan",)])
def test_a_bad_safety_limit_is_refused_before_anything_is_written(tmp_path, args):
    line = one_line(tactile_run(tmp_path, "analyze=false", "progress=false", *args))
    assert line.startswith(f"error: {args[0].split('=')[0]}: got ") and "expected" in line, line
    assert not (tmp_path / "outputs").exists()


# ----------------------------------------------------------------------------- item 6: analysis
def test_the_analysis_views_are_checked_with_the_run():
    err = refused_key("analysis.views=[bottom,lefft]", "plan_only=true")
    assert err.key == "analysis.views[1]" and "did you mean `left`?" in str(err)
    assert refused_key("analysis.tactile.render=fast").key == "analysis.tactile.render"


@pytest.mark.parametrize("labels, key, words", [
    ("[approach,before,durign,after,lift]", "protocol.labels[2]", "did you mean `during`?"),
    ("[pour,initial_slp,held]", "protocol.labels[1]", "did you mean `initial_slip`?"),
    ("[approach,before,after,lift]", "protocol.labels[1]", "select the generic scheme")])
def test_a_label_that_would_switch_the_analysis_scheme_is_refused(labels, key, words):
    err = refused_key(f"protocol.labels={labels}")
    assert err.key == key and words in str(err), str(err)


def test_labels_of_ones_own_still_name_a_generic_run():
    assert run_settings(_cfg("protocol.labels=[touch]")).protocol.labels == ["touch"]


@pytest.mark.slow
def test_a_bad_analysis_view_records_nothing(tmp_path):
    line = one_line(tactile_run(tmp_path, "progress=false", "analysis.views=[bottom,lefft]"))
    assert line == "error: analysis.views[1]: unknown view; expected one of bottom, left, right; did you mean `left`?"
    assert not (tmp_path / "outputs").exists()


@pytest.mark.slow
def test_a_misspelt_label_in_a_protocol_file_names_the_file_and_line(tmp_path):
    path = user_conf(tmp_path, "protocol", "mine", SWEEP.replace("name: straws_sweep", "name: mine")
                     .replace("during, after", "durign, after"))
    line = one_line(tactile_run(tmp_path, path, "protocol=mine", "plan_only=true"))
    assert "my_conf/protocol/mine.yaml line 10: protocol.labels[2]: unknown label 'durign'" in line, line
    assert line.endswith("did you mean `during`?")


# ----------------------------------------------------------------------------- item 7: one error line
@pytest.mark.slow
def test_a_bad_key_is_the_same_line_from_the_command_line_or_a_file(tmp_path):
    typed = one_line(tactile_run(tmp_path, "protocol.sweep_sped=3", "plan_only=true"))
    assert typed == ("error: protocol.sweep_sped: unknown key; expected one of the 26 keys of protocol; "
                     "did you mean `sweep_speed`?")
    path = user_conf(tmp_path, "protocol", "mine", SWEEP.replace("name: straws_sweep", "name: mine")
                     .replace("sweep_speed: 10.0", "sweep_sped: 10.0"))
    written = one_line(tactile_run(tmp_path, path, "protocol=mine", "plan_only=true"))
    where, _, rest = written.removeprefix("error: ").partition(": ")
    assert where.endswith("my_conf/protocol/mine.yaml line 12") and f"error: {rest}" == typed, written


@pytest.mark.slow
def test_a_value_of_the_wrong_type_is_one_line_from_either_place(tmp_path):
    typed = one_line(tactile_run(tmp_path, "protocol.sweep_speed=fast", "plan_only=true"))
    assert typed == "error: protocol.sweep_speed: got 'fast'; expected a number"
    path = user_conf(tmp_path, "protocol", "mine", SWEEP.replace("name: straws_sweep", "name: mine")
                     .replace("sweep_speed: 10.0", "sweep_speed: fast"))
    written = one_line(tactile_run(tmp_path, path, "protocol=mine", "plan_only=true"))
    assert written.endswith("mine.yaml line 12: protocol.sweep_speed: got 'fast'; expected a number"), written


@pytest.mark.slow
def test_a_step_value_set_from_the_command_line_is_not_blamed_on_the_file(tmp_path):
    line = one_line(tactile_run(tmp_path, "protocol.sweep_speed=300", "plan_only=true"))
    assert line.startswith("error: protocol.steps[3].sweep.speed: 300.0 mm/s exceeds"), line
    path = user_conf(tmp_path, "protocol", "mine", SWEEP.replace("name: straws_sweep", "name: mine")
                     .replace('speed: "${protocol.sweep_speed}"', "speed: 300"))
    line = one_line(tactile_run(tmp_path, path, "protocol=mine", "plan_only=true"))
    assert "mine.yaml line 18: protocol.steps[3].sweep.speed: 300.0 mm/s exceeds" in line, line


@pytest.mark.slow
def test_a_protocol_file_without_its_package_line_is_blamed(tmp_path):
    path = user_conf(tmp_path, "protocol", "nohead", SWEEP.replace("# @package _global_\n", "")
                     .replace("name: straws_sweep", "name: nohead"))
    line = one_line(tactile_run(tmp_path, path, "protocol=nohead", "plan_only=true"))
    assert "my_conf/protocol/nohead.yaml line" in line and "# @package _global_" in line, line
    assert "surface/straws" not in line


@pytest.mark.slow
def test_list_and_help_show_the_search_paths_protocols(tmp_path):
    path = user_conf(tmp_path, "protocol", "mine", SWEEP.replace("name: straws_sweep", "name: mine"))
    listed = tactile_run(tmp_path, path, "--list")
    assert listed.returncode == 0, listed.stderr
    lines = listed.stdout.splitlines()
    assert any(x.split()[:1] == ["mine"] and "[file://./my_conf]" in x for x in lines), listed.stdout
    assert any(x.split()[:1] == ["straws_sweep"] for x in lines)
    helped = tactile_run(tmp_path, path, "--help")
    assert helped.returncode == 0 and "protocol: mine, pour_grasp" in helped.stdout


@pytest.mark.slow
@pytest.mark.parametrize("extra", [("plan_only=true",), ("--list",), ("--help",)])
def test_a_misspelt_search_path_folder_is_an_error(tmp_path, extra):
    user_conf(tmp_path, "protocol", "mine", SWEEP.replace("name: straws_sweep", "name: mine"))
    line = one_line(tactile_run(tmp_path, "hydra.searchpath=[file://./my_cnof]", *extra))
    assert line == ("error: hydra.searchpath: file://./my_cnof: no such folder; expected file://<a folder "
                    "holding config groups: protocol/, surface/, ...>")


@pytest.mark.slow
def test_a_launcher_setting_without_its_launcher_says_what_to_add(tmp_path):
    line = one_line(tactile_run(tmp_path, "-m", "hydra.launcher.n_jobs=2", "plan_only=true"))
    assert line.startswith("error: hydra.launcher.n_jobs: ") and "hydra/launcher=joblib" in line, line

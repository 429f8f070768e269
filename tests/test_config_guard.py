"""A protocol file is data: it never reaches Hydra's settings or names code, and no YAML can
hang or exhaust config loading (issue 13, items 1, 2 and 17's deep repeat). Real
``tactile-run`` processes with a config directory added by ``hydra.searchpath``."""

import subprocess
import sys
import time

import pytest

from tactile_flow.cliapp.config_guard import ConfigFileError, check_overrides, check_text

PY = [sys.executable, "-c", "from tactile_flow.protocols.cli import main; main()"]
CLI = [*PY, "analyze=false", "progress=false"]
HEAD = "# @package _global_\nprotocol:\n  name: shared\n  steps:\n    - wait: {duration: 0.1}\n"


def run_with(tmp_path, name: str, text: str, *args, group="protocol", timeout=60, multirun=False):
    conf = tmp_path / "extra_conf" / group
    conf.mkdir(parents=True, exist_ok=True)
    (conf / f"{name}.yaml").write_text(text)
    select = f"{group}={name}" if group == "protocol" else f"+{group}={name}"
    return subprocess.run([*PY, *(["-m"] if multirun else []), *CLI[len(PY):], "hydra.searchpath=[file://./extra_conf]",
                           select, *args], cwd=tmp_path,
                          capture_output=True, text=True, timeout=timeout)


def assert_refused(proc, *words):
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert proc.returncode == 2, proc.stderr
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    for w in words:
        assert w in lines[0], lines[0]


@pytest.mark.slow
@pytest.mark.parametrize("plan_only", ["true", "false"])
def test_a_protocol_setting_hydra_callbacks_is_refused_before_hydra_builds_them(tmp_path, plan_only):
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    proc = run_with(tmp_path, "evil", HEAD + "hydra:\n  callbacks:\n    x:\n      _target_: builtins.open\n"
                                            "      file: victim.txt\n      mode: w\n", f"plan_only={plan_only}")
    assert_refused(proc, "evil.yaml", "hydra.callbacks.x._target_")
    assert victim.read_text() == "precious"
    assert not list(tmp_path.rglob("run.zarr"))


@pytest.mark.slow
def test_a_protocol_cannot_point_a_log_handler_at_another_file(tmp_path):
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    proc = run_with(tmp_path, "logger", HEAD + "hydra:\n  job_logging:\n    handlers:\n      file:\n"
                                              "        filename: victim.txt\n        mode: w\n", "plan_only=true")
    assert_refused(proc, "logger.yaml", "hydra.job_logging.handlers.file.filename", "Hydra's settings")
    assert victim.read_text() == "precious"


@pytest.mark.slow
def test_a_protocol_cannot_select_hydra_groups_or_move_configs_there(tmp_path):
    proc = run_with(tmp_path, "defs", "# @package _global_\ndefaults:\n  - override /hydra/job_logging: stdout\n"
                    + HEAD.split("\n", 1)[1], "plan_only=true")
    assert_refused(proc, "defs.yaml", "defaults[0]")
    proc = run_with(tmp_path, "pkg", "# @package hydra.callbacks\nx:\n  _target_: builtins.print\n", "plan_only=true")
    assert_refused(proc, "pkg.yaml", "hydra.callbacks.x._target_")


@pytest.mark.slow
def test_experiments_sweep_run_keys_but_not_hydra_settings(tmp_path):
    ok = subprocess.run([*PY, "-m", "+experiment=speeds_by_surface", "plan_only=true"], cwd=tmp_path,
                        capture_output=True, text=True, timeout=120)
    assert ok.returncode == 0, ok.stderr
    proc = run_with(tmp_path, "sneaky", "# @package _global_\nhydra:\n  sweeper:\n    params:\n"
                                        "      hydra.job_logging.root.level: DEBUG,INFO\n",
                    "plan_only=true", group="experiment", multirun=True)
    assert_refused(proc, "sneaky.yaml", "hydra.sweeper.params.hydra.job_logging.root.level")


@pytest.mark.slow
def test_a_yaml_alias_bomb_is_refused_at_once(tmp_path):
    lines = ["# @package _global_", "a0: &a0 [x, x, x]"]
    lines += [f"a{i}: &a{i} [*a{i - 1}, *a{i - 1}, *a{i - 1}]" for i in range(1, 27)]
    text = "\n".join(lines) + "\n" + HEAD.split("\n", 1)[1]
    assert len(text) < 1200
    t0 = time.monotonic()
    proc = run_with(tmp_path, "bomb", text, "plan_only=true", timeout=60)
    assert time.monotonic() - t0 < 30
    assert_refused(proc, "bomb.yaml", "aliases", "100000")


@pytest.mark.slow
def test_a_200_deep_repeat_is_one_line_naming_the_file_or_the_key(tmp_path):
    inner = "[{wait: {duration: 0.1}}]"
    for _ in range(200):
        inner = "[{repeat: {times: 1, steps: " + inner + "}}]"
    proc = run_with(tmp_path, "deep", "# @package _global_\nprotocol:\n  name: deep\n  steps: " + inner + "\n",
                    "plan_only=true")
    assert_refused(proc, "deep.yaml", "nested more than")
    proc = subprocess.run([*CLI, "protocol.steps=" + inner.replace(" ", ""), "plan_only=true"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=60)
    assert_refused(proc, "protocol.steps", "nested more than")
    assert "recursion" not in proc.stderr


def test_the_text_checks_directly():
    check_text("a: &x [1, 2]\nb: *x\n", "ok.yaml")
    with pytest.raises(ConfigFileError, match="nested more than"):
        check_text("a: " + "[" * 60 + "]" * 60 + "\n", "deep.yaml")
    with pytest.raises(ConfigFileError, match="not valid YAML"):
        check_text("a: [\n", "bad.yaml")
    check_overrides(["protocol.name='[[[['", "x=[1,[2]]"])
    with pytest.raises(ConfigFileError, match="x: the value"):
        check_overrides(["x=" + "[" * 60])

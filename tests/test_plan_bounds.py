"""Every value that reaches a device goes through the plan check, whatever its route (step
keys, protocol-level defaults, the hardware config), and nothing runs unbounded in time
(issue 13, items 3, 4, 5 and 17's messages)."""

import subprocess
import sys
from pathlib import Path

import pytest
import xarray as xr
from hydra import compose, initialize_config_dir

from tactile_flow.hardware.errors import ConfigError
from tactile_flow.protocols.settings import run_settings
from tactile_flow.protocols.plan import make_plan
from tactile_flow.protocols.run import run_protocol
from tactile_flow.protocols.schema import register

register()
CONF_DIR = Path(__file__).resolve().parents[1] / "conf"
GRASP = "protocol.steps=[{grasp: {fingers: [ff, mf, th]}}, {wait: {duration: 0.5}}]"


def _cfg(*overrides):
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base=None):
        return compose("config", overrides=["analyze=false", "progress=false", *overrides])


def refused(*overrides, error=ConfigError, check=make_plan) -> str:
    with pytest.raises(error) as info:
        check(_cfg(*overrides))
    return str(info.value)


@pytest.mark.parametrize("value", ["nan", "1e308", "-50", "0"])
def test_a_grasp_without_flexion_checks_the_protocol_default(value):
    msg = refused("protocol=pour_grasp", GRASP, f"protocol.grasp_flexion={value}")
    assert msg.startswith("protocol.grasp_flexion:"), msg


@pytest.mark.parametrize("value", ["nan", "-500", "0", "1e9"])
def test_the_protocol_acceleration_is_checked_before_any_move(value):
    assert refused(f"protocol.accel={value}").startswith("protocol.accel:")
    assert refused("protocol=pour_grasp", f"protocol.accel={value}").startswith("protocol.accel:")


def test_hand_targets_are_checked_for_range_and_speed():
    assert "beyond the hand's range" in refused("protocol.steps=[{grasp: {joints: {rh_FFJ3: 7.0}}}]")
    msg = refused("protocol.steps=[{grasp: {fingers: [ff], flexion: 3.0, duration: 0.05}}]")
    assert msg.startswith("protocol.steps[0].grasp") and "max_velocity_rad_s" in msg
    msg = refused("protocol.steps=[{grasp: {flexion: 1.5}}, {repeat: {times: 9, steps: [{tighten: {flexion: 0.5}}]}}]")
    assert "tighten" in msg and "beyond the hand's range" in msg


@pytest.mark.parametrize("override", ["protocol.steps.2.wait.duration=1e9", "protocol.sweep_speed=1e-300",
                                      "protocol.steps=[{wait: {duration: 1e308}}, {wait: {duration: 1e308}}]",
                                      "protocol.steps=[{repeat: {times: 3, steps: [{wait: {duration: 3000}}]}}]"])
def test_a_protocol_planned_beyond_the_time_limit_is_refused(override):
    msg = refused(override)
    assert "safety.max_duration_s=7200" in msg and len(msg) < 200, msg


def test_the_time_limit_is_configurable_and_pours_are_bounded_too():
    plan = make_plan(_cfg("safety.max_duration_s=20"))
    assert plan.duration < 20
    assert "safety.max_duration_s=10" in refused("safety.max_duration_s=10")
    assert refused("safety.max_duration_s=nan").startswith("safety.max_duration_s")
    msg = refused("protocol=pour_grasp", "protocol.steps.2.pour.volume=1e9")
    assert msg.startswith("protocol.steps[2].pour.volume") and "would pour" in msg, msg


@pytest.mark.parametrize("override, key", [
    ("hardware.step_s=1e-7", "hardware.step_s"), ("hardware.step_s=1", "hardware.step_s"),
    ("hardware.biotac_rate_hz=1e308", "hardware.biotac_rate_hz"),
    ("hardware.hand_rate_hz=1e-300", "hardware.hand_rate_hz"),
    ("hardware.pump.rate_hz=1e6", "hardware.pump.rate_hz"), ("hardware.scale.rate_hz=0.001", "hardware.scale.rate_hz"),
    ("hardware.buffer_s=1e9", "hardware.buffer_s"), ("hardware.seed=-5", "hardware.seed"),
    ("hardware.seed=100000000000000000000000000", "hardware.seed")])
def test_the_simulator_step_every_rate_and_the_seed_are_bounded(override, key):
    msg = refused(override, error=ConfigError, check=run_settings)
    assert msg.startswith(key + ":") and len(msg) < 120, msg


@pytest.mark.parametrize("override, key", [
    ("hardware.biotac.rate_hz=1e308", "hardware.biotac.rate_hz"),
    ("hardware.pump.poll_hz=1e-9", "hardware.pump.poll_hz"),
    ("++hardware.scale.buffer_s=1e12", "hardware.scale.buffer_s"),
    ("++hardware.hand.rate_hz=inf", "hardware.hand.rate_hz")])
def test_the_real_drivers_bound_their_rates_too(override, key):
    assert refused("hardware=lab", override, error=ConfigError, check=run_settings).startswith(key + ":")


def test_numbers_in_messages_are_brief():
    msg = refused("protocol.sweep_depth=1e300")
    assert "1e+297" in msg and len(msg) < 220, msg
    msg = refused("protocol.steps=[{wait: {duration: -" + "9" * 300 + "}}]")
    assert "-1e+300" in msg and len(msg) < 120, msg


@pytest.mark.slow
def test_explicit_grasp_joints_run_on_the_simulated_lab(tmp_path):
    cfg = _cfg("protocol=pour_grasp", "protocol.steps=[{grasp: {joints: {rh_FFJ3: 0.5, rh_MFJ3: 0.4}}}, "
                                      "{wait: {duration: 0.3}}]")
    result = run_protocol(cfg, tmp_path / "run", console=lambda *a: None)
    assert result.status == "success", result.error
    hand = xr.open_datatree(result.store, engine="zarr")["hand"]
    target = hand["target"].sel(joint="rh_FFJ3").values
    assert target[-1] == pytest.approx(0.5)


@pytest.mark.slow
def test_a_bad_hardware_value_is_one_line_naming_its_key_even_with_plan_only(tmp_path):
    for extra in ([], ["plan_only=true"]):
        proc = subprocess.run([sys.executable, "-c", "from tactile_flow.protocols.cli import main; main()", "analyze=false",
                               "progress=false", "hardware.seed=-5", *extra], cwd=tmp_path, capture_output=True,
                              text=True, timeout=120)
        lines = [line for line in proc.stderr.splitlines() if line.strip()]
        assert proc.returncode == 2 and len(lines) == 1 and lines[0].startswith("error: hardware.seed:"), proc.stderr
    assert not list(tmp_path.rglob("run.zarr"))

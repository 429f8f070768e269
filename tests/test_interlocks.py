"""Safety interlocks: each limit, breached on the simulator, stops and retracts the arm and
aborts the run with the interlock named."""

from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir

from tactile_flow.hardware.sim import make_sim_lab
from tactile_flow.protocols.engine import ABORTED, SUCCESS, RunEngine
from tactile_flow.protocols.plan import make_plan
from conftest import EventLog
from tactile_flow.protocols.schema import register

register()
CONF_DIR = Path(__file__).resolve().parents[1] / "conf"


def _run(*overrides):
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base=None):
        cfg = compose("config", overrides=list(overrides))
    plan = make_plan(cfg)
    lab = make_sim_lab(cfg.hardware, cfg.surface)
    events = EventLog()
    with lab:
        outcome = RunEngine(lab, events, cfg, plan, log=lambda *a: None).run()
        z = lab.arm.tcp_pose()[2]
        pump_running = lab.pump.status().running
    interlocks = [(n, d) for k, n, d in events.events if k == "interlock"]
    return outcome, interlocks, [k for k, _, _ in events.events], z, pump_running


@pytest.mark.parametrize("overrides, name", [
    (["safety.force_max=2.0"], "tcp_force"),
    (["safety.speed_max=0.02"], "tcp_speed"),
    (["safety.pdc_max=2900"], "pdc_saturation"),
    (["safety.electrode_min=1500"], "electrode_saturation"),
    (["hardware.faults.biotac_dropout=[[6.0,7.0]]"], "stale_biotac"),
    (["safety.contact_time_max=0.5"], "contact_time"),
])
def test_breached_limit_aborts_names_the_interlock_and_retracts(overrides, name):
    outcome, interlocks, kinds, z, _ = _run(*overrides)
    assert outcome.status == ABORTED and name in outcome.error
    assert interlocks and interlocks[0][0] == name
    assert "retract" in kinds


def test_pour_interlock_stops_the_pump():
    outcome, interlocks, _, _, pump_running = _run("protocol=pour_grasp", "safety.contact_time_max=5")
    assert outcome.status == ABORTED and interlocks[0][0] == "contact_time"
    assert not pump_running


def test_a_short_dropout_under_the_stale_limit_does_not_stop_the_run():
    outcome, interlocks, _, _, _ = _run("hardware.faults.biotac_dropout=[[6.0,6.05]]")
    assert outcome.status == SUCCESS and not interlocks


def test_protective_stop_mid_sweep_aborts_or_recovers_per_config():
    stop = "hardware.faults.protective_stop_s=9.0"               # in the middle of the sweep
    outcome, _, kinds, _, _ = _run(stop)
    assert outcome.status == "failed" and "protective stop" in outcome.error
    outcome, _, kinds, z, _ = _run(stop, "safety.on_protective_stop=recover")
    assert outcome.status == SUCCESS and kinds.count("step_end") == 6
    assert kinds.index("protective_stop") < kinds.index("recovered")

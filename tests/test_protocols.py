"""Protocols are data: parsing, the plan check before motion, and the run engine on the sim."""

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from tactile_flow.hardware.sim import make_sim_lab
from tactile_flow.protocols.engine import ABORTED, FAILED, SUCCESS, RunEngine
from tactile_flow.protocols.plan import format_timeline, make_plan
from conftest import EventLog
from tactile_flow.protocols.schema import register
from tactile_flow.protocols.steps import ProtocolError, parse_steps


register()
CONF_DIR = Path(__file__).resolve().parents[1] / "conf"


def _cfg(*overrides):
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base=None):
        return compose("config", overrides=list(overrides))


@pytest.mark.parametrize("protocol", ["straws_sweep", "sticks_sweep", "pour_grasp"])
def test_every_protocol_plans_and_names_its_labels(protocol):
    plan = make_plan(_cfg(f"protocol={protocol}"))
    assert plan.steps and plan.duration > 0
    assert plan.labels
    text = format_timeline(plan)
    assert protocol in text and all(p.step.kind in text for p in plan.steps)


@pytest.mark.parametrize("protocol", ["straws_sweep", "sticks_sweep", "pour_grasp"])
def test_every_protocol_s_timeline_is_contiguous_inside_the_workspace_and_labelled_as_declared(protocol):
    cfg = _cfg(f"protocol={protocol}")
    plan = make_plan(cfg)
    assert plan.protocol == protocol and plan.labels == list(cfg.protocol.labels)
    assert [p.index for p in plan.steps] == list(range(len(plan.steps)))
    assert plan.steps[0].start == 0.0
    for before, after in zip(plan.steps, plan.steps[1:]):      # each step starts where the one before ends
        assert after.start == pytest.approx(before.start + before.duration)
    assert plan.duration == pytest.approx(sum(p.duration for p in plan.steps))
    assert all(p.duration >= 0 for p in plan.steps)
    lo, hi = (np.array(cfg.hardware.workspace[k]) for k in ("min_m", "max_m"))
    points = np.array([w[:3] for p in plan.steps for w in p.waypoints]).reshape(-1, 3)
    assert np.all(points >= lo - 1e-9) and np.all(points <= hi + 1e-9)
    assert len(points) or "sweep" not in protocol                 # a sweep moves
    moving = [p for p in plan.steps if p.waypoints]
    assert all(p.duration > 0 for p in moving)                  # a move takes time


def test_one_protocol_serves_every_board():
    """Steps refer to features by name, so the same sweep plans on straws and sticks."""
    straws = make_plan(_cfg("protocol=straws_sweep"))
    sticks = make_plan(_cfg("protocol=straws_sweep", "surface=sticks"))
    assert straws.steps[3].waypoints[0][0] != sticks.steps[3].waypoints[0][0]


@pytest.mark.parametrize("steps, key, words", [
    ([{"swipe": {}}], "protocol.steps[0]", "unknown step kind 'swipe'"),
    ([{"sweep": {"speeed": 3}}], "protocol.steps[0].sweep.speeed", "unknown parameter"),
    ([{"sweep": {"speed": "fast"}}], "protocol.steps[0].sweep.speed", "expected float"),
    ([{"wait": {"duration": -1}}], "protocol.steps[0].wait.duration", "> 0"),
    ([{"hold": {"until": {"pdc_rsie": 3}}}], "protocol.steps[0].hold.until.pdc_rsie", "unknown criterion"),
    ([{"move_to": {"at": "before:feature_9"}}], "protocol.steps[0].move_to.at", "no feature 'feature_9'"),
    ([{"repeat": {"times": 0, "steps": [{"wait": {}}]}}], "protocol.steps[0].repeat.times", "≥ 1"),
    ([{"grasp": {"fingers": ["ff", "xx"]}}], "protocol.steps[0].grasp.fingers[1]", "expected one of"),
    ([{"approach": {"until": {"force": 500.0}}}], "protocol.steps[0].approach.until.force", "max_contact_force_n"),
    ([{"hold": {"until": {"pdc_rise": 5, "contact_lost": 5}}}], "protocol.steps[0].hold.until", "contradict"),
    ([{"move_to": {"at": "home", "pose": [0.3, 0, 0.2, 3.14, 0, 0]}}], "protocol.steps[0].move_to", "not both"),
    ([{"move_to": {}}], "protocol.steps[0].move_to", "expected `at`"),
])
def test_bad_steps_name_the_yaml_key(steps, key, words):
    cfg = _cfg()
    cfg.protocol.steps = steps
    with pytest.raises(ProtocolError) as err:
        make_plan(cfg)
    assert err.value.key == key and words in str(err.value)


def test_leaving_the_workspace_is_rejected_before_motion_naming_step_and_limit():
    cfg = _cfg("protocol.steps.5.lift.height=900")
    with pytest.raises(ProtocolError, match=r"protocol\.steps\[5\]\.lift: .*hardware\.workspace\.max_m\[2\]"):
        make_plan(cfg)
    with pytest.raises(ProtocolError, match=r"speed.*hardware\.arm\.max_speed_m_s"):
        make_plan(_cfg("protocol.sweep_speed=900"))


def test_repeat_expands_into_the_timeline():
    steps = parse_steps([{"repeat": {"times": 3, "steps": [{"wait": {"duration": 0.5}}, {"lift": {"height": 1}}]}}])
    assert steps[0].times == 3 and len(steps[0].steps) == 2
    cfg = _cfg()
    cfg.protocol.steps = [{"move_to": {"at": "before:first"}},
                          {"repeat": {"times": 3, "steps": [{"wait": {"duration": 0.5}}]}}]
    plan = make_plan(cfg)
    assert [p.step.kind for p in plan.steps] == ["move_to", "wait", "wait", "wait"]


def _run(cfg):
    plan = make_plan(cfg)
    lab = make_sim_lab(cfg.hardware, cfg.surface)
    events = EventLog()
    with lab:
        outcome = RunEngine(lab, events, cfg, plan, log=lambda *a: None).run()
        truth = lab.truth.to_dict()
        lab.pump_running = lab.pump.status().running
    return outcome, events, truth, lab


def test_sweep_runs_to_success_crossing_every_feature():
    outcome, events, truth, _ = _run(_cfg())
    assert outcome.status == SUCCESS and outcome.steps_done == 6
    assert events.kinds().count("step_start") == events.kinds().count("step_end") == 6
    assert list(truth["feature_crossings"]["feature"]) == ["feature_0", "feature_1", "feature_2"]


def test_pour_holds_until_the_bottle_has_slipped_out():
    outcome, events, truth, lab = _run(_cfg("protocol=pour_grasp"))
    assert outcome.status == SUCCESS
    assert ("criterion", "protocol.steps[3].hold") in [(k, n) for k, n, _ in events.events]
    assert truth["pour"]["full_slip"] < lab.clock.now()
    assert not lab.pump_running


def test_a_failing_step_stops_motion_and_the_pump():
    cfg = _cfg("protocol=pour_grasp", "hardware.faults.protective_stop_s=3.0")
    outcome, events, _, lab = _run(cfg)
    assert outcome.status == FAILED and "protective stop" in outcome.error
    assert "error" in events.kinds()
    assert not lab.pump_running


def test_operator_stop_retracts_and_aborts():
    """A stop request mid-sweep (Ctrl-C once) ends the motion, retracts 20 mm, aborts."""
    cfg = _cfg()
    plan = make_plan(cfg)
    lab = make_sim_lab(cfg.hardware, cfg.surface)
    events = EventLog()
    with lab:
        engine = RunEngine(lab, events, cfg, plan, log=lambda *a: None)
        tick = engine.ctx._tick

        def operator_presses_ctrl_c_at_8s():
            if lab.clock.now() > 8.0:
                engine.ctx.stop_requested = True
            tick()
        engine.ctx._tick = operator_presses_ctrl_c_at_8s
        outcome = engine.run()
        z_after = lab.arm.tcp_pose()[2]
    assert outcome.status == ABORTED
    assert "retract" in events.kinds() and "step_end" in events.kinds()
    sweep_z = plan.steps[3].waypoints[0][2]
    assert z_after == pytest.approx(sweep_z + 0.02, abs=1e-3)


def test_parallel_launchers_are_refused_for_real_hardware():
    from tactile_flow.protocols.cli import _refuse_parallel_hardware
    hc = OmegaConf.create({"launcher": {"_target_": "hydra_plugins.hydra_joblib_launcher.JoblibLauncher"}})
    lab = SimpleNamespace(backend="lab")                     # as RunSettings say it
    with pytest.raises(ValueError, match="one robot"):
        _refuse_parallel_hardware(lab, hc)
    _refuse_parallel_hardware(SimpleNamespace(backend="sim"), hc)   # sim: allowed
    basic = OmegaConf.create({"launcher": {"_target_": "hydra._internal.core_plugins.basic_launcher.BasicLauncher"}})
    _refuse_parallel_hardware(lab, basic)

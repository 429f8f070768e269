"""Bad configuration or commands: a clear error naming the key, before anything runs."""

import numpy as np
import pytest

from tactile_flow.hardware.errors import ConfigError, SafetyError, WorkspaceError
from tactile_flow.hardware.sim import make_sim_lab


@pytest.mark.parametrize("surface, key", [
    ({"kind": "pebbles"}, "surface.kind"),
    ({"kind": "straws", "diameter_mm": -6.0}, "surface.diameter_mm"),
    ({"kind": "sticks", "height_mm": -2.0}, "surface.height_mm"),
    ({"kind": "sticks", "width_mm": 10.0, "spacing_mm": 8.0}, "surface.spacing_mm"),
    ({"kind": "straws", "count": 30, "spacing_mm": 20.0}, "surface.count"),
    ({"kind": "straws", "colour": "red"}, "surface.colour"),
    ({"kind": "straws", "count": 2.5}, "surface.count"),
])
def test_bad_surfaces_name_the_key(surface, key):
    with pytest.raises(ConfigError) as e:
        make_sim_lab({}, surface)
    assert e.value.key == key and str(e.value).startswith(key)
    assert isinstance(e.value, ValueError)


@pytest.mark.parametrize("cfg, key", [
    ({"fingers": ["ff", "index"]}, "hardware.fingers[1]"),
    ({"fingers": ["ff", "ff"]}, "hardware.fingers"),
    ({"fingers": []}, "hardware.fingers"),
    ({"pour": {"grasp_fingers": ["thumb"]}}, "hardware.pour.grasp_fingers[0]"),
    ({"seed": "abc"}, "hardware.seed"),
    ({"sensor": {"noise": 2}}, "hardware.sensor.noise"),
    ({"workspace": {"min_m": [0, 0, 1], "max_m": [1, 1, 0.5]}}, "hardware.workspace.min_m"),
    ({"faults": {"biotac_dropout": [[2.0, 1.0]]}}, "hardware.faults.biotac_dropout[0]"),
    ({"faults": {"disconnect": {"robot": 1.0}}}, "hardware.faults.disconnect.robot"),
    ({"biotac_rate_hz": 97.0}, "hardware.biotac_rate_hz"),
])
def test_bad_hardware_config_names_the_key(cfg, key):
    with pytest.raises(ConfigError) as e:
        make_sim_lab(cfg)
    assert e.value.key == key, str(e.value)


def test_pose_outside_the_workspace_is_refused_before_moving():
    lab = make_sim_lab({"workspace": {"min_m": [0.0, -0.3, 0.02], "max_m": [0.6, 0.3, 0.5]}})
    with lab:
        start = lab.arm.tcp_pose()
        bad = start.copy()
        bad[2] = -0.05
        with pytest.raises(WorkspaceError, match=r"hardware\.workspace.*z=-0\.05"):
            lab.arm.move_linear(bad)
        with pytest.raises(ValueError):                      # WorkspaceError is a ValueError
            lab.arm.check_pose(bad)
        with pytest.raises(WorkspaceError):                  # a speed command that would leave it
            lab.arm.speed_linear([0, 0, -0.1, 0, 0, 0], 0.5, duration=3.0)
        assert lab.clock.now() == 0.0
        np.testing.assert_array_equal(lab.arm.tcp_pose(), start)


def test_unsafe_commands_are_refused_naming_the_limit():
    with make_sim_lab({}) as lab:
        with pytest.raises(SafetyError, match="hardware.arm.max_speed_m_s"):
            lab.arm.move_linear(lab.arm.tcp_pose() + [0.01, 0, 0, 0, 0, 0], speed=3.0)
        with pytest.raises(ValueError, match="hardware.pump.max_rate_ml_min"):
            lab.pump.set_rate(1000.0)
        with pytest.raises(ValueError, match="rh_FFJ9"):
            lab.hand.move_to({"rh_FFJ9": 0.1}, 1.0)
        with pytest.raises(SafetyError, match="hardware.hand.max_velocity_rad_s"):
            lab.hand.move_to({"rh_FFJ3": 1.5}, 0.01)
    assert lab.clock.now() == 0.0


def test_surface_features_are_found_by_name():
    lab = make_sim_lab({}, {"kind": "sticks", "count": 4, "spacing_mm": 25})
    assert lab.surface.feature("feature_3").index == 3
    with pytest.raises(KeyError, match="feature_4"):
        lab.surface.feature("feature_4")

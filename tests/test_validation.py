"""One validation layer: one error format, unknown keys refused anywhere (also added with
``+``) naming the nearest known key, step parameters resolved in one place."""

import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir

from tactile_flow.analysis.config import AnalysisConfigError, load_config as load_analysis
from tactile_flow.hardware.config import SimConfig, load_config as load_hardware
from tactile_flow.protocols.plan import make_plan
from tactile_flow.protocols.schema import register
from tactile_flow.protocols.settings import run_settings
from tactile_flow.protocols.steps import STEP_KINDS, Pour, ProtocolError, parse_steps
from tactile_flow.validation import ConfigError, build, spec, suggest, unknown_key

register()
CONF_DIR = Path(__file__).resolve().parents[1] / "conf"


def _cfg(*overrides):
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base=None):
        return compose("config", overrides=list(overrides))


@dataclass
class Toy:
    rate_hz: float = spec(10.0, gt=0, le=100, units="Hz")
    mode: str = spec("auto", choices=("auto", "pdc"))
    pose: list[float] = spec(factory=lambda: [0.0] * 6, length=6)
    count: int = 1


def test_one_error_format_names_key_wrong_and_expected():
    with pytest.raises(ConfigError) as e:
        build(Toy, {"rate_hz": 0}, "toy")
    assert str(e.value) == "toy.rate_hz: got 0.0; expected a number > 0 and <= 100 Hz" and e.value.key == "toy.rate_hz"
    with pytest.raises(ConfigError, match=r"^toy.mode: got 'fast'; expected one of auto, pdc$"):
        build(Toy, {"mode": "fast"}, "toy")
    with pytest.raises(ConfigError, match=r"^toy.pose: got 2 values; expected 6$"):
        build(Toy, {"pose": [1, 2]}, "toy")
    with pytest.raises(ConfigError, match=r"^toy.count: got 1.5; expected a whole number$"):
        build(Toy, {"count": 1.5}, "toy")
    with pytest.raises(ConfigError, match=r"^toy.rate_hz: got inf; expected a finite number$"):
        build(Toy, {"rate_hz": float("inf")}, "toy")
    with pytest.raises(ConfigError, match=r"^toy.rate: unknown key; expected one of count, mode, pose, rate_hz; "
                                          r"did you mean `rate_hz`\?$"):
        build(Toy, {"rate": 3}, "toy")
    assert build(Toy, {"rate_hz": 100, "count": 2.0}, "toy") == Toy(rate_hz=100.0, count=2)


def test_did_you_mean_only_when_a_key_is_close():
    assert suggest("sweep_sped", ["sweep_speed", "sweep_depth"]) == "sweep_speed"
    assert suggest("zzz", ["sweep_speed"]) is None
    assert "did you mean" not in str(unknown_key("protocol", "zzz", ["sweep_speed"]))


@pytest.mark.parametrize("node, key, near", [
    ({"sed": 3}, "hardware.sed", "seed"),
    ({"arm": {"max_sped_m_s": 1.0}}, "hardware.arm.max_sped_m_s", "max_speed_m_s"),
    ({"sensor": {"noise": 2}}, "hardware.sensor.noise", "noise_scale"),
])
def test_every_hardware_node_refuses_unknown_keys_with_the_nearest(node, key, near):
    with pytest.raises(ConfigError) as e:
        load_hardware(node)
    assert e.value.key == key and f"did you mean `{near}`?" in str(e.value)


def test_bounds_are_declared_on_the_fields():
    with pytest.raises(ConfigError, match=r"^hardware.contact.friction_static: got -1.0; expected a number > 0$"):
        load_hardware({"contact": {"friction_static": -1.0}})
    with pytest.raises(ConfigError, match=r"^hardware.pour.slip_release: got 1.0; expected a number >= 0 and < 1$"):
        load_hardware({"pour": {"slip_release": 1.0}})
    assert isinstance(load_hardware(None), SimConfig)


def test_analysis_refuses_unknown_keys_with_the_nearest_in_the_same_format():
    with pytest.raises(AnalysisConfigError) as e:
        load_analysis({"segmentation": {"smoth_s": 0.1}})
    assert isinstance(e.value, ConfigError) and e.value.key == "analysis.segmentation.smoth_s"
    assert "did you mean `smooth_s`?" in str(e.value)
    with pytest.raises(AnalysisConfigError, match=r"^analysis.segmentation.prominence: got 2.0; expected a number > 0 "
                                                  r"and < 1$"):
        load_analysis({"segmentation": {"prominence": 2.0}})


def test_steps_refuse_unknown_kinds_and_parameters_with_the_nearest():
    with pytest.raises(ProtocolError) as e:
        parse_steps([{"swep": {}}])
    assert e.value.key == "protocol.steps[0]" and "did you mean `sweep`?" in str(e.value)
    with pytest.raises(ProtocolError) as e:
        parse_steps([{"sweep": {"sped": 3}}])
    assert e.value.key == "protocol.steps[0].sweep.sped" and "did you mean `speed`?" in str(e.value)
    assert issubclass(ProtocolError, ConfigError)


@pytest.mark.parametrize("override, key, near", [
    ("+protocol.sweep_sped=10", "protocol.sweep_sped", "sweep_speed"),
    ("+safety.pdc_mx=3", "safety.pdc_mx", "pdc_max"),
    ("+live.slip.onset_tim=3", None, None),
    ("+analysis.flw=3", "analysis.flw", "flow"),
    ("+plan_onl=true", "plan_onl", "plan_only"),
])
def test_keys_added_with_plus_are_refused_after_composition(override, key, near):
    cfg = _cfg(override)
    with pytest.raises(ConfigError) as e:
        run_settings(cfg)
    if key:
        assert e.value.key == key and f"did you mean `{near}`?" in str(e.value)


def test_a_surface_key_added_with_plus_is_refused_by_the_plan():
    with pytest.raises(ConfigError) as e:
        make_plan(_cfg("+surface.diamter_mm=3"))
    assert e.value.key == "surface.diamter_mm" and "did you mean `diameter_mm`?" in str(e.value)


def test_step_defaults_are_resolved_in_one_place():
    """``plan`` and ``run`` both take the protocol's defaults from ``resolve``."""
    cfg = _cfg("protocol=pour_grasp", "protocol.pour_rate=42")
    plan = make_plan(cfg)
    pour = next(s for s in plan.steps if isinstance(s.step, Pour))
    assert pour.step.resolve(_Ctx(cfg)) == {"rate": 42.0, "volume": cfg.protocol.pour_volume}
    for kind, cls in STEP_KINDS.items():
        assert "resolve" in vars(cls) or not any("ctx.params" in line for line in _source(cls.plan)), kind


class _Ctx:
    def __init__(self, cfg):
        self.params = cfg.protocol


def _source(fn):
    import inspect
    return inspect.getsource(fn).splitlines()


@pytest.mark.slow
@pytest.mark.parametrize("override, expected", [
    ("protocol.sweep_sped=10", "error: protocol.sweep_sped: unknown key; expected one of the 26 keys of protocol; "
                               "did you mean `sweep_speed`?"),
    ("+protocol.sweep_sped=10", "error: protocol.sweep_sped: unknown key; expected one of the 26 keys of protocol; "
                                "did you mean `sweep_speed`?"),
    ("hardware.sed=3", "did you mean `seed`?"),
    ("+hardware.sed=3", "did you mean `seed`?"),
    ("+surface.diamter_mm=3", "did you mean `diameter_mm`?"),
    ("analysis.flow.methd=dis", "did you mean `method`?"),
    ("protocol.steps.0.move_to.hieght=3", "expected one of at, height, margin, pose, speed; did you mean `height`?"),
])
def test_tactile_run_refuses_a_misspelt_key_in_one_line(tmp_path, override, expected):
    proc = subprocess.run([sys.executable, "-c", "from tactile_flow.protocols.cli import main; main()", override], cwd=tmp_path,
                          capture_output=True, text=True, timeout=120)
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert proc.returncode == 2 and len(lines) == 1 and expected in lines[0], proc.stderr
    assert "To append" not in proc.stderr and "+" not in lines[0].split(":", 1)[0]
    assert list(tmp_path.iterdir()) == [], list(tmp_path.rglob("*"))      # nothing recorded, no run directory

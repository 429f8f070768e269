"""Slip in place: the object stage, the skin's stick and slip, the protocol and its ground truth.

The protocol runs through the real ``tactile-run`` (one multirun process, real zarr stores);
pattern checks run the same config in-process (``protocols.slip_grid``).
"""

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from tactile_flow.hardware.errors import SafetyError
from tactile_flow.hardware.sim import make_sim_lab
from tactile_flow.hardware.sim import skin
from tactile_flow.hardware.stage import ObjectStage
from tactile_flow.protocols.slip_grid import Condition, compose, conditions, run_slip_in_place
from tactile_flow.tactile.geometry import load_taxels

BIN = Path(sys.executable).parent
TAXELS = load_taxels()


def _kohm(c):
    return (4095.0 / np.clip(np.asarray(c, float), 1, None) - 1.0) * 10.0


def _events(tree, kind=None):
    ev = tree["events"].to_dataset()
    return [(float(t), str(k), str(n), json.loads(str(d)) if str(d) else {})
            for t, k, n, d in zip(ev.time.values, ev.kind.values, ev.name.values, ev.detail.values)
            if kind is None or k == kind]


def _motion(tree) -> dict:
    m = tree["truth/object_motions"].to_dataset()
    assert m.sizes["object_motions"] == 1
    t0 = float(tree.attrs["t0_clock_s"])
    out = {k: m[k].values[0].item() if m[k].dtype.kind == "f" else str(m[k].values[0]) for k in m.data_vars}
    for k in ("start", "slip_onset", "end"):
        out[k] -= t0                                        # run time, as the store's time axes
    return out


def _pattern(tree, finger="ff"):
    """Activation (kΩ above the stored baseline) and its centre of pressure per frame; time (s)."""
    e = tree["biotac/electrodes"].sel(finger=finger).values.astype(float)
    base = tree["biotac/baseline"].sel(finger=finger).values
    a = np.clip(_kohm(e) - _kohm(base), 0, None)
    with np.errstate(invalid="ignore"):                     # frames out of contact have no centre
        return tree["biotac/time"].values, a, (a @ TAXELS) / a.sum(1, keepdims=True)


def _shift(tree):
    """Displacement (mm, sensor x, y) of the centre of pressure from the 0.4 s before the motion
    to the 0.4 s after it, and the change of the pattern's xy moment (mm²)."""
    t, a, cop = _pattern(tree)
    m = _motion(tree)
    before = (t > m["start"] - 0.4) & (t < m["start"])
    after = (t > m["end"]) & (t < m["end"] + 0.4)

    def xy(sel):
        w = a[sel]
        c = cop[sel]
        return np.mean(((w * (TAXELS[:, 0] - c[:, :1]) * (TAXELS[:, 1] - c[:, 1:2])).sum(1)) / w.sum(1))
    return cop[after, :2].mean(0) - cop[before, :2].mean(0), xy(after) - xy(before)


# ----------------------------------------------------------------------------- skin and stage


def test_the_skin_sticks_then_slips_at_the_kinetic_level():
    """Cattaneo–Mindlin: the traction grows ever more slowly with the stretch (initial slope k_t),
    the whole contact slips at s* = 3μs·F / (2k_t), and the skin then relaxes to where the
    traction is the kinetic μk·F."""
    s = skin.Skin()
    kt, _ = skin.stiffness(4.0, 0.08)
    star = 1.5 * 0.8 * 2.0 / kt                              # mm of travel the skin follows
    assert not skin.step(s, [0.01 * star, 0], 0.0, 2.0, 4.0, 0.8, 0.6, 0.08)
    assert s.traction_n == pytest.approx(kt * 0.01 * star, rel=0.02)              # the initial stiffness
    assert not skin.step(s, [0.49 * star, 0], 0.0, 2.0, 4.0, 0.8, 0.6, 0.08)
    assert s.stretch[0] == pytest.approx(0.5 * star) and 0.5 * 1.6 < s.traction_n < 1.6   # partial slip
    assert skin.step(s, [0.5 * star, 0], 0.0, 2.0, 4.0, 0.8, 0.6, 0.08)        # gross slip
    assert s.traction_n == pytest.approx(0.6 * 2.0) and s.stretch[1] == 0 and s.stretch[0] < star
    # the twist: turns with the object, then slips at the kinetic torque of the patch
    assert skin.step(s, [0, 0], math.radians(40), 2.0, 4.0, 0.8, 0.6, 0.08)
    assert s.torque_n_mm == pytest.approx(0.6 * skin.TORSION_CAPACITY * 2.0 * 4.0) and s.twist > 0
    s.relax()
    assert s.traction_n == 0 and s.twist == 0


def test_a_growing_contact_keeps_its_traction_not_its_stretch():
    """Mindlin–Deresiewicz: skin joining a contact as the press grows it is unstressed, so a
    stretch taken at touchdown (the holder's tremor) keeps its traction, not its length, while
    the contact widens: 0.02 mm at a = 0.5 mm is 0.0025 mm at 4 mm (k_t ∝ a), the twist falls
    by (0.5/4)³. A contact that narrows and widens again to a radius it had keeps its stretch
    (no ratchet under the tremor's force wobble); lifted off, it starts again."""
    s = skin.Skin()
    assert not skin.step(s, [0.02, 0.0], 1e-3, 0.05, 0.5, 0.8, 0.6, 0.08)
    q, m = s.traction_n, s.torque_n_mm
    assert s.stretch[0] == pytest.approx(0.02) and s.widest_mm == 0.5
    assert not skin.step(s, [0.0, 0.0], 0.0, 1.3, 4.0, 0.8, 0.6, 0.08)
    assert s.stretch[0] == pytest.approx(0.02 * 0.5 / 4.0)
    # kept to the initial stiffness (the touchdown's stretch was a tenth of the way to gross slip)
    assert s.traction_n == pytest.approx(q, rel=0.05) and s.twist == pytest.approx(1e-3 * (0.5 / 4.0) ** 3)
    assert s.torque_n_mm == pytest.approx(m, rel=0.05)
    before = s.stretch.copy()
    for a in (3.9, 4.0, 3.95, 4.0):
        skin.step(s, [0.0, 0.0], 0.0, 1.3, a, 0.8, 0.6, 0.08)
    assert np.allclose(s.stretch, before)
    s.relax()
    assert s.widest_mm == 0.0


def test_a_twist_loads_opposite_quadrants_of_an_elongated_patch():
    x, y = np.meshgrid(np.linspace(-5, 5, 21), np.linspace(-2, 2, 9))
    pts = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], -1)
    taxels = np.array([[4, 2, 0], [-4, -2, 0], [4, -2, 0], [-4, 2, 0.0]])
    load = skin.torsion_loads(taxels, np.zeros(3), pts, np.ones(len(pts)), 1.0, 0.6, 6.0)
    assert load[0] > 0 and load[1] > 0 and load[2] < 0 and load[3] < 0      # + about +z: +xy quadrants load
    assert np.all(np.sign(skin.torsion_loads(taxels, np.zeros(3), pts, np.ones(len(pts)), -1.0, 0.6, 6.0))
                  == -np.sign(load))


def test_the_sim_stage_moves_the_object_within_its_limits():
    lab = make_sim_lab({"seed": 1, "fingers": ["ff"]}, {"kind": "flat"})
    assert isinstance(lab.stage, ObjectStage) and lab.stage.identity.serial_or_address.startswith("sim://stage")
    with lab:
        lab.stage.translate(0.003, -0.004, 0.01)
        assert np.allclose(lab.stage.pose(), [0.003, -0.004, 0.0]) and not lab.stage.is_moving()
        lab.stage.rotate(-0.5, 1.0, asynchronous=True)
        assert lab.stage.is_moving()
        lab.clock.sleep(0.2)
        lab.stage.stop()
        lab.clock.sleep(0.2)
        pose = lab.stage.pose()
        assert not lab.stage.is_moving() and -0.5 < pose[2] < -0.15
        states = lab.stage.read_states()
        assert len(states) > 50 and states[-1].pose.shape == (3,) and any(s.moving for s in states)
        assert np.all(np.diff([s.host_time for s in states]) > 0)
        with pytest.raises(SafetyError, match="max_travel_m"):
            lab.stage.translate(0.06, 0.0, 0.01)
        with pytest.raises(SafetyError, match="max_speed_m_s"):
            lab.stage.translate(0.001, 0.0, 1.0)
    assert make_sim_lab({"stage": None}).stage is None


# ----------------------------------------------------------------------------- through tactile-run


@pytest.fixture(scope="module")
def cli_runs(tmp_path_factory):
    """Every motion kind with and without tare, through ``tactile-run -m`` (one process)."""
    cwd = tmp_path_factory.mktemp("slip_cli")
    env = dict(os.environ, TACTILE_CACHE_DIR=os.environ.get("TACTILE_CACHE_DIR", str(cwd / "cache")))
    r = subprocess.run([str(BIN / "tactile-run"), "-m", "protocol=slip_in_place", "analyze=false", "progress=false",
                        "protocol.motion=translate,rotate,none", "protocol.tare=true,false",
                        "protocol.direction_deg=120", "protocol.rotation_deg=-30"],
                       cwd=cwd, capture_output=True, text=True, timeout=900, env=env)
    assert r.returncode == 0, r.stderr[-3000:]
    runs = {}
    for store in cwd.glob("multirun/*/*/*/run.zarr"):
        tree = xr.open_datatree(str(store), engine="zarr")
        key = (_motion(tree)["kind"], bool(tree["truth/conditions/tare"].values))
        runs[key] = (tree, json.loads((store.parent / "run.json").read_text()))
        tree.attrs["_store"] = str(store)
    assert len(runs) == 6, sorted(runs)
    return runs


@pytest.mark.parametrize("kind", ["translate", "rotate", "none"])
@pytest.mark.parametrize("tare", [True, False])
def test_the_protocol_runs_and_the_truth_is_what_was_commanded(cli_runs, kind, tare):
    tree, run_json = cli_runs[(kind, tare)]
    assert run_json["status"] == "success" and tree.attrs["status"] == "success"
    m = _motion(tree)
    cond = tree["truth/conditions"].to_dataset()
    assert str(cond.object.values) == "flat" and float(cond.press_force_n.values) == pytest.approx(1.3)
    assert m["finger"] == "ff" and m["force_n"] == pytest.approx(1.3, rel=0.15)
    assert 0 < m["start"] < m["end"]
    if kind == "translate":
        assert m["direction_sensor_deg"] == pytest.approx(120.0) and m["distance_mm"] == pytest.approx(4.0)
        assert m["speed_mm_s"] == pytest.approx(5.0) and m["start"] < m["slip_onset"] < m["end"]
    elif kind == "rotate":
        assert m["rotation_deg"] == pytest.approx(-30.0) and math.isnan(m["direction_sensor_deg"])
        assert m["start"] < m["slip_onset"] < m["end"]
    else:
        assert m["rotation_deg"] == 0 and math.isnan(m["slip_onset"])
    # the stage stream: moving exactly while the truth says the object moved
    st = tree["stage"].to_dataset()
    moving = st.time_stage.values[st.moving.values]
    if kind == "none":
        assert moving.size == 0
    else:
        assert moving.min() == pytest.approx(m["start"], abs=0.02) and moving.max() == pytest.approx(m["end"], abs=0.02)
    assert st.pose.attrs["units"] == "m, rad" and list(st.stage_axis.values) == ["x", "y", "rz"]
    # tare and baseline
    tares = _events(tree, "tare")
    assert bool(tree.attrs["tare"]) is tare and (len(tares) == 1) is tare
    assert tree.attrs["baseline"]["method"] == "simulated_calibration"
    assert tree["biotac/baseline"].dims == ("finger", "taxel") and tree["biotac/baseline"].attrs["units"] == "count"


def test_a_run_without_tare_begins_in_contact(cli_runs):
    """Its first frame is pressed: some electrodes sit far below the stored calibration, beyond
    the sensor noise (≤ 10 counts) and the calibration's drift (shared by the electrodes: the
    median difference); a tared run's first frame is the unloaded sensor."""
    def pressed(tree):
        diff = tree["biotac/baseline"].sel(finger="ff").values - tree["biotac/electrodes"].sel(finger="ff").values[0]
        return float(np.max(diff - np.median(diff)))
    tree, _ = cli_runs[("translate", False)]
    assert pressed(tree) > 100
    (setup,) = [d for _, _, n, d in _events(tree, "info") if n == "setup"]
    assert setup["steps"] == 1 and setup["force_n"] == pytest.approx(1.3, rel=0.15)
    assert all(t <= 0 for t, *_ in setup["events"]) and setup["events"][0][0] < -1   # pressed before the record
    assert not _events(tree, "tare")
    assert pressed(cli_runs[("translate", True)][0]) < 50


# ----------------------------------------------------------------------------- the pattern


@pytest.fixture(scope="module")
def pattern_runs(tmp_path_factory):
    out = {}
    conds = [Condition("translate", d, press_force=f, surface=s, tare=t)
             for d, f, s, t in ((0, 1.3, "flat", True), (60, 5.0, "flat", False), (150, 1.3, "cylinder", False),
                                (240, 5.0, "cylinder", True), (300, 1.3, "flat", False))]
    conds += [Condition("rotate", rotation_deg=r, press_force=f, surface=s)
              for r, f, s in ((30, 1.3, "flat"), (-30, 5.0, "flat"), (30, 5.0, "cylinder"), (-30, 1.3, "cylinder"))]
    for c in conds:
        r = run_slip_in_place(tmp_path_factory.mktemp(c.name) / "run", c)
        assert r.status == "success", r.error
        out[c] = xr.open_datatree(str(r.store), engine="zarr")
    return out


def test_a_pulled_object_shifts_the_pattern_along_its_direction_and_a_twist_turns_it(pattern_runs):
    shifts = []
    for c, tree in pattern_runs.items():
        d, dxy = _shift(tree)
        if c.motion == "translate":
            angle = math.degrees(math.atan2(d[1], d[0]))
            err = (angle - c.direction_deg + 180) % 360 - 180
            assert abs(err) < 45, (c.name, d, angle)
            shifts.append(float(np.hypot(*d)))
        else:
            # a twist hardly moves the pattern's centre but turns it: the xy moment changes sign
            # with the sense (+ = counter-clockwise seen from outside the pad: about the sensor's −z)
            assert np.hypot(*d) < 0.6, (c.name, d)
            assert np.sign(dxy) == -np.sign(c.rotation_deg), (c.name, dxy)
    assert min(shifts) > 1.0


def test_a_touch_is_not_a_flat_record(tmp_path):
    """The holder's tremor makes the touch fluctuate; without it only the sensor noise is left."""
    def spread(noise_tremor):
        c = Condition("none", press_force=1.3)
        r = run_slip_in_place(tmp_path / f"t{noise_tremor}", c,
                              overrides=[f"protocol.tremor_mm={0.01 * noise_tremor}",
                                         f"protocol.tremor_normal_mm={0.005 * noise_tremor}",
                                         f"protocol.tremor_deg={0.03 * noise_tremor}"])
        tree = xr.open_datatree(str(r.store), engine="zarr")
        t, a, _ = _pattern(tree)
        m = _motion(tree)
        total = a[(t > m["start"]) & (t < m["end"])].sum(1)
        return np.std(np.diff(total))
    assert spread(1) > 1.2 * spread(0)


def test_same_seed_same_data_other_seed_other_noise(tmp_path):
    c = Condition("rotate", rotation_deg=30, tare=False)
    trees = [xr.open_datatree(str(run_slip_in_place(tmp_path / f"r{i}", c, seed=s).store), engine="zarr")
             for i, s in enumerate((4, 4, 5))]
    a, b, other = (t["biotac/electrodes"].values for t in trees)
    assert np.array_equal(a, b)
    assert np.array_equal(trees[0]["stage/pose"].values, trees[1]["stage/pose"].values)
    assert np.array_equal(trees[0]["biotac/baseline"].values, trees[1]["biotac/baseline"].values)
    assert not np.array_equal(a[: len(other)], other[: len(a)])


def test_the_grid_has_every_condition_and_the_hydra_grid_the_same_count():
    grid = conditions()
    assert len(grid) == 72 and len({c.name for c in grid}) == 72
    assert {c.motion for c in grid} == {"translate", "rotate", "none"}
    cfg = compose(grid[7], noise=0.5)
    assert cfg.hardware.sensor.noise_scale == 0.5 and cfg.protocol.tremor_mm == pytest.approx(0.005)
    exp = Path(__file__).resolve().parents[1] / "conf" / "experiment" / "slip_in_place_grid.yaml"
    from omegaconf import OmegaConf
    params = OmegaConf.load(exp).hydra.sweeper.params
    assert np.prod([len(str(v).split(",")) for v in params.values()]) == 72


def test_a_lab_without_a_stage_refuses_the_protocol_in_one_line(tmp_path):
    env = dict(os.environ, TACTILE_CACHE_DIR=os.environ.get("TACTILE_CACHE_DIR", str(tmp_path / "cache")))
    r = subprocess.run([str(BIN / "tactile-run"), "protocol=slip_in_place", "hardware=lab", "plan_only=true"],
                       cwd=tmp_path, capture_output=True, text=True, timeout=120, env=env)
    assert r.returncode == 2 and r.stderr.strip().count("\n") == 0, r.stderr
    assert "needs an object stage" in r.stderr and "Traceback" not in r.stderr


@pytest.mark.parametrize("overrides, key, words", [
    (["protocol.speed_mm_s=500"], "protocol.speed_mm_s", "(0, 50] mm/s"),
    (["protocol.distance_mm=80"], "protocol.distance_mm", "max_travel_m"),
    (["protocol.distance_mm=0"], "protocol.distance_mm", "> 0"),
    (["protocol.motion=twist"], "protocol.steps[2].move_object.motion", "translate, rotate, none"),
    (["protocol.motion=rotate", "protocol.rotation_speed_deg_s=1000"], "protocol.rotation_speed_deg_s",
     "max_angular_speed_rad_s"),
    (["protocol.motion=rotate", "protocol.rotation_deg=200"], "protocol.rotation_deg", "max_rotation_rad"),
    (["protocol.motion=rotate", "protocol.rotation_deg=0"], "protocol.rotation_deg", "non-zero"),
    (["protocol.press_force=100"], "protocol.steps[0].press.force", "max_contact_force_n"),
    (["protocol.tare=false", "protocol.steps=[{hold:{duration:1}}]"], "protocol.tare", "add a `press` step"),
    (["protocol.tare=false", "protocol.steps=[{press:{}},{hold:{until:{pdc_rise:20}}}]"],
     "protocol.steps[1].hold.until.pdc_rise", "without one"),
    (["hardware.stage=null"], "protocol.steps[0].press.at", "needs an object stage"),
    (["hardware.stage=null", "protocol.steps=[{slide:{}}]"], "protocol.steps[0].slide", "needs an object stage"),
])
def test_bad_slip_protocols_are_refused_naming_the_key(overrides, key, words):
    from tactile_flow.protocols.plan import make_plan
    from tactile_flow.protocols.steps import ProtocolError
    with pytest.raises(ProtocolError) as err:
        make_plan(compose(Condition("translate"), overrides=overrides))
    assert err.value.key == key and words in str(err.value), str(err.value)


def test_a_run_without_tare_refuses_the_live_monitor(tmp_path):
    from tactile_flow.protocols.run import run_protocol
    from tactile_flow.protocols.steps import ProtocolError
    cfg = compose(Condition("none", tare=False), overrides=["live.enabled=true", "analyze=false"])
    with pytest.raises(ProtocolError, match="live monitor needs a tare"):
        run_protocol(cfg, tmp_path / "run", console=lambda *a: None)
    assert not (tmp_path / "run").exists()


def test_a_calibration_file_is_stored_and_a_bad_one_refused(tmp_path):
    from tactile_flow.hardware.errors import ConfigError
    cal = {f: {"sensor_id": f"SN-{f}", "source": "bench, 2026-11-23", "baseline_counts": [3000.0] * 24}
           for f in ("ff", "mf", "rf", "lf", "th")}
    path = tmp_path / "cal.json"
    path.write_text(json.dumps(cal))
    r = run_slip_in_place(tmp_path / "run", Condition("none", tare=False), baseline=str(path))
    tree = xr.open_datatree(str(r.store), engine="zarr")
    assert tree.attrs["baseline"]["method"] == "calibration_file"
    assert tree.attrs["calibration"]["th"]["sensor_id"] == "SN-th"
    assert np.all(tree["biotac/baseline"].values == 3000.0)
    r = run_slip_in_place(tmp_path / "none", Condition("none", tare=False), baseline=None)
    tree = xr.open_datatree(str(r.store), engine="zarr")
    assert "baseline" not in tree["biotac"] and tree.attrs["baseline"]["method"] == "none"
    assert str(tree["truth/conditions/baseline"].values) == "none"
    with pytest.raises(ConfigError, match="hardware.biotac_calibration: no such file"):
        run_slip_in_place(tmp_path / "bad", Condition("none"), baseline=str(tmp_path / "missing.json"))


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["translate", "rotate", "none"])
@pytest.mark.parametrize("tare", [True, False])
def test_the_analysis_reads_the_slip_and_meets_its_targets(cli_runs, kind, tare, tmp_path):
    """The recorded runs analysed as tactile-run hands them off: score.json's slip targets met
    (direction within 45°, rotation sense, touch vs slip, contact found), and nothing else scored."""
    import shutil

    from tactile_flow.analysis.run import analyze_run
    tree, _ = cli_runs[(kind, tare)]
    store = tmp_path / "run.zarr"
    shutil.copytree(tree.attrs["_store"], store)
    summary = analyze_run(store, {"figures": False, "progress": False}, console=lambda *a: None)
    score = json.loads((tmp_path / "analysis" / "score.json").read_text())
    assert score["all_targets_met"] is True, score["targets"]
    assert set(score["targets"]) <= {"slip_direction_correct_fraction", "rotation_sense_correct_fraction",
                                     "touch_vs_slip_correct_fraction", "contact_found_fraction"}
    slip = summary["estimates"]["slip"]["ff"]
    assert slip["slip_class"] == {"translate": "translation", "rotate": "rotation", "none": "none"}[kind]
    assert slip["reference"] == ("contact_onset" if tare else "first_settled")
    if kind == "none":
        assert slip["slip_onset_s"] is None and slip["slip_direction_sensor_deg"] is None
    else:              # dated inside the motion (how close to the breakaway: benchmarks/bench_slip_direction.py)
        m = score["object_motions"][0]
        assert m["start"] - 0.2 <= slip["slip_onset_s"] <= m["end"] and slip["slip_onset_uncertainty_s"] > 0, m


GAIN_3 = ["hardware.sensor.shear_kohm_per_n=3"]
"""The shear gain the real contact frames allow (docs/simulator.md)."""


def _slip_of(tmp_path, condition, **run) -> tuple[dict, dict]:
    """``condition`` run in place (``run``: ``seed=``, ``overrides=``) and analysed with the
    defaults: the slip estimate of the object's motion and that motion's truth."""
    from tactile_flow.analysis.config import load_config
    from tactile_flow.analysis.load import load_run, open_truth
    from tactile_flow.analysis.pipeline import analyse
    from tactile_flow.analysis.score import score
    r = run_slip_in_place(tmp_path / "run", condition, **run)
    assert r.status == "success", r.error
    a = analyse(load_run(r.store), load_config({"figures": False, "progress": False}))
    truth = score(a, open_truth(r.store))["object_motions"][0]
    return a.slips[truth["segment"]], truth


@pytest.mark.slow
def test_a_light_twist_that_drifts_back_is_read_as_a_twist(tmp_path):
    """The SP grid's light (1.3 N) counter-clockwise twist on the flat board without tare: the
    pattern turns the right way while the board turns, then drifts back, so the flows' end
    values average below ``min_rotation_deg`` (round 2 read it as a touch). Its centre of
    pressure stays in place, so the decision reads the static flow's turn since the reference
    window: a rotation, the right sense, dated."""
    c = Condition("rotate", rotation_deg=30.0, press_force=1.3, surface="flat", tare=False)
    slip, _ = _slip_of(tmp_path, c)
    rot = slip["evidence"]["rotation"]
    assert abs(rot["rotation_deg"]) < 0.9 and rot["read_as"] == "static", rot   # the end values alone miss it
    assert slip["slip_class"] == "rotation" and slip["rotation_deg"] > 0.45, rot
    assert slip["slip_onset_s"] is not None


@pytest.mark.slow
def test_a_twist_at_the_shear_the_real_frames_allow_is_a_twist_dated_by_its_static_turn(tmp_path):
    """The firm clockwise twist on the flat board without tare, with the simulator's shear gain at
    3 kΩ/N, the bound the real contact frames allow (docs/simulator.md): the pattern turns under a
    degree, the summed dynamic curl the wrong way (round 3 read it as a touch). Its centre of
    pressure stays in place, so its static flow's turn since the reference window is read: a
    rotation, clockwise, and — the summed curl being noise — dated by that turn, within 50 ms of
    the board's start."""
    c = Condition("rotate", rotation_deg=-30.0, press_force=5.0, surface="flat", tare=False)
    slip, truth = _slip_of(tmp_path, c, overrides=GAIN_3)
    rot = slip["evidence"]["rotation"]
    assert rot["read_as"] == "static" and max(abs(rot["rotation_deg"]), abs(rot["peak_deg"])) < 0.9, rot
    assert slip["slip_class"] == "rotation" and slip["rotation_deg"] < -0.45, rot
    assert abs(slip["slip_onset_s"] - truth["true_slip_onset_s"]) <= 0.05, (slip["slip_onset_s"], truth)
    assert 0.3 < rot["static_straightness"] <= 1.0, rot             # it turned one way (0.53 measured)


@pytest.mark.slow
def test_a_light_twist_at_the_shear_the_real_frames_allow_is_read_by_how_far_its_static_turn_rose(tmp_path):
    """The light (1.3 N) clockwise twist on the flat board without tare, with the simulator's shear
    gain at 3 kΩ/N: the stuck skin's pattern turned half a degree in the static flow, then drifted
    back to an end value of 0.27° once the skin broke away — under ``min_still_rotation_deg``,
    read as a touch before. Read by how far its static turn rose in its one ramp
    (``static_rise_deg``): a rotation, clockwise, dated."""
    from tactile_flow.analysis.config import load_config
    c = Condition("rotate", rotation_deg=-30.0, press_force=1.3, surface="flat", tare=False)
    slip, _ = _slip_of(tmp_path, c, overrides=GAIN_3)
    rot = slip["evidence"]["rotation"]
    cfg = load_config({}).slip
    assert abs(rot["static_deg"]) < cfg.min_still_rotation_deg <= abs(rot["static_rise_deg"]), rot
    assert rot["read_as"] == "static" and slip["slip_class"] == "rotation" and slip["rotation_deg"] < 0, slip
    assert slip["slip_onset_s"] is not None and slip["slip_displacement_mm"] < cfg.min_displacement_mm


@pytest.mark.slow
def test_a_firm_tared_pull_at_the_shear_the_real_frames_allow_is_dated_at_its_release(tmp_path):
    """The firm (5 N) pull at 0° on the cylinder with a tare, at shear gain 3 kΩ/N: the press goes
    on loading the contact after its reference window, so the change from the motion onset to the
    knee is mostly the press; projected on it, the skin's release did not show and a fall 131 ms
    after the breakaway was taken. Read on the stretch's shape (the press's part removed) against
    the signal's own noise while still, it is dated within 50 ms of the breakaway."""
    c = Condition("translate", direction_deg=0.0, press_force=5.0, surface="cylinder", tare=True)
    slip, truth = _slip_of(tmp_path, c, overrides=GAIN_3)
    assert slip["slip_class"] == "translation" and slip["evidence"]["onset"]["dated_by"] == "release", slip
    assert abs(slip["slip_onset_s"] - truth["true_slip_onset_s"]) <= 0.05, (slip["slip_onset_s"], truth)


@pytest.mark.slow
def test_a_firm_pull_whose_stretch_eased_off_its_high_is_dated_at_its_release(tmp_path):
    """Seed 1's firm (5 N) pull at 120° on the cylinder without tare, at shear gain 3 kΩ/N: the
    stretch eases off its high for four frames before the skin breaks away (916 → 876 × its noise,
    then a fall of 221 × its noise in one frame). A release had to fall from a new high, so none
    was found and the knee, 78 ms early, dated it; a fall from within a tenth of the rise below
    the high counts for a translation, and dates it within 50 ms of the breakaway."""
    c = Condition("translate", direction_deg=120.0, press_force=5.0, surface="cylinder", tare=False)
    slip, truth = _slip_of(tmp_path, c, seed=1, overrides=GAIN_3)
    assert slip["slip_class"] == "translation" and slip["evidence"]["onset"]["dated_by"] == "release", slip
    assert abs(slip["slip_onset_s"] - truth["true_slip_onset_s"]) <= 0.05, (slip["slip_onset_s"], truth)


@pytest.mark.slow
def test_a_light_pull_on_the_cylinder_under_the_holders_tremor_reads_as_a_pull(tmp_path):
    """Seed 1's light pull at 180° on the cylinder with a tare: the holder's tremor at touchdown
    had left the skin stretched by ~0.02 mm at the full press's stiffness, whose shear loads
    widened the pattern (RMS radius 3.9 mm against 3.2 under seed 0) and turned the pull's
    rendered pattern by 4°: read as a twist. With the traction kept as the contact grows
    (``hardware.sim.skin.grown``) it is a pull, in its direction."""
    c = Condition("translate", direction_deg=180.0, press_force=1.3, surface="cylinder", tare=True)
    slip, _ = _slip_of(tmp_path, c, seed=1)
    assert slip["evidence"]["motion"]["radius_mm"] < 3.8, slip["evidence"]["motion"]
    assert slip["slip_class"] == "translation", slip["evidence"]["rotation"]
    assert abs((slip["slip_direction_sensor_deg"] - 180.0 + 180.0) % 360.0 - 180.0) <= 45.0

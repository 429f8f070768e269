"""Slip reactions in protocols: parsing, the plan check, and the reactive pour on the simulator.

The acceptance run: ``pour_grasp`` drops the bottle; ``pour_grasp_reactive`` with the same
seed catches the slip live, tightens the grasp and stops the pump, and the bottle is held.
"""

import json
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from hydra import compose, initialize_config_dir

from tactile_flow.protocols.plan import make_plan
from tactile_flow.protocols.run import live_setup, run_protocol
from tactile_flow.protocols.schema import register
from tactile_flow.protocols.steps import Criterion, ProtocolError
from conftest import DATA

register()
CONF_DIR = Path(__file__).resolve().parents[1] / "conf"
QUIET = ("progress=false", "analyze=false")


def _cfg(*overrides):
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base=None):
        return compose("config", overrides=list(overrides))


def test_until_slip_is_a_criterion_and_reactions_parse():
    plan = make_plan(_cfg("protocol=pour_grasp_reactive"))
    pour = next(p.step for p in plan.steps if p.step.kind == "pour")
    assert pour.until == Criterion(slip=True)
    assert [r.kind for r in pour.on_slip] == ["tighten", "stop_pump", "mark"]
    assert pour.on_slip[0].flexion == pytest.approx(0.3)
    assert plan.slip_steps() == [pour.key]
    # the pour waits for its volume (or the slip): 600 ml at 150 ml/min
    assert next(p for p in plan.steps if p.step.kind == "pour").duration == pytest.approx(240.0)


@pytest.mark.parametrize("steps, key, words", [
    ([{"hold": {"on_slip": [{"wait": {"duration": 1}}]}}], "protocol.steps[0].hold.on_slip[0].wait",
     "on_slip takes tighten, stop_pump, mark"),
    ([{"hold": {"on_slip": []}}], "protocol.steps[0].hold.on_slip", "non-empty list"),
    ([{"hold": {"until": "slips"}}], "protocol.steps[0].hold.until", "expected Criterion"),
    ([{"hold": {"until": {"slip": "yes"}}}], "protocol.steps[0].hold.until.slip", "expected bool"),
    ([{"hold": {"on_slip": [{"tighten": {"flexion": 2.0}}]}}], "protocol.steps[0].hold.on_slip[0].tighten.flexion",
     "increment in (0, 0.5]"),
    ([{"pour": {"on_slip": [{"tighten": {"fingers": ["zz"]}}]}}],
     "protocol.steps[0].pour.on_slip[0].tighten.fingers[0]", "expected one of"),
])
def test_bad_reactions_name_the_yaml_key(steps, key, words):
    cfg = _cfg()
    cfg.protocol.steps = steps
    with pytest.raises(ProtocolError) as err:
        make_plan(cfg)
    assert err.value.key == key and words in str(err.value)


def test_a_reacting_protocol_with_the_live_monitor_off_is_refused_before_anything_moves(tmp_path):
    cfg = _cfg("protocol=pour_grasp_reactive", "live.enabled=false", *QUIET)
    with pytest.raises(ProtocolError, match=r"pour.*live.enabled=false"):
        run_protocol(cfg, tmp_path / "run", console=lambda *a: None)
    assert not (tmp_path / "run").exists()


def test_live_monitor_is_only_built_when_needed():
    assert live_setup(_cfg("protocol=straws_sweep"), make_plan(_cfg("protocol=straws_sweep")))[1] is None
    cfg = _cfg("protocol=straws_sweep", "live.enabled=true", "live.views=[bottom]")
    assert live_setup(cfg, make_plan(cfg))[1].config.views == ("bottom",)


@pytest.mark.parametrize("override, key", [("live.fingers=[ff,zz]", "live.fingers"),
                                           ("live.views=[bottom,top]", "live.views[1]"),
                                           ("live.slip.release_drop=-0.2", "live.slip.release_drop")])
def test_bad_live_settings_are_refused_by_key(override, key):
    """(Unknown keys never get this far: the run config's schema refuses them at composition.)"""
    from tactile_flow.hardware.errors import ConfigError
    cfg = _cfg("protocol=pour_grasp_reactive", override)
    with pytest.raises(ConfigError) as err:
        live_setup(cfg, make_plan(cfg))
    assert err.value.key == key


def _events(tree, kind):
    ev = tree["events"].to_dataset()
    return [(float(t), str(n), json.loads(str(d)) if str(d) else {})
            for t, k, n, d in zip(ev.time.values, ev.kind.values, ev.name.values, ev.detail.values) if k == kind]


@pytest.fixture(scope="module")
def pours(tmp_path_factory):
    """The same seed, with and without the reflex."""
    out = {"stores": {}}
    for name in ("pour_grasp", "pour_grasp_reactive"):
        run_dir = tmp_path_factory.mktemp(name)
        result = run_protocol(_cfg(f"protocol={name}", "hardware.seed=7", *QUIET), run_dir, console=lambda *a: None)
        assert result.status == "success", result.error
        out[name] = xr.open_datatree(result.store, engine="zarr")
        out["stores"][name] = Path(result.store)
    return out


def test_the_reactive_pour_holds_the_bottle_the_plain_pour_drops(pours):
    plain, reactive = pours["pour_grasp"], pours["pour_grasp_reactive"]
    assert np.isfinite(float(plain["truth/pour/full_slip"].values))            # dropped
    assert np.isnan(float(reactive["truth/pour/full_slip"].values))            # held
    # it neither turned nor slid down while held: only once the protocol's release opened the hand
    released = next(t for t, n, _ in _events(reactive, "step_start") if n.endswith("release"))
    released += float(reactive.attrs["t0_clock_s"])
    for phase in ("rotation", "downward"):
        t = float(reactive[f"truth/pour/{phase}"].values)
        assert np.isnan(t) or t >= released, (phase, t, released)
    # the slip began the same way in both runs
    assert float(reactive["truth/pour/slip_onset"].values) == pytest.approx(
        float(plain["truth/pour/slip_onset"].values), abs=0.05)


def test_the_reaction_follows_the_slip_onset_within_50_ms(pours):
    tree = pours["pour_grasp_reactive"]
    t0 = float(tree.attrs["t0_clock_s"])
    onset = float(tree["truth/pour/slip_onset"].values) - t0
    (slip,) = _events(tree, "slip")
    reactions = _events(tree, "reaction")
    assert [n for _, n, _ in reactions] == ["tighten", "stop_pump", "mark"]
    latency = reactions[0][0] - onset
    assert 0 <= latency <= 0.05, latency
    assert slip[1] in ("ff", "mf", "th") and slip[2]["cause"] in ("release", "creep", "rotation")
    # the pump stopped within a pump period of the reaction, and no more water went in
    pour = tree["pour"].to_dataset()
    after = pour.time_pump.values > reactions[0][0] + 0.2
    assert not pour.pump_running.values[after].any()


def test_at_a_realistic_shear_gain_the_reflex_still_holds_the_bottle(tmp_path):
    """At 3 kΩ/N (what the real BioTac SP contact frames allow; docs/simulator.md) the
    release moves no pixel past the flow's absolute noise level: the detector must see the
    thumb's mean flow stand out of its own level, or the bottle falls (it did: full slip at
    53.64 s)."""
    cfg = _cfg("protocol=pour_grasp_reactive", "hardware.sensor.shear_kohm_per_n=3", "hardware.seed=1", *QUIET)
    result = run_protocol(cfg, tmp_path / "run", console=lambda *a: None)
    assert result.status == "success", result.error
    tree = xr.open_datatree(result.store, engine="zarr")
    assert np.isnan(float(tree["truth/pour/full_slip"].values))                 # held
    onset = float(tree["truth/pour/slip_onset"].values) - float(tree.attrs["t0_clock_s"])
    (slip,) = _events(tree, "slip")
    assert slip[0] >= onset and slip[2]["cause"] == "release"                   # not before the slip
    reactions = _events(tree, "reaction")
    assert [n for _, n, _ in reactions] == ["tighten", "stop_pump", "mark"]
    assert 0 <= reactions[0][0] - onset <= 0.05
    # the grasp closing, the wait and the filling before it never fired
    live = tree["live"].to_dataset()
    assert not live.slip_fired.values[live.time_live.values < onset].any()


def test_the_live_stream_records_what_the_monitor_saw(pours):
    tree = pours["pour_grasp_reactive"]
    live = tree["live"].to_dataset()
    assert list(live.live_finger.values) == ["ff", "mf", "th"]
    assert list(live.view.values) == ["bottom"]
    assert live.magnitude.dims == ("time_live", "live_finger", "view")
    # one row per BioTac frame after the tare, joined by seq
    seqs = tree["biotac/seq"].values
    assert np.isin(live.seq.values, seqs).all() and len(live.seq) > 0.9 * (len(seqs) - 60)
    # the frame that fired is in the stream, before the reaction, and processed in time
    (slip,) = _events(tree, "slip")
    fired = live.time_live.values[live.slip_fired.values.any(axis=1)]
    assert fired.size and fired[0] == pytest.approx(slip[2]["frame_time"], abs=1e-3)
    assert (live.processed_time.values - live.time_live.values).max() < 0.05
    assert tree.attrs["live"]["frames"] == len(live.seq)


def test_the_plain_pour_records_no_live_group(pours):
    assert "live" not in pours["pour_grasp"].children
    assert not _events(pours["pour_grasp"], "reaction")


# ----------------------------------------------------------------------------- false alarms

BAG = DATA / "biotac_rest_untouched.bag"


def test_no_false_alarm_on_the_resting_recording(model):
    from dataclasses import replace

    from tactile_flow.importers.bag import read_bag
    from tactile_flow.importers.recording import select_fingers
    from tactile_flow.protocols.live import replay
    from tactile_flow.tactile import signals
    from tactile_flow.tactile.pipeline import TactileModel

    rec, _ = select_fingers(read_bag(BAG))
    online = TactileModel.build(replace(model.config, smooth=False))
    rest = signals.baseline_from_rest(rec.electrodes, 0, 100)          # the first second
    out = replay(online, rest, rec.seq, rec.device_time - rec.device_time[0], rec.electrodes, rec.fingers)
    assert out["frames"] == 977 and list(rec.fingers) == ["ff", "mf", "th"]
    assert out["detections"] == []
    assert all(c["processed"] == 977 for c in out["counters"].values())


@pytest.mark.parametrize("gain", [12, 3])
def test_no_false_alarm_on_a_simulated_sweep(tmp_path, gain):
    cfg = _cfg("protocol=straws_sweep", "live.enabled=true", f"hardware.sensor.shear_kohm_per_n={gain}", *QUIET)
    result = run_protocol(cfg, tmp_path / "run", console=lambda *a: None)
    tree = xr.open_datatree(result.store, engine="zarr")
    live = tree["live"].to_dataset()
    assert len(live.seq) > 1000 and not live.slip_fired.values.any()
    assert not _events(tree, "slip")
    # the finger did slide across the straws: the live flow saw it
    ff = list(live.live_finger.values).index("ff")
    assert np.nanmax(live.confidence.values[:, ff]) > 0.5


@pytest.mark.parametrize("gain", [12, 3])
def test_corrupt_and_missing_frames_are_skipped_and_counted_never_taken_for_slip(tmp_path, gain):
    cfg = _cfg("protocol=pour_grasp_reactive", "hardware.seed=3", f"hardware.sensor.shear_kohm_per_n={gain}", *QUIET,
               "hardware.faults.biotac_dropout=[[8.0,8.2]]", "hardware.faults.biotac_corrupt=[12.0,12.5,13.0]")
    result = run_protocol(cfg, tmp_path / "run", console=lambda *a: None)
    assert result.status == "success", result.error
    tree = xr.open_datatree(result.store, engine="zarr")
    onset = float(tree["truth/pour/slip_onset"].values) - float(tree.attrs["t0_clock_s"])
    (slip,) = _events(tree, "slip")
    assert slip[0] >= onset                                   # not fired by the faults before it
    counters = tree.attrs["live"]["counters"]
    assert all(c["skipped_invalid"] == 3 and c["gaps"] >= 1 for c in counters.values()), counters
    live = tree["live"].to_dataset()
    bad = ~live.processed.values.all(axis=1)
    assert bad.sum() == 3 and np.isnan(live.magnitude.values[bad]).all()
    assert np.isnan(float(tree["truth/pour/full_slip"].values))


def test_the_operator_line_shows_each_finger_and_the_slip_state():
    from tactile_flow.hardware.sim import make_sim_lab
    from tactile_flow.protocols.live import LiveConfig, LiveMonitor, tactile_config
    from tactile_flow.tactile.pipeline import TactileModel

    class Rec:
        t0 = 0.0
        rows = []

        def live(self, cols):
            self.rows.append(cols)

    lines = []
    cfg = LiveConfig(fingers=["ff", "th"], views=["bottom"], console_hz=4.0)
    model = TactileModel.build(tactile_config(None, cfg.views))
    with make_sim_lab() as lab:
        mon = LiveMonitor(lab.biotac, Rec(), model, cfg, lab.clock, display=lines.append)
        assert mon.line() == "live: taring"
        lab.clock.sleep(0.3)
        mon.poll()
        mon.begin()
        for _ in range(100):                                  # 1 s of frames, polled every 10 ms
            lab.clock.sleep(0.01)
            mon.poll(still=True)
        summary = mon.close()
    assert 3 <= len(lines) <= 6                               # about 4 lines a second
    assert lines[-1].startswith("ff ") and "| th " in lines[-1] and lines[-1].endswith("slip: -")
    assert summary["frames"] == sum(len(r["seq"]) for r in Rec.rows) >= 99
    assert summary["tap_overflows"] == 0


def test_the_analysis_dates_the_slip_labels_the_held_grasp_and_marks_the_reaction(pours):
    from tactile_flow.analysis.run import analyze_run

    store = pours["stores"]["pour_grasp_reactive"]
    summary = analyze_run(store, {"progress": False, "max_segment_figures": 0}, console=lambda *a: None)
    labels = {s["label"] for s in summary["segments"]}
    assert {"pour", "held"} <= labels and not labels & {"rotation", "downward", "full_slip"}
    score = json.loads((store.parent / "analysis" / "score.json").read_text())
    assert abs(score["summary"]["slip_onset_error_ms"]) <= 20
    assert (store.parent / "analysis" / "figures" / "pressure.png").stat().st_size > 10_000


def test_a_restarted_frame_counter_restarts_the_online_flow_instead_of_blinding_it():
    from tactile_flow.hardware.biotac import BiotacFrame, FrameTap
    from tactile_flow.protocols.live import RESTART_FRAMES, LiveConfig, LiveMonitor, tactile_config
    from tactile_flow.tactile.pipeline import TactileModel

    class Biotac:                        # a sensor whose bridge reconnects mid-run
        fingers, rate_hz = ("ff",), 100.0

        def tap(self, maxlen):
            self.the_tap = FrameTap(maxlen)
            return self.the_tap

        def untap(self, tap):
            pass

    class Rec:
        t0 = 0.0
        events, rows = [], []

        def live(self, cols):
            self.rows.append(cols)

        def event(self, *e):
            self.events.append(e)

    class Clock:
        def now(self):
            return 0.0

    def frame(seq, t):
        e = np.full((1, 24), 3000, np.int16)
        z = np.zeros(1, np.int32)
        return BiotacFrame(seq, t, t, e, z, z, z, np.zeros((1, 2), np.int16))

    bt, rec = Biotac(), Rec()
    mon = LiveMonitor(bt, rec, TactileModel.build(tactile_config(None, ["bottom"])), LiveConfig(views=["bottom"]),
                      Clock())
    for i in range(50):
        bt.the_tap.put(frame(1000 + i, i * 0.01))
    mon.begin()
    for i in range(50, 100):
        bt.the_tap.put(frame(1000 + i, i * 0.01))
    for i in range(100):                                      # the counter starts again at 1
        bt.the_tap.put(frame(1 + i, 1.0 + i * 0.01))
    mon.poll()
    processed = np.concatenate([r["processed"][:, 0] for r in rec.rows])
    assert processed[:50].all() and not processed[50:50 + RESTART_FRAMES - 1].any()
    assert processed[50 + RESTART_FRAMES - 1:].all()
    assert [e[1] for e in rec.events] == ["live"] and "restarted" in rec.events[0][2]["message"]

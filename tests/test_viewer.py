"""The viewer (``tactile-view``, ``live.viewer=rerun``): recordings written for real simulated runs
and read back with Rerun's own dataframe reader.

The slow tests run a straws sweep and a reactive pour (``protocols.run.run_protocol``, the
analysis, then ``tactile-view --save``) and check that every stream is on the run's timeline with
the rows and the time range the run store says it should have; the reactive pour runs with the
live viewer on, and its ``live.rrd`` must hold every frame the monitor processed.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from conftest import DATA
from tactile_flow.hardware.transforms import rotvec_to_quaternion

pytest.importorskip("rerun")
pytest.importorskip("datafusion")

from rerun.chunk import RrdReader  # noqa: E402

from tactile_flow.viewer import TIMELINE, draw  # noqa: E402
from tactile_flow.viewer.cli import main as tactile_view  # noqa: E402

CONF_DIR = Path(__file__).resolve().parents[1] / "conf"
VIEWS = ("bottom", "left", "right")
NS = 1e-9


# ----------------------------------------------------------------------------- reading recordings

class Recording:
    """An .rrd file read back through Rerun's dataframe reader (one query per entity)."""

    def __init__(self, path):
        self.store = RrdReader(str(path)).stream().collect()
        self.entities = {c.entity_path for c in self.store.schema() if hasattr(c, "entity_path")}

    def table(self, entity: str):
        return self.store.reader(index=TIMELINE, contents=entity).to_arrow_table()

    def rows(self, entity: str) -> tuple[int, float, float]:
        """(rows, first time, last time) of an entity on the timeline, s."""
        t = self.table(entity)
        ns = t[TIMELINE].cast("int64").to_numpy()
        return len(ns), ns.min() * NS, ns.max() * NS

    def chunk_rows(self, entity: str) -> int:
        """Rows logged on an entity (the dataframe folds rows that share a time into one)."""
        return sum(c.num_rows for c in self.store.stream() if c.entity_path == entity and not c.is_static)

    def values(self, entity: str, component: str) -> list:
        return self.table(entity)[f"{entity}:{component}"].to_pylist()


def assert_on_timeline(rec: Recording, entity: str, times) -> None:
    """The entity has one row per distinct time in ``times`` (s) and spans exactly their range."""
    times = np.unique(np.round(np.asarray(times, float) / NS).astype(np.int64)) * NS
    n, first, last = rec.rows(entity)
    assert n == len(times), (entity, n, len(times))
    assert first == pytest.approx(times[0], abs=2e-9) and last == pytest.approx(times[-1], abs=2e-9), entity


# ----------------------------------------------------------------------------- the runs

def _cfg(*overrides):
    from hydra import compose, initialize_config_dir

    from tactile_flow.protocols.schema import register
    register()
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base=None):
        return compose("config", overrides=list(overrides))


def _run_analyse_view(run_dir: Path, *overrides) -> dict:
    from tactile_flow.analysis.run import analyze_run
    from tactile_flow.protocols.run import run_protocol
    lines = []
    result = run_protocol(_cfg(*overrides, "progress=false", "analyze=false"), run_dir, console=lines.append)
    assert result.status == "success", result.error
    analyze_run(result.store, {"progress": False, "figures": False}, console=lambda *a: None)
    rrd = run_dir / "view.rrd"
    assert tactile_view([str(run_dir), "--save", str(rrd)]) == 0
    return {"dir": run_dir, "rrd": Recording(rrd), "tree": xr.open_datatree(str(result.store), engine="zarr"),
            "summary": json.loads((run_dir / "analysis" / "summary.json").read_text()), "console": lines}


@pytest.fixture(scope="module")
def straws(tmp_path_factory):
    return _run_analyse_view(tmp_path_factory.mktemp("straws") / "run", "protocol=straws_sweep")


@pytest.fixture(scope="module")
def pour(tmp_path_factory):
    return _run_analyse_view(tmp_path_factory.mktemp("pour") / "run", "protocol=pour_grasp_reactive",
                             "live.viewer=rerun")


def _shown_times(tree, fps=25.0):
    """The frames tactile-view shows, from the store alone: valid frames, every round(rate/fps)-th from the second."""
    b = tree["biotac"].to_dataset()
    t = b.time.values[b.valid.values]
    step = max(1, int(round(1.0 / np.median(np.diff(t)) / fps)))
    return t, t[np.arange(1, len(t), step)]


def _check_replay(run: dict) -> None:
    rec, tree = run["rrd"], run["tree"]
    fingers = [str(f) for f in tree["biotac"].finger.values]
    t, shown = _shown_times(tree)
    for f in fingers:
        assert_on_timeline(rec, f"/signals/pressure/{f}", t)
        assert_on_timeline(rec, f"/signals/electrodes/{f}", t)
        assert len(rec.values(f"/signals/electrodes/{f}", "Scalars:scalars")[0]) == 24
        assert_on_timeline(rec, f"/world/tcp/{f}/mesh", shown)
        for v in VIEWS:
            for entity in (f"/tactile/{f}/{v}/frame", f"/tactile/{f}/{v}/flow", f"/tactile/{f}/{v}/direction",
                           f"/flow/{f}/{v}/direction", f"/flow/{f}/{v}/magnitude"):
                assert_on_timeline(rec, entity, shown)
    arm = tree["arm"].to_dataset()
    assert_on_timeline(rec, "/world/tcp", arm.time_arm.values)
    assert_on_timeline(rec, "/arm/speed", arm.time_arm.values)
    p = tree["pour"].to_dataset()
    assert_on_timeline(rec, "/pour/pump_rate", p.time_pump.values)
    assert_on_timeline(rec, "/pour/mass", p.time_scale.values)
    ev = tree["events"].to_dataset()
    assert_on_timeline(rec, "/events", ev.time.values)
    assert rec.chunk_rows("/events") == ev.sizes["event"]                     # every event, not one per time
    steps = np.isin([str(k) for k in ev.kind.values], ["step_start", "step_end"])
    assert_on_timeline(rec, "/protocol/step", ev.time.values[steps])
    for f in fingers:                                                       # segments, in order, as analysed
        segs = [s for s in run["summary"]["segments"] if s["finger"] == f]
        if not segs:
            assert f"/segments/{f}" not in rec.entities
            continue
        states = [s[0] for s in rec.values(f"/segments/{f}", "StateChange:state") if s]
        assert states == [s["label"] for s in sorted(segs, key=lambda s: s["start_s"])]
        n, first, last = rec.rows(f"/segments/{f}")
        assert first == pytest.approx(min(s["start_s"] for s in segs), abs=1e-6)
        assert last == pytest.approx(max(s["end_s"] for s in segs), abs=1e-6)


@pytest.mark.slow
def test_a_straws_sweep_replays_every_stream_on_the_run_timeline(straws):
    _check_replay(straws)
    rec = straws["rrd"]
    assert not any(e.startswith("/live") for e in rec.entities)             # no live monitor in this run
    # the sweeping finger's frames show the contact, and its flow moves
    t, shown = _shown_times(straws["tree"])
    peak = straws["summary"]["estimates"]["crossings"][0]["peak_time"]
    frames = rec.table("/tactile/ff/bottom/frame")
    k = int(np.argmin(np.abs(frames[TIMELINE].cast("int64").to_numpy() * NS - peak)))
    assert max(frames["/tactile/ff/bottom/frame:Image:buffer"][k].as_py()[0]) > 100
    # at the peak itself the pattern turns (its flow is smallest there): the arrows of the shown
    # frames around it, ±0.12 s, move
    shown_flow = rec.values("/tactile/ff/bottom/flow", "Arrows2D:vectors")
    assert max(np.abs(np.array(shown_flow[j])).max() for j in range(k - 3, k + 4)) > 0.5
    # the frames and flow shown are the analysis' own, frame for frame
    from tactile_flow.analysis.config import load_config
    from tactile_flow.analysis.load import load_run
    from tactile_flow.analysis.pipeline import analyse
    from tactile_flow.viewer.scene import load_scene, tactile_tracks
    scene = load_scene(straws["dir"])
    cfg = load_config({**scene.run.config["analysis"], "save_fields": True, "progress": False})
    (cf, *_) = [c for c in analyse(load_run(straws["dir"] / "run.zarr"), cfg).flows if c.finger == "ff"]
    (w0, w1), (track,) = cf.window, tactile_tracks(scene, ["ff"])[:1]
    inside = [(j, i - w0) for j, i in enumerate(scene.shown) if w0 < i < w1]
    assert len(inside) > 10
    result = cf.views["bottom"]
    for j, i in inside:
        assert np.array_equal(track.frames[j], result.frames[i])
        assert np.array_equal(track.arrows[j], draw.sample_field(result.dynamic_field[i], track.grid))
    # the run document names what was shown and the arrow scale
    (doc,) = RrdReader(str(straws["dir"] / "view.rrd")).stream().collect().reader(
        index=None, contents="/run").to_arrow_table()["/run:TextDocument:text"].to_pylist()
    assert "straws_sweep" in doc[0] and "arrows ×" in doc[0]


@pytest.mark.slow
def test_a_reactive_pour_replays_every_stream_and_the_live_verdicts(pour):
    _check_replay(pour)
    rec, live = pour["rrd"], pour["tree"]["live"].to_dataset()
    for entity, series in (("/live/magnitude", 3), ("/live/direction", 3), ("/live/activation_total", 3),
                           ("/live/slip_cause", 3)):                      # ff, mf, th × bottom
        assert_on_timeline(rec, entity, live.time_live.values)
        assert len(rec.values(entity, "Scalars:scalars")[0]) == series
    magnitude = np.array(rec.values("/live/magnitude", "Scalars:scalars"))
    assert np.allclose(magnitude, live.magnitude.values.reshape(len(magnitude), -1), equal_nan=True)
    assert [s for (s,) in rec.values("/live/slip", "StateChange:state")] == ["watching", "slip"]
    _, first, _ = rec.rows("/live/slip")
    assert first == pytest.approx(float(live.time_live[0]), abs=2e-9)
    pump = [v for (v,) in rec.values("/pour/dispensed", "Scalars:scalars")]
    assert max(pump) > 10                                                   # it poured


@pytest.mark.slow
def test_the_live_viewer_shows_every_frame_the_monitor_processed(pour):
    tree, run_dir = pour["tree"], pour["dir"]
    live, biotac = tree["live"].to_dataset(), tree["biotac"].to_dataset()
    attrs = tree.attrs["live"]
    attrs = json.loads(attrs) if isinstance(attrs, str) else attrs
    # the monitor processed every frame recorded from the end of the tare on, each once
    (tare,) = [json.loads(str(d)) for k, d in zip(tree["events"].kind.values, tree["events"].detail.values)
               if str(k) == "tare"]
    assert float(live.time_live[0]) == pytest.approx(tare["end"], abs=0.02)
    recorded = biotac.seq.values[biotac.seq.values >= int(live.seq[0])]
    assert np.array_equal(live.seq.values, recorded) and attrs["frames"] == len(recorded)
    # ... and the viewer got every one of them (none dropped on this machine), on the same times
    viewer = attrs["viewer"]
    assert viewer["rows_offered"] == viewer["rows_shown"] == live.sizes["time_live"] and viewer["rows_dropped"] == 0
    assert any("no display" in line for line in pour["console"]) or viewer["display"]
    rec = Recording(run_dir / "live.rrd")
    assert_on_timeline(rec, "/live/magnitude", live.time_live.values)
    for f in [str(f) for f in live.live_finger.values]:
        n, first, last = rec.rows(f"/tactile/{f}/bottom/frame")
        assert 0.8 * 25 * (last - first) <= n <= 25 * (last - first) + 2     # live frames at ≈ 25 per second
    assert rec.chunk_rows("/events") == tree["events"].sizes["event"]           # the engine's events, as they came
    assert [s for (s,) in rec.values("/live/slip", "StateChange:state")] == ["watching", "slip"]


def _listening_on(port: int) -> set[str]:
    """The local addresses with a TCP socket listening on ``port`` (/proc/net/tcp and tcp6)."""
    found = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        for line in Path(table).read_text().splitlines()[1:]:
            local, state = line.split()[1], line.split()[3]
            address, hexport = local.rsplit(":", 1)
            if state == "0A" and int(hexport, 16) == port:             # 0A: LISTEN
                found.add({"0100007F": "127.0.0.1", "00000000": "0.0.0.0"}.get(address, address))
    return found


def _serve(run_dir, *args):
    import socket
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    proc = subprocess.Popen([sys.executable, "-c", "import sys; from tactile_flow.viewer.cli import main; "
                             "sys.exit(main(sys.argv[1:]))", str(run_dir), "--web", "--port", str(port), *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    return proc, port


@pytest.mark.slow
def test_web_serves_the_viewer_on_this_machine_only_until_stopped(straws):
    """Issue 34, item 4: the web viewer and its gRPC proxy listen on loopback (they listened on
    every interface, 0.0.0.0); Ctrl-C stops serving, exit 0, nothing on stderr."""
    import re
    import signal
    import urllib.request
    proc, port = _serve(straws["dir"])
    try:
        line = proc.stdout.readline()                          # printed once everything is sent
        assert f"http://127.0.0.1:{port}/?url=" in line and "Ctrl-C" in line, line + proc.stderr.read()
        grpc = int(re.search(r"%3A(\d+)%2Fproxy", line).group(1))
        assert _listening_on(port) == {"127.0.0.1"} and _listening_on(grpc) == {"127.0.0.1"}
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=10) as page:
            assert page.status == 200 and b"Rerun" in page.read()
        assert proc.poll() is None                             # still serving
        proc.send_signal(signal.SIGINT)
        assert proc.wait(30) == 0 and proc.stderr.read() == ""
        assert _listening_on(port) == set() and _listening_on(grpc) == set()     # its server is gone too
    finally:
        proc.kill()
        proc.wait(30)


@pytest.mark.slow
def test_web_on_every_interface_only_when_asked_and_with_a_warning(straws):
    proc, port = _serve(straws["dir"], "--bind", "0.0.0.0")
    try:
        assert "Ctrl-C" in proc.stdout.readline()
        assert _listening_on(port) == {"0.0.0.0"}
    finally:
        proc.terminate()
        proc.wait(30)
    (warning,) = [x for x in proc.stderr.read().splitlines() if x.strip()]
    assert warning.startswith("tactile-view: warning: serving on every network interface") and "127.0.0.1" in warning


@pytest.mark.slow
def test_an_imported_and_analysed_run_replays_without_a_rerun_warning(tmp_path):
    """Issue 34, item 13: Rerun warned (with a line of our source) that three segment colours
    were ambiguous (packed colours or one RGB?): every Rerun warning is an error here."""
    import csv
    import warnings

    from rerun.error_utils import RerunWarning

    from tactile_flow.analysis.run import analyze_run
    from tactile_flow.importers.importer import ImportSettings, import_source
    with open(DATA / "biotac_sp_grasps" / "palm_down_test.csv") as f:
        grasps = np.array([[float(x) for x in row[2:]] for row in list(csv.reader(f))[1:]])
    rest, rng = np.percentile(grasps, 99, axis=0), np.random.default_rng(0)
    frames = [*(rest + rng.normal(0, 3, rest.shape) for _ in range(150)), *grasps[:60],
              *(rest + rng.normal(0, 3, rest.shape) for _ in range(150))]
    names = [f"{f}_e{k}" for f in ("ff", "mf", "th") for k in range(1, 25)]
    source = tmp_path / "press.csv"
    source.write_text(",".join(names) + "\n" + "".join(",".join(str(int(np.clip(v, 1, 4095))) for v in row) + "\n"
                                                      for row in frames))
    (result,) = import_source(source, tmp_path / "imported", ImportSettings(rate_hz=100.0))
    summary = analyze_run(result.store, {"progress": False, "figures": False}, console=lambda *a: None)
    assert summary["segments"], "the press must be segmented (the colours of three labels are what warned)"
    with warnings.catch_warnings():
        warnings.simplefilter("error", RerunWarning)
        assert tactile_view([result.run_dir, "--save", str(tmp_path / "view.rrd")]) == 0


# ----------------------------------------------------------------------------- the live viewer's queue

def test_the_live_viewer_drops_and_counts_when_it_cannot_keep_up_and_never_blocks(model, tmp_path, rng):
    """Rows offered far faster than 100 Hz: the queue fills, what does not fit is dropped and
    counted, every offer returns at once, and offered = shown + dropped."""
    from tactile_flow.tactile.online import OnlineFlow
    from tactile_flow.viewer.live import QUEUE_ITEMS, LiveViewer
    fingers = ("ff", "mf")
    flow = OnlineFlow(model, np.full((2, 24), 10.0), fingers, ("bottom",))
    for i in range(3):
        flow.push(i, 0.01 * i, rng.integers(2500, 3000, (2, 24)))
    viewer = LiveViewer(fingers, ("bottom",), model, tmp_path, spawn=False)
    n, waits = 4 * QUEUE_ITEMS, []
    for i in range(n):
        rows = _rows(i, fingers)
        t0 = time.perf_counter()
        viewer.offer(rows, flow)
        waits.append(time.perf_counter() - t0)
    counts = viewer.close()
    assert counts["rows_offered"] == n and counts["rows_dropped"] > 0
    assert counts["rows_shown"] + counts["rows_dropped"] == n and counts["error"] is None
    # Never waits for the viewer: an offer that waited would take the viewer's drawing time,
    # offer after offer. A loaded machine may stall any one call, so the bound is on the 95th
    # percentile (a few ms) and on the worst (well under one blocked drain).
    assert np.percentile(waits, 95) < 0.01 and max(waits) < 0.5, (np.percentile(waits, 95), max(waits))
    rec = Recording(tmp_path / "live.rrd")
    assert rec.chunk_rows("/live/magnitude") == counts["rows_shown"]


def _rows(i, fingers):
    """One row of the ``live`` block, as :meth:`protocols.live.LiveMonitor._process` makes it."""
    f = len(fingers)
    return {"time_live": np.array([0.01 * i]), "processed_time": np.array([0.01 * i]), "seq": np.array([i]),
            "processed": np.ones((1, f), bool), "activation_total": np.full((1, f), 1.0),
            **{k: np.full((1, f, 1), 0.1) for k in ("flow_col", "flow_row", "magnitude", "direction", "divergence",
                                                     "curl", "confidence")},
            "slip_fired": np.zeros((1, f), bool), "slip_cause": np.zeros((1, f), np.int8),
            "slip_detected": np.array([i > 500])}


# ----------------------------------------------------------------------------- the command line

def _cli(*args, env=None, pre=""):
    code = f"{pre}import sys; from tactile_flow.viewer.cli import main; sys.exit(main({list(args)!r}))"
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                          env={**os.environ, **(env or {})})


def test_without_the_view_extra_tactile_view_says_how_to_install_it():
    block = ("import importlib.abc, sys\n"
             "class NoRerun(importlib.abc.MetaPathFinder):\n"
             "    def find_spec(self, name, path=None, target=None):\n"
             "        if name.split('.')[0] in ('rerun', 'rerun_bindings'):\n"
             "            raise ModuleNotFoundError(name)\n"
             "sys.meta_path.insert(0, NoRerun())\n")
    r = _cli("anything", pre=block)
    assert r.returncode == 2
    assert r.stderr.strip().count("\n") == 0 and "pip install -e '.[view]'" in r.stderr


def test_the_core_packages_never_import_rerun():
    code = ("import sys, protocols.run, protocols.cli, analysis.run, viewer, viewer.cli, viewer.live, viewer.scene;"
            "print('rerun' in sys.modules)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and r.stdout.strip() == "False", r.stderr


@pytest.mark.parametrize("args, words", [
    (["{tmp}/nothing"], "no such run directory"),
    (["{tmp}"], "not a run directory"),
    (["{tmp}", "--save", "{tmp}/x.png"], "not a run directory"),
    (["{tmp}/run", "--save", "{tmp}/x.png"], "expected a file name ending in .rrd"),
    (["{tmp}/run", "--save", "{tmp}/missing/x.rrd"], "its directory does not exist"),
    (["{tmp}/run", "--fps", "0", "--save", "{tmp}/x.rrd"], "fps"),
    (["{tmp}/run", "--save", "{tmp}/x.rrd"], "not a run store"),
])
def test_bad_input_is_one_line_and_exit_2(tmp_path, args, words):
    (tmp_path / "run" / "run.zarr").mkdir(parents=True)          # a run directory whose store is not one
    r = _cli(*[a.format(tmp=tmp_path) for a in args])
    assert r.returncode == 2, r.stderr
    assert words in r.stderr and r.stderr.strip().count("\n") == 0
    assert not list(tmp_path.glob("*.rrd*"))


def test_without_a_display_tactile_view_asks_for_web_or_save(tmp_path):
    (tmp_path / "run.zarr").mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    r = subprocess.run([sys.executable, "-c", f"import sys; from tactile_flow.viewer.cli import main; sys.exit(main([{str(tmp_path)!r}]))"],
                       capture_output=True, text=True, timeout=120, env=env)
    assert r.returncode == 2 and "--web" in r.stderr and "--save" in r.stderr


def test_a_live_viewer_that_is_not_installed_is_refused_before_anything_moves(tmp_path):
    from tactile_flow.hardware.errors import ConfigError
    from tactile_flow.protocols.plan import make_plan
    from tactile_flow.protocols.run import live_setup
    cfg = _cfg("live.viewer=foxglove")
    with pytest.raises(ConfigError) as err:
        live_setup(cfg, make_plan(cfg))
    assert err.value.key == "live.viewer" and "rerun" in str(err.value)
    cfg = _cfg("live.viewer=rerun", "live.enabled=false")
    with pytest.raises(ConfigError, match="live.enabled=false"):
        live_setup(cfg, make_plan(cfg))
    cfg = _cfg("live.viewer=rerun")                                           # the viewer turns the monitor on
    assert live_setup(cfg, make_plan(cfg), build=False)[0].viewer == "rerun"


# ----------------------------------------------------------------------------- drawing

def test_arrows_sit_on_the_footprint_and_the_gain_reads_simply(model):
    mask = model.plans["bottom"].mask
    rows, cols = draw.arrow_grid(mask, 3)
    assert mask[rows, cols].all() and len(rows) > 20
    assert np.all(np.diff(np.unique(rows)) == 3) and np.all(np.diff(np.unique(cols)) == 3)
    vectors = np.zeros((50, len(rows), 2), np.float32)
    vectors[:, :, 0] = np.linspace(0.001, 0.1, 50)[:, None]
    assert draw.nice_gain(vectors, 3) == 20.0                       # 3 px / p99 (≈ 0.098) = 30.6 → 20 (1-2-5 steps)
    assert draw.nice_gain(np.zeros((4, 2)), 3) == 1.0


def test_a_still_pattern_has_no_direction_and_a_sweep_along_the_finger_does_not_wrap():
    d = draw.direction_deg([np.pi, -np.pi + 1e-3, 0.3], [0.2, 0.2, 0.001], noise=0.05)
    assert d[0] == pytest.approx(180) and d[1] == pytest.approx(180.06, abs=0.01) and np.isnan(d[2])
    wobble = draw.unwrap_stretches([359.0, 1.0, 358.0, np.nan, 2.0, 359.0])  # about 0°: no 360° jumps
    assert np.allclose(wobble[:3], [359, 361, 358]) and np.isnan(wobble[3]) and np.allclose(wobble[4:], [2, -1])
    arrows = draw.direction_arrows(np.array([[0.1, 0.0], [0.0, 0.001], [np.nan, np.nan]]), 0.05, 10)
    assert arrows[0] == pytest.approx([10, 0]) and not arrows[1:].any()


def test_mesh_and_frame_colours_share_one_scale(model):
    from tactile_flow.tactile.frames import to_uint8
    lo, hi = model.config.intensity_range
    values = np.array([[lo, (lo + hi) / 2, hi, hi * 2], [0.0, 0.5, 1.0, 2.0]])
    rgba = draw.activation_colours(values, [(lo, hi), (0.0, 1.0)])          # a row per frame, each its own range
    assert np.array_equal(rgba[0, :, :3], draw.colour_frames(to_uint8(values[0], lo, hi)))
    assert np.array_equal(rgba[1, :, :3], draw.colour_frames(to_uint8(values[1], 0.0, 1.0)))
    assert np.array_equal(rgba[0, 2], rgba[0, 3]) and np.array_equal(rgba[1, 2], rgba[0, 2]) and (rgba[..., 3] == 255).all()


def test_rotation_vectors_become_rerun_quaternions():
    q = rotvec_to_quaternion(np.array([[np.pi, 0, 0], [0, 0, 0]]))
    assert q[0] == pytest.approx([1, 0, 0, 0], abs=1e-12) and q[1] == pytest.approx([0, 0, 0, 1])


"""A first analysis on a machine compiles the numba kernels in child processes, one per core
(``tactile.warmup``). After that the analysis compiles none of the method's kernels itself,
and an error while the children run stops them."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from conftest import DATA
from tactile_flow.importers import ImportSettings, import_source, read_bag, select_fingers
from tactile_flow.tactile import warmup

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="reads child processes from /proc")

LISTEN = """
import json, sys
from numba.core import event
compiled = []      # every kernel this process compiles (numba reports no load from its cache)
class Listener(event.Listener):
    def on_start(self, ev):
        f = ev.data["dispatcher"].py_func
        compiled.append(f"{f.__module__}.{f.__qualname__}")
    def on_end(self, ev):
        pass
event.register("numba:compile", Listener())
"""

ANALYSE = LISTEN + """
from tactile_flow.analysis.run import analyze_run
summary = analyze_run(sys.argv[1], {"workers": 2, "figures": False, "progress": False}, console=print)
print(json.dumps({"segments": len(summary["segments"]), "compiled": sorted(set(compiled))}))
"""

LIVE = LISTEN + """
from hydra import compose, initialize_config_dir
from tactile_flow.protocols.plan import make_plan
from tactile_flow.protocols.run import live_setup
from tactile_flow.protocols.schema import register
register()
with initialize_config_dir(config_dir=sys.argv[1], version_base=None):
    cfg = compose("config", overrides=["protocol=pour_grasp_reactive"])
live, model = live_setup(cfg, make_plan(cfg), console=print)
print(json.dumps({"views": list(model.config.views), "compiled": sorted(set(compiled))}))
"""

INTERRUPTED = """
import os, time
from tactile_flow.analysis.config import load_config
from tactile_flow.tactile import warmup

def children():
    out = []
    for stat in os.listdir("/proc"):
        if stat.isdigit():
            try:
                fields = open(f"/proc/{stat}/stat").read().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == os.getpid():
                out.append(int(stat))
    return out

try:
    with warmup.compiling(load_config(None).tactile, 2):
        time.sleep(1.0)
        running = children()
        raise RuntimeError("stop")
except RuntimeError:
    pass
print(len(running), len(children()))
warmup.WAIT_S = 1.0          # children that take longer than this are stopped, the caller goes on
t0 = time.monotonic()
warmup.compile_cold(load_config(None).tactile, 2)
print(round(time.monotonic() - t0, 1), len(children()))
"""


def _fresh_caches(tmp_path: Path) -> dict:
    """The environment of a machine that has compiled nothing and cached no geodesics."""
    return {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba"), "TACTILE_CACHE_DIR": str(tmp_path / "tactile")}


def _pressed_store(tmp_path: Path) -> Path:
    """The real resting recording's ff sensor pressed on four taxels for 2 s, imported."""
    rec, _ = select_fingers(read_bag(DATA / "biotac_rest_untouched.bag"))
    counts = rec.electrodes[:, :1].astype(float)
    counts[300:500, 0, 20:24] -= 400
    names = [f"ff_e{k}" for k in range(1, 25)]
    csv = tmp_path / "pressed.csv"
    csv.write_text(",".join(names) + "\n" + "\n".join(",".join(str(int(v)) for v in row.ravel()) for row in counts)
                   + "\n")
    (res,) = import_source(csv, tmp_path / "imported", ImportSettings(rate_hz=100.0))
    return Path(res.store)


@pytest.mark.slow
def test_a_first_analysis_compiles_in_children_and_then_nothing_itself(tmp_path):
    store = _pressed_store(tmp_path)
    env = _fresh_caches(tmp_path)
    first = subprocess.run([sys.executable, "-c", ANALYSE, str(store)], env=env, capture_output=True, text=True,
                           timeout=900)
    assert first.returncode == 0, first.stderr[-2000:]
    lines = first.stdout.splitlines()
    assert any("compiling the numba kernels" in line and "in 2 processes" in line for line in lines), lines
    result = json.loads(lines[-1])
    assert result["segments"] >= 1                     # the press was rendered and flowed
    assert [k for k in result["compiled"] if k.startswith("tactile.")] == []

    again = subprocess.run([sys.executable, "-c", ANALYSE, str(store)], env=env, capture_output=True, text=True,
                           timeout=300)
    assert again.returncode == 0, again.stderr[-2000:]
    assert not any("compiling the numba kernels" in line for line in again.stdout.splitlines())
    assert json.loads(again.stdout.splitlines()[-1])["compiled"] == []


@pytest.mark.slow
def test_a_first_run_with_the_live_monitor_compiles_its_kernels_in_children(tmp_path):
    """Before a reactive pour moves anything, the live chain's kernels and the model's geodesics
    are compiled in children; the run's process then only loads them."""
    conf = Path(__file__).resolve().parents[1] / "conf"
    out = subprocess.run([sys.executable, "-c", LIVE, str(conf)], env=_fresh_caches(tmp_path), capture_output=True,
                         text=True, timeout=900)
    assert out.returncode == 0, out.stderr[-2000:]
    lines = out.stdout.splitlines()
    assert any("compiling the numba kernels" in line and "(model, online) in 2 processes" in line
               for line in lines), lines
    result = json.loads(lines[-1])
    assert result["views"] and [k for k in result["compiled"] if k.startswith("tactile.")] == []


@pytest.mark.slow
def test_an_error_or_a_child_past_its_time_stops_the_children(tmp_path):
    out = subprocess.run([sys.executable, "-c", INTERRUPTED], env=_fresh_caches(tmp_path), capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    first, late = out.stdout.splitlines()
    running, left = map(int, first.split())
    assert running == 2 and left == 0
    waited, left = late.split()
    assert float(waited) < 10 and int(left) == 0


def test_groups_are_shared_out_longest_first():
    groups = ["signals", "flow", "model", "frames"]
    assert warmup._share_out(groups, 1) == [["frames", "flow", "model", "signals"]]
    assert warmup._share_out(groups, 2) == [["frames", "signals"], ["flow", "model"]]
    assert sorted(map(tuple, warmup._share_out(groups, 8))) == [("flow",), ("frames",), ("model",), ("signals",)]


def test_a_warm_machine_has_nothing_to_compile(model):
    """Once the kernels have run (here, in this test session) no group is cold, so an analysis
    starts no child."""
    from tactile_flow.tactile.pipeline import process_view
    activation = model.smooth(np.zeros((20, 24)))
    process_view(model, activation, "bottom", references={"unloaded": None})
    warmup.compile_group("signals", model.config)
    assert warmup.cold_groups(model.config) == []


def test_the_model_is_cold_only_while_its_geodesic_distances_are_not_on_disk(model, cache_dir, tmp_path,
                                                                            monkeypatch):
    """Distances on disk are all the model needs: its geodesic kernel may never have been
    compiled on this machine (a fresh clone with the user's cache), and nothing starts."""
    monkeypatch.setenv("TACTILE_CACHE_DIR", str(cache_dir))        # where the session's model cached them
    assert warmup.cold_groups(model.config, ("model",)) == []
    monkeypatch.setenv("TACTILE_CACHE_DIR", str(tmp_path))
    assert warmup.cold_groups(model.config, ("model",)) == ["model"]

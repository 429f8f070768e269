"""Soak: one hour of simulated lab, five fingers with PAC, at full speed: no sample lost,
flat memory, and the throughput. Not in the default run; run it with

    pytest -m soak -s tests/test_soak.py
"""

import threading
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from hydra import compose, initialize_config_dir

from tactile_flow.protocols import run as run_module
from tactile_flow.protocols.schema import register

pytestmark = pytest.mark.soak
CONF_DIR = Path(__file__).resolve().parents[1] / "conf"


def rss_mb() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def test_one_hour_of_sweeps_loses_nothing_with_flat_memory(tmp_path):
    register()
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base=None):
        cfg = compose("config", overrides=["protocol=soak_sweeps", "analyze=false", "progress=false"])
    samples, done = [], threading.Event()

    def watch():
        while not done.wait(2.0):
            samples.append((time.monotonic(), rss_mb()))
    threading.Thread(target=watch, daemon=True).start()
    built = {}
    make_lab = run_module.make_lab

    def keep(cfg_):
        built["lab"] = make_lab(cfg_)
        return built["lab"]
    run_module.make_lab = keep
    t0 = time.monotonic()
    try:
        result = run_module.run_protocol(cfg, tmp_path / "run", console=lambda *a: None)
    finally:
        run_module.make_lab = make_lab
        done.set()
    wall = time.monotonic() - t0
    lab = built["lab"]
    assert result.status == "success"
    tree = xr.open_datatree(result.store, engine="zarr")
    frames = tree["biotac"].sizes["time"]
    sim_s = float(tree["biotac"]["time"].values[-1])
    assert sim_s >= 3600
    assert frames == lab.biotac.seq and np.all(np.diff(tree["biotac"]["seq"].values) == 1)   # none lost
    assert tree["biotac_pac"].sizes["time_pac"] == 22 * frames
    assert result.stats["biotac"]["gaps"] == 0 and lab.biotac.overflows == 0
    rss = np.array([r for _, r in samples])
    steady = rss[len(rss) // 5:]                              # after the first fifth (warm-up)
    growth = float(steady[-1] - steady[0])
    print(f"\nsoak: {sim_s:.0f} s simulated in {wall:.0f} s wall ({sim_s / wall:.1f}x real time), "
          f"{frames} BioTac frames, {tree['arm'].sizes['time_arm']} arm states, "
          f"{tree['biotac_pac'].sizes['time_pac']} PAC samples, none lost; RSS {steady[0]:.0f} → "
          f"{steady[-1]:.0f} MB (max {rss.max():.0f} MB)")
    assert growth < 50, f"memory grew by {growth:.0f} MB over the run"

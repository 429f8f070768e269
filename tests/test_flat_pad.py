"""A new taxel array needs one file and no code: the toy flat 4 × 4 pad of
``tests/data/conf/sensor/flat_pad.yaml`` (a plane, 16 taxels, one view, no pressure or vibration
channel) goes through a simulated straws sweep, its recording, its analysis and the viewer from
that file alone, given to the commands as a user would (a Hydra search path and ``sensor=``)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
import xarray as xr

from conftest import DATA

pytestmark = pytest.mark.slow                   # a whole run, its analysis and the viewer, in subprocesses
CONF = DATA / "conf"


def test_the_flat_pad_runs_end_to_end_from_its_yaml_alone(tmp_path):
    run_dir = tmp_path / "run"
    done = subprocess.run([sys.executable, "-c", "from tactile_flow.protocols.entry import main; main()", f"hydra.searchpath=[file://{CONF}]",
                           "sensor=flat_pad", "progress=false", f"hydra.run.dir={run_dir}"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "analysis" in done.stdout and "run " in done.stdout.splitlines()[-1]
    tree = xr.open_datatree(run_dir / "run.zarr", engine="zarr")
    b = tree["biotac"]
    assert b["electrodes"].shape[1:] == (5, 16) and "pdc" not in b and "biotac_pac" not in tree
    sensor = tree.attrs["sensor"]
    assert sensor["name"] == "flat_pad" and sensor["file"] == str(CONF / "sensor" / "flat_pad.yaml")
    summary = json.loads((run_dir / "summary.json").read_text())
    h = summary["headline"]
    assert h["crossings"] == 3 and h["score_direction_correct_fraction"] == 1.0
    assert summary["provenance"]["pressure_signal"] == "proxy"              # no pressure channel: the taxel sum
    assert set(summary["provenance"]["config"]["views"]) == {"bottom"}       # the pad's one view
    assert (run_dir / "figures" / "ellipsoid.png").stat().st_size > 10_000

    pytest.importorskip("rerun")
    pytest.importorskip("datafusion")
    from test_viewer import Recording
    rrd = tmp_path / "view.rrd"
    view = subprocess.run([sys.executable, "-m", "tactile_flow.viewer.cli", str(run_dir), "--save", str(rrd)],
                          capture_output=True, text=True, timeout=600)
    assert view.returncode == 0, view.stderr[-2000:]
    rec = Recording(rrd)
    assert len(rec.values("/signals/electrodes/ff", "Scalars:scalars")[0]) == 16
    assert "/tactile/ff/bottom/frame" in rec.entities and "/tactile/ff/left/frame" not in rec.entities
    assert "/world/tcp/ff/taxels" in rec.entities and "/world/tcp/ff/mesh" in rec.entities

"""tactile-import on ROS bags: the real resting recording (ROS1) and a ROS2 bag written here."""

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from tactile_flow.runstore import store_url
from tactile_flow.importers import ImportSettings, import_source, read_bag
from tactile_flow.importers.bag import MSGTYPE, biotac_typestore
from tactile_flow.analysis.run import analyze_run
from conftest import DATA

BAG = DATA / "biotac_rest_untouched.bag"


@pytest.fixture(scope="module")
def imported(tmp_path_factory):
    out = tmp_path_factory.mktemp("imp")
    (res,) = import_source(BAG, out)
    return res


def test_real_bag_keeps_three_fingers_drops_two(imported):
    assert imported.fingers == ["ff", "mf", "th"]
    assert sorted(imported.dropped) == ["lf", "rf"]
    assert all("-22072" in why for why in imported.dropped.values())
    dt = xr.open_datatree(store_url(imported.store), engine="zarr")
    b = dt["biotac"]
    assert list(b["finger"].values) == ["ff", "mf", "th"]
    assert b.sizes["time"] == 977 and b["electrodes"].shape == (977, 3, 24)
    assert dt["biotac_pac"]["pac"].shape == (2 * 977, 3)           # pac0, pac1 per frame
    # connected sensors at rest: real counts, nothing like the empty-port signature
    assert (b["pdc"].values > 0).all() and (b["electrodes"].values > 1000).all()
    assert bool(b["valid"].values.all())
    a = dt.attrs
    assert (a["protocol"], a["status"], a["labels"]) == ("import", "success", [])
    assert a["import"]["fingers"]["kept"] == ["ff", "mf", "th"]
    assert set(a["import"]["fingers"]["dropped"]) == {"rf", "lf"}
    assert a["baseline"]["method"] == "none"


def test_real_bag_seq_and_times(imported):
    dt = xr.open_datatree(store_url(imported.store), engine="zarr")
    b = dt["biotac"]
    seq = b["seq"].values
    assert seq[0] == 10195 and np.all(np.diff(seq) == 1)
    t, dev, host = b["time"].values, b["device_time"].values, b["host_time"].values
    assert t[0] == 0.0 and t[-1] == pytest.approx(9.76, abs=0.005)
    assert np.median(np.diff(t)) == pytest.approx(0.01, abs=1e-5)
    assert dev[0] == pytest.approx(1542626996.851954, abs=1e-6)         # header stamp of the first message
    np.testing.assert_allclose(t, dev - dev[0], atol=1e-5)             # drift 0 over 9.8 s: time = stamp − first
    lat = host - t                                                     # receipt after the fitted frame time
    assert lat.min() > -1e-4 and np.median(lat) < 1e-3 and lat.max() < 5e-3
    assert dt.attrs["recording_start_time"].startswith("2018-11-19T11:29:56")
    events = dt["events"]
    assert list(events["kind"].values) == ["info"]                     # no sequence gaps


def test_real_bag_provenance_names_source_and_checksum(imported):
    sha = hashlib.sha256(BAG.read_bytes()).hexdigest()
    assert imported.sha256 == sha
    dt = xr.open_datatree(store_url(imported.store), engine="zarr")
    prov = dt.attrs["provenance"]
    assert prov["source"]["sha256"] == sha and prov["source"]["path"] == str(BAG.resolve())
    assert prov["importer"]["reader"] == "tactile_flow.importers.bag.read_bag"
    assert prov["protocol"] == "import" and prov["source"]["format"] == "rosbag1"
    run_json = json.loads((Path(imported.run_dir) / "run.json").read_text())
    assert run_json["status"] == "success" and run_json["source"]["sha256"] == sha
    assert run_json["import"]["reader"]["topic"] == "/rh/tactile"
    leftovers = [p.name for p in Path(imported.run_dir).parent.iterdir() if p.name.startswith(".")]
    assert leftovers == []


def test_real_resting_recording_analyses_to_no_contact(imported, tmp_path):
    summary = analyze_run(imported.store, {"progress": False, "figures": False},
                                       console=lambda *a: None)
    assert summary["run_status"] == "success" and summary["protocol"] == "import"
    assert summary["headline"]["status"] == "no_contact"
    assert summary["headline"]["fingers_in_contact"] == 0 and summary["contacts"] == {}
    assert summary["provenance"]["input"]["frames"] == 977


# ----------------------------------------------------------------------------- ROS2
def _write_ros2_bag(path: Path, n: int = 150, n_pac: int = 22, rate_hz: float = 100.0) -> dict:
    """A ROS2 bag (sqlite3) of ``n`` BiotacAll messages of the newer form (``pac[]``): ff and th
    connected, mf, rf, lf empty ports. Returns what was written."""
    from rosbags.rosbag2 import Writer
    ts = biotac_typestore()
    T = ts.types
    Biotac, BiotacAll = T["sr_robot_msgs/msg/Biotac"], T[MSGTYPE]
    Header, Time = T["std_msgs/msg/Header"], T["builtin_interfaces/msg/Time"]
    rng = np.random.default_rng(3)
    base = rng.integers(2500, 3400, size=(2, 24))
    stamps, elec = [], []
    t0 = 1_700_000_000.0
    with Writer(path, version=9) as w:
        conn = w.add_connection("/rh/tactile", MSGTYPE, typestore=ts)
        for i in range(n):
            stamp = t0 + i / rate_hz
            e = base + rng.integers(-3, 4, size=base.shape)
            tact = []
            for f in range(5):
                if f in (0, 4):
                    k = 0 if f == 0 else 1
                    pac = (2000 + rng.integers(-5, 5, n_pac)).astype(np.int16)
                    tact.append(Biotac(pac0=int(pac[0]), pac1=int(pac[1]), pdc=2700, tac=2000, tdc=2250,
                                       electrodes=e[k].astype(np.int16), pac=pac))
                else:
                    tact.append(Biotac(pac0=0, pac1=0, pdc=-22072, tac=32570, tdc=0,
                                       electrodes=np.zeros(24, np.int16), pac=np.zeros(n_pac, np.int16)))
            sec = int(stamp)
            msg = BiotacAll(header=Header(stamp=Time(sec=sec, nanosec=int(round((stamp - sec) * 1e9))),
                                          frame_id="rh_distal"), tactiles=tact)
            w.write(conn, int(round((stamp + 0.0015) * 1e9)), ts.serialize_cdr(msg, MSGTYPE))
            stamps.append(stamp)
            elec.append(e)
    return {"stamps": np.array(stamps), "electrodes": np.array(elec)}


def test_ros2_bag_roundtrip(tmp_path):
    bag = tmp_path / "press_ros2"
    written = _write_ros2_bag(bag)
    rec = read_bag(bag)
    assert rec.meta["format"] == "rosbag2" and rec.meta["pac_source"] == "pac[]"
    assert rec.meta["seq_source"].startswith("message index")
    (res,) = import_source(bag, tmp_path / "out", ImportSettings(rate_hz=100))
    assert res.fingers == ["ff", "th"] and sorted(res.dropped) == ["lf", "mf", "rf"]
    dt = xr.open_datatree(store_url(res.store), engine="zarr")
    b = dt["biotac"]
    np.testing.assert_array_equal(b["electrodes"].values, written["electrodes"])
    np.testing.assert_array_equal(b["seq"].values, np.arange(150))
    np.testing.assert_allclose(b["device_time"].values, written["stamps"], atol=1e-6)
    np.testing.assert_allclose(b["host_time"].values - b["time"].values, 0.0, atol=2e-5)   # constant 1.5 ms latency
    assert dt["biotac_pac"].sizes["time_pac"] == 150 * 22
    pac_t = dt["biotac_pac"]["time_pac"].values
    assert np.allclose(np.diff(pac_t[:22]), 1 / 2200, atol=1e-6)
    assert dt.attrs["provenance"]["source"]["format"] == "rosbag2"
    assert len(dt.attrs["import"]["source_files"]) == 2                # metadata.yaml + the .db3

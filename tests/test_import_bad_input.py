"""tactile-import on bad input: one clear line, a non-zero exit, nothing left behind."""

import subprocess
import zipfile
import sys
from pathlib import Path

import numpy as np
import pytest
from omegaconf import OmegaConf

from tactile_flow.importers import ImportInputError, ImportSettings, import_source
from tactile_flow.importers import writer as writer_mod
from tactile_flow.importers.cli import BAD_INPUT, FAILED, run
from conftest import DATA

CONF = Path(__file__).resolve().parents[1] / "conf" / "import.yaml"
BAG = DATA / "biotac_rest_untouched.bag"


def electrode_csv(path: Path, n=50, prefix="", time=None, extra=(), drop=()) -> Path:
    rng = np.random.default_rng(0)
    names = [f"{prefix}e{i}" for i in range(1, 25)] + list(extra)
    data = rng.integers(2500, 3400, size=(n, len(names))).astype(float)
    if time is not None:
        names, data = ["time", *names], np.hstack([np.asarray(time, float)[:, None], data])
    keep = [i for i, c in enumerate(names) if c not in drop]
    path.write_text(",".join(names[i] for i in keep) + "\n"
                    + "\n".join(",".join(f"{v:g}" for v in row[keep]) for row in data) + "\n")
    return path


def assert_nothing_written(out: Path):
    assert not out.exists(), sorted(p.name for p in out.iterdir())


def one_line_error(tmp_path, source, **settings) -> str:
    out = tmp_path / "out"
    with pytest.raises(ImportInputError) as ei:
        import_source(source, out, ImportSettings(**settings))
    assert_nothing_written(out)
    msg = str(ei.value)
    assert "\n" not in msg
    return msg


def test_nonexistent_path(tmp_path):
    msg = one_line_error(tmp_path, tmp_path / "nope.bag")
    assert "nope.bag" in msg and "no such file" in msg


def test_bag_without_tactile_topic(tmp_path):
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore
    ts = get_typestore(Stores.ROS1_NOETIC)
    String = ts.types["std_msgs/msg/String"]
    bag = tmp_path / "chatter.bag"
    with Writer(bag) as w:
        conn = w.add_connection("/chatter", "std_msgs/msg/String", typestore=ts)
        for i in range(3):
            w.write(conn, 1_000_000_000 + i, ts.serialize_ros1(String(data=f"hi {i}"), "std_msgs/msg/String"))
    msg = one_line_error(tmp_path, bag)
    assert "no topic /rh/tactile" in msg and "/chatter (std_msgs/msg/String)" in msg


def test_not_a_bag(tmp_path):
    bad = tmp_path / "garbage.bag"
    bad.write_bytes(b"not a bag at all")
    assert "cannot be read as a ROS bag" in one_line_error(tmp_path, bad)


def test_csv_missing_columns(tmp_path):
    src = electrode_csv(tmp_path / "m.csv", prefix="ff_", drop=("ff_e7", "ff_e20"))
    msg = one_line_error(tmp_path, src, rate_hz=100)
    assert "missing columns: ff_e7, ff_e20" in msg


def test_csv_extra_columns(tmp_path):
    src = electrode_csv(tmp_path / "x.csv", extra=("force_n", "note"))
    msg = one_line_error(tmp_path, src, rate_hz=100)
    assert "unexpected columns: force_n, note" in msg


def test_csv_pdc_for_some_fingers_only(tmp_path):
    rng = np.random.default_rng(1)
    names = [f"{f}_e{i}" for f in ("ff", "mf") for i in range(1, 25)] + ["ff_pdc"]
    (tmp_path / "p.csv").write_text(",".join(names) + "\n" + "\n".join(
        ",".join(str(v) for v in rng.integers(2000, 3000, len(names))) for _ in range(5)) + "\n")
    assert "missing columns: mf_pdc" in one_line_error(tmp_path, tmp_path / "p.csv", rate_hz=100)


def test_csv_wrong_rate(tmp_path):
    src = electrode_csv(tmp_path / "t.csv", time=np.arange(50) / 100.0)
    msg = one_line_error(tmp_path, src, rate_hz=50)
    assert "rate_hz=50 disagrees" in msg and "100 Hz" in msg


def test_csv_missing_rate(tmp_path):
    src = electrode_csv(tmp_path / "r.csv")
    assert "no time column" in one_line_error(tmp_path, src) and "rate_hz" in one_line_error(tmp_path, src)
    assert "positive" in one_line_error(tmp_path, src, rate_hz=-3)


def test_directory_whose_every_file_is_bad_writes_nothing(tmp_path):
    d = tmp_path / "session"
    d.mkdir()
    electrode_csv(d / "a.csv", drop=("e3",))
    electrode_csv(d / "b.csv", extra=("oops",))
    msg = one_line_error(tmp_path, d, rate_hz=100)
    assert "no file could be imported" in msg and "a.csv" in msg and "b.csv" in msg and "oops" in msg


def test_calibration_without_a_finger(tmp_path):
    src = electrode_csv(tmp_path / "c.csv", prefix="mf_")
    cal = tmp_path / "cal.json"
    cal.write_text('{"ff": {"sensor_id": "SN1", "source": "", "baseline_counts": ' + str([3000.0] * 24) + "}}")
    msg = one_line_error(tmp_path, src, rate_hz=100, calibration=str(cal))
    assert "no entry for finger mf" in msg


def test_failure_while_writing_keeps_complete_runs_and_the_next_import_finishes(tmp_path, monkeypatch):
    d = tmp_path / "session"
    d.mkdir()
    electrode_csv(d / "a.csv")
    electrode_csv(d / "b.csv")
    real = writer_mod.write_import_store
    calls = []

    def flaky(rec, store_path, *a, **k):          # the second store fails half-way through
        calls.append(store_path)
        if len(calls) == 2:
            store_path.mkdir()
            (store_path / "zarr.json").write_text("{}")
            raise OSError("disk full")
        return real(rec, store_path, *a, **k)

    monkeypatch.setattr(writer_mod, "write_import_store", flaky)
    out = tmp_path / "out" / "deeper"
    with pytest.raises(OSError, match="disk full"):
        import_source(d, out, ImportSettings(rate_hz=100))
    assert len(calls) == 2
    assert sorted(p.name for p in out.iterdir()) == ["a"]            # complete; b's half store is gone
    assert (out / "a" / "run.json").is_file()
    monkeypatch.setattr(writer_mod, "write_import_store", real)
    lines = []
    (res,) = import_source(d, out, ImportSettings(rate_hz=100), console=lines.append)   # finishes the job
    assert res.source.endswith("b.csv") and sorted(p.name for p in out.iterdir()) == ["a", "b"]
    assert lines[0].startswith(f"already imported {d / 'a.csv'}") and "skipped" in lines[0]


def test_existing_run_directory_is_not_overwritten(tmp_path):
    src = electrode_csv(tmp_path / "e.csv")
    out = tmp_path / "out"
    (out / "e").mkdir(parents=True)
    with pytest.raises(FileExistsError, match="already exist"):
        import_source(src, out, ImportSettings(rate_hz=100))
    assert [p.name for p in out.iterdir()] == ["e"] and list((out / "e").iterdir()) == []


def test_cli_run_exit_codes_and_one_line(tmp_path, capsys):
    cfg = OmegaConf.load(CONF)
    del cfg["defaults"], cfg["hydra"]
    cfg.out = str(tmp_path / "out")
    cfg.source = str(electrode_csv(tmp_path / "ok.csv", prefix="th_"))
    assert run(cfg) == BAD_INPUT                                    # no rate
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("import error: ") and "rate_hz" in err
    cfg.rate_hz = 100
    assert run(cfg, console=lambda *a: None) == 0
    assert zipfile.is_zipfile(tmp_path / "out" / "ok" / "run.zarr.zip")        # packed: one file
    capsys.readouterr()
    assert run(cfg) == 0                                            # done already: skipped
    assert "already imported" in capsys.readouterr().out
    cfg.rate_hz = 50                                                # another import of it: refused
    assert run(cfg) == BAD_INPUT
    assert "already exist" in capsys.readouterr().err
    assert FAILED != BAD_INPUT != 0


def test_cli_process_nonexistent_source(tmp_path):
    r = subprocess.run([sys.executable, "-m", "tactile_flow.importers.cli", f"source={tmp_path / 'missing.csv'}"],
                       cwd=tmp_path, capture_output=True, text=True, timeout=60)
    assert r.returncode == BAD_INPUT
    assert r.stderr.strip().count("\n") == 0 and "missing.csv: no such file" in r.stderr
    assert list(tmp_path.iterdir()) == []                           # no log file, no output directory


def test_cli_process_imports_the_real_bag(tmp_path):
    r = subprocess.run([sys.executable, "-m", "tactile_flow.importers.cli", f"source={BAG}", "out=imp"],
                       cwd=tmp_path, capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert "977 frames" in r.stdout and "dropped rf" in r.stdout
    assert sorted(p.name for p in tmp_path.iterdir()) == ["imp"]
    assert (tmp_path / "imp" / "biotac_rest_untouched" / "run.json").is_file()

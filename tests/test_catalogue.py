"""The run catalogue and ``tactile-runs list|show|diff|index`` (issue 32, part 3).

Run directories made as ``tactile-run`` leaves them (``benchmarks/bench_catalogue.py``'s
``make_run``), real SQLite files, real processes for the concurrent writers and the lock;
the slow test checks that a real run registers itself.
"""

import importlib.util
import json
import os
import shutil
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

from tactile_flow.runstore import catalogue as cat_mod
from tactile_flow.runstore.catalogue import Catalogue, CatalogueError

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("bench_catalogue", ROOT / "benchmarks" / "bench_catalogue.py")
bench = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(bench)
make_run = bench.make_run


def runs_cli(*args, cwd, catalogue):
    return subprocess.run([sys.executable, "-c", "import sys; from tactile_flow.runstore.runs_cli import main; "
                           "sys.exit(main())", "--catalogue", str(catalogue), *args], cwd=cwd, capture_output=True,
                          text=True, timeout=120)


@pytest.fixture
def lab(tmp_path):
    out = tmp_path / "outputs"
    make_run(out / "a", protocol="straws_sweep", speed=10.0, width_error=0.5, start="2026-11-02T10:00:00.000000Z",
             analysis="farneback-aaaaaaaaaaaa")
    make_run(out / "b", protocol="straws_sweep", speed=20.0, width_error=1.3, start="2026-11-03T10:00:00.000000Z",
             analysis="dis-bbbbbbbbbbbb")
    make_run(out / "c", protocol="sticks_sweep", speed=10.0, width_error=0.7, start="2026-10-20T10:00:00.000000Z",
             status="aborted")
    make_run(out / "d", protocol="straws_sweep", speed=5.0, width_error=0.9, start="2026-11-05T10:00:00.000000Z")
    cat = Catalogue.open(tmp_path / "runs.sqlite")
    cat.index([out], console=lambda *_: None)
    return tmp_path, cat


def names(rows):
    return sorted(Path(r["path"]).name for r in rows)


def test_the_issues_filter_and_every_kind_of_key(lab):
    _, cat = lab
    q = cat.query
    assert names(q(["protocol=straws_sweep", "protocol.sweep_speed>=10", "score.width_error_mm_median<1",
                    "status=success", "since=2026-11-01"])) == ["a"]
    assert names(q(["protocol.sweep_speed>=10"])) == ["a", "b", "c"]
    assert names(q(["config.protocol.sweep_speed=20"])) == ["b"]                # the long form too
    assert names(q(["status!=success"])) == ["c"]
    assert names(q(["until=2026-11-02"])) == ["a", "c"]
    assert names(q(["analysis=dis-bbbbbbbbbbbb"])) == ["b"]
    assert names(q(["analysis~farneback"])) == ["a", "c", "d"]
    assert names(q(["width_mm_median>7"])) == ["b"]                             # a headline number, short
    assert names(q(["surface=sticks"])) == ["c"]
    assert names(q(["dirty=false"])) == ["a", "b", "c", "d"]
    assert names(q(["protocol.steps[1].sweep.speed=5"])) == ["d"]
    assert names(q(["hardware.seed<100", "protocol~sticks"])) == ["c"]


@pytest.mark.parametrize("bad, says", [("speed>>3", "malformed filter 'speed>>3'"), ("speed", "malformed filter"),
                                       ("protocol=", "malformed filter"),
                                       ("protocol.sweep_sped>=3", "did you mean `protocol.sweep_speed`?"),
                                       ("since=yesterday", "expected a date"),
                                       ("protocol.sweep_speed>=fast", "is not one")])
def test_a_malformed_filter_is_one_line_with_what_was_expected(lab, bad, says):
    tmp, cat = lab
    with pytest.raises(CatalogueError) as err:
        cat.query([bad])
    assert says in str(err.value) and "\n" not in str(err.value)
    before = (tmp / "runs.sqlite").stat().st_mtime_ns
    proc = runs_cli("list", bad, cwd=tmp, catalogue=tmp / "runs.sqlite")
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1 and says in proc.stderr, proc.stderr
    assert proc.stdout == "" and (tmp / "runs.sqlite").stat().st_mtime_ns == before


def test_outputs_a_table_csv_json_and_an_export_pandas_loads_in_one_line(lab):
    import pandas as pd
    tmp, _ = lab
    table = runs_cli("list", "protocol=straws_sweep", cwd=tmp, catalogue=tmp / "runs.sqlite")
    lines = table.stdout.splitlines()
    assert table.returncode == 0 and lines[0].split()[:4] == ["start_time", "protocol", "surface", "status"]
    assert lines[-1] == "(3 runs)" and len({len(x.rstrip()) > 0 for x in lines}) == 1
    assert [x.index("straws_sweep") for x in lines[1:-1]] == [lines[0].index("protocol")] * 3     # aligned
    csv_out = runs_cli("list", "--format", "csv", "--columns", "protocol,params,score.width_error_mm_median", cwd=tmp,
                       catalogue=tmp / "runs.sqlite").stdout
    assert csv_out.splitlines()[0] == "protocol,params,score.width_error_mm_median"
    js = json.loads(runs_cli("list", "--format", "json", "status=aborted", cwd=tmp, catalogue=tmp / "runs.sqlite").stdout)
    assert [r["protocol"] for r in js] == ["sticks_sweep"]
    exported = runs_cli("list", "since=2026-11-01", "--export", str(tmp / "runs.csv"), cwd=tmp,
                        catalogue=tmp / "runs.sqlite")
    assert exported.returncode == 0, exported.stderr
    df = pd.read_csv(tmp / "runs.csv")
    assert len(df) == 3 and {"config.protocol.sweep_speed", "score.width_error_mm_median", "run_id"} <= set(df.columns)
    assert sorted(df["config.protocol.sweep_speed"]) == [5.0, 10.0, 20.0]


def test_index_notices_new_changed_moved_and_deleted_runs(lab):
    tmp, cat = lab
    out = tmp / "outputs"
    run_id = json.loads((out / "a" / "run.json").read_text())["run_id"]
    shutil.move(out / "a", out / "moved_a")
    shutil.rmtree(out / "b")
    make_run(out / "e", protocol="pour_grasp", start="2026-11-07T10:00:00.000000Z")
    report = cat.index([out], console=lambda *_: None)
    assert "1 added" in report and "1 gone" in report and "1 moved" in report, report
    assert names(cat.query([])) == ["c", "d", "e", "moved_a"]
    assert cat.query(["run_id=" + run_id[:8]])[0]["path"].endswith("moved_a")
    again = cat.index(None, console=lambda *_: None)                  # the known roots; nothing changed
    assert "0 added, 0 refreshed, 0 gone" in again


def test_a_corrupt_catalogue_is_rebuilt_from_the_run_directories_with_a_message(lab):
    tmp, cat = lab
    cat.close()
    path = tmp / "runs.sqlite"
    for suffix in ("-wal", "-shm"):
        Path(f"{path}{suffix}").unlink(missing_ok=True)
    path.write_bytes(b"this is not a database, it was overwritten" * 100)
    proc = runs_cli("list", "protocol=straws_sweep", cwd=tmp, catalogue=path)
    assert proc.returncode == 0, proc.stderr
    assert "was damaged" in proc.stderr and "rebuilt from the run directories" in proc.stderr
    assert proc.stdout.splitlines()[-1] == "(3 runs)"
    assert list(tmp.glob("runs.sqlite.corrupt-*"))


def test_a_locked_catalogue_is_one_line_and_nothing_is_written(lab, monkeypatch):
    tmp, cat = lab
    cat.close()
    holder = subprocess.Popen([sys.executable, "-c", "import sqlite3, sys, time\n"
                               f"db = sqlite3.connect({str(tmp / 'runs.sqlite')!r}, isolation_level=None)\n"
                               "db.execute('BEGIN EXCLUSIVE'); print('locked', flush=True); time.sleep(60)"],
                              stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "locked"
        monkeypatch.setattr(cat_mod, "BUSY_TIMEOUT_S", 0.5)
        with pytest.raises(CatalogueError) as err:
            c = Catalogue.open(tmp / "runs.sqlite")
            c.index([tmp / "outputs"], console=lambda *_: None)
        assert "locked by another process" in str(err.value)
    finally:
        holder.kill()
        holder.wait()
    c = Catalogue.open(tmp / "runs.sqlite")
    assert len(c.query([])) == 4


def test_concurrent_writers_in_several_processes_never_lose_an_entry(tmp_path):
    """Four processes register 25 runs each at once (a joblib sweep's workers closing runs,
    an import beside them), each run in its own transaction: all 100 are there."""
    dirs = [make_run(tmp_path / "outputs" / f"w{w}" / f"r{i:02d}", start=f"2026-11-0{1 + w}T10:{i:02d}:00.000000Z")
            for w in range(4) for i in range(25)]
    script = ("import sys\nfrom tactile_flow.runstore.catalogue import Catalogue\n"
              "for d in sys.argv[2:]:\n    c = Catalogue.open(sys.argv[1]); c.register(d); c.close()\n")
    procs = [subprocess.Popen([sys.executable, "-c", script, str(tmp_path / "runs.sqlite"),
                               *map(str, dirs[w * 25:(w + 1) * 25])], stderr=subprocess.PIPE, text=True)
             for w in range(4)]
    for p in procs:
        assert p.wait(timeout=120) == 0, p.stderr.read()
    db = sqlite3.connect(tmp_path / "runs.sqlite")
    assert db.execute("SELECT count(*) FROM runs").fetchone()[0] == 100
    assert db.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
    assert db.execute("PRAGMA journal_mode").fetchone()[0] == "wal"


def test_show_and_diff_tell_what_a_run_is_whatever_its_name(lab):
    tmp, _ = lab
    shown = runs_cli("show", str(tmp / "outputs" / "b"), cwd=tmp, catalogue=tmp / "runs.sqlite")
    assert shown.returncode == 0
    assert "protocol    straws_sweep  on surface straws" in shown.stdout
    assert "protocol.sweep_speed=20.0" in shown.stdout and "* dis-bbbbbbbbbbbb" in shown.stdout
    run_id = json.loads((tmp / "outputs" / "b" / "run.json").read_text())["run_id"]
    by_id = runs_cli("show", run_id[:8], cwd=tmp, catalogue=tmp / "runs.sqlite")
    assert by_id.returncode == 0 and by_id.stdout == shown.stdout.replace(f"run {tmp / 'outputs' / 'b'}",
                                                                          f"run {(tmp / 'outputs' / 'b').resolve()}")
    d = runs_cli("diff", str(tmp / "outputs" / "a"), str(tmp / "outputs" / "b"), cwd=tmp,
                 catalogue=tmp / "runs.sqlite").stdout
    assert "protocol.sweep_speed" in d and "10" in d and "20" in d
    assert "score.width_error_mm_median" in d and "protocol.finger" not in d
    for bad in (str(tmp / "outputs"), "nosuchrun", str(tmp / "missing")):
        proc = runs_cli("show", bad, cwd=tmp, catalogue=tmp / "runs.sqlite")
        assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1, proc.stderr


def test_every_option_is_in_the_help():
    from tactile_flow.runstore.runs_cli import parser
    ap = parser()
    text = ap.format_help()
    for command in ("list", "show", "diff", "reproduce", "index"):
        assert command in text
    sub = ap._subparsers._group_actions[0].choices
    for command, p in sub.items():
        help_text = p.format_help()
        for action in p._actions:
            for flag in action.option_strings:
                assert flag in help_text, (command, flag)


@pytest.mark.slow
def test_a_real_run_and_its_analyses_register_themselves(tmp_path):
    cat = tmp_path / "runs.sqlite"
    env = {**os.environ, "TACTILE_CATALOGUE": str(cat)}
    rec = subprocess.run([sys.executable, "-c", "from tactile_flow.protocols.entry import main; main()",
                          "progress=false", "analysis.progress=false", "analysis.figures=false",
                          "protocol.sweep_speed=20", "hydra.run.dir=run"], cwd=tmp_path, env=env, capture_output=True,
                         text=True, timeout=300)
    assert rec.returncode == 0, rec.stderr
    rows = Catalogue.open(cat).query(["protocol.sweep_speed=20"])
    assert len(rows) == 1 and rows[0]["analysis"].startswith("farneback-") and rows[0]["status"] == "success"
    ana = subprocess.run([sys.executable, "-c", "from tactile_flow.analysis.cli import main; main()",
                          f"run={tmp_path / 'run'}", "analysis.progress=false", "analysis.figures=false",
                          "name=second"], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert ana.returncode == 0, ana.stderr
    assert Catalogue.open(cat).query(["analysis=second"])[0]["analysis"] == "second"


# ----------------------------------------------------------------------------- sweeps a researcher can read
def test_run_directory_names_say_what_the_run_is_and_stay_typeable():
    from tactile_flow.runstore.paths import run_name
    name = run_name("straws_sweep", "tall_sticks", "hardware.seed-3_protocol.sweep_speed-20")
    assert name == "straws_sweep_on_tall_sticks_hardware.seed-3_protocol.sweep_speed-20"
    odd = run_name("p", "", "protocol.steps-[{wait: {duration: 0.2}}]")
    assert not set("=,[]{}: ") & set(odd)                # a path typed as run=PATH needs no quotes


def test_the_analysis_table_gives_the_slip_of_each_finger_columns_of_its_own(tmp_path):
    """Before: the ``slip`` column of ``analysis_summary.*`` was a Python dict printed as text."""
    from tactile_flow.analysis.cli import write_table
    slip = {"ff": {"slip_class": "translation", "slip_direction_sensor_deg": 92.5, "slip_displacement_mm": 2.1},
            "th": {"slip_class": "none", "slip_direction_sensor_deg": None, "slip_displacement_mm": 0.1}}
    write_table(tmp_path, [{"run": "a", "analysis": "x", "result": "analysed", "segments": 4, "slip": slip},
                           {"run": "b", "analysis": "y", "result": "analysed", "segments": 5}])
    import pandas as pd
    df = pd.read_csv(tmp_path / "analysis_summary.csv")
    assert "slip" not in df.columns and df.loc[0, "slip.ff.slip_class"] == "translation"
    assert df.loc[0, "slip.ff.slip_direction_sensor_deg"] == 92.5 and df.loc[1, "slip.ff.slip_class"] != "translation"
    md = (tmp_path / "analysis_summary.md").read_text()
    assert "{" not in md and "slip.th.slip_class" in md.splitlines()[0]


@pytest.mark.slow
def test_a_sweep_has_a_column_per_parameter_a_figure_and_names_that_say_what_differs(tmp_path):
    cat = tmp_path / "runs.sqlite"
    env = {**os.environ, "TACTILE_CATALOGUE": str(cat)}
    proc = subprocess.run([sys.executable, "-c", "from tactile_flow.protocols.entry import main; main()", "-m",
                           "progress=false", "analysis.progress=false", "analysis.figures=false",
                           "protocol.sweep_speed=10,20", "hardware.seed=0,1", f"hydra.sweep.dir={tmp_path / 'sweep'}",
                           "hydra/launcher=joblib", "hydra.launcher.n_jobs=2"], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    jobs = sorted(p.parent.name for p in (tmp_path / "sweep").glob("*/run.json"))
    assert jobs == ["0_straws_sweep_on_straws_hardware.seed-0_protocol.sweep_speed-10",
                    "1_straws_sweep_on_straws_hardware.seed-1_protocol.sweep_speed-10",
                    "2_straws_sweep_on_straws_hardware.seed-0_protocol.sweep_speed-20",
                    "3_straws_sweep_on_straws_hardware.seed-1_protocol.sweep_speed-20"]
    import pandas as pd
    table = pd.read_csv(tmp_path / "sweep" / "summary.csv")
    assert list(table.columns[:3]) == ["job", "protocol.sweep_speed", "hardware.seed"]
    assert sorted(table["protocol.sweep_speed"]) == [10, 10, 20, 20] and "overrides" not in table.columns
    assert "progress" not in table.columns and table["result.score_width_error_mm_median"].notna().all()
    assert (tmp_path / "sweep" / "sweep.png").stat().st_size > 20_000 and "sweep.png" in proc.stdout
    rows = Catalogue.open(cat).query(["protocol.sweep_speed=20", "hardware.seed=1"])
    assert len(rows) == 1 and rows[0]["sweep"] == str((tmp_path / "sweep").resolve())
    moved = tmp_path / "renamed_by_hand"                              # a name that says nothing
    shutil.move(tmp_path / "sweep" / jobs[3], moved)
    shown = runs_cli("show", str(moved), cwd=tmp_path, catalogue=cat).stdout
    assert "protocol    straws_sweep  on surface straws" in shown
    assert "protocol.sweep_speed=20" in shown and "hardware.seed=1" in shown


def test_a_real_lab_reproduction_is_judged_against_stated_tolerances(tmp_path):
    """On the real lab the world is not the same twice: the headline and score numbers are
    compared against runstore.reproduce.TOLERANCES, not bit for bit."""
    from tactile_flow.runstore import reproduce

    def lab_run(name, width_error):
        d = make_run(tmp_path / name, width_error=width_error)
        info = json.loads((d / "run.json").read_text())
        info["config"]["hardware"]["backend"] = "lab"
        (d / "run.json").write_text(json.dumps(info))
        return d
    original = lab_run("original", 0.5)
    close = reproduce.compare(original, lab_run("close", 0.8))
    assert close.real_lab and close.reproduced and close.line().startswith("reproduced: within tolerance")
    far = reproduce.compare(original, lab_run("far", 1.9))
    assert not far.reproduced and "score.width_error_mm_median 0.5 -> 1.9" in far.line()
    assert far.line().startswith("reproduced: outside tolerance")


def test_a_run_outside_any_outputs_folder_is_its_own_root_and_its_deletion_is_noticed(tmp_path):
    """A run made with hydra.run.dir=somewhere: ``index`` walks that run, never its parent
    (which may be a home directory), and notices when it is gone."""
    cat = Catalogue.open(tmp_path / "runs.sqlite")
    run = make_run(tmp_path / "home" / "exp1")
    (tmp_path / "home" / "big_unrelated_tree").mkdir()
    cat.register(run)
    assert cat.known_roots() == [str(run.resolve())]
    shutil.rmtree(run)
    assert "1 gone" in cat.index(None, console=lambda *_: None) and cat.query([]) == []

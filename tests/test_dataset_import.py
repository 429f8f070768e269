"""A dataset directory imported and analysed over several processes (issue 36, part 2): the same
stores and analyses as one process; bad files (unreadable, duplicate-named, of another
sensor model) named with their reason while the good ones import; an import interrupted at
any point (Ctrl-C, SIGTERM, a worker killed) leaves no half store visible as a run, and a
second import finishes the job. Real processes and real signals."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from tactile_flow.importers import ImportSettings, import_source
from tactile_flow.runstore import open_group
from tactile_flow.importers.cli import BAD_INPUT, FAILED

IMPORT = [sys.executable, "-c", "from tactile_flow.importers.cli import main; main()"]
ANALYZE = [sys.executable, "-c", "from tactile_flow.analysis.cli import main; main()"]
INTERRUPTED = 3


def short_csv(path: Path, seed: int, n_taxels: int = 24, frames: int = 275) -> Path:
    """A short electrode-only CSV (no time column: rate_hz=100): counts at rest with noise and
    a press of ``seed``'s depth in its middle."""
    rng = np.random.default_rng(seed)
    rest = rng.uniform(2600, 3300, n_taxels)
    press = np.zeros((frames, n_taxels))
    press[frames // 3: 2 * frames // 3, : n_taxels // 2] = rng.uniform(100, 400)
    counts = np.round(rest + rng.normal(0, 4, (frames, n_taxels)) - press).astype(int)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(",".join(f"e{i}" for i in range(1, n_taxels + 1)) + "\n"
                    + "\n".join(",".join(map(str, row)) for row in counts) + "\n")
    return path


def dataset(root: Path, n: int, folders: int = 3) -> list[Path]:
    return [short_csv(root / f"object_{k % folders}" / f"take_{k // folders:03d}.csv", k) for k in range(n)]


def visible_runs(out: Path) -> list[Path]:
    """Every run directory a user (or ``tactile-analyze``) would see under ``out``."""
    found = []
    for here, dirs, names in os.walk(out):           # not into hidden staging, which changes meanwhile
        found += [Path(here)] if "run.zarr" in dirs or "run.zarr.zip" in names else []
        dirs[:] = [d for d in dirs if not d.startswith(".") and not d.endswith(".zarr")]
    return sorted(found)


def assert_complete(run: Path, frames: int = 275) -> None:
    """A visible run is whole: its run.json says success and its store holds every frame."""
    doc = json.loads((run / "run.json").read_text())
    assert doc["status"] == "success", run
    assert open_group(run / "run.zarr.zip")["biotac/electrodes"].shape[0] == frames, run


def arrays(store: Path) -> dict:
    out = {}

    def walk(group, prefix=""):
        for name, member in group.members():
            if hasattr(member, "members"):
                walk(member, f"{prefix}{name}/")
            else:
                out[prefix + name] = member[...]
    walk(open_group(store))
    return out


def test_a_directory_over_two_workers_is_the_same_stores_as_one(tmp_path):
    dataset(tmp_path / "data", 6)
    one = import_source(tmp_path / "data", tmp_path / "one", ImportSettings(rate_hz=100), workers=1)
    two = import_source(tmp_path / "data", tmp_path / "two", ImportSettings(rate_hz=100), workers=2)
    assert [Path(r.run_dir).relative_to(tmp_path / "one") for r in one] == \
           [Path(r.run_dir).relative_to(tmp_path / "two") for r in two]
    for a, b in zip(one, two):
        x, y = arrays(Path(a.store)), arrays(Path(b.store))
        assert sorted(x) == sorted(y) and len(x) > 10
        for k in x:
            np.testing.assert_array_equal(x[k], y[k], err_msg=k)
        ja, jb = (json.loads((Path(r.run_dir) / "run.json").read_text())["import"] for r in (a, b))
        assert ja == jb


def test_workers_must_be_a_positive_whole_number(tmp_path):
    dataset(tmp_path / "data", 2)
    r = subprocess.run([*IMPORT, f"source={tmp_path / 'data'}", "out=out", "rate_hz=100", "workers=0"],
                       cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert r.returncode == BAD_INPUT and "workers=0" in r.stderr and r.stderr.count("\n") == 1
    assert not (tmp_path / "out").exists()


def test_unreadable_duplicate_named_and_mixed_sensor_files_are_named_the_good_ones_import(tmp_path):
    data = tmp_path / "data"
    good = dataset(data, 5)
    (data / "object_0" / "broken.csv").write_text("e1,e2\n1,2\n3,oops\n")          # unreadable
    short_csv(data / "object_1" / "Take_000.csv", 99)                               # take_000 but for case
    short_csv(data / "object_2" / "classic.csv", 98, n_taxels=19)                   # the classic BioTac's 19
    unreadable = data / "object_0" / "locked.csv"
    short_csv(unreadable, 97).chmod(0)
    r = subprocess.run([*IMPORT, f"source={data}", "out=out", "rate_hz=100", "workers=2"], cwd=tmp_path,
                       capture_output=True, text=True, timeout=300)
    unreadable.chmod(0o644)
    assert r.returncode == BAD_INPUT, r.stderr
    err = r.stderr.splitlines()
    named = {line for line in err if line.startswith("import error: ")}
    assert any("broken.csv" in x and "line 3" in x for x in named), err
    assert any("classic.csv" in x and "mixed sensors" in x and "19 electrodes" in x for x in named), err
    dup = [x for x in named if "duplicate name" in x]
    assert any(x.startswith(f"import error: {data / 'object_1' / 'Take_000.csv'}: ") for x in dup), err
    assert any(x.startswith(f"import error: {data / 'object_1' / 'take_000.csv'}: ") for x in dup), err
    if os.geteuid() != 0:                                     # root reads a file of mode 000
        assert any("locked.csv" in x for x in named), err
    imported = {p.relative_to(tmp_path / "out").as_posix() for p in visible_runs(tmp_path / "out")}
    expected = {p.relative_to(data).with_suffix("").as_posix() for p in good if p.parent.name != "object_1"
                or p.stem != "take_000"}
    assert expected <= imported and not {"object_0/broken", "object_2/classic"} & imported
    assert err[-1].startswith("import: ") and "files imported" in err[-1]


def _children(pid: int) -> list[int]:
    try:
        return [int(x) for x in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]
    except OSError:
        return []


@pytest.mark.parametrize("how", ["SIGINT", "SIGTERM", "kill -9 of a worker"])
def test_an_interrupted_import_leaves_no_half_store_and_a_second_one_finishes(tmp_path, how):
    n = 60
    dataset(tmp_path / "data", n)
    cmd = [*IMPORT, f"source={tmp_path / 'data'}", "out=out", "rate_hz=100", "workers=2"]
    proc = subprocess.Popen(cmd, cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 240
    while len(visible_runs(tmp_path / "out")) < 3:                 # in the middle of writing
        assert proc.poll() is None, proc.stderr.read()
        assert time.monotonic() < deadline
        time.sleep(0.02)
    if how == "kill -9 of a worker":
        workers = [c for c in _children(proc.pid) if c]
        assert workers
        os.kill(workers[0], signal.SIGKILL)
    else:
        proc.send_signal(getattr(signal, how))
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == (FAILED if how.startswith("kill") else INTERRUPTED), err
    assert "Traceback" not in err
    if how.startswith("kill"):
        assert "worker process died" in err and "run the same import again" in err
    runs = visible_runs(tmp_path / "out")
    assert 3 <= len(runs) < n
    for run in runs:
        assert_complete(run)
    assert not [c for c in _children(proc.pid)]
    again = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert again.returncode == 0, again.stderr
    assert again.stdout.count("already imported") == len(runs)
    assert again.stdout.count("\nimported ") + again.stdout.startswith("imported ") == n - len(runs)
    final = visible_runs(tmp_path / "out")
    assert len(final) == n
    for run in final:
        assert_complete(run)
    assert not [p for p in (tmp_path / "out").glob("*/.*importing*")]    # the killed one's staging removed


@pytest.mark.slow
def test_a_directory_analysed_over_two_workers_is_the_same_as_one(tmp_path):
    dataset(tmp_path / "data", 4, folders=2)
    for name in ("one", "two"):
        import_source(tmp_path / "data", tmp_path / name, ImportSettings(rate_hz=100), workers=1)
    for name, w in (("one", 1), ("two", 2)):
        r = subprocess.run([*ANALYZE, f"run={name}", f"workers={w}", "analysis.figures=false"], cwd=tmp_path,
                           capture_output=True, text=True, timeout=600)
        assert r.returncode == 0, r.stderr
        assert r.stdout.count("analysis ") >= 4
    tables = [(tmp_path / d / "analysis_summary.csv").read_text().replace(f"{d}/", "X/") for d in ("one", "two")]
    assert tables[0] == tables[1] and tables[0].count("analysed") == 4
    for run in visible_runs(tmp_path / "one"):
        rel = run.relative_to(tmp_path / "one")
        s1, s2 = (json.loads((tmp_path / d / rel / "analysis" / "summary.json").read_text()) for d in ("one", "two"))
        for key in ("headline", "contacts", "segments", "estimates", "whole_run", "skipped", "labels"):
            assert s1[key] == s2[key], key
        x, y = (arrays(tmp_path / d / rel / "analysis" / "analysis.zarr.zip") for d in ("one", "two"))
        assert sorted(x) == sorted(y)
        for k in x:
            np.testing.assert_array_equal(x[k], y[k], err_msg=k)


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_directory_analysis_interrupted_keeps_whole_analyses_and_the_next_one_finishes(tmp_path, sig):
    dataset(tmp_path / "data", 12, folders=2)
    import_source(tmp_path / "data", tmp_path / "runs", ImportSettings(rate_hz=100), workers=2)
    cmd = [*ANALYZE, "run=runs", "workers=2", "analysis.figures=false"]
    proc = subprocess.Popen(cmd, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 300
    while not list((tmp_path / "runs").glob("*/*/analysis")):           # the first analysis in place
        assert proc.poll() is None and time.monotonic() < deadline
        time.sleep(0.02)
    proc.send_signal(sig)
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == INTERRUPTED and "Traceback" not in err, err
    assert "analysis interrupted" in err and "the same command again" in err
    assert not _children(proc.pid)
    done = [r for r in visible_runs(tmp_path / "runs") if (r / "analysis").exists()]
    assert 1 <= len(done) < 12
    for run in done:                                                   # whole: its summary is there
        assert json.loads((run / "summary.json").read_text())["headline"]
    again = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert again.returncode == 0, again.stderr
    assert (tmp_path / "runs" / "analysis_summary.csv").read_text().count("analysed") == 12


def test_a_directory_import_on_a_terminal_shows_one_progress_line_of_files_done_total_and_rate(tmp_path):
    import pty
    dataset(tmp_path / "data", 6)
    import fcntl
    import struct
    import termios
    main, tty = pty.openpty()
    fcntl.ioctl(tty, termios.TIOCSWINSZ, struct.pack("HHHH", 40, 120, 0, 0))   # a terminal 120 wide
    proc = subprocess.Popen([*IMPORT, f"source={tmp_path / 'data'}", "out=out", "rate_hz=100", "workers=2"],
                            cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=tty)
    os.close(tty)
    chunks = []
    while True:
        try:
            data = os.read(main, 4096)
        except OSError:                                   # the terminal closed: the process is done
            break
        if not data:
            break
        chunks.append(data)
    proc.wait(timeout=120)
    os.close(main)
    text = b"".join(chunks).decode(errors="replace")
    assert proc.returncode == 0, text
    assert "\n" not in text.rstrip()                      # redrawn in place (\r): one line
    assert "import: writing" in text and "6/6" in text and "file/s" in text

"""Damaged run stores get one line naming what is damaged, never a traceback (issue 13,
item 17): a corrupt chunk, a garbage ``labels`` attribute, a garbage ``zarr.json``, for
``tactile-analyze`` and ``tactile-recover``. Real stores from a real run, damaged on disk."""

import json
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow
RUN = [sys.executable, "-c", "from tactile_flow.protocols.cli import main; main()", "progress=false", "analyze=false"]
ANALYZE = [sys.executable, "-c", "from tactile_flow.analysis.cli import main; main()", "analysis.figures=false"]
RECOVER = [sys.executable, "-c", "from tactile_flow.runstore.recover import main; import sys; sys.exit(main())"]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    root = tmp_path_factory.mktemp("rec")
    assert subprocess.run([*RUN, "hydra.run.dir=run"], cwd=root, capture_output=True, timeout=300).returncode == 0
    return root / "run"


@pytest.fixture
def copy(recorded, tmp_path):
    shutil.copytree(recorded, tmp_path / "run", ignore=shutil.ignore_patterns(".tactile.lock"))
    return tmp_path / "run" / "run.zarr"


def one_line(proc, code: int, *words):
    lines = [x for x in proc.stderr.splitlines() if x.strip()]
    assert proc.returncode == code and len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    for w in words:
        assert w in lines[0], lines[0]


def corrupt(chunk: Path) -> None:
    data = bytearray(chunk.read_bytes())
    data[20:60] = b"x" * 40
    chunk.write_bytes(bytes(data))


def test_a_corrupt_chunk_is_named(copy):
    corrupt(sorted(p for p in (copy / "biotac" / "electrodes" / "c").rglob("*") if p.is_file())[0])
    proc = subprocess.run([*ANALYZE, f"run={copy}"], capture_output=True, text=True, timeout=300)
    one_line(proc, 2, "biotac/electrodes", "cannot be read", "damaged")
    assert not (copy.parent / "analysis" / "summary.json").exists()


def test_a_garbage_labels_attribute_is_named(copy):
    meta = json.loads((copy / "zarr.json").read_text())
    meta["attributes"]["labels"] = 42
    (copy / "zarr.json").write_text(json.dumps(meta))
    proc = subprocess.run([*ANALYZE, f"run={copy}"], capture_output=True, text=True, timeout=300)
    one_line(proc, 2, "labels", "expected a list")


@pytest.mark.parametrize("text", ["{not json", '{"zarr_format": 3, "node_type": "group", "attributes": 7}', ""])
def test_a_garbage_zarr_json_is_one_line_for_recover_and_analyze(copy, text):
    (copy / "zarr.json").write_text(text)
    one_line(subprocess.run([*RECOVER, str(copy)], capture_output=True, text=True, timeout=120), 2,
             str(copy), "zarr.json")
    one_line(subprocess.run([*ANALYZE, f"run={copy}"], capture_output=True, text=True, timeout=300), 2, str(copy))


def test_recover_names_a_damaged_last_chunk(tmp_path):
    proc = subprocess.Popen([*RUN, "hydra.run.dir=run", "hardware.realtime=true"], cwd=tmp_path)
    store = tmp_path / "run" / "run.zarr"
    deadline = time.monotonic() + 90
    while not (store / "biotac" / "time" / "c" / "0").exists():
        assert time.monotonic() < deadline and proc.poll() is None
        time.sleep(0.05)
    time.sleep(1.0)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    corrupt(store / "biotac" / "time" / "c" / "0")
    one_line(subprocess.run([*RECOVER, str(store)], capture_output=True, text=True, timeout=120), 2,
             "biotac/time", "cannot be read", "damaged")

"""tactile-import on hostile files: truncated and corrupt bags, CSVs with garbage rows, enormous files.

Policy (docs/import.md): a truncated bag imports every complete message before the cut and
says so (``import.reader.truncated``, a warning); a bag with nothing readable, a corrupt bag
and a CSV with any bad row are refused with one line naming the file (and the line and
column), exit 2, nothing written. Memory does not grow with the file's length.
"""

import struct
import subprocess
import sys
import time
import tracemalloc
import zipfile
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from omegaconf import OmegaConf

from tactile_flow.runstore import store_url
from tactile_flow.importers import ImportInputError, ImportSettings, import_source, read_bag
from tactile_flow.importers import importer as importer_mod
from tactile_flow.importers.bag import BIOTAC_MSGS, MSGTYPE, TOPIC
from tactile_flow.importers.cli import BAD_INPUT, run
from tactile_flow.importers.recording import median_of, order_statistics
from conftest import DATA

BAG = DATA / "biotac_rest_untouched.bag"
CONF = Path(__file__).resolve().parents[1] / "conf" / "import.yaml"


# ----------------------------------------------------------------------------- helpers
def cli(cwd: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "tactile_flow.importers.cli", *args], cwd=cwd,
                          capture_output=True, text=True, timeout=120)


def assert_one_line_refusal(r: subprocess.CompletedProcess, *words: str) -> None:
    assert r.returncode == BAD_INPUT, r.stderr
    assert r.stderr.count("\n") == 1 and r.stderr.startswith("import error: "), r.stderr
    assert "Traceback" not in r.stderr
    for w in words:
        assert w in r.stderr, (w, r.stderr)


def refused(tmp_path: Path, source: Path, **settings) -> str:
    """The one-line ImportInputError of importing ``source``; nothing may be written."""
    out = tmp_path / "out"
    with pytest.raises(ImportInputError) as ei:
        import_source(source, out, ImportSettings(**settings))
    assert not out.exists()
    msg = str(ei.value)
    assert "\n" not in msg and str(source) in msg
    return msg


def cut_bag(tmp_path: Path, nbytes: int, name: str = "cut") -> Path:
    path = tmp_path / f"{name}.bag"
    path.write_bytes(BAG.read_bytes()[:nbytes])
    return path


def message_records() -> tuple[list[int], int]:
    """File offsets of the real bag's message records (from its own index) and its chunk's end."""
    from rosbags.rosbag1 import Reader
    with Reader(BAG) as r:
        (chunk,) = r.chunks.values()
        offsets = sorted(e.offset for e in r.indexes[r.connections[0].id])
    return [chunk.datapos + o for o in offsets], chunk.datapos + chunk.datasize


def complete_messages_before(nbytes: int) -> int:
    """How many messages of the real bag end before byte ``nbytes``."""
    starts, end = message_records()
    return sum(e <= nbytes for e in [*starts[1:], end])


def write_bag(path: Path, n: int, compression: str | None = None, chunk_bytes: int = 1 << 20) -> Path:
    """A ROS1 bag of ``n`` BiotacAll messages (pac[] of 22; rf, lf empty ports), seq 0..n−1,
    100 Hz; about 1700 messages per 1 MB chunk (``chunk_bytes``: rosbags' chunk threshold)."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore
    ts = get_typestore(Stores.ROS1_NOETIC)
    types = {}
    for name, text in BIOTAC_MSGS.items():
        types.update(get_types_from_msg(text, name))
    ts.register(types)
    T = ts.types
    Biotac, BiotacAll = T["sr_robot_msgs/msg/Biotac"], T[MSGTYPE]
    Header, Time = T["std_msgs/msg/Header"], T["builtin_interfaces/msg/Time"]
    rng = np.random.default_rng(7)
    w = Writer(path)
    w.chunk_threshold = chunk_bytes
    if compression:
        w.set_compression(getattr(Writer.CompressionFormat, compression))
    with w:
        conn = w.add_connection(TOPIC, MSGTYPE, typestore=ts)
        for i in range(n):
            tact = [Biotac(pac0=0, pac1=0, pdc=-22072, tac=0, tdc=0, electrodes=np.zeros(24, np.int16),
                           pac=np.zeros(22, np.int16)) if f in (2, 3) else
                    Biotac(pac0=2000, pac1=2001, pdc=2700, tac=2000, tdc=2250,
                           electrodes=rng.integers(2000, 3500, 24).astype(np.int16),
                           pac=rng.integers(1900, 2100, 22).astype(np.int16)) for f in range(5)]
            stamp = 1_700_000_000 * 10**9 + i * 10_000_000
            msg = BiotacAll(header=Header(seq=i, stamp=Time(sec=stamp // 10**9, nanosec=stamp % 10**9),
                                          frame_id="rh"), tactiles=tact)
            w.write(conn, stamp + 1_500_000, ts.serialize_ros1(msg, MSGTYPE))
    return path


# ----------------------------------------------------------------------------- truncated bags
def test_bag_cut_inside_its_chunk_imports_every_complete_message(tmp_path):
    full = read_bag(BAG)
    src = cut_bag(tmp_path, 200_000)
    (res,) = import_source(src, tmp_path / "out")
    n = complete_messages_before(200_000)
    assert 400 < n < 977 and res.frames == n
    assert res.warnings and "truncated bag" in res.warnings[0] and f"{n} complete messages" in res.warnings[0]
    dt = xr.open_datatree(store_url(res.store), engine="zarr")
    b = dt["biotac"]
    assert list(b["finger"].values) == ["ff", "mf", "th"]
    np.testing.assert_array_equal(b["electrodes"].values, full.electrodes[:n][:, [0, 1, 4]])
    np.testing.assert_array_equal(b["seq"].values, full.seq[:n])
    np.testing.assert_allclose(b["device_time"].values, full.device_time[:n])
    t = dt.attrs["import"]["reader"]["truncated"]
    assert t["ends"] == "inside chunk 1" and t["file_bytes"] == 200_000 and t["messages_read"] == n
    assert t["chunks_read"] == 0 and t["chunks_in_header"] == 1 and "unknown" in t["messages_lost"]
    assert dt.attrs["import"]["frames"] == n and dt.attrs["status"] == "success"


@pytest.mark.parametrize("nbytes, ends", [(378_000, "inside the index data of chunk 1"),
                                          (390_000, "inside the bag index")])
def test_bag_cut_in_its_index_loses_nothing(tmp_path, nbytes, ends):
    full = read_bag(BAG)
    (res,) = import_source(cut_bag(tmp_path, nbytes), tmp_path / "out")
    assert res.frames == 977
    dt = xr.open_datatree(store_url(res.store), engine="zarr")
    np.testing.assert_array_equal(dt["biotac"]["seq"].values, full.seq)
    t = dt.attrs["import"]["reader"]["truncated"]
    assert t["ends"] == ends and t["messages_lost"].startswith("none")


def test_bag_never_closed_is_read_to_its_last_chunk(tmp_path):
    """What a killed ``rosbag record`` leaves: index_pos = 0 in the header, no index."""
    data = bytearray(BAG.read_bytes())
    i = data.index(b"index_pos=") + len(b"index_pos=")
    data[i:i + 8] = bytes(8)
    src = tmp_path / "killed.bag"
    src.write_bytes(bytes(data[:377_512]))              # the chunk, not its index data
    (res,) = import_source(src, tmp_path / "out")
    assert res.frames == 977
    t = xr.open_datatree(store_url(res.store), engine="zarr").attrs["import"]["reader"]["truncated"]
    assert "never closed" in t["ends"] and t["index_pos"] is None and "unknown" in t["messages_lost"]


@pytest.mark.parametrize("compression", ["LZ4", "BZ2"])
def test_compressed_bag_cut_mid_chunk(tmp_path, compression):
    src = write_bag(tmp_path / "long.bag", 5000, compression)
    full = read_bag(src)
    data = src.read_bytes()
    cut = tmp_path / "long_cut.bag"
    cut.write_bytes(data[:int(len(data) * 0.7)])
    (res,) = import_source(cut, tmp_path / "out")
    n = res.frames
    assert 1500 < n < 5000                              # whole chunks, and what decompresses of the cut one
    dt = xr.open_datatree(store_url(res.store), engine="zarr")
    np.testing.assert_array_equal(dt["biotac"]["seq"].values, np.arange(n))
    np.testing.assert_array_equal(dt["biotac"]["electrodes"].values, full.electrodes[:n][:, [0, 1, 4]])
    assert dt["biotac_pac"].sizes["time_pac"] == 22 * n
    assert dt.attrs["import"]["reader"]["truncated"]["ends"].startswith("inside chunk")


def test_bag_cut_before_any_message_is_refused(tmp_path):
    src = cut_bag(tmp_path, 4200)
    msg = refused(tmp_path, src)
    assert "truncated ROS bag" in msg and "before any complete message on /rh/tactile" in msg
    assert "cannot be read as a ROS bag (truncated" in refused(tmp_path, cut_bag(tmp_path, 2000, "tiny"))


@pytest.mark.parametrize("field, expected", [("record length", "corrupt ROS bag at byte 4117 (a record inside a chunk "
                                                               "runs past the chunk)"),
                                             ("electrode count", "corrupt ROS bag: message 300 of /rh/tactile cannot "
                                                                 "be decoded")])
def test_corrupt_bag_is_refused(tmp_path, field, expected):
    data = bytearray(BAG.read_bytes())
    record = message_records()[0][300]
    (hl,) = struct.unpack_from("<I", data, record)
    # message data: seq, stamp (12 bytes), frame_id "rh_distal" (4 + 9), ff's pac0..tdc (10), electrodes length
    where = record if field == "record length" else record + 8 + hl + 12 + 13 + 10
    data[where:where + 4] = b"\xff\xff\xff\xff"
    src = tmp_path / "corrupt.bag"
    src.write_bytes(bytes(data))
    assert expected in refused(tmp_path, src)


def test_cli_truncated_bags(tmp_path):
    cut_bag(tmp_path, 200_000, "half")
    r = cli(tmp_path, "source=half.bag", "out=imp")
    assert r.returncode == 0, r.stderr
    assert "WARNING: truncated bag" in r.stdout and f"{complete_messages_before(200_000)} frames" in r.stdout
    assert zipfile.is_zipfile(tmp_path / "imp" / "half" / "run.zarr.zip")
    cut_bag(tmp_path, 4200, "stub")
    assert_one_line_refusal(cli(tmp_path, "source=stub.bag", "out=imp2"), "stub.bag", "truncated")
    assert not (tmp_path / "imp2").exists()


# ----------------------------------------------------------------------------- CSV garbage
HEADER = ["time", *(f"ff_e{i}" for i in range(1, 25)), "ff_pdc"]


def csv_lines(n: int = 40) -> list[str]:
    rng = np.random.default_rng(2)
    return [f"{i / 100:.2f}," + ",".join(map(str, rng.integers(2500, 3400, 25))) for i in range(n)]


def set_cell(lines, row, col, text):
    cells = lines[row].split(",")
    cells[HEADER.index(col)] = text
    lines[row] = ",".join(cells)


def write_garbage(path: Path, mutate) -> Path:
    lines = csv_lines()
    raw = mutate(lines)
    body = ("\n".join([",".join(HEADER), *lines]) + "\n").encode() if raw is None else raw
    path.write_bytes(body)
    return path


def _binary_line(lines):
    head = ("\n".join([",".join(HEADER), *lines[:12]]) + "\n").encode()
    return head + b"\x89PNG" + bytes(range(0, 9)) + b"\n" + ("\n".join(lines[12:]) + "\n").encode()


def _bad_utf8(lines):
    set_cell(lines, 20, "ff_e2", "27\udcff3")
    return ("\n".join([",".join(HEADER), *lines]) + "\n").encode("utf-8", "surrogateescape")


GARBAGE = {   # name: (mutation of the 40 data lines (line k + 2 of the file), expected message after the file)
    "not_a_number": (lambda ls: set_cell(ls, 10, "ff_e7", "abc"), " line 12, column ff_e7: 'abc' is not a number"),
    "empty_cell": (lambda ls: set_cell(ls, 4, "ff_e1", ""), " line 6, column ff_e1: '' is not a number"),
    "quoted": (lambda ls: set_cell(ls, 4, "ff_pdc", '"2700"'), " line 6, column ff_pdc: '\"2700\"' is not a number"),
    "too_few_cells": (lambda ls: ls.__setitem__(5, ls[5].rsplit(",", 1)[0]), " line 7: 25 cells, expected 26"),
    "too_many_cells": (lambda ls: ls.__setitem__(5, ls[5] + ",1"), " line 7: 27 cells, expected 26"),
    "blank_line_inside": (lambda ls: ls.insert(7, ""), " line 9: blank line before more rows (line 10)"),
    "binary_line": (_binary_line, " line 14: binary data ('\\x89PNG\\x00\\x01"),
    "invalid_utf8": (_bad_utf8, " line 22: binary data ("),
    "nan": (lambda ls: set_cell(ls, 3, "ff_e3", "nan"), " line 5, column ff_e3: nan is not a finite number"),
    "inf": (lambda ls: set_cell(ls, 3, "ff_e3", "-inf"), " line 5, column ff_e3: -inf is not a finite number"),
    "huge_float": (lambda ls: set_cell(ls, 30, "ff_e24", "1e300"),
                   " line 32, column ff_e24: 1e+300 is outside the range of a count (int16"),
    "huge_integer": (lambda ls: set_cell(ls, 30, "ff_pdc", "99999999999999999999"),
                     " line 32, column ff_pdc: 1e+20 is outside the range of a count"),
    "time_backwards": (lambda ls: set_cell(ls, 18, "time", "0.05"),
                       " line 20, column time: 0.05 s does not increase on the line before (0.17 s)"),
    "endless_line": (lambda ls: ls.__setitem__(3, "7" * 1_000_000), " line 5: longer than 2688 characters"),
}


@pytest.mark.parametrize("case", sorted(GARBAGE))
def test_csv_garbage_is_refused_with_line_and_column(tmp_path, case):
    mutate, expected = GARBAGE[case]
    src = write_garbage(tmp_path / "bad.csv", mutate)
    msg = refused(tmp_path, src)
    assert msg.startswith(f"{src}{expected}"), msg


@pytest.mark.parametrize("case", sorted(GARBAGE))
def test_csv_garbage_cli_run_exit_2_one_line_nothing_written(tmp_path, case, capsys):
    mutate, expected = GARBAGE[case]
    cfg = OmegaConf.load(CONF)
    del cfg["defaults"], cfg["hydra"]
    cfg.source = str(write_garbage(tmp_path / "bad.csv", mutate))
    cfg.out = str(tmp_path / "out")
    assert run(cfg, console=lambda *a: None) == BAD_INPUT
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"import error: {cfg.source}{expected}"), err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("case", ["not_a_number", "binary_line"])
def test_csv_garbage_tactile_import_process(tmp_path, case):
    mutate, expected = GARBAGE[case]
    write_garbage(tmp_path / "bad.csv", mutate)
    r = cli(tmp_path, "source=bad.csv", "out=imp")
    assert_one_line_refusal(r, f"bad.csv{expected}")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.csv"]


def test_csv_blank_lines_after_the_last_row_are_ignored(tmp_path):
    src = tmp_path / "tail.csv"
    src.write_text("\n".join([",".join(HEADER), *csv_lines()]) + "\n\n   \n\r\n\n")
    (res,) = import_source(src, tmp_path / "out")
    assert res.frames == 40


def test_csv_counts_outside_12_bits_are_stored_and_flagged(tmp_path):
    """Within int16 a count is stored as read (as a recorded corrupt frame is), valid = False."""
    lines = csv_lines()
    set_cell(lines, 9, "ff_e5", "-5")
    set_cell(lines, 11, "ff_pdc", "5000")
    src = tmp_path / "odd.csv"
    src.write_text("\n".join([",".join(HEADER), *lines]) + "\n")
    (res,) = import_source(src, tmp_path / "out")
    b = xr.open_datatree(store_url(res.store), engine="zarr")["biotac"]
    assert b["electrodes"].values[9, 0, 4] == -5 and b["pdc"].values[11, 0] == 5000
    assert list(np.flatnonzero(~b["valid"].values)) == [9, 11]


def test_file_changed_between_the_two_passes_is_refused(tmp_path, monkeypatch):
    src = tmp_path / "growing.csv"
    src.write_text("\n".join([",".join(HEADER), *csv_lines()]) + "\n")
    real = importer_mod.prepare

    def prepare_then_append(s, settings):
        p = real(s, settings)
        with open(src, "a") as f:
            f.write(csv_lines(41)[-1] + "\n")
        return p

    monkeypatch.setattr(importer_mod, "prepare", prepare_then_append)
    assert "changed while being imported (40 frames on the first read, 41 on the second)" in refused(tmp_path, src)


# ----------------------------------------------------------------------------- enormous files
def write_long_csv(path: Path, rows: int) -> list[str]:
    """``rows`` frames at 100 Hz (time column, ff and th electrodes + pdc), written block by
    block; the counts repeat every 1000 rows. Returns those 1000 count rows."""
    rng = np.random.default_rng(4)
    names = ["time", *(f"{f}_{c}" for f in ("ff", "th") for c in [*(f"e{i}" for i in range(1, 25)), "pdc"])]
    block = [",".join(map(str, r)) for r in rng.integers(2000, 3500, (1000, 50))]
    with open(path, "w") as f:
        f.write(",".join(names) + "\n")
        for s in range(0, rows, 1000):
            f.write("".join(f"{(s + k) / 100:.2f},{block[k]}\n" for k in range(min(1000, rows - s))))
    return block


def test_200k_row_csv(tmp_path):
    src = tmp_path / "long.csv"
    block = write_long_csv(src, 200_000)
    t = time.perf_counter()
    (res,) = import_source(src, tmp_path / "out")
    elapsed = time.perf_counter() - t
    assert res.frames == 200_000 and res.rate_hz == pytest.approx(100.0)
    b = xr.open_datatree(store_url(res.store), engine="zarr")["biotac"]
    assert b.sizes["time"] == 200_000
    for row in (0, 9_999, 10_000, 123_456, 199_999):                  # chunk edges and beyond
        counts = np.array(block[row % 1000].split(","), int).reshape(2, 25)
        np.testing.assert_array_equal(b["electrodes"].values[row], counts[:, :24])
        np.testing.assert_array_equal(b["pdc"].values[row], counts[:, 24])
    np.testing.assert_array_equal(b["seq"].values, np.arange(200_000))
    assert b["time"].values[-1] == pytest.approx(1999.99)
    assert elapsed < 60, f"{elapsed:.1f} s"


def _traced_peak(src: Path, out: Path, chunk_frames: int) -> int:
    tracemalloc.start()
    try:
        import_source(src, out, ImportSettings(chunk_frames=chunk_frames))
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_memory_does_not_grow_with_csv_length(tmp_path):
    write_long_csv(tmp_path / "short.csv", 4_000)
    write_long_csv(tmp_path / "long.csv", 32_000)
    _traced_peak(tmp_path / "short.csv", tmp_path / "warm", 1000)      # imports and caches warmed up
    short = _traced_peak(tmp_path / "short.csv", tmp_path / "o1", 1000)
    long = _traced_peak(tmp_path / "long.csv", tmp_path / "o2", 1000)
    assert long < 1.3 * short, (short, long)                           # 8× the rows, the same memory


def test_memory_does_not_grow_with_bag_length(tmp_path):
    """Memory is one import chunk plus one chunk of the bag (64 kB here, as rosbags writes 1 MB)."""
    write_bag(tmp_path / "short.bag", 1_000, chunk_bytes=1 << 16)
    write_bag(tmp_path / "long.bag", 4_000, chunk_bytes=1 << 16)
    _traced_peak(tmp_path / "short.bag", tmp_path / "warm", 250)
    short = _traced_peak(tmp_path / "short.bag", tmp_path / "o1", 250)
    long = _traced_peak(tmp_path / "long.bag", tmp_path / "o2", 250)
    assert long < 1.3 * short, (short, long)                           # 4× the messages, the same memory


def test_chunk_frames_must_be_positive(tmp_path):
    src = tmp_path / "ok.csv"
    src.write_text("\n".join([",".join(HEADER), *csv_lines()]) + "\n")
    with pytest.raises(ImportInputError, match="chunk_frames=0"):
        import_source(src, tmp_path / "out", ImportSettings(chunk_frames=0))


# ----------------------------------------------------------------------------- exact medians
@pytest.mark.parametrize("seed", range(6))
def test_streamed_median_is_numpys(seed, monkeypatch):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 5000))
    a = [rng.normal(0.01, 1e-6, n), rng.integers(-3, 4, n).astype(float), np.full(n, 0.01),
         rng.normal(0, 1e200, n), rng.exponential(1.0, n), np.r_[rng.normal(size=n - 1), np.inf]][seed]
    size = int(rng.integers(1, 700))

    def chunks():
        return (a[i:i + size] for i in range(0, len(a), size))
    assert median_of(chunks, len(a)) == np.median(a)         # read whole (a short record)
    import tactile_flow.importers.recording as recording
    monkeypatch.setattr(recording, "IN_MEMORY_MEDIAN", 0)    # streamed, as a long record is
    assert median_of(chunks, len(a)) == np.median(a)
    ranks = sorted(rng.integers(0, len(a), 4))
    assert order_statistics(chunks, ranks) == list(np.sort(a)[ranks])


def test_streamed_median_of_a_32k_record_matches_the_whole_array():
    """The rate of a long record, chunk by chunk, is the same float as from the whole array."""
    rng = np.random.default_rng(11)
    t = np.cumsum(rng.normal(0.01, 1e-5, 32_001))
    from tactile_flow.importers.recording import diffs, rate_of
    got = rate_of(median_of(lambda: diffs(t[i:i + 1000] for i in range(0, len(t), 1000)), len(t) - 1))
    assert got == float(1.0 / np.median(np.diff(t)))
    assert struct.pack("<d", got) == struct.pack("<d", float(1.0 / np.median(np.diff(t))))

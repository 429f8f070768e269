"""The packed layout (``runstore.packed``): a store written once, as one zip file of its keys,
read through the one opener (``runstore.open_group`` / ``open_run``) like a directory store,
also from processes forked while it is open."""

from __future__ import annotations

import multiprocessing
import os
import zipfile

import numpy as np
import pytest
import zarr

from tactile_flow.runstore import open_group, open_run, packed, store_url


def _directory_store(path, rows=20_000):
    """A directory store with a many-chunk int16 array and a text attribute."""
    root = zarr.open_group(str(path), mode="w", zarr_format=3, attributes={"schema_version": "1.0", "who": "test"})
    g = root.create_group("biotac")
    a = g.create_array("electrodes", shape=(rows, 24), chunks=(500, 24), dtype="i2",
                       dimension_names=["time", "taxel"])
    a[...] = (np.arange(rows * 24) % 4000).reshape(rows, 24).astype("i2")
    zarr.consolidate_metadata(str(path))
    return a[...]


def test_a_packed_store_holds_the_directory_store_s_files_and_reads_the_same(tmp_path):
    values = _directory_store(tmp_path / "run.zarr")
    target = packed.pack(tmp_path / "run.zarr", tmp_path / "run.zarr.zip")
    files = {p.relative_to(tmp_path / "run.zarr").as_posix(): p.read_bytes()
             for p in (tmp_path / "run.zarr").rglob("*") if p.is_file()}
    with zipfile.ZipFile(target) as z:
        assert {i.filename: z.read(i) for i in z.infolist()} == files
        kinds = {i.filename: i.compress_type for i in z.infolist()}
    assert all(k == (zipfile.ZIP_DEFLATED if n.endswith("zarr.json") else zipfile.ZIP_STORED) for n, k in kinds.items())
    assert packed.is_packed(target) and packed.is_store(target) and packed.is_store(tmp_path / "run.zarr")
    assert not packed.is_packed(tmp_path / "run.zarr") and not packed.is_store(tmp_path)
    for store in (tmp_path / "run.zarr", target):
        np.testing.assert_array_equal(open_group(store)["biotac/electrodes"][...], values)
        assert open_run(store)["biotac"]["electrodes"].shape == values.shape
    assert store_url(target) == f"zip::{target.resolve()}" and store_url(tmp_path / "run.zarr") == str(tmp_path / "run.zarr")
    np.testing.assert_array_equal(zarr.open_group(store_url(target), mode="r")["biotac/electrodes"][...], values)


def test_find_prefers_the_directory_and_names_the_packed_one_otherwise(tmp_path):
    assert packed.find(tmp_path) is None
    (tmp_path / "run.zarr.zip").write_bytes(b"")
    assert packed.find(tmp_path) == tmp_path / "run.zarr.zip"
    (tmp_path / "run.zarr").mkdir()
    assert packed.find(tmp_path) == tmp_path / "run.zarr"
    assert packed.run_store(tmp_path, {"store": "run.zarr.zip"}) == tmp_path / "run.zarr.zip"


def test_packing_is_whole_or_absent_and_never_over_a_store(tmp_path):
    _directory_store(tmp_path / "run.zarr", rows=10)
    os.symlink("/etc/hostname", tmp_path / "run.zarr" / "link")
    with pytest.raises(ValueError, match="not a regular file"):
        packed.pack(tmp_path / "run.zarr", tmp_path / "run.zarr.zip")
    os.unlink(tmp_path / "run.zarr" / "link")
    with pytest.raises(OSError):                       # a failure while writing: no part file left
        packed.write_zip([("zarr.json", b"{}"), ("c/0", tmp_path / "missing")], tmp_path / "x.zip")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.zarr"]
    packed.pack(tmp_path / "run.zarr", tmp_path / "run.zarr.zip")
    before = (tmp_path / "run.zarr.zip").read_bytes()
    with pytest.raises(FileExistsError):
        packed.pack(tmp_path / "run.zarr", tmp_path / "run.zarr.zip")
    assert (tmp_path / "run.zarr.zip").read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.zarr", "run.zarr.zip"]


def _read_many(array, rounds, out):
    ok = True
    for _ in range(rounds):
        for start in range(0, array.shape[0], 500):
            block = array[start:start + 500]
            ok &= bool(np.array_equal(block, (np.arange(start * 24, (start + len(block)) * 24) % 4000)
                                      .reshape(-1, 24).astype("i2")))
    out.put(ok)


@pytest.mark.skipif(not hasattr(os, "fork"), reason="fork")
def test_a_packed_store_opened_before_a_fork_reads_right_in_parent_and_children_at_once(tmp_path):
    """The analysis forks figure workers (and dataset workers) while a store is open; a zip read
    is a seek then a read on a file the processes would share: each reopens it."""
    _directory_store(tmp_path / "run.zarr")
    packed.pack(tmp_path / "run.zarr", tmp_path / "run.zarr.zip")
    array = open_group(tmp_path / "run.zarr.zip")["biotac/electrodes"]
    array[:10]                                          # opened in this process
    ctx = multiprocessing.get_context("fork")
    out = ctx.Queue()
    children = [ctx.Process(target=_read_many, args=(array, 5, out)) for _ in range(2)]
    for c in children:
        c.start()
    mine = multiprocessing.Queue()
    _read_many(array, 5, mine)
    results = [out.get(timeout=120) for _ in children] + [mine.get(timeout=10)]
    for c in children:
        c.join(timeout=60)
    assert results == [True, True, True]


@pytest.mark.parametrize("damage", ["truncated", "not a zip", "no root metadata"])
def test_a_damaged_packed_store_is_named_in_one_line_by_the_analysis(tmp_path, damage):
    from tactile_flow.analysis.load import AnalysisInputError, load_run
    _directory_store(tmp_path / "run.zarr", rows=10)
    good = packed.pack(tmp_path / "run.zarr", tmp_path / "good.zarr.zip").read_bytes()
    bad = tmp_path / "run.zarr.zip"
    if damage == "truncated":
        bad.write_bytes(good[:len(good) // 2])
    elif damage == "not a zip":
        bad.write_bytes(b"not a zip file at all")
    else:
        packed.write_zip([("biotac/zarr.json", b"{}")], bad)
    with pytest.raises(AnalysisInputError) as err:
        load_run(bad)
    message = str(err.value)
    assert message.startswith(f"{bad}: ") and "\n" not in message
    assert "cannot be read as a run store" in message

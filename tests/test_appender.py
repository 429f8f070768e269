"""The run store's own appends and commits (runstore.appender) write exactly the files zarr-python
writes for the same rows, and keep the commit protocol when a write fails."""

import asyncio
import json
import os
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest
import zarr

from conftest import tmpfs
from tactile_flow.protocols.store import RunStore, open_run

LIVE = (("ff", "th"), ("a", "b", "c"))


def random_rows(store: RunStore, block: str, n: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """``n`` rows of every variable of ``block``: numbers with NaN and -0.0 among them, text
    with the fill value, non-ASCII and empty strings, flags that are all False for a while."""
    out = {}
    for v in store.schema[block].vars:
        meta = json.loads((store.path / store.schema[block].group / v.name / "zarr.json").read_bytes())
        shape = (n, *meta["shape"][1:])
        if v.dtype == "str":
            words = np.array(["", "step_start", "ünïcode", '{"a": [1, 2]}', "x" * 300], dtype=object)
            out[v.name] = rng.choice(words, size=shape)
        elif v.dtype == "bool":
            out[v.name] = rng.random(shape) < 0.5
            if store.length(block) < store.schema[block].chunk:
                out[v.name][:] = False                   # the first chunk holds only the fill value
            elif n:
                out[v.name][0] = True
        elif v.dtype == "f8":
            a = rng.normal(size=shape) * 1e3
            a[rng.random(shape) < 0.1] = np.nan
            a[rng.random(shape) < 0.05] = -0.0
            out[v.name] = a
        else:
            info = np.iinfo(np.dtype(v.dtype))
            out[v.name] = rng.integers(max(info.min, -5000), min(info.max, 5000), size=shape).astype(v.dtype)
    return out


async def zarr_append(items) -> None:
    """zarr's own resize and setitem of each ``(array, n0, rows)``, concurrently (zarr's
    synchronous calls take ~10 ms an array on a loaded machine)."""
    async def one(arr, n0, a):
        await arr.async_array.resize((n0 + len(a), *arr.shape[1:]))
        await arr.async_array.setitem(slice(n0, n0 + len(a)), a)
    await asyncio.gather(*(one(*it) for it in items))


def files(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def test_appends_and_commits_write_the_files_zarr_writes(tmp_path):
    """Every chunk and zarr.json after each commit, byte for byte against zarr's resize, setitem
    and consolidate_metadata on a copy of the same new store: chunks crossing chunk boundaries,
    partial chunks rewritten, chunks holding only the fill value (never written), text."""
    store = RunStore.create(tmp_path / "ours.zarr", protocol="unit_test", chunk_s=0.2, live=LIVE, stage=True,
                            provenance={"nan": float("nan"), "text": "ü"})
    theirs = tmp_path / "zarr.zarr"
    shutil.copytree(store.path, theirs)
    raw = zarr.open_group(str(theirs), mode="r+", use_consolidated=False)
    rng = np.random.default_rng(7)
    for step, n in enumerate([3, 25, 0, 2]):
        blocks = {b: random_rows(store, b, n + (i % 3), rng) for i, b in enumerate(store.schema)}
        asyncio.run(zarr_append([(raw[f"{store.schema[b].group}/{name}"], store.length(b), a)
                                 for b, data in blocks.items() for name, a in data.items()]))
        store.append_many(blocks)
        store.commit()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")             # "consolidated metadata not in the v3 spec"
            zarr.consolidate_metadata(str(theirs))
        ours_files, zarr_files = files(store.path), files(theirs)
        assert sorted(ours_files) == sorted(zarr_files), f"step {step}: different files"
        for name in ours_files:
            assert ours_files[name] == zarr_files[name], f"step {step}: {name} differs"
    assert store.length("biotac") > store.schema["biotac"].chunk              # chunk boundaries crossed
    assert not (store.path / "biotac/valid/c/0").exists() and (store.path / "biotac/valid/c/1").exists()
    assert open_run(store.path)["biotac"].sizes["time"] == store.length("biotac")


def test_attributes_and_the_closing_commit_match_zarr(tmp_path):
    """Root attributes go out with the commit (one file), as zarr's update + consolidation
    writes them; group attributes (written through zarr) are published by the next commit."""
    store = RunStore.create(tmp_path / "run.zarr", protocol="unit_test", chunk_s=0.1)
    rng = np.random.default_rng(1)
    store.append("arm", random_rows(store, "arm", 30, rng))
    store.set_attrs(t0_clock_s=12.5, streams_recorded=["arm"])
    store.commit()
    ours = (store.path / "zarr.json").read_bytes()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        zarr.consolidate_metadata(str(store.path))
    assert (store.path / "zarr.json").read_bytes() == ours
    store.set_group_attrs("arm", stream={"samples": 30})
    store.append("arm", random_rows(store, "arm", 4, rng))
    store.close("success")
    dt = open_run(store.path)
    assert dt["arm"].attrs["stream"] == {"samples": 30} and dt["arm"].sizes["time_arm"] == 34
    assert dt.attrs["status"] == "success" and dt.attrs["t0_clock_s"] == 12.5


def test_appending_after_a_rewrite_keeps_the_rewritten_rows(tmp_path):
    """The last partial chunk is kept in memory; a rewrite through zarr (the final clock refit)
    must not be undone by the next append, which rewrites that chunk."""
    store = RunStore.create(tmp_path / "run.zarr", protocol="unit_test", chunk_s=0.1)     # 10 frames a chunk
    rng = np.random.default_rng(2)
    first = random_rows(store, "biotac", 7, rng)
    store.append("biotac", first)
    store.rewrite("biotac", "time", np.arange(7) * 0.5)
    store.transform("biotac", "device_time", "time", lambda t: t + 100.0)
    more = random_rows(store, "biotac", 5, rng)
    store.append("biotac", more)
    store.commit()
    b = open_run(store.path)["biotac"]
    np.testing.assert_array_equal(b["time"].values, np.concatenate([np.arange(7) * 0.5, more["time"]]))
    np.testing.assert_array_equal(b["device_time"].values,
                                  np.concatenate([np.arange(7) * 0.5 + 100, more["device_time"]]))
    np.testing.assert_array_equal(b["electrodes"].values, np.concatenate([first["electrodes"], more["electrodes"]]))


@pytest.fixture
def small_disk(tmp_path):
    with tmpfs(tmp_path / "disk", "1m") as mount:
        yield mount


def test_a_write_that_fails_midway_is_rolled_back_and_retried(small_disk):
    """A full disk in the middle of an append (some arrays written, others not): the block's
    length stays, readers see the last commit, and once there is room the same append goes
    through with every committed row intact."""
    store = RunStore.create(small_disk / "run.zarr", protocol="unit_test")
    rng = np.random.default_rng(3)
    first = random_rows(store, "biotac", 120, rng)
    store.append("biotac", first)
    store.commit()
    filler = small_disk / "filler"
    try:                                                 # fill the disk up to its last blocks
        with open(filler, "wb", buffering=0) as f:
            while True:
                f.write(b"\0" * 4096)
    except OSError:
        pass
    os.truncate(filler, max(0, filler.stat().st_size - 150_000))
    more = random_rows(store, "biotac", 1500, rng)      # 3 chunks of electrodes alone: ~300 kB
    with pytest.raises(OSError):
        store.append("biotac", more)
    assert store.length("biotac") == 120
    assert not list(small_disk.rglob("*.partial"))      # no temporary files left behind
    assert open_run(store.path)["biotac"].sizes["time"] == 120
    store.commit()                                      # the lengths are consistent again
    filler.unlink()
    store.append("biotac", more)
    store.commit()
    b = open_run(store.path)["biotac"]
    for name in ("seq", "electrodes", "pdc", "valid"):
        np.testing.assert_array_equal(b[name].values, np.concatenate([first[name], more[name]]), err_msg=name)


def test_metadata_it_does_not_know_is_refused_with_the_array_named(tmp_path):
    from tactile_flow.runstore.appender import GrowingArray
    store = RunStore.create(tmp_path / "run.zarr", protocol="unit_test")
    meta = json.loads((store.path / "arm" / "tcp_pose" / "zarr.json").read_bytes())
    with pytest.raises(ValueError, match=r"arm/tcp_pose.*codecs"):
        GrowingArray(store.path / "arm" / "tcp_pose", {**meta, "codecs": [{"name": "bytes"}, {"name": "blosc"}]})
    with pytest.raises(ValueError, match="rows of shape"):
        store.append("arm", {**random_rows(store, "arm", 2, np.random.default_rng(0)), "tcp_pose": np.zeros((2, 5))})

"""A short packed store read without zarr (``runstore.packedread``) gives zarr-python's values,
and the analysis's loader reads the same run from it."""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np
import pytest

from tactile_flow.analysis import load as load_mod
from tactile_flow.analysis.load import load_run
from tactile_flow.importers import ImportSettings, import_source
from tactile_flow.runstore import packedread
from tactile_flow.runstore.reader import open_group
from conftest import DATA

BAG = DATA / "biotac_rest_untouched.bag"


@pytest.fixture(scope="module")
def stores(tmp_path_factory) -> list[Path]:
    """The real bag (three fingers, vibration, host times) and a one-finger electrode-only CSV."""
    tmp = tmp_path_factory.mktemp("packed_read")
    (bag,) = import_source(BAG, tmp / "bag")
    from test_dataset_import import short_csv
    (csv,) = import_source(short_csv(tmp / "take.csv", seed=4), tmp / "csv", ImportSettings(rate_hz=100))
    return [Path(bag.store), Path(csv.store)]


def walk(group, prefix=""):
    for name, a in group.arrays():
        yield f"{prefix}{name}", a
    for name, g in group.groups():
        yield from walk(g, f"{prefix}{name}/")


def test_every_array_and_attribute_as_zarr_reads_them(stores):
    for store in stores:
        ours, theirs = packedread.open_small(store), open_group(store)
        assert ours is not None
        assert dict(ours.attrs) == dict(theirs.attrs)
        assert sorted(ours.group_keys()) == sorted(theirs.group_keys())
        a, b = dict(walk(ours)), dict(walk(theirs))
        assert sorted(a) == sorted(b) and len(a) >= 10
        for key in a:
            assert a[key].shape == b[key].shape, key
            assert tuple(a[key].metadata.dimension_names) == tuple(b[key].metadata.dimension_names), key
            x, y = a[key][...], b[key][...]
            if y.dtype.kind in "OT":                    # text: object str here, StringDType in zarr
                assert [str(v) for v in x.ravel()] == [str(v) for v in y.ravel()], key
            else:
                assert x.dtype == y.dtype and x.tobytes() == y.tobytes(), key
                assert np.array_equal(a[key][1:5], b[key][1:5], equal_nan=True), key


def test_the_loader_reads_the_same_run_either_way(stores, monkeypatch):
    for store in stores:
        ours = load_run(store)
        monkeypatch.setattr(packedread, "open_small", lambda path: None)       # zarr-python's way
        theirs = load_run(store)
        monkeypatch.undo()
        assert ours.input_sha256 == theirs.input_sha256
        assert ours.fingers == theirs.fingers and ours.attrs == theirs.attrs
        np.testing.assert_array_equal(ours.electrodes, theirs.electrodes)
        np.testing.assert_array_equal(ours.events.time, theirs.events.time)
        assert (ours.events.kind, ours.events.name, ours.events.detail) == \
               (theirs.events.kind, theirs.events.name, theirs.events.detail)
        assert isinstance(ours.tree, packedread.Group)


def test_a_store_it_does_not_decode_or_a_damaged_one_goes_to_zarr(stores, tmp_path):
    store = stores[1]
    big = tmp_path / "run.zarr.zip"
    big.write_bytes(store.read_bytes())
    with zipfile.ZipFile(big, "a") as z:                 # a store beyond the size read whole
        z.writestr("padding/c/0", b"\0" * (packedread.MAX_BYTES + 1))
    assert packedread.open_small(big) is None
    cut = tmp_path / "cut.zarr.zip"
    cut.write_bytes(store.read_bytes()[:-40])              # truncated: zarr says what is wrong
    assert packedread.open_small(cut) is None
    assert isinstance(load_mod.open_store(store), packedread.Group)

"""A run outlives this code: every array of a run store is read by an independent zarr v3
implementation (tensorstore's ``zarr3`` driver, C++) with the values zarr-python reads, except
the text arrays, which the zarr v3 core has no data type for: tensorstore refuses them, and they
are read here from their files by the published formats of the zarr extensions they use
(``docs/run_store.md``, "Reading a store without zarr-python"). Stores of both layouts: a
directory (a recording, any store of 0.2.0 or before) and packed, one zip file (an import's
``run.zarr.zip``, an analysis's ``analysis.zarr.zip``), which tensorstore reads through its
``zip`` kvstore. Also: the stores of an import and of a run open with ``xarray.open_datatree``
(a packed one by its ``zip::`` URL), and an import holds no empty device groups."""

from __future__ import annotations

import itertools
import json
import struct
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pytest
import zarr
from hydra import compose, initialize_config_dir

from conftest import DATA
from tactile_flow.runstore import open_group, open_run, packed, store_url

ts = pytest.importorskip("tensorstore")
xr = pytest.importorskip("xarray")

CONF_DIR = Path(__file__).resolve().parents[1] / "conf"
FAST = ["protocol.sweep_speed=40", "protocol.travel_speed=100", "protocol.approach_speed=10",
        "progress=false", "analyze=false"]
#: the data types of text: zarr-python's "string" (codec vlen-utf8; run stores) and
#: "fixed_length_utf32" (numpy's <U, as xarray writes labels; analysis.zarr), extensions
#: outside the v3 core, which tensorstore refuses (its data types: the core's, plus r<N>)
TEXT = ("string", "fixed_length_utf32")


def _arrays(store: Path) -> dict[str, zarr.Array]:
    """Every array of the store at its last commit (the consolidated metadata), by path."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        root = open_group(store)
        return {path: a for path, a in root.members(max_depth=None) if isinstance(a, zarr.Array)}


def _is_zip(store: Path) -> bool:
    return store.is_file() and zipfile.is_zipfile(store)


def _get(store: Path, key: str) -> bytes | None:
    """The value of ``key`` in the store (a directory, or a packed zip), ``None`` if absent;
    read with the standard library only."""
    if _is_zip(store):
        with zipfile.ZipFile(store) as z:
            try:
                return z.read(key)
            except KeyError:
                return None
    file = store / key
    return file.read_bytes() if file.exists() else None


def _tensorstore(store: Path, path: str):
    """The array ``path`` of ``store`` opened by tensorstore: its ``file`` kvstore for a
    directory store, its ``zip`` kvstore over that file for a packed one."""
    if _is_zip(store):
        kv = {"driver": "zip", "base": {"driver": "file", "path": str(store)}, "path": path + "/"}
    else:
        kv = {"driver": "file", "path": str(store / path)}
    return ts.open({"driver": "zarr3", "kvstore": kv}, read=True).result()


def _zstd_decompress(data: bytes) -> bytes:
    try:
        from compression import zstd                      # Python 3.14
    except ImportError:
        from backports import zstd                         # the same module before 3.14 (rosbags needs it)
    return zstd.decompress(data)


def _read_text(store: Path, path: str) -> np.ndarray:
    """A text array read from its files by the published formats of the zarr extensions it uses
    (``string`` with ``vlen-utf8``: per chunk a u32le count, then per element a u32le byte length
    and its UTF-8 bytes; ``fixed_length_utf32``: ``length_bytes`` of UTF-32LE per element through
    the core ``bytes`` codec), then ``zstd``: no zarr-python, no numcodecs."""
    meta = json.loads(_get(store, f"{path}/zarr.json"))
    shape, chunks = meta["shape"], meta["chunk_grid"]["configuration"]["chunk_shape"]
    sep = meta["chunk_key_encoding"].get("configuration", {}).get("separator", "/")
    codecs = [c["name"] for c in meta["codecs"]]
    out = np.full(shape, meta["fill_value"], dtype=object)
    for index in itertools.product(*(range(-(-n // c)) for n, c in zip(shape, chunks))):
        raw = _get(store, f"{path}/" + sep.join(["c", *map(str, index)]))
        if raw is None:                                    # a chunk of fill values is not written
            continue
        if "zstd" in codecs:
            raw = _zstd_decompress(raw)
        if codecs[0] == "vlen-utf8":
            (n,), pos, items = struct.unpack_from("<I", raw), 4, []
            for _ in range(n):
                (length,) = struct.unpack_from("<I", raw, pos)
                items.append(raw[pos + 4:pos + 4 + length].decode("utf-8"))
                pos += 4 + length
            block = np.array(items, dtype=object).reshape(chunks)
        else:
            width = meta["data_type"]["configuration"]["length_bytes"]
            block = np.array([raw[i:i + width].decode("utf-32-le").rstrip("\0")
                              for i in range(0, len(raw), width)], dtype=object).reshape(chunks)
        where = tuple(slice(i * c, min(n, (i + 1) * c)) for i, c, n in zip(index, chunks, shape))
        out[where] = block[tuple(slice(0, w.stop - w.start) for w in where)]
    return out


def _check_every_array(store: Path) -> tuple[int, list[str]]:
    """Read every array with tensorstore and compare it with zarr-python's values; returns the
    count read and the text arrays, which tensorstore must refuse (for the documented reason)
    and which :func:`_read_text` reads, by their published formats, as zarr-python does."""
    read, text = 0, []
    for path, a in _arrays(store).items():
        meta = json.loads(_get(store, f"{path}/zarr.json"))
        data_type = meta["data_type"]
        if (data_type["name"] if isinstance(data_type, dict) else data_type) in TEXT:
            with pytest.raises(ValueError, match="data type is not one of the supported"):
                _tensorstore(store, path)
            assert _read_text(store, path).tolist() == np.asarray(a[...], dtype=object).tolist(), path
            text.append(path)
            continue
        expected = a[...]
        got = _tensorstore(store, path).read().result()
        assert got.dtype == expected.dtype and got.shape == expected.shape, path
        np.testing.assert_array_equal(got, expected, err_msg=path)
        read += 1
    return read, text


@pytest.fixture(scope="module")
def default_run(tmp_path_factory):
    """The default protocol (the straws sweep) on the simulated lab, shortened."""
    from tactile_flow.protocols.run import run_protocol
    from tactile_flow.protocols.schema import register
    register()
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base=None):
        cfg = compose("config", overrides=FAST)
    result = run_protocol(cfg, tmp_path_factory.mktemp("run"), console=lambda *a: None)
    assert result.status == "success", result.error
    return Path(result.store)


def test_tensorstore_reads_every_numeric_array_of_a_default_run(default_run):
    read, text = _check_every_array(default_run)
    assert read >= 70                                    # every device, events' times, the truth
    assert {"events/kind", "events/name", "events/detail", "biotac/finger", "arm/axis6", "hand/joint"} <= set(text)


def test_tensorstore_reads_every_numeric_array_of_imported_records(tmp_path):
    from tactile_flow.importers import ImportSettings, import_source
    (bag,) = import_source(DATA / "biotac_rest_untouched.bag", tmp_path / "bag", ImportSettings())
    assert _is_zip(Path(bag.store)) and Path(bag.store).name == "run.zarr.zip"     # packed, read through zip
    read, text = _check_every_array(Path(bag.store))
    assert read == 15 and sorted(text) == ["biotac/finger", "biotac_pac/finger", "events/detail",
                                           "events/kind", "events/name"]
    electrodes = _tensorstore(Path(bag.store), "biotac/electrodes").read().result()
    assert electrodes.shape == (977, 3, 24) and electrodes.dtype == np.int16


def test_an_imported_csv_holds_only_its_streams_and_opens_with_xarray(tmp_path):
    """A CSV of one finger's electrodes: the store has ``biotac`` and ``events`` only, every
    array readable, and ``xarray.open_datatree`` gives the values written."""
    from tactile_flow.importers import ImportSettings, import_source
    rng = np.random.default_rng(3)
    counts = rng.integers(2000, 3500, (275, 24))
    src = tmp_path / "short.csv"
    src.write_text("time," + ",".join(f"e{i}" for i in range(1, 25)) + "\n"
                   + "".join(f"{k / 100:.2f}," + ",".join(map(str, row)) + "\n" for k, row in enumerate(counts)))
    (res,) = import_source(src, tmp_path / "out", ImportSettings(rate_hz=100.0))
    store = Path(res.store)
    tree = xr.open_datatree(f"zip::{store}", engine="zarr")          # a packed store, by a string
    assert set(tree.children) == {"biotac", "events"}
    np.testing.assert_array_equal(tree["biotac"]["electrodes"].values[:, 0, :], counts)
    assert tree["events"]["kind"].values.tolist() == ["info"]
    read, text = _check_every_array(store)
    assert read == 8 and sorted(text) == ["biotac/finger", "events/detail", "events/kind", "events/name"]
    assert sorted(p.name for p in store.parent.iterdir()) == [".tactile.lock", "run.json", "run.zarr.zip"]
    with zipfile.ZipFile(store) as z:                     # one file, the nodes of the store inside
        members = z.infolist()
    assert len(members) <= 28, [m.filename for m in members]
    assert all(m.compress_type == (zipfile.ZIP_DEFLATED if m.filename.endswith("zarr.json") else zipfile.ZIP_STORED)
               for m in members)                          # metadata deflated; chunks (zstd already) stored
    assert xr.open_datatree(f"zip::file://{store}", engine="zarr")["biotac"]["electrodes"].shape == (275, 1, 24)
    assert zarr.open_group(f"zip::{store}", mode="r")["biotac/electrodes"][...].shape == (275, 1, 24)


def _analysis_tree(run_dir: Path):
    return open_run(packed.find(run_dir / "analysis", "analysis.zarr"))


def test_a_store_of_the_earlier_layout_opens_and_analyses_as_the_same_file_imported_today(tmp_path):
    """``import_store_0.2.zip``: a CSV imported before issue 36 (every lab group present, the
    empty ones too; indented metadata). It opens with xarray, tensorstore reads its numeric
    arrays, and its analysis equals, array for array, that of the same CSV imported today."""
    import zipfile
    from tactile_flow.analysis.run import analyze_run
    from tactile_flow.importers import ImportSettings, import_source
    old = tmp_path / "old"
    with zipfile.ZipFile(DATA / "import_store_0.2.zip") as z:
        z.extractall(old)
    tree = xr.open_datatree(old / "run.zarr", engine="zarr")
    assert set(tree.children) == {"biotac", "biotac_pac", "arm", "hand", "pour", "events"}
    assert tree["arm"].sizes["time_arm"] == 0 and tree["biotac"].sizes["time"] == 275
    read, text = _check_every_array(old / "run.zarr")
    assert read > 30 and {"events/kind", "arm/axis6", "hand/joint"} <= set(text)

    (new,) = import_source(old / "short.csv", tmp_path / "new", ImportSettings(rate_hz=100.0, baseline="estimate"))
    new_dir = Path(new.store).parent
    assert set(xr.open_datatree(store_url(new.store), engine="zarr").children) == {"biotac", "events"}
    np.testing.assert_array_equal(xr.open_datatree(store_url(new.store), engine="zarr")["biotac"]["electrodes"].values,
                                  tree["biotac"]["electrodes"].values)
    cfg = {"figures": False, "progress": False}
    before = analyze_run(old / "run.zarr", cfg, console=lambda *a: None)
    after = analyze_run(new.store, cfg, console=lambda *a: None)
    assert before["segments"] == after["segments"] and len(before["segments"]) >= 1
    assert _is_zip(new_dir / "analysis" / "analysis.zarr.zip")                     # packed (after 0.2.0)
    read, text = _check_every_array(new_dir / "analysis" / "analysis.zarr.zip")  # and the analysis' arrays
    assert read > 40 and "segments/label" in text
    a, b = _analysis_tree(old), _analysis_tree(new_dir)
    assert [n.path for n in a.subtree] == [n.path for n in b.subtree]
    for node in a.subtree:
        for name, var in node.ds.variables.items():
            other = b[node.path].ds.variables[name]
            assert var.dims == other.dims, (node.path, name)
            np.testing.assert_array_equal(var.values, other.values, err_msg=f"{node.path}/{name}")

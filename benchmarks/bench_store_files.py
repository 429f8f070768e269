"""Files and bytes of a short imported record's run directory and of its analysis.

Writes a 275-frame, one-finger CSV (24 electrode counts and the pressure, 100 Hz, a contact
that rolls across the pad from 0.8 to 2.2 s: the size of a short dataset recording), imports it
with the real ``tactile-import`` and analyses it with ``tactile-analyze``, then prints one JSON
line per part: files, bytes of the files (apparent) and bytes on disk (allocated blocks), and
the ratio of each to the record's raw counts (frames × channels × 2 bytes):

- ``run_zarr``: the store (``run.zarr.zip``, one file, since 0.3; ``run.zarr``, a directory,
  before); ``run_dir``: the run directory without its analyses (store, ``run.json``, lock);
  ``analysis``: one analysis directory, figures aside; ``figures``.

Then, for the packing of a store (``runstore.packed``), the run store and the analysis store
re-packed three ways (``"part": "packing"``): every member stored, every member deflated, and
the layout written (``zarr.json`` deflated, chunks stored), bytes and ratio to the raw counts.

    python benchmarks/bench_store_files.py [--frames 275] [--dir DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np


def write_record(path: Path, frames: int, seed: int = 1) -> int:
    """A one-finger CSV (``time``, ``e1..e24``, ``pdc``) with one rolling contact; returns the
    bytes of its raw counts (int16)."""
    rng = np.random.default_rng(seed)
    rest = rng.integers(2600, 3200, 24).astype(float)
    lines = ["time," + ",".join(f"e{i}" for i in range(1, 25)) + ",pdc"]
    for k in range(frames):
        t = k / 100
        press = np.sin(np.pi * (t - 0.8) / 1.4) if 0.8 <= t <= 2.2 else 0.0
        centre = 4 + 16 * (t - 0.8) / 1.4
        row = (rest - 600 * press * np.exp(-0.5 * ((np.arange(24) - centre) / 3) ** 2) + rng.normal(0, 4, 24)).astype(int)
        lines.append(f"{t:.2f}," + ",".join(map(str, row)) + f",{int(2000 + 300 * press + rng.normal(0, 2))}")
    path.write_text("\n".join(lines) + "\n")
    return frames * 25 * 2


def measure(files: list[Path]) -> dict:
    """Count, apparent bytes and allocated bytes (st_blocks × 512) of ``files``."""
    stats = [f.stat() for f in files]
    return {"files": len(files), "bytes": sum(s.st_size for s in stats),
            "disk_bytes": sum(s.st_blocks * 512 for s in stats)}


def tree_files(root: Path, exclude=()) -> list[Path]:
    return [p for p in root.rglob("*") if p.is_file() and not p.is_symlink()
            and not any(part in exclude for part in p.relative_to(root).parts)]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=275)
    ap.add_argument("--dir", type=Path, default=None)
    args = ap.parse_args(argv)
    work = args.dir or Path(tempfile.mkdtemp(prefix="bench-store-files-"))
    work.mkdir(parents=True, exist_ok=True)
    raw = write_record(work / "short.csv", args.frames)
    env = {**os.environ, "MPLBACKEND": "Agg"}
    bin_dir = Path(sys.executable).parent
    subprocess.run([str(bin_dir / "tactile-import"), f"source={work / 'short.csv'}", f"out={work / 'out'}",
                    "rate_hz=100", "baseline=estimate"], check=True, env=env, stdout=subprocess.DEVNULL)
    run = work / "out" / "short"
    subprocess.run([str(bin_dir / "tactile-analyze"), f"run={run}", "analysis.progress=false"], check=True, env=env,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    (analysis,) = [p for p in (run / "analyses").iterdir() if p.is_dir()]
    store = run / "run.zarr.zip" if (run / "run.zarr.zip").is_file() else run / "run.zarr"
    parts = {"run_zarr": [store] if store.is_file() else tree_files(store),
             "run_dir": tree_files(run, exclude=("analyses",)),
             "analysis": tree_files(analysis, exclude=("figures",)),
             "figures": tree_files(analysis / "figures")}
    for name, files in parts.items():
        m = measure(files)
        print(json.dumps({"part": name, **m, "raw_bytes": raw, "bytes_per_raw": round(m["bytes"] / raw, 2),
                          "disk_per_raw": round(m["disk_bytes"] / raw, 2)}), flush=True)
    for name, packed in (("run_zarr", store), ("analysis", analysis / "analysis.zarr.zip")):
        if packed.is_file():
            print(json.dumps({"part": "packing", "store": name, **packings(packed, work / "packing"),
                              "raw_bytes": raw}), flush=True)
    return 0


def packings(store: Path, work: Path) -> dict:
    """Bytes of the packed ``store`` re-packed with every member stored, every member deflated,
    and as written (``zarr.json`` deflated, chunks stored), with their ratios to the raw counts."""
    import zipfile
    work.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(store) as z:
        members = [(i.filename, z.read(i)) for i in z.infolist()]
    out = {}
    for name, kind in (("stored", zipfile.ZIP_STORED), ("deflated", zipfile.ZIP_DEFLATED)):
        path = work / f"{name}.zip"
        with zipfile.ZipFile(path, "w", kind) as z:
            for key, data in members:
                z.writestr(key, data)
        out[f"{name}_bytes"] = path.stat().st_size
    out["written_bytes"] = store.stat().st_size
    return out


if __name__ == "__main__":
    sys.exit(main())

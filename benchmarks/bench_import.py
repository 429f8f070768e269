"""tactile-import on large files: throughput and peak memory, for a file and one ``--ratio`` times smaller.

Writes a large CSV (three fingers, electrodes + pdc, a ``time`` column; ``--csv-rows`` rows)
and a large ROS1 bag (``/rh/tactile`` BiotacAll messages, three connected fingers and two
empty ports, 22 PAC samples per frame; ``--bag-messages`` messages) to a temporary
directory, plus the same files ``--ratio`` times shorter, and imports each with the real
``tactile-import`` command in its own process. Prints one JSON line per import — rows, file
MB, wall seconds, rows/s, peak resident memory of the importing process (its
``ru_maxrss``, read with ``os.wait4`` so each process is measured alone: the figure
``resource.getrusage(RUSAGE_CHILDREN)`` gives for a single child) — then one line per format
with the large/small ratios: rows ×``ratio``, memory ×~1 when the import streams.

    python benchmarks/bench_import.py [--csv-rows 1000000] [--bag-messages 250000] [--ratio 4] [--dir DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

FINGERS = ("ff", "mf", "rf", "lf", "th")
CONNECTED = ("ff", "mf", "th")
TEMPLATES = 1000                     # distinct rows / messages, repeated with fresh times and seq


def emit(**row):
    print(json.dumps(row), flush=True)


def write_csv(path: Path, rows: int, seed: int = 0) -> Path:
    """``rows`` frames at 100 Hz: ``time`` (s) and ``<finger>_e1..e24, <finger>_pdc`` counts for
    ff, mf, th (the counts cycle through ``TEMPLATES`` random rows). Written block by block."""
    rng = np.random.default_rng(seed)
    names = ["time"] + [f"{f}_{c}" for f in CONNECTED for c in [*(f"e{i}" for i in range(1, 25)), "pdc"]]
    block = [",".join(map(str, r)) for r in rng.integers(2000, 3500, (TEMPLATES, len(names) - 1))]
    with open(path, "w") as f:
        f.write(",".join(names) + "\n")
        for start in range(0, rows, TEMPLATES):
            f.write("".join(f"{(start + k) / 100:.2f},{block[k]}\n" for k in range(min(TEMPLATES, rows - start))))
    return path


def write_bag(path: Path, messages: int, n_pac: int = 22, seed: int = 0) -> Path:
    """A ROS1 bag of ``messages`` ``sr_robot_msgs/BiotacAll`` frames at 100 Hz on ``/rh/tactile``
    (newer form, ``pac[]`` of ``n_pac`` samples; rf and lf empty ports), record time 1.5 ms after
    the stamp. ``TEMPLATES`` messages are serialised once; each written message is a template
    with its header seq and stamp patched (ROS1 layout: uint32 seq, sec, nsec first)."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    from tactile_flow.importers.bag import BIOTAC_MSGS, MSGTYPE, TOPIC

    ts = get_typestore(Stores.ROS1_NOETIC)
    types = {}
    for name, text in BIOTAC_MSGS.items():
        types.update(get_types_from_msg(text, name))
    ts.register(types)
    T = ts.types
    Biotac, BiotacAll = T["sr_robot_msgs/msg/Biotac"], T[MSGTYPE]
    Header, Time = T["std_msgs/msg/Header"], T["builtin_interfaces/msg/Time"]
    rng = np.random.default_rng(seed)
    templates = []
    for _ in range(TEMPLATES):
        tact = []
        for f in FINGERS:
            if f in CONNECTED:
                pac = rng.integers(1900, 2100, n_pac).astype(np.int16)
                tact.append(Biotac(pac0=int(pac[0]), pac1=int(pac[1]), pdc=int(rng.integers(2600, 2800)), tac=2000,
                                   tdc=2250, electrodes=rng.integers(2000, 3500, 24).astype(np.int16), pac=pac))
            else:
                tact.append(Biotac(pac0=0, pac1=0, pdc=-22072, tac=0, tdc=0, electrodes=np.zeros(24, np.int16),
                                   pac=np.zeros(n_pac, np.int16)))
        msg = BiotacAll(header=Header(seq=0, stamp=Time(sec=0, nanosec=0), frame_id="rh_distal"), tactiles=tact)
        templates.append(bytes(ts.serialize_ros1(msg, MSGTYPE)))
    t0_ns = 1_700_000_000 * 10**9
    with Writer(path) as w:
        conn = w.add_connection(TOPIC, MSGTYPE, typestore=ts)
        for i in range(messages):
            stamp = t0_ns + i * 10_000_000
            raw = bytearray(templates[i % TEMPLATES])
            struct.pack_into("<III", raw, 0, i, stamp // 10**9, stamp % 10**9)
            w.write(conn, stamp + 1_500_000, bytes(raw))
    return path


def import_once(source: Path, out: Path) -> dict:
    """Run ``tactile-import source=... out=...`` in a fresh process; wall s and its peak RSS (MB)."""
    cmd = [sys.executable, "-m", "tactile_flow.importers.cli", f"source={source}", f"out={out}"]
    log = out.with_name(out.name + ".log")
    with open(log, "w+") as f:                   # a file, not a pipe: wait4 before reading cannot block
        t = time.perf_counter()
        proc = subprocess.Popen(cmd, stdout=f, stderr=subprocess.STDOUT, text=True)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t
        proc.returncode = os.waitstatus_to_exitcode(status)
        f.seek(0)
        text = f.read()
    log.unlink()
    if proc.returncode:
        raise RuntimeError(f"{' '.join(cmd)} exited {proc.returncode}: {text.strip()}")
    frames = int(text.split(" frames at ")[0].rsplit(" ", 1)[-1])
    return {"wall_s": wall, "peak_rss_mb": usage.ru_maxrss / 1024, "frames": frames}   # ru_maxrss: kB on Linux


def measure(fmt: str, path: Path, rows: int, work: Path) -> dict:
    out = work / f"out_{path.name.replace('.', '_')}"
    r = import_once(path, out)
    shutil.rmtree(out)
    if r["frames"] != rows:
        raise RuntimeError(f"{path}: imported {r['frames']} frames, wrote {rows}")
    row = {"format": fmt, "rows": rows, "file_mb": round(path.stat().st_size / 1e6, 1), "wall_s": round(r["wall_s"], 2),
           "rows_per_s": round(rows / r["wall_s"]), "peak_rss_mb": round(r["peak_rss_mb"], 1)}
    emit(**row)
    return row


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--csv-rows", type=int, default=1_000_000, help="rows of the large CSV")
    ap.add_argument("--bag-messages", type=int, default=250_000, help="messages of the large bag")
    ap.add_argument("--ratio", type=int, default=4, help="the small files are this many times shorter")
    ap.add_argument("--dir", help="work directory (default: a temporary one, removed at the end)")
    args = ap.parse_args(argv)
    work = Path(args.dir) if args.dir else Path(tempfile.mkdtemp(prefix="bench_import-"))
    work.mkdir(parents=True, exist_ok=True)
    try:
        for fmt, n, writer, suffix in (("csv", args.csv_rows, write_csv, "csv"),
                                       ("rosbag1", args.bag_messages, write_bag, "bag")):
            small_n = max(2, n // args.ratio)
            t = time.perf_counter()
            big = writer(work / f"large.{suffix}", n)
            small = writer(work / f"small.{suffix}", small_n)
            emit(format=fmt, written_s=round(time.perf_counter() - t, 1))
            a = measure(fmt, small, small_n, work)
            b = measure(fmt, big, n, work)
            emit(format=fmt, rows_ratio=round(b["rows"] / a["rows"], 2),
                 file_ratio=round(b["file_mb"] / a["file_mb"], 2),
                 peak_rss_ratio=round(b["peak_rss_mb"] / a["peak_rss_mb"], 3),
                 wall_ratio=round(b["wall_s"] / a["wall_s"], 2))
            for p in (big, small):
                p.unlink()
    finally:
        if not args.dir:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()

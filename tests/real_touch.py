"""Records of real touches: a real BioTac SP contact frame held still under the real sensor's
resting noise, as a touch (``slip_class`` ``none``) looks on the real sensor.

The frames are rows of ``tests/data/biotac_sp_grasps`` (another lab's grasps of 41 objects; see
its README); the noise is a stretch of the same finger's real resting recording
(``tests/data/biotac_rest_untouched.bag``), glitches included. Two kinds of record, electrode-only
CSVs at 100 Hz, one finger each (the frame's own), as imported data are:

- ``first``: the record begins in contact, on the held frame (the held-out layout: no tare);
- ``rest``: 0.5 s at the sensor's unloaded state (the per-file estimate of
  ``hardware/sim/biotac_contact_calibration.json``), a 0.3 s press into the frame (linear in
  impedance), then the frame held.

Each grasp file is its own import, as the files were recorded on different days. A ``first``
record has no rest to take its zero from: its import estimates the baseline across the file's
records (``baseline=estimate``, as the held-out records are imported). A ``rest`` record begins at
rest: it is imported as such a record would be (no stored baseline: the analysis takes the
record's own quiet stretch), since an estimate pooled over early windows that hold contacts
reads the far field's rise as part of the unloaded state. Used by ``tests/test_slip_real_touch.py`` and
``benchmarks/bench_slip_direction.py``.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parent / "data"
GRASPS = sorted((DATA / "biotac_sp_grasps").glob("*.csv"))
FINGERS = ("ff", "mf", "th")
RATE_HZ = 100.0
RECORD_S = 2.7
REST_S, PRESS_S = 0.5, 0.3
MIN_DROP_COUNTS = 200.0
"""A finger's row is a contact frame when one electrode reads this much below its unloaded state."""


def grasp_rows(path: Path) -> np.ndarray:
    """(N, 3, 24) raw counts of ff, mf, th, one row per grasp reading."""
    with open(path) as f:
        rows = list(csv.reader(f))[1:]
    return np.array([[float(x) for x in r[2:]] for r in rows]).reshape(-1, 3, 24)


def rest_noise() -> np.ndarray:
    """(T, 3, 24) the real resting recording of ff, mf, th minus each electrode's median (counts)."""
    from tactile_flow.importers import read_bag, select_fingers
    rec, _ = select_fingers(read_bag(DATA / "biotac_rest_untouched.bag"))
    e = rec.electrodes.astype(float)
    return e - np.median(e, axis=0)


def unloaded(path: Path) -> np.ndarray:
    """(3, 24) the unloaded counts of the file's sensors (the contact calibration's estimate)."""
    cal = Path(__file__).resolve().parents[1] / "hardware" / "sim" / "biotac_contact_calibration.json"
    state = json.loads(cal.read_text())["unloaded_state"][path.name]
    return np.array([state[f]["baseline_counts"] for f in FINGERS], float)


def _kohm(c):
    return (4095.0 / np.clip(c, 1.0, 4095.0) - 1.0) * 10.0


def _counts(z):
    return 4095.0 / (1.0 + np.asarray(z) / 10.0)


def touch_counts(frame, base, noise, kind: str) -> np.ndarray:
    """(T, 24) counts of one record: ``frame`` (24,) held (``kind`` ``first``), or reached from
    ``base`` (24,) after a rest (``rest``); ``noise`` (≥ T, 24) added."""
    n = int(round(RECORD_S * RATE_HZ))
    if kind == "first":
        clean = np.repeat(frame[None], n, axis=0)
    else:
        r, p = int(round(REST_S * RATE_HZ)), int(round(PRESS_S * RATE_HZ))
        w = np.r_[np.zeros(r), np.linspace(0.0, 1.0, p), np.ones(n - r - p)][:, None]
        clean = _counts((1 - w) * _kohm(base) + w * _kohm(frame))
    return np.clip(np.rint(clean + noise[:n]), 1, 4094)


def picks(per_finger: int, seed: int = 0, files=None):
    """Deterministic ``(file, row, finger index)`` choices: ``per_finger`` contact frames of each
    finger of each grasp file (``files``: default all), spread over its rows."""
    rng = np.random.default_rng(seed)
    out = []
    for path in files or GRASPS:
        rows = grasp_rows(path)
        drop = (unloaded(path)[None] - rows).max(axis=2)          # (N, 3) largest drop per finger
        for k in range(len(FINGERS)):
            candidates = np.flatnonzero(drop[:, k] > MIN_DROP_COUNTS)
            for i in np.sort(rng.choice(candidates, size=min(per_finger, len(candidates)), replace=False)):
                out.append((path, int(i), k))
    return out


def write_records(out: Path, per_finger: int, kinds=("first", "rest"), seed: int = 0,
                  files=None) -> dict[str, list[Path]]:
    """Write the records as CSV directories ``out/<kind>/<file stem>/`` (one import each: its
    fingers' baselines are estimated from their ``per_finger`` records); returns kind → the
    directories."""
    noise = rest_noise()
    rng = np.random.default_rng(seed + 1)
    n = int(round(RECORD_S * RATE_HZ))
    dirs: dict[str, list[Path]] = {k: [] for k in kinds}
    chosen = picks(per_finger, seed, files)
    for kind in kinds:
        for path in files or GRASPS:
            mine = [(row, k) for p, row, k in chosen if p == path]
            if not mine:
                continue
            d = out / kind / path.stem
            d.mkdir(parents=True, exist_ok=True)
            rows, base = grasp_rows(path), unloaded(path)
            for row, k in mine:
                s = int(rng.integers(0, len(noise) - n))
                counts = touch_counts(rows[row, k], base[k], noise[s:s + n, k], kind)
                f = FINGERS[k]
                head = ",".join(f"{f}_e{j}" for j in range(1, 25))
                (d / f"row{row:04d}_{f}.csv").write_text(
                    head + "\n" + "\n".join(",".join(str(int(v)) for v in r) for r in counts) + "\n")
            dirs[kind].append(d)
    return dirs


def read_as_touch(directory: Path, work: Path, baseline: str = "estimate") -> list[dict]:
    """Import one directory of records (``rate_hz=100``, ``baseline``: ``estimate`` for ``first``
    records, ``none`` for ``rest`` ones) and analyse each with ``tactile-analyze``'s defaults;
    one row per record: its name and its finger's slip estimate (``None`` where the analysis
    found no contact)."""
    from tactile_flow.analysis.run import analyze_run
    from tactile_flow.importers import ImportSettings, import_source
    results = import_source(directory, work / directory.name, ImportSettings(rate_hz=RATE_HZ, baseline=baseline))
    rows = []
    for r in results:
        summary = analyze_run(r.store, {"figures": False, "progress": False}, console=lambda *_: None)
        slips = summary["estimates"]["slip"]
        rows.append({"record": Path(r.store).parent.name, "slip": next(iter(slips.values()), None)})
    return rows


BASELINE = {"first": "estimate", "rest": "none"}
"""How each kind of record is imported (module docstring)."""

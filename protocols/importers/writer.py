"""Write a :class:`~.recording.Recording` as a run store (``run.zarr`` + ``run.json``), atomically.

The store has the layout of a recorded run (``docs/run_store.md``), written through
:class:`protocols.store.RunStore` with the recorder's column helpers, so ``tactile-analyze``
reads it like any run:

- ``biotac``: ``time`` (s since the first frame, from the clock model of ``device_time``
  against ``host_time`` when the file has both, else ``device_time − device_time[0]``),
  ``device_time``, ``host_time`` (NaN when the file has none), ``seq``, ``valid``,
  ``electrodes``; ``pdc``/``tdc``/``tac`` only when the file holds them (an electrode-only
  record has no ``pdc`` variable, so the analysis uses its electrode proxy);
  ``baseline`` (finger, taxel) counts when a baseline from elsewhere was given;
- ``biotac_pac``: the PAC samples (bags), empty for CSV;
- ``events``: an ``info`` event ``import`` at 0 s, and a ``gap`` event per sequence jump;
- root attributes: ``protocol="import"``, ``labels=[]``, ``status="success"``, ``import``
  (source, checksum, importer, finger decision), ``baseline``, ``calibration``, ``streams``.

Nothing half-written: everything goes to a hidden temporary directory beside the target,
renamed into place by :func:`publish` once every store of the import is complete.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import tempfile
import warnings
from pathlib import Path

import numpy as np
import zarr

from hardware.biotac import BiotacFrame
from protocols.clockmodel import fit_envelope, latency_stats, sequence_gaps, window_minima
from protocols.provenance import write_run_json
from protocols.recorder import biotac_columns, pac_columns
from protocols.store import RunStore, jsonable

from .baseline import Baseline
from .recording import Recording

PROTOCOL = "import"
OPTIONAL = ("pdc", "tdc", "tac")


def frames_of(rec: Recording) -> list[BiotacFrame]:
    """The recording as :class:`hardware.biotac.BiotacFrame` s (absent channels as zeros,
    ``host_time`` NaN when unknown), so the recorder's column helpers apply unchanged."""
    n, F = rec.n_frames, len(rec.fingers)
    zeros = np.zeros((n, F), np.int64)
    host = rec.host_time if rec.host_time is not None else np.full(n, math.nan)
    pac = rec.pac if rec.pac is not None else [np.zeros((F, 0), np.int64)] * n
    return [BiotacFrame(int(rec.seq[i]), float(rec.device_time[i]), float(host[i]), rec.electrodes[i],
                        (rec.pdc if rec.pdc is not None else zeros)[i], (rec.tdc if rec.tdc is not None else zeros)[i],
                        (rec.tac if rec.tac is not None else zeros)[i], pac[i])
            for i in range(n)]


def time_base(device_time: np.ndarray, host_time: np.ndarray | None, window_s: float = 1.0):
    """Map device time (s) to seconds since the first frame.

    With host receipt times: the clock model of :mod:`protocols.clockmodel` (lower envelope
    of ``host − device`` per ``window_s`` window), origin at the first frame's fitted time.
    Without: ``device − device[0]``. Returns ``(to_run_time, t0, model)`` where
    ``to_run_time(d)`` maps (N,) device s to run s, ``t0`` is the origin on the host clock
    (device clock without host times) and ``model`` is the JSON-ready clock-model summary
    (``None`` without host times).
    """
    d = np.asarray(device_time, float)
    if host_time is None:
        t0 = float(d[0])
        return (lambda x: np.asarray(x, float) - t0), t0, None
    h = np.asarray(host_time, float)
    _, dm, hm = window_minima(d, h, window_s, float(d[0]))
    fit = fit_envelope(dm, hm)
    t0 = float(fit(d[0]))
    model = {"offset_s": fit.offset_s, "drift_ppm": fit.drift * 1e6, "windows": fit.n_windows,
             "windows_used": fit.n_used, "min_latency_s": 0.0, "residual_latency": latency_stats(fit, d, h)}
    return (lambda x: fit(x) - t0), t0, model


def store_columns(rec: Recording) -> tuple[dict, dict, dict]:
    """The ``biotac`` and ``biotac_pac`` block columns of ``rec`` (times in s since run start)
    and a stream summary (samples, gaps, missing, invalid, clock model, t0)."""
    frames = frames_of(rec)
    to_run, t0, model = time_base(rec.device_time, rec.host_time)
    bio = biotac_columns(frames)
    bio["time"] = to_run(bio["device_time"])
    bio["host_time"] = bio["host_time"] - (t0 if rec.host_time is not None else 0.0)
    pac = pac_columns(frames)
    pac["time_pac"] = to_run(pac["device_time"]) if len(pac["device_time"]) else np.zeros(0)
    pac["host_time"] = pac["host_time"] - (t0 if rec.host_time is not None else 0.0)
    gaps = sequence_gaps(rec.seq)
    summary = {"samples": rec.n_frames, "gaps": sum(m > 0 for _, _, m in gaps),
               "missing": int(sum(m for _, _, m in gaps if m > 0)), "invalid": int((~bio["valid"]).sum()),
               "faults": 0, "clock_model": model, "t0": t0,
               "t0_clock": "host (bag record time)" if rec.host_time is not None else "device (file time)"}
    return bio, pac, summary


def event_columns(rec: Recording, time: np.ndarray, detail: dict) -> dict:
    """``events`` block: ``info``/``import`` at 0 s, then one ``gap`` per sequence jump
    (``detail``: after_seq, next_seq, missing, gap_s), as the recorder writes them."""
    rows = [(0.0, "info", "import", detail)]
    for i, before, missing in sequence_gaps(rec.seq):
        rows.append((float(time[i]), "gap", "biotac",
                     {"after_seq": before, "next_seq": int(rec.seq[i]), "missing": missing,
                      "gap_s": float(time[i] - time[i - 1]) if i else None}))
    return {"time": np.array([r[0] for r in rows], float),
            "kind": np.array([r[1] for r in rows], dtype=object),
            "name": np.array([r[2] for r in rows], dtype=object),
            "detail": np.array([json.dumps(jsonable(r[3])) for r in rows], dtype=object)}


def write_store(rec: Recording, store_path: Path, provenance: dict, import_attrs: dict,
                baseline: Baseline | None = None) -> dict:
    """Create the run store ``store_path`` (must not exist) holding ``rec``; status ``success``.

    Args:
        rec: the recording, unconnected fingers already dropped.
        provenance: :func:`protocols.provenance.collect` output (plus ``source``, ``importer``).
        import_attrs: the root attribute ``import`` (source, checksum, finger decision...).
        baseline: an unloaded baseline from elsewhere, or ``None``.
    Returns the stream summary (see :func:`store_columns`).
    """
    bio, pac, summary = store_columns(rec)
    baseline_attrs = baseline.to_attrs(rec.fingers) if baseline else {
        "method": "none", "source": "none stored: the analysis takes its rest stretch from the record"}
    attrs = {"labels": [], "import": import_attrs, "baseline": baseline_attrs,
             "calibration": baseline.calibration_attrs(rec.fingers) if baseline else {},
             "streams_recorded": ["biotac"], "t0_clock_s": summary["t0"],
             "recording_start_time": _iso(summary["t0"]) if rec.host_time is not None else None}
    store = RunStore.create(store_path, protocol=PROTOCOL, fingers=rec.fingers, provenance=provenance, attrs=attrs)
    try:
        store.append_many({"biotac": bio, "biotac_pac": pac,
                           "events": event_columns(rec, bio["time"], {"source": import_attrs.get("source"),
                                                                      "fingers": import_attrs.get("fingers")})})
        stream = {k: v for k, v in summary.items() if k != "t0"}
        store.set_group_attrs("biotac", stream=stream, source_channels=list(rec.channels))
        store.close("success", streams={"biotac": stream})
    finally:
        if not store.closed:
            store.close("failed")
    absent = [c for c in OPTIONAL if getattr(rec, c) is None]
    _finish_biotac_group(store_path, absent, baseline.counts(rec.fingers) if baseline else None, baseline_attrs)
    return summary


def _finish_biotac_group(store_path: Path, absent: list[str], baseline: np.ndarray | None, attrs: dict) -> None:
    """Remove the channels the source does not hold and add ``biotac/baseline`` (F, 24) counts,
    then re-consolidate (the store is not yet visible to anyone: it is still in staging)."""
    if not absent and baseline is None:
        return
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        g = zarr.open_group(str(store_path), mode="r+", use_consolidated=False)["biotac"]
        for name in absent:
            del g[name]
        if baseline is not None:
            a = g.create_array("baseline", shape=baseline.shape, chunks=baseline.shape, dtype="f8",
                               dimension_names=["finger", "taxel"],
                               attributes={"units": "count",
                                           "long_name": "unloaded electrode baseline from outside the record "
                                                        f"({attrs['method']}: {attrs['source']})",
                                           "method": attrs["method"]})
            a[...] = baseline
        zarr.consolidate_metadata(str(store_path))


def _iso(epoch_s: float) -> str | None:
    from datetime import datetime, timezone
    try:
        return datetime.fromtimestamp(epoch_s, timezone.utc).isoformat(timespec="microseconds").replace("+00:00", "Z")
    except (OverflowError, OSError, ValueError):
        return None


# ----------------------------------------------------------------------------- staging
def staging_dir(target: Path) -> Path:
    """A fresh hidden directory beside ``target`` (same filesystem, so the rename is atomic)."""
    target.parent.mkdir(parents=True, exist_ok=True)
    path = Path(tempfile.mkdtemp(prefix=f".{target.name}.importing-", dir=target.parent))
    umask = os.umask(0)
    os.umask(umask)
    path.chmod(0o777 & ~umask)                  # mkdtemp makes it 0700; the run directory is not private
    return path


def write_run(rec: Recording, staging: Path, provenance: dict, import_attrs: dict,
              baseline: Baseline | None = None) -> dict:
    """``staging/run.zarr`` and ``staging/run.json`` (provenance + status ``success``)."""
    summary = write_store(rec, staging / "run.zarr", provenance, import_attrs, baseline)
    write_run_json(staging / "run.json", provenance, "success",
                   extra={"import": import_attrs, "baseline": (baseline.to_attrs(rec.fingers) if baseline
                                                               else {"method": "none"})})
    return summary


def publish(pairs: list[tuple[Path, Path]]) -> None:
    """Rename each staging directory to its target. A target that appeared meanwhile is an
    error before any rename; on a failed rename the ones already made are rolled back."""
    for _, target in pairs:
        if target.exists():
            raise FileExistsError(f"{target} already exists")
    done = []
    try:
        for staging, target in pairs:
            os.rename(staging, target)
            done.append((staging, target))
    except BaseException:
        for staging, target in reversed(done):
            os.rename(target, staging)
        raise


def discard(paths) -> None:
    """Remove staging directories (best effort)."""
    for p in paths:
        shutil.rmtree(p, ignore_errors=True)

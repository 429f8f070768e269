"""Write a file's :class:`~.recording.Recording` chunks as a run store (``run.zarr.zip`` + ``run.json``), atomically.

The store has the layout of a recorded run (``docs/run_store.md``), written through
:class:`runstore.RunStore` with the recorder's column layout, so ``tactile-analyze``
reads it like any run:

- ``biotac``: ``time`` (s since the first frame, from the clock model of ``device_time``
  against ``host_time`` when the file has both, else ``device_time − device_time[0]``),
  ``device_time``, ``host_time`` (NaN when the file has none), ``seq``, ``valid``,
  ``electrodes``; ``pdc``/``tdc``/``tac`` only when the file holds them (an electrode-only
  record has no ``pdc`` variable, so the analysis uses its electrode proxy);
  ``baseline`` (finger, taxel) counts when a baseline from elsewhere was given;
- ``biotac_pac``: the PAC samples, only when the file holds them (bags); no ``arm``, ``hand``,
  ``pour`` or ``stage`` group (a file of tactile frames never had those devices, and every
  empty group or array would be files on disk: ``docs/run_store.md``, "Files per run");
- ``events``: an ``info`` event ``import`` at 0 s, and a ``gap`` event per sequence jump;
- root attributes: ``protocol="import"``, ``labels=[]``, ``status="success"``, ``import``
  (source, checksum, importer, finger decision), ``baseline``, ``calibration``, ``streams``.

Streaming (:func:`write_import_store`): the file is read again chunk by chunk (the second pass; the
first, :func:`.importer.scan`, fitted the clock model and chose the fingers) and each chunk is
appended as it comes, so memory is one chunk whatever the file's length. What needs every
frame is computed without holding them: the frame rate (the exact median interval,
:func:`.recording.median_of`, read back from the stored ``device_time`` four chunks at a time), the
residual latency of the clock model (over every ⌊N / 100 000⌋-th frame, as the recorder
does: every frame below 200 000 frames).

Nothing half-written: everything goes to a hidden temporary directory beside the target,
renamed into place by :func:`publish` once every store of the import is complete. The store
is published packed, one zip file (``run.zarr.zip``: :mod:`runstore.packed`): an import is
never appended to, and one file per run is what a shared file system wants
(``docs/run_store.md``, "Files per run"). A file of at most one chunk has its store made in
memory and the zip written once (:class:`runstore.inmemory.MemoryRunStore`, ~0.1 CPU s less
per short record than a directory of ~30 files made through zarr and then packed); a longer
one is streamed into a directory store there and then packed — the same members either way.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import warnings
from pathlib import Path

import numpy as np
import zarr

from tactile_flow.hardware.biotac import COUNTS_MAX, PAC_RATE_HZ, BiotacFrame
from tactile_flow.hardware.device import batch_times
from tactile_flow.hardware.streams import as_dtype
from tactile_flow.runstore import RunStatus, RunStore, inflight, packed, rundir
from tactile_flow.runstore.inmemory import MemoryRunStore
from tactile_flow.runstore.clockmodel import ClockFit, latency_stats, sequence_gaps
from tactile_flow.runstore.provenance import write_run_json
from tactile_flow.runstore.layout import event_columns

from .baseline import Baseline
from .recording import ImportInputError, PreparedSource, Recording, diffs, median_of, rate_of

PROTOCOL = "import"
#: the store as written (a directory, in staging only) and as published (packed: one file)
STORE = "run.zarr"
PACKED = packed.packed_name(STORE)
OPTIONAL = ("pdc", "tdc", "tac")
#: frames of the residual-latency sample: every max(1, N // LATENCY_SAMPLE)-th frame
LATENCY_SAMPLE = 100_000
#: rows of a stored time array read at once when computing the median interval, in chunks
READ_CHUNKS = 4


def time_base(clock: ClockFit | None, t0: float):
    """``to_run_time(d)``: device time (s, any shape) to seconds since the first frame — the
    clock model ``clock`` minus ``t0`` (its value at the first frame), or ``d − t0`` without
    host times (``clock`` ``None``, ``t0`` the first device time)."""
    if clock is None:
        return lambda x: np.asarray(x, float) - t0
    return lambda x: clock(x) - t0


def _i16(a) -> np.ndarray:
    """Counts as int16, values beyond int16 clipped (as the recorder stores them; only frames
    flagged ``valid = False`` have any)."""
    return as_dtype(a, np.int16)


def _in_range(a: np.ndarray, axes) -> np.ndarray:
    return np.all((a >= 0) & (a <= COUNTS_MAX), axis=axes)


def biotac_block(rec: Recording, to_run, host_t0: float, sensor=None) -> dict:
    """``biotac`` columns of a chunk (N frames, F fingers): ``time`` (s since run start),
    ``device_time`` (s), ``host_time`` (s since run start; NaN without host times), ``seq``,
    ``valid`` (every channel, PAC included, in 0..4095, as ``BiotacFrame.is_valid``), int16
    ``electrodes`` (N, F, E) and ``pdc``, ``tdc``, ``tac`` (N, F; zeros when absent) under the
    names the sensor model (``sensor``, default the BioTac SP) gives them, those it has."""
    n, F = rec.n_frames, len(rec.fingers)
    zeros = np.zeros((n, F), np.int64)
    chan = {c: getattr(rec, c) if getattr(rec, c) is not None else zeros for c in OPTIONAL}
    valid = _in_range(rec.electrodes, (1, 2))
    for c in OPTIONAL:
        valid &= _in_range(chan[c], 1)
    if rec.pac is not None:
        valid &= np.array([bool(np.all((p >= 0) & (p <= COUNTS_MAX))) for p in rec.pac], bool)
    device = np.asarray(rec.device_time, float)
    host = np.full(n, np.nan) if rec.host_time is None else np.asarray(rec.host_time, float)
    names = stored_names(sensor)
    return {"time": to_run(device), "device_time": device, "host_time": host - host_t0,
            "seq": np.asarray(rec.seq, np.int64), "valid": valid, "electrodes": _i16(rec.electrodes),
            **{names[c]: _i16(chan[c]) for c in OPTIONAL if c in names}}


def stored_names(sensor=None) -> dict:
    """``{pdc|tdc|tac|pac: stored name}`` of the channels the sensor model has (default the BioTac SP's)."""
    if sensor is None:
        from tactile_flow.tactile.sensor import builtin_sensor
        sensor = builtin_sensor()
    roles = {"pdc": "pressure", "tdc": "temperature", "tac": "temperature_change", "pac": "vibration"}
    return {c: ch.name for c, role in roles.items() if (ch := sensor.channel(role)) is not None}


def pac_block(rec: Recording, to_run, host_t0: float, rate_hz: float = PAC_RATE_HZ,
              previous: float | None = None, name: str = "pac") -> dict:
    """``biotac_pac`` columns of a chunk with PAC: (M, F) int16 ``pac`` and (M,) ``time_pac``,
    ``device_time``, ``host_time`` (s). A frame's n samples end at its timestamp, 1/rate apart
    (closer when the frame follows the one before sooner than that), strictly increasing, as
    :func:`hardware.biotac.pac_columns`; ``previous``: the last PAC device time before the chunk."""
    counts = np.array([p.shape[1] for p in rec.pac], np.int64)                  # (N,)
    pac = np.concatenate([p.T for p in rec.pac]) if len(rec.pac) else np.zeros((0, len(rec.fingers)))
    device = batch_times(rec.device_time, counts, 1.0 / rate_hz, previous)
    host = (np.repeat(np.asarray(rec.host_time, float), counts) if rec.host_time is not None
            else np.full(len(device), np.nan))
    return {"time_pac": to_run(device) if len(device) else np.zeros(0), "device_time": device,
            "host_time": host - host_t0, name: _i16(pac)}


def gap_events(seq: np.ndarray, time: np.ndarray, last_seq: int | None, last_time: float | None) -> list[tuple]:
    """One ``gap`` event per sequence jump in a chunk (``seq``, ``time`` (N,) s since run
    start), following frame ``last_seq`` at ``last_time`` (``None`` for the first chunk)."""
    rows = []
    for i, before, missing in sequence_gaps(seq, last_seq):
        prev = time[i - 1] if i else last_time
        rows.append((float(time[i]), "gap", "biotac",
                     {"after_seq": before, "next_seq": int(seq[i]), "missing": missing,
                      "gap_s": float(time[i] - prev) if prev is not None else None}))
    return rows


def stored_rate(store_path: Path, n: int, rows: int) -> float:
    """Frame rate (Hz) from the median interval of the ``n`` stored ``biotac/device_time``
    values, exact, reading them back ``rows`` at a time; NaN for fewer than 2."""
    if n < 2:
        return float("nan")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        arr = zarr.open_group(str(store_path), mode="r", use_consolidated=False)["biotac"]["device_time"]

    def intervals():
        return diffs(arr[i:min(n, i + rows)] for i in range(0, n, rows))
    return rate_of(median_of(intervals, n - 1))


def write_import_store(prepared: PreparedSource, store_path: Path, provenance: dict, import_attrs: dict,
                baseline: Baseline | None = None) -> dict:
    """Create the run store ``store_path`` (must not exist) holding the file; status ``success``.
    A directory store is written as the file is read, chunk by chunk; a path ending in ``.zip``
    is the store made in memory (:class:`runstore.inmemory.MemoryRunStore`, the same members)
    and written packed in one go, for a file that fits in one chunk (:func:`write_run`).

    Args:
        prepared: the file after the first pass (reader, scan, fingers kept).
        provenance: :func:`runstore.provenance.collect` output (plus ``source``, ``importer``).
        import_attrs: the root attribute ``import`` (source, checksum, finger decision...);
            its ``rate_hz`` is set here, from the stored times.
        baseline: an unloaded baseline from elsewhere, or ``None``.
    Returns the stream summary (samples, gaps, missing, invalid, faults, clock model,
    t0_clock) plus ``t0`` and ``rate_hz``. Raises :class:`ImportInputError` when the rate
    disagrees with a given one or the file changed since the first pass.
    """
    scan, fingers = prepared.scan, prepared.fingers
    has_host = scan.clock is not None
    to_run = time_base(scan.clock, scan.t0)
    host_t0 = scan.t0 if has_host else 0.0
    baseline_attrs = baseline.to_attrs(fingers) if baseline else {
        "method": "none", "source": "none stored: the analysis takes its rest stretch from the record"}
    attrs = {"labels": [], "import": import_attrs, "baseline": baseline_attrs,
             "calibration": baseline.calibration_attrs(fingers) if baseline else {},
             "streams_recorded": ["biotac"], "t0_clock_s": scan.t0,
             "recording_start_time": _iso(scan.t0) if has_host else None}
    in_memory = store_path.name.endswith(packed.SUFFIX)
    create = dict(protocol=PROTOCOL, fingers=fingers, provenance=provenance, attrs=attrs, sensor=prepared.sensor,
                  streams=source_streams(fingers, prepared.sensor, scan.channels))
    store = MemoryRunStore(**create) if in_memory else RunStore.create(store_path, **create)
    try:
        counters = _append_chunks(store, prepared, to_run, host_t0,
                                  {"source": import_attrs.get("source"), "fingers": import_attrs.get("fingers")})
        if counters["samples"] != scan.frames:
            raise ImportInputError(f"{prepared.reader.path}: changed while being imported ({scan.frames} frames "
                                   f"on the first read, {counters['samples']} on the second)")
        rate = (rate_of(median_of(lambda: diffs([store.read("biotac", "device_time")]), scan.frames - 1))
                if in_memory else stored_rate(store_path, scan.frames, READ_CHUNKS * prepared.chunk_frames))
        prepared.reader.finish(rate)
        import_attrs["rate_hz"] = rate
        model = None
        if has_host:
            d, h = counters.pop("latency_sample")
            model = {"offset_s": scan.clock.offset_s, "drift_ppm": scan.clock.drift * 1e6,
                     "windows": scan.clock.n_windows, "windows_used": scan.clock.n_used, "min_latency_s": 0.0,
                     "residual_latency": latency_stats(scan.clock, d, h)}
        counters.pop("latency_sample", None)
        stream = {**counters, "faults": 0, "clock_model": model,
                  "t0_clock": "host (bag record time)" if has_host else "device (file time)"}
        store.set_attrs(**{"import": import_attrs})
        store.set_group_attrs("biotac", stream=stream, source_channels=list(scan.channels))
        store.close(RunStatus.SUCCESS, streams={"biotac": stream})
    finally:
        if not store.closed:
            store.close(RunStatus.FAILED)
    names = stored_names(prepared.sensor)
    absent = [names[c] for c in OPTIONAL if c in names and c not in scan.channels]
    counts = baseline.counts(fingers) if baseline else None
    if in_memory:
        for name in absent:
            store.remove_variable("biotac", name)
        if counts is not None:
            store.write_variable("biotac", "baseline", np.asarray(counts, np.float64), ("finger", "taxel"),
                                 **_baseline_attrs(baseline_attrs))
        store.write(store_path)
    else:
        _finish_biotac_group(store_path, absent, counts, baseline_attrs)
    return {**stream, "t0": scan.t0, "rate_hz": rate}


def source_streams(fingers, sensor, channels) -> dict:
    """The streams an imported file fills: ``biotac``, and ``biotac_pac`` when ``channels`` (the
    file's optional channels) hold ``pac`` and the sensor model has a vibration channel."""
    streams = {s.name: s for s in BiotacFrame.describe(tuple(fingers), sensor)}
    if "pac" not in channels:
        streams.pop("biotac_pac", None)
    return streams


def _append_chunks(store: RunStore, prepared: PreparedSource, to_run, host_t0: float, import_detail: dict) -> dict:
    """Append every chunk (the second pass) with its gap events after the ``import`` event;
    returns the counters (samples, gaps, missing, invalid) and the residual-latency sample
    (device s, host s) of every ``max(1, N // LATENCY_SAMPLE)``-th frame."""
    step = max(1, prepared.scan.frames // LATENCY_SAMPLE)
    samples = gaps = missing = invalid = 0
    last_seq = last_time = last_pac = None
    sample_d, sample_h = [], []
    store.append("events", event_columns([(0.0, "info", "import", import_detail)]))
    sensor = prepared.sensor
    vib = sensor.vibration if sensor is not None else None
    for chunk in prepared.chunks():
        bio = biotac_block(chunk, to_run, host_t0, sensor)
        blocks = {"biotac": bio}
        if chunk.pac is not None and "biotac_pac" in store.schema:
            blocks["biotac_pac"] = pac_block(chunk, to_run, host_t0, vib.rate_hz if vib else PAC_RATE_HZ,
                                             previous=last_pac, name=vib.name if vib else "pac")
            if len(blocks["biotac_pac"]["device_time"]):
                last_pac = float(blocks["biotac_pac"]["device_time"][-1])
        events = gap_events(bio["seq"], bio["time"], last_seq, last_time)
        if events:
            blocks["events"] = event_columns(events)
        store.append_many(blocks)
        gaps += sum(e[3]["missing"] > 0 for e in events)
        missing += sum(e[3]["missing"] for e in events if e[3]["missing"] > 0)
        invalid += int((~bio["valid"]).sum())
        if chunk.host_time is not None:
            first = (-samples) % step
            sample_d.append(bio["device_time"][first::step])
            sample_h.append(np.asarray(chunk.host_time, float)[first::step])
        samples += chunk.n_frames
        last_seq, last_time = int(bio["seq"][-1]), float(bio["time"][-1])
    latency = (np.concatenate(sample_d), np.concatenate(sample_h)) if sample_d else None
    return {"samples": samples, "gaps": gaps, "missing": missing, "invalid": invalid, "latency_sample": latency}


def _finish_biotac_group(store_path: Path, absent: list[str], baseline: np.ndarray | None, attrs: dict) -> None:
    """Remove the channels the source does not hold and add ``biotac/baseline`` (F, E) counts,
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
                               dimension_names=["finger", "taxel"], attributes=_baseline_attrs(attrs))
            a[...] = baseline
        zarr.consolidate_metadata(str(store_path))


def _baseline_attrs(attrs: dict) -> dict:
    """The attributes of ``biotac/baseline`` from the root attribute ``baseline`` (``attrs``)."""
    return {"units": "count", "long_name": "unloaded electrode baseline from outside the record "
                                           f"({attrs['method']}: {attrs['source']})", "method": attrs["method"]}


def _iso(epoch_s: float) -> str | None:
    from datetime import datetime, timezone
    try:
        return datetime.fromtimestamp(epoch_s, timezone.utc).isoformat(timespec="microseconds").replace("+00:00", "Z")
    except (OverflowError, OSError, ValueError):
        return None


# ----------------------------------------------------------------------------- staging
STAGING_MARK = ".importing-"


def staging_dir(target: Path) -> Path:
    """A fresh hidden directory beside ``target`` (same filesystem, so the rename is atomic),
    locked by this process (:mod:`runstore.rundir`) until :func:`release_staging`, so that
    :func:`remove_stale_staging` can tell a live import's staging from a killed one's."""
    target.parent.mkdir(parents=True, exist_ok=True)
    path = Path(tempfile.mkdtemp(prefix=f".{target.name}{STAGING_MARK}", dir=target.parent))
    rundir.acquire(path)
    umask = os.umask(0)
    os.umask(umask)
    path.chmod(0o777 & ~umask)                  # mkdtemp makes it 0700; the run directory is not private
    return path


def release_staging(path: Path) -> None:
    """Give back the lock of a staging directory (published, discarded or not)."""
    rundir.release(path)


def remove_stale_staging(folders) -> list[Path]:
    """Remove the staging directories a killed import left in ``folders`` (no live process
    holds their lock); returns them."""
    stale = [p for folder in folders if Path(folder).is_dir() for p in sorted(Path(folder).glob(f".*{STAGING_MARK}*"))
             if p.is_dir() and rundir.holder(p) is None]
    discard(stale)
    return stale


def write_run(prepared: PreparedSource, staging: Path, provenance: dict, import_attrs: dict,
              baseline: Baseline | None = None) -> dict:
    """``staging/run.zarr.zip`` and ``staging/run.json`` (provenance + status ``success``,
    ``store`` naming the packed store). Returns :func:`write_import_store`'s summary.

    A file of at most one import chunk (``prepared.chunk_frames``: memory holds it anyway) has
    its store made in memory and written packed at once; a longer one is streamed into a
    directory store, then packed (:mod:`runstore.packed`) — the same members either way."""
    if prepared.scan.frames <= prepared.chunk_frames:
        summary = write_import_store(prepared, staging / PACKED, provenance, import_attrs, baseline)
    else:
        store = staging / STORE
        summary = write_import_store(prepared, store, provenance, import_attrs, baseline)
        packed.pack(store, staging / PACKED)
        shutil.rmtree(store)
    write_run_json(staging / "run.json", provenance, RunStatus.SUCCESS,
                   extra={"import": import_attrs, "store": PACKED,
                          "baseline": baseline.to_attrs(prepared.fingers) if baseline else {"method": "none"}})
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
    from tactile_flow.runstore.catalogue import register_quietly
    for _, target in pairs:                       # the run catalogue (tactile-runs list) knows them
        register_quietly(target)


def discard(paths) -> None:
    """Remove staging directories (best effort), once zarr has stopped writing into them."""
    inflight.settle()
    for p in paths:
        shutil.rmtree(p, ignore_errors=True)

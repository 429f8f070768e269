"""Import a source (a bag, a CSV, or a directory of them) into run stores: :func:`import_source`.

Every file is read twice, chunk by chunk, so memory does not grow with its length: a first
pass (:func:`scan`) checks every frame and collects what the import must decide before
writing (connected fingers, the early window of a baseline estimate, the clock model); the
second pass (:func:`.writer.write_import_store`) writes the frames as they come.

Order of work, so that bad input never leaves anything behind: check the options, discover
the files (a directory's subfolders included), check no target exists, remove what a
killed import left, scan every file, choose the fingers and the baseline (one pool for the
whole import), then write each run into a hidden staging directory beside its target (the
rate check, which needs the exact median interval, is made on the stored times) and rename
them all into place at the end. A bad file of a directory is left out, and named once the
others are in place (:class:`ImportIncomplete`); any other error before the renames removes
every staging directory.
"""

from __future__ import annotations

import functools
import importlib.metadata
import json
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np

from tactile_flow.runstore import packed
from tactile_flow.runstore.clockmodel import OnlineClockModel
from tactile_flow.runstore.provenance import collect
from tactile_flow.tactile.sensor import SensorModelError, sensor_for_taxels
from tactile_flow.tactile.signals import SensorCalibration

from .bag import TOPIC, BagFile
from .baseline import Baseline, EarlyWindow, estimate_baseline, load_calibration
from .csv import GAP_FACTOR, RELATIVE_REST_COUNTS, TIME_UNITS, CsvFile
from .recording import (CHUNK_FRAMES, Connectivity, ImportInputError, PreparedSource, Reader, Recording, Scan,
                        decide_fingers, keep_fingers, parse_rate)
from .sources import Source, checksum, discover, sha256_file
from .writer import PACKED, discard, publish, release_staging, remove_stale_staging, staging_dir, write_run

BASELINES = ("auto", "none", "file", "estimate")


@dataclass(frozen=True)
class ImportSettings:
    """Options of one import (the ``tactile-import`` config, ``conf/import.yaml``).

    Attributes:
        rate_hz: CSV sample rate (Hz); required without a ``time`` column, checked against it otherwise.
        calibration: a calibration JSON file (see :mod:`.baseline`) or ``None``.
        baseline: ``auto`` (the calibration file if given, else none), ``none``, ``file``, ``estimate``.
        fingers: fingers to keep (default: every connected one); for an unprefixed CSV, its one finger.
        topic: the bags' BioTac topic.
        estimate_early_s, estimate_percentile: see :func:`.baseline.estimate_baseline`.
        chunk_frames: frames read and written at a time (the memory bound; also the most
            frames of one file's early window).
        sensor: the :class:`tactile.sensor.SensorModel` of the recording (``None``: chosen by
            each file's electrode count, :func:`tactile.sensor.sensor_for_taxels`).
        columns: CSV column renames ``{name in the file: canonical name}`` (:mod:`.csv`).
        time_unit: a CSV time column's unit: ``auto`` (its name, else guessed from its steps),
            ``s``, ``ms``, ``us``, ``ns``.
        relative: CSV electrode values relative to rest: ``auto`` (detected), True, False;
            ``relative_rest_counts``: the rest they are added to without a calibration.
    """

    rate_hz: float | None = None
    calibration: str | None = None
    baseline: str = "auto"
    fingers: tuple[str, ...] | None = None
    topic: str = TOPIC
    estimate_early_s: float = 1.0
    estimate_percentile: float = 95.0
    chunk_frames: int = CHUNK_FRAMES
    sensor: object = None
    columns: dict | None = None
    time_unit: str = "auto"
    relative: object = "auto"
    relative_rest_counts: float = RELATIVE_REST_COUNTS


@dataclass
class ImportResult:
    """One run store written: where, from what, and what was decided.

    ``warnings``: what the researcher must know about the data (a truncated bag), one
    sentence each; also in the store's ``import.reader`` attribute."""

    source: str
    sha256: str
    run_dir: str
    store: str
    fingers: list[str]
    dropped: dict
    frames: int
    rate_hz: float
    baseline: str
    warnings: list[str] = field(default_factory=list)
    subfolder: str = ""
    sensor: str = ""
    notes: list[str] = field(default_factory=list)


def open_source(src: Source, settings: ImportSettings) -> Reader:
    """The chunk reader of one source (:class:`.bag.BagFile` or :class:`.csv.CsvFile`)."""
    if src.kind == "bag":
        return BagFile(src.path, settings.topic, settings.rate_hz, settings.sensor)
    # an unprefixed (one-sensor) file is the finger named by fingers=[x], else ff
    finger = settings.fingers[0] if settings.fingers and len(settings.fingers) == 1 else "ff"
    return CsvFile(src.path, settings.rate_hz, finger, sensor=settings.sensor, columns=settings.columns,
                   time_unit=settings.time_unit, relative=settings.relative, rest_counts=settings.relative_rest_counts)


def scan(reader: Reader, early_s: float = 1.0, frames: int = CHUNK_FRAMES) -> Scan:
    """The first pass over a file: read (and so check) every frame, chunk by chunk, keeping
    only the frame count, the unconnected-finger test (:class:`.recording.Connectivity`),
    the early window (:class:`.baseline.EarlyWindow`, ``early_s`` s) and the clock model of
    device against host time (:class:`runstore.clockmodel.OnlineClockModel`, one point per
    1 s window). Memory: one chunk of ``frames`` frames (plus the early window, at most as
    much), and one clock-model point (~0.2 kB) per second recorded."""
    conn, early, clock = None, EarlyWindow(early_s, frames), OnlineClockModel(window_s=1.0)
    n, first, channels = 0, None, ()
    for chunk in reader.chunks(frames):
        if conn is None:
            conn, first, channels = Connectivity(chunk.fingers), float(chunk.device_time[0]), chunk.channels
        conn.update(chunk)
        early.add(chunk)
        if chunk.host_time is not None:
            clock.update(chunk.device_time, chunk.host_time)
        n += chunk.n_frames
    fit = clock.final()
    return Scan(frames=n, fingers=tuple(conn.fingers), channels=channels, unconnected=conn.unconnected(),
                head=early.recording(), clock=fit, t0=float(fit(first)) if fit is not None else first)


def check_settings(settings: ImportSettings) -> None:
    """Refuse bad options before any file is read (:class:`ImportInputError`, one sentence)."""
    frames = settings.chunk_frames
    if isinstance(frames, bool) or not isinstance(frames, int) or frames < 1:
        raise ImportInputError(f"chunk_frames={frames!r}: expected a positive whole number of frames")
    if settings.baseline not in BASELINES:
        raise ImportInputError(f"baseline={settings.baseline!r}: expected one of {', '.join(BASELINES)}")
    if settings.time_unit not in ("auto", *TIME_UNITS):
        raise ImportInputError(f"time_unit={settings.time_unit!r}: expected auto, {', '.join(TIME_UNITS)}")
    if settings.relative not in ("auto", True, False):
        raise ImportInputError(f"relative={settings.relative!r}: expected auto, true or false")
    rest = settings.relative_rest_counts
    if isinstance(rest, bool) or not isinstance(rest, (int, float)) or not 1 <= rest <= 4094:
        raise ImportInputError(f"relative_rest_counts={rest!r}: expected a count within 1..4094")
    if settings.columns is not None and not isinstance(settings.columns, dict):
        raise ImportInputError(f"columns={settings.columns!r}: expected a mapping {{name in the file: canonical "
                               f"name}}")
    parse_rate(settings.rate_hz)


def prepare(src: Source, settings: ImportSettings) -> PreparedSource:
    """Open and scan one source (the first pass) and decide its fingers (see
    :func:`.recording.decide_fingers`)."""
    reader = open_source(src, settings)
    where = str(reader.meta.get("path", src.path))
    if isinstance(reader, CsvFile) and settings.calibration and settings.relative is not False:
        try:                    # relative values are relative to the calibration's rest, when it covers the file
            cal = load_calibration(settings.calibration, reader.finger_names)
            reader.set_rest(cal.counts(reader.finger_names, where))
        except ImportInputError:
            if settings.relative is True:
                raise
    found = scan(reader, settings.estimate_early_s, settings.chunk_frames)
    decision = decide_fingers(found.fingers, found.unconnected, settings.fingers, where)
    kept = tuple(f for f in found.fingers if f in decision["kept"])
    sensor, how = file_sensor(reader, settings.sensor, where)
    _check_channels(found, sensor, where)
    prepared = PreparedSource(reader, found, kept, decision, settings.chunk_frames, sensor=sensor, sensor_how=how)
    return prepared


def file_sensor(reader: Reader, requested, where: str):
    """``(model, how)``: the sensor model of a file — ``requested`` (its electrode count was
    checked while reading), or the one built-in model with the file's electrode count
    (:func:`tactile.sensor.sensor_for_taxels`: one line listing the models and their counts
    when none has it)."""
    n = reader.n_taxels
    if requested is not None:
        return requested, f"sensor={requested.name}"
    try:
        model = sensor_for_taxels(n)
    except SensorModelError as exc:
        raise ImportInputError(f"{where}: {exc.message}; give sensor=FILE.yaml for another model") from None
    return model, f"inferred from {n} electrodes per sensor"


def _check_channels(found: Scan, sensor, where: str) -> None:
    """Refuse a file holding a channel its sensor model does not have (nowhere to store it)."""
    roles = {"pdc": "pressure", "tdc": "temperature", "tac": "temperature_change", "pac": "vibration"}
    for c in found.channels:
        if sensor.channel(roles[c]) is None:
            raise ImportInputError(f"{where}: the file has {c}, but the sensor model {sensor.name} has no "
                                   f"{roles[c].replace('_', ' ')} channel ({sensor.file or 'its file'}); "
                                   f"expected a file without it, or another sensor=")


def relative_baseline(p: PreparedSource) -> Baseline | None:
    """The baseline of a file whose electrode values are relative to rest: that rest (module
    :mod:`.csv`), which the values were added to; ``None`` for other files."""
    reader = p.reader
    if not getattr(reader, "relative", False):
        return None
    rest = np.broadcast_to(np.asarray(reader.rest, float), (len(reader.finger_names), p.sensor.n_taxels))
    cals = {f: SensorCalibration(np.clip(rest[k], 1, p.sensor.counts_max), f"relative-{f}",
                                 "the rest the file's relative values were added to")
            for k, f in enumerate(reader.finger_names)}
    nominal = np.asarray(reader.rest).ndim == 0
    how = (f"a nominal {float(reader.rest):g} counts per electrode (relative_rest_counts; give calibration= for "
           f"the sensors' own)" if nominal else "the calibration file's counts")
    return Baseline("relative", cals, f"the file's values are relative to rest: rest = {how}",
                    {"nominal": nominal, "rest_counts": float(reader.rest) if nominal else None})


def choose_baseline(settings: ImportSettings, recs: list[Recording], names: list[str]) -> Baseline | None:
    """The baseline of the whole import (or ``None``): see :class:`ImportSettings`. ``recs``:
    the files' early windows (or whole recordings), kept fingers only."""
    mode = settings.baseline
    if mode not in BASELINES:
        raise ImportInputError(f"baseline={mode!r}: expected one of {', '.join(BASELINES)}")
    if mode == "auto":
        mode = "file" if settings.calibration else "none"
    if mode == "file":
        if not settings.calibration:
            raise ImportInputError("baseline=file needs calibration=FILE")
        path = Path(settings.calibration)
        fingers = list(dict.fromkeys(f for r in recs for f in r.fingers))
        sha = sha256_file(path) if path.is_file() else None
        return load_calibration(path, fingers, sha256=sha)
    if settings.calibration:
        raise ImportInputError(f"calibration={settings.calibration} given with baseline={mode}; "
                               f"use baseline=file (or auto) to use it, or drop calibration")
    if mode == "estimate":
        return estimate_baseline(recs, settings.estimate_early_s, settings.estimate_percentile, names)
    return None


class ImportIncomplete(ImportInputError):
    """Some files of a directory could not be imported; the others were. ``results``: the
    imported files; ``failures``: ``[(path, one-sentence reason)]`` for every file that was not."""

    def __init__(self, results: list, failures: list[tuple[str, str]]):
        self.results, self.failures = results, failures
        super().__init__(f"{len(failures)} of {len(failures) + len(results)} files not imported: "
                         + "; ".join(reason for _, reason in failures))


def import_source(source, out, settings: ImportSettings | None = None, *, config_yaml: str | None = None,
                  overrides=(), console=None, workers: int | None = 1, progress: bool = False) -> list[ImportResult]:
    """Import ``source`` into one run directory per file under ``out``, in ``workers``
    processes (``None``: the cores available; :mod:`cliapp.workers`), the same stores with any.

    Each run directory ``out/<subfolder>/<file stem>/`` (the source's folder tree, mirrored)
    holds ``run.zarr.zip`` (the run store, packed: one file) and ``run.json`` (provenance, status ``success``); it
    appears (a rename) only once complete, so an import interrupted or killed at any point
    leaves complete runs and hidden staging, which the next import removes. A run directory
    already holding this file's import with the same options is skipped (a second import
    finishes an interrupted one). A bad file of a directory is left out and the others are
    imported: then :class:`ImportIncomplete` names every bad file (after the good ones are in
    place) — unreadable, two files that would share a run directory, a run directory holding
    something else, a sensor model other than the rest of the directory's. Raises
    :class:`ImportInputError` (one sentence; nothing written) when nothing can be imported,
    ``FileExistsError`` when the run directory of a single file holds something else; any
    other failure (a full disk) keeps the runs completed before it and removes the rest.
    ``progress``: one progress line (on a terminal) of files done, total and rate.
    """
    from tactile_flow.cliapp.workers import each_in_workers, resolve_workers
    from tactile_flow.runstore.catalogue import kept_open
    from tactile_flow.runstore.provenance import same_code
    settings = settings or ImportSettings()
    check_settings(settings)
    try:
        workers = resolve_workers(workers, "workers")
    except ValueError as exc:
        raise ImportInputError(str(exc)) from None
    out = Path(out)
    options = {f.name: getattr(settings, f.name) for f in fields(settings) if f.name != "sensor"}
    options["sensor"] = settings.sensor.name if settings.sensor is not None else None
    sources = discover(source)
    single = len(sources) == 1
    failures: list[tuple[str, str]] = duplicate_targets(sources, out)
    bad = {f for f, _ in failures}
    sources = [s for s in sources if str(s.path) not in bad]
    done, todo = [], []
    for src in sources:                                                 # before reading anything long
        target = src.target(out)
        if not target.exists() and not target.is_symlink():
            todo.append(src)
        elif already_imported(target, src, options):
            done.append(src)
        elif single:
            _check_targets(out, [target])
        else:
            failures.append((str(src.path), f"{src.path}: its run directory {target} already exists and holds "
                                            f"another import or something else; choose another out= or remove it"))
    remove_stale_staging({src.target(out).parent for src in sources})
    if console:
        for src in done:
            console(f"already imported {src.path} -> {packed.find(src.target(out))}: skipped")
    pooled = _baseline_mode(settings) == "estimate"                     # the done ones' rest counts too
    scanned = todo + (done if pooled else [])
    if not scanned:
        if failures:
            raise ImportIncomplete([], failures)
        return []
    from tactile_flow.cliapp.progress import progress_bar
    bar = progress_bar(total=len(scanned), unit="file", desc="import: reading", disable=not progress,
                       dynamic_ncols=True)
    say = (lambda line: bar.write(line)) if not bar.disable else console
    with same_code(), kept_open(), bar:
        prepared = {}
        for i, got in each_in_workers(_prepare_one, [(src, settings) for src in scanned], workers):
            src = scanned[i]
            bar.update(1)
            if isinstance(got, ImportInputError):
                if single:
                    raise got
                failures.append((str(src.path), str(got)))
            elif isinstance(got, BaseException):
                raise got
            else:
                prepared[src] = got
        failures += mixed_sensors(prepared, settings.sensor)
        prepared = {src: p for src, p in prepared.items() if str(src.path) not in {f for f, _ in failures}}
        if not any(src in prepared for src in todo):
            if failures and not done:
                raise ImportInputError(f"source={source}: no file could be imported: "
                                       + "; ".join(reason for _, reason in failures))
            if failures:
                raise ImportIncomplete([], failures)
            return []
        good = [src for src in scanned if src in prepared]
        heads = [keep_fingers(prepared[src].scan.head, prepared[src].fingers) for src in good]
        baseline = choose_baseline(settings, heads, [str(src.path) for src in good])
        own = {src: relative_baseline(prepared[src]) for src in good}          # relative values: their rest
        for src in good:
            b = own[src] or baseline
            if b is not None:
                counts = b.counts(prepared[src].fingers, where=str(src.path))  # every finger covered
                n = prepared[src].sensor.n_taxels
                if counts.shape[1] != n:
                    raise ImportInputError(f"{src.path}: the {b.method.replace('_', ' ')} baseline has "
                                           f"{counts.shape[1]} counts per finger; the sensor model "
                                           f"{prepared[src].sensor.name} has {n} electrodes")
        writing = [src for src in todo if src in prepared]
        config_yaml = config_yaml if config_yaml is not None else json.dumps(
            {"source": str(source), "out": str(out), **options}, indent=1)
        missing_dirs = sorted({d for src in writing for t in [src.target(out)] for d in (t.parent, *t.parent.parents)
                               if not d.exists()}, key=lambda d: -len(d.parts))   # made by staging; removed on error
        jobs, staged, results = [], [], []
        bar.reset(total=len(writing))
        bar.set_description("import: writing")
        try:
            for src in writing:
                p, b = prepared[src], own[src] or baseline
                staging = staging_dir(src.target(out))
                staged.append(staging)
                jobs.append((src, p, staging, b, config_yaml, overrides, len(writing), options))
            for i, got in each_in_workers(_write_one, jobs, workers):
                src, (_, p, staging, b, *_) = writing[i], jobs[i]
                bar.update(1)
                if isinstance(got, ImportInputError):  # found while writing (a rate that disagrees, a changed file)
                    if single:
                        raise got
                    discard([staging])
                    failures.append((str(src.path), str(got)))
                    continue
                if isinstance(got, BaseException):
                    raise got
                target = src.target(out)
                got, sha256 = got
                publish([(staging, target)])                    # complete: it appears as a run
                r = ImportResult(str(src.path), sha256, str(target), str(target / PACKED),
                                 list(p.fingers), p.decision["dropped"], p.scan.frames, got["rate_hz"],
                                 b.method if b else "none", reader_warnings(p.reader.meta), src.subfolder,
                                 f"{p.sensor.name} ({p.sensor_how})", reader_notes(p.reader.meta))
                results.append((i, r))
                if say:
                    say(result_line(r))
        except BaseException:
            discard(staged)                                     # the published ones are no longer there
            for d in missing_dirs:                  # deepest first; only if empty
                try:
                    d.rmdir()
                except OSError:
                    pass
            raise
        finally:
            for s in staged:
                release_staging(s)
    results = [r for _, r in sorted(results, key=lambda x: x[0])]          # the sources' order, as with one worker
    if failures:
        raise ImportIncomplete(results, failures)
    return results


def _prepare_one(job) -> PreparedSource:
    """:func:`prepare` of ``(source, settings)`` (a worker's job)."""
    return prepare(*job)


def _write_one(job) -> tuple[dict, str]:
    """:func:`run_metadata` then :func:`.writer.write_run` of ``(source, prepared, staging,
    baseline, config_yaml, overrides, files in the import, options)`` (a worker's job, so the
    metadata of every file, ~7 ms each, is not gathered in the parent before the workers
    start); its summary and the source's SHA-256."""
    src, p, staging, b, config_yaml, overrides, n_sources, options = job
    import_attrs, prov = run_metadata(src, p, b, config_yaml, overrides, n_sources)
    import_attrs["options"] = options
    return write_run(p, staging, prov, import_attrs, b), import_attrs["sha256"]


def result_line(r: ImportResult) -> str:
    """The output line of one imported file."""
    dropped = f", dropped {', '.join(f'{f} ({why})' for f, why in r.dropped.items())}" if r.dropped else ""
    return (f"imported {r.source} -> {r.store}: {r.frames} frames at {r.rate_hz:.4g} Hz, "
            f"fingers {', '.join(r.fingers)}{dropped}; sensor {r.sensor}; baseline: {r.baseline}"
            + "".join(f"; {n}" for n in r.notes) + "".join(f"; WARNING: {w}" for w in r.warnings))


def duplicate_targets(sources: list[Source], out: Path) -> list[tuple[str, str]]:
    """``[(path, reason)]`` for the sources that would share a run directory with another: the
    same path but for letter case (one directory on a case-insensitive file system, e.g. a
    laptop's), or one's run directory holding the other's (``take1.csv`` beside a folder
    ``take1/``)."""
    by_key: dict[str, list[Source]] = {}
    for src in sources:
        by_key.setdefault(str(src.target(out)).casefold(), []).append(src)
    out_list = []
    for group in by_key.values():
        if len(group) > 1:
            for src in group:
                others = ", ".join(str(o.path) for o in group if o is not src)
                out_list.append((str(src.path), f"{src.path}: duplicate name: {others} would have the same run "
                                                f"directory {src.target(out)} (names differing only in letter case); "
                                                f"rename one"))
    dirs = {str(src.target(out)).casefold() for src in sources}
    for src in sources:
        parents = [p for p in src.target(out).parents if str(p).casefold() in dirs]
        if parents:
            owner = next(o for o in sources if str(o.target(out)).casefold() == str(parents[0]).casefold())
            out_list.append((str(owner.path), f"{owner.path}: duplicate name: its run directory {parents[0]} "
                                              f"would hold the runs of the folder of the same name "
                                              f"({src.path}); rename it"))
    return list(dict.fromkeys(out_list))


def mixed_sensors(prepared: dict, requested) -> list[tuple[str, str]]:
    """``[(path, reason)]`` for the files of a directory whose sensor model, inferred from their
    electrode count (none given with ``sensor=``), is not the one most of its files have: a
    dataset is one sensor model's (its baseline, its analyses compare), a file of another is
    most likely misplaced. Ties go to the model of the first file."""
    if requested is not None or len(prepared) < 2:
        return []
    counts: dict[str, int] = {}
    for p in prepared.values():
        counts[p.sensor.name] = counts.get(p.sensor.name, 0) + 1
    if len(counts) < 2:
        return []
    main = max(counts, key=counts.get)
    ref = next(p.sensor for p in prepared.values() if p.sensor.name == main)
    return [(str(src.path), f"{src.path}: mixed sensors: {p.sensor.n_taxels} electrodes ({p.sensor.name}) in a "
                            f"directory of {ref.name} recordings ({ref.n_taxels} electrodes, {counts[main]} files); "
                            f"import it on its own, or give sensor= to import only that model's files")
            for src, p in prepared.items() if p.sensor.name != main]


def already_imported(target: Path, src: Source, options: dict) -> bool:
    """Whether ``target`` is a complete import (``run.json`` status ``success`` and a run
    store) of the file ``src`` (same SHA-256) with the same ``options``."""
    try:
        doc = json.loads((target / "run.json").read_text())
    except (OSError, ValueError):
        return False
    imp = doc.get("import") if isinstance(doc, dict) else None
    if not isinstance(imp, dict) or doc.get("status") != "success" or not packed.is_store(packed.find(target) or target):
        return False
    return imp.get("sha256") == checksum(src)["sha256"] and imp.get("options") == json.loads(json.dumps(options))


def _baseline_mode(settings: ImportSettings) -> str:
    mode = settings.baseline
    return ("file" if settings.calibration else "none") if mode == "auto" else mode


def _check_targets(out: Path, targets: list[Path]) -> None:
    existing = [str(t) for t in targets if t.exists()]
    if existing:
        raise FileExistsError(f"out={out}: {', '.join(existing)} already exist(s); choose another out= "
                              f"or remove {'it' if len(existing) == 1 else 'them'}")


def reader_warnings(meta: dict) -> list[str]:
    """Sentences for what a reader noted about a damaged file (``meta["truncated"]``) or its
    time column (``meta["time_gaps"]``)."""
    out = []
    t = meta.get("truncated")
    if t:
        out.append(f"truncated bag: the file ({t['file_bytes']} bytes) ends {t['ends']}; imported the "
                   f"{t['messages_read']} complete messages before that; lost: {t['messages_lost']}")
    g = meta.get("time_gaps")
    if g:
        out.append(f"time column: {g['count']} gap(s) longer than {GAP_FACTOR:g} x the median step, the "
                   f"largest {g['largest_s']:.4g} s at line {g['at_line']}")
    return out


def reader_notes(meta: dict) -> list[str]:
    """What a reader guessed about a file, to say on the output line: a time unit it guessed,
    values it found relative to rest."""
    out = []
    if str(meta.get("time_unit_source", "")).startswith("guessed"):
        out.append(f"time column in {meta['time_unit']} ({meta['time_unit_source']}; time_unit= to change)")
    if meta.get("relative_to_rest"):
        out.append(f"electrode values relative to rest ({meta.get('relative_detected') or 'relative=true'}; "
                   f"{meta['relative_to_rest']}; relative=false to change)")
    return out


def run_metadata(src: Source, prepared: PreparedSource, baseline: Baseline | None, config_yaml: str,
                 overrides, n_sources: int) -> tuple[dict, dict]:
    """The root attribute ``import`` and the provenance of one imported file.

    ``import``: source path, ``sha256``, bytes and files, ``importer``, what the reader found,
    the finger decision, frames, rate (Hz; ``None`` here, set by the writer from the stored
    times), channels. Provenance: :func:`runstore.provenance.collect` plus ``source`` (path,
    sha256, bytes, files, format) and ``importer``.
    """
    summ = checksum(src)
    importer = _importer(src)
    meta, fingers = prepared.reader.meta, prepared.fingers
    import_attrs = {"source": str(src.path.resolve()), "source_name": src.path.name, "subfolder": src.subfolder,
                    "sha256": summ["sha256"], "source_bytes": summ["bytes"], "source_files": summ["files"],
                    "importer": importer,
                    "reader": meta, "fingers": prepared.decision, "frames": prepared.scan.frames,
                    "rate_hz": None, "channels": list(prepared.scan.channels), "files_in_import": n_sources,
                    "sensor": {**prepared.sensor.summary(), "how": prepared.sensor_how}}
    identity = {"biotac": {"model": f"{prepared.sensor.name} (imported)", "serial_or_address": src.path.name,
                           "firmware": "unknown"}}
    prov = collect(config_yaml, list(overrides), identity,
                   baseline.calibration_attrs(fingers) if baseline else {}, None, protocol="import")
    prov["source"] = {"path": str(src.path.resolve()), "sha256": summ["sha256"], "bytes": summ["bytes"],
                      "files": summ["files"], "format": meta.get("format")}
    prov["importer"] = importer
    return import_attrs, prov


@functools.cache
def _version(name: str) -> str:
    """An installed package's version, asked once per process (~1.5 ms each time)."""
    try:
        return importlib.metadata.version(name)
    except importlib.metadata.PackageNotFoundError:
        return "unknown"


def _importer(src: Source) -> dict:
    """Which code read the file: module, function, package versions."""
    version = _version
    fn = "tactile_flow.importers.bag.read_bag" if src.kind == "bag" else "tactile_flow.importers.csv.read_csv"
    out = {"name": "tactile-import", "reader": fn, "tactile-flow": version("tactile-flow")}
    if src.kind == "bag":
        out["rosbags"] = version("rosbags")
    return out

"""Import a source (a bag, a CSV, or a directory of them) into run stores: :func:`import_source`.

Order of work, so that bad input never leaves anything behind: discover the files, read and
check every one (fingers, rate, columns), choose the baseline, check no target exists, then
write each run into a hidden staging directory beside its target and rename them all into
place at the end. Any error before the renames removes every staging directory.
"""

from __future__ import annotations

import importlib.metadata
import json
from dataclasses import asdict, dataclass
from pathlib import Path

from protocols.provenance import collect

from .bag import TOPIC, read_bag
from .baseline import Baseline, estimate_baseline, load_calibration
from .csv import read_csv
from .recording import ImportInputError, Recording, check_rate, select_fingers
from .sources import Source, checksum, discover, sha256_file
from .writer import discard, publish, staging_dir, write_run

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
    """

    rate_hz: float | None = None
    calibration: str | None = None
    baseline: str = "auto"
    fingers: tuple[str, ...] | None = None
    topic: str = TOPIC
    estimate_early_s: float = 1.0
    estimate_percentile: float = 95.0


@dataclass
class ImportResult:
    """One run store written: where, from what, and what was decided."""

    source: str
    sha256: str
    run_dir: str
    store: str
    fingers: list[str]
    dropped: dict
    frames: int
    rate_hz: float
    baseline: str


def read_source(src: Source, settings: ImportSettings) -> Recording:
    """Read one source with the reader of its kind."""
    if src.kind == "bag":
        rec = read_bag(src.path, settings.topic)
        check_rate(rec.nominal_rate_hz(), settings.rate_hz, f"{src.path}: header stamps of {settings.topic}")
        return rec
    # an unprefixed (one-sensor) file is the finger named by fingers=[x], else ff
    finger = settings.fingers[0] if settings.fingers and len(settings.fingers) == 1 else "ff"
    return read_csv(src.path, settings.rate_hz, finger)


def choose_baseline(settings: ImportSettings, recs: list[Recording], names: list[str]) -> Baseline | None:
    """The baseline of the whole import (or ``None``): see :class:`ImportSettings`."""
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


def import_source(source, out, settings: ImportSettings | None = None, *, config_yaml: str | None = None,
                  overrides=(), console=None) -> list[ImportResult]:
    """Import ``source`` into one run directory per file under ``out``.

    Each run directory ``out/<file stem>/`` holds ``run.zarr`` (the run store) and ``run.json``
    (provenance, status ``success``). Raises :class:`ImportInputError` (one sentence; nothing
    written) for bad input, ``FileExistsError`` when a run directory already exists.
    """
    settings = settings or ImportSettings()
    out = Path(out)
    sources = discover(source)
    recs, decisions = [], []
    for src in sources:
        rec, decision = select_fingers(read_source(src, settings), settings.fingers)
        recs.append(rec)
        decisions.append(decision)
    baseline = choose_baseline(settings, recs, [str(s.path) for s in sources])
    if baseline is not None:
        for src, rec in zip(sources, recs):
            baseline.counts(rec.fingers, where=str(src.path))           # every finger covered
    targets = [out / s.name for s in sources]
    existing = [str(t) for t in targets if t.exists()]
    if existing:
        raise FileExistsError(f"out={out}: {', '.join(existing)} already exist(s); choose another out= "
                              f"or remove {'it' if len(existing) == 1 else 'them'}")
    config_yaml = config_yaml if config_yaml is not None else json.dumps(
        {"source": str(source), "out": str(out), **asdict(settings)}, indent=1)
    missing_dirs = [d for d in (out, *out.parents) if not d.exists()]      # created by staging; removed on error
    staged, results = [], []
    try:
        for src, rec, decision, target in zip(sources, recs, decisions, targets):
            staging = staging_dir(target)
            staged.append(staging)
            import_attrs, prov = run_metadata(src, rec, decision, baseline, config_yaml, overrides, len(sources))
            write_run(rec, staging, prov, import_attrs, baseline)
            results.append(ImportResult(str(src.path), import_attrs["sha256"], str(target),
                                        str(target / "run.zarr"), list(rec.fingers), decision["dropped"],
                                        rec.n_frames, rec.nominal_rate_hz(), baseline.method if baseline else "none"))
        publish(list(zip(staged, targets)))
    except BaseException:
        discard(staged)
        for d in missing_dirs:                  # deepest first; only if still empty
            try:
                d.rmdir()
            except OSError:
                break
        raise
    if console:
        for r in results:
            dropped = f", dropped {', '.join(f'{f} ({why})' for f, why in r.dropped.items())}" if r.dropped else ""
            console(f"imported {r.source} -> {r.store}: {r.frames} frames at {r.rate_hz:.4g} Hz, "
                    f"fingers {', '.join(r.fingers)}{dropped}; baseline: {r.baseline}")
    return results


def run_metadata(src: Source, rec: Recording, decision: dict, baseline: Baseline | None, config_yaml: str,
                 overrides, n_sources: int) -> tuple[dict, dict]:
    """The root attribute ``import`` and the provenance of one imported file.

    ``import``: source path, ``sha256``, bytes and files, ``importer``, what the reader found,
    the finger decision, frames, rate (Hz), channels. Provenance: :func:`protocols.provenance.collect`
    plus ``source`` (path, sha256, bytes, files, format) and ``importer``.
    """
    summ = checksum(src)
    importer = _importer(src)
    import_attrs = {"source": str(src.path.resolve()), "source_name": src.path.name, "sha256": summ["sha256"],
                    "source_bytes": summ["bytes"], "source_files": summ["files"], "importer": importer,
                    "reader": rec.meta, "fingers": decision, "frames": rec.n_frames,
                    "rate_hz": rec.nominal_rate_hz(), "channels": list(rec.channels), "files_in_import": n_sources}
    identity = {"biotac": {"model": "SynTouch BioTac SP (imported)", "serial_or_address": src.path.name,
                           "firmware": "unknown"}}
    prov = collect(config_yaml, list(overrides), identity,
                   baseline.calibration_attrs(rec.fingers) if baseline else {}, None, protocol="import")
    prov["source"] = {"path": str(src.path.resolve()), "sha256": summ["sha256"], "bytes": summ["bytes"],
                      "files": summ["files"], "format": rec.meta.get("format")}
    prov["importer"] = importer
    return import_attrs, prov


def _importer(src: Source) -> dict:
    """Which code read the file: module, function, package versions."""
    def version(name):
        try:
            return importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            return "unknown"
    fn = "protocols.importers.bag.read_bag" if src.kind == "bag" else "protocols.importers.csv.read_csv"
    out = {"name": "tactile-import", "reader": fn, "tactile-flow": version("tactile-flow")}
    if src.kind == "bag":
        out["rosbags"] = version("rosbags")
    return out

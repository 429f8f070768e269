"""Analyse one run store and write the results beside it (the ``tactile_flow.analysis`` entry point).

``analyze_run(store_path, analysis_cfg) -> dict`` (the summary) is what ``tactile-run`` calls
when a run ends and what ``tactile-analyze`` calls per run. Each analysis goes into its own
directory, ``RUN/analyses/<name>/`` (``analysis.json``, ``analysis.zarr.zip``, ``summary.json``,
``score.json`` on simulated runs, i.e. stores with a ``truth`` group, ``figures/*.png``), and
becomes the run's current one, ``RUN/analysis`` (:mod:`runstore.analyses`: made in a staging
directory, renamed in whole, made current by one rename; every earlier analysis is kept).

Its name is ``name=`` or, by default, ``<flow method>-<key>``, the key a hash of the code
that computes it (:func:`code_version`), its effective config and the checksum of the
stored arrays it reads (:func:`analysis_key`): analysing again with the same code, config
and store reuses the kept result (``force=True`` computes it again). The run directory is
locked shared while it is analysed (``runstore.rundir``: not while the run records; other
analyses of it may run at once), and what a killed analysis left behind is removed first.
"""

from __future__ import annotations

import contextlib
import functools
import json
import uuid
from datetime import datetime, timezone
from pathlib import Path


from tactile_flow.cliapp.heap import long_lived_frozen
from tactile_flow.cliapp.runner import signals_received
from tactile_flow.runstore import analyses, files, inflight, labelled, packed, paths, rundir
from tactile_flow.runstore.catalogue import register_quietly
from tactile_flow.runstore.provenance import code_identity, git_state
from tactile_flow.tactile import warmup

from . import figure_reuse
from . import figures as figs
from . import results
from . import score as scoring
from .config import as_dict, for_sensor, load_config
from .headline import headline, whole_contact_slips
from .load import AnalysisInputError, load_run, open_truth, peek_sensor
from .pipeline import analyse, get_model

SCHEMA_VERSION = "1.0"


#: settings that do not change an analysis's results (not part of its key)
NOT_IN_KEY = ("progress", "workers", "enabled")
#: the code an analysis's results depend on (their git trees are part of its key)
CODE_PATHS = ("analysis", "tactile", "runstore")


def analysis_key(effective: dict, input_sha256: str) -> tuple[str, dict]:
    """The key of an analysis (12 hex digits) and what it hashes: the code
    (:func:`runstore.provenance.code_identity` of :data:`CODE_PATHS`), the effective config
    without :data:`NOT_IN_KEY`, and the checksum of the stored arrays the analysis reads."""
    import hashlib
    parts = {"code": code_identity(CODE_PATHS), "config": {k: v for k, v in effective.items() if k not in NOT_IN_KEY},
             "input_sha256": input_sha256}
    blob = json.dumps(parts, sort_keys=True, default=str).encode()
    return hashlib.sha256(blob).hexdigest()[:12], parts


def default_name(cfg, key: str) -> str:
    """``<flow method>-<key>``: a name that says what it is and changes with what it depends on."""
    return f"{cfg.tactile.flow.method}-{key}"


def code_version() -> dict:
    """Package version and git commit (``unknown`` outside a git checkout)."""
    pkg = _package_version()
    git = git_state(Path(__file__).resolve().parents[1], paths=("analysis", "tactile"))
    dirty = None if git["dirty"] == "unknown" else bool(git["dirty"] or git["untracked_files"])
    commit = git["commit"]
    return {"package": pkg, "git_commit": commit, "analysis_or_tactile_dirty": dirty}


@functools.cache
def _package_version() -> str:
    """The installed tactile-flow's version, asked once per process (~1.5 ms each time)."""
    from importlib.metadata import PackageNotFoundError, version
    try:
        return version("tactile-flow")
    except PackageNotFoundError:  # pragma: no cover
        return "unknown"


def _segments_json(a) -> list[dict]:
    rows = {r["segment"]: r for r in a.aggregates}
    out = []
    t = a.run.time
    for sg in a.segments:
        r = rows.get(sg.id, {})
        flows = {f"{v}/{k}": vals for (v, k), vals in r.get("flows", {}).items()}
        out.append({"id": sg.id, "label": sg.label, "finger": sg.finger, "feature": sg.feature,
                    "start_s": float(t[sg.start]), "end_s": float(t[min(sg.stop, len(t) - 1)]),
                    "frames": sg.frames(), "cop_mm": r.get("cop"), "cop_displacement_mm": r.get("cop_displacement"),
                    "slip": a.slips.get(sg.id), "flow": flows})
    return out


def analyze_run(store_path, analysis_cfg=None, *, name: str | None = None, force: bool = False,
                console=print, sensor=None) -> dict:
    """Analyse ``store_path`` (a ``run.zarr``, or a packed ``run.zarr.zip``) with the ``analysis`` config node into the run's
    analysis ``name`` (default: :func:`default_name`) and make it current; return its summary.
    An analysis with the same code, config and store already kept is reused (made current,
    nothing computed) unless ``force``. The sensor model is the one the store was recorded
    with; ``sensor`` (a :class:`tactile.sensor.SensorModel`) asks for one, which must be that
    one (:func:`runstore.sensors.require_same_sensor`). Raises :class:`AnalysisInputError`
    (nothing written) when the input cannot be analysed at all, a ``ConfigError``
    (:class:`analysis.config.AnalysisConfigError`, ``tactile.sensor.SensorModelError``) on bad
    parameters or a store of another sensor model, :class:`runstore.analyses.AnalysisNameTaken`
    when ``name`` is an analysis of another code, config or store (``force`` replaces it; the
    old one is kept)."""
    cfg = load_config(analysis_cfg)
    store_path = Path(store_path)
    if name is not None:
        paths.component(name, "name")
    if not cfg.enabled:
        console(f"analysis: disabled (analysis.enabled=false); {store_path} not analysed")
        return {"headline": {"status": "disabled"}}
    if cfg.pour.rotation_rad is not None:
        console("analysis: analysis.pour.rotation_rad is retired and ignored (since 0.3 the rotation phase "
                "is read by analysis.pour.rotation_noise_k)")
    if not packed.is_store(store_path):
        return _analyse_and_write(store_path, cfg, console, name, force, sensor)    # load_run says what is wrong
    run_dir = store_path.parent
    with rundir.locked(run_dir, shared=True):
        files.refuse_links(run_dir, (analyses.HISTORY, analyses.ANALYSES, rundir.LOCK_NAME))
        removed = analyses.remove_debris(run_dir)
        if removed:
            console(f"analysis: removed what a killed analysis left in {run_dir}: {', '.join(removed)}")
        analyses.adopt_legacy(run_dir)
        return _analyse_and_write(store_path, cfg, console, name, force, sensor)


def _analyse_and_write(store_path: Path, cfg, console, name, force, sensor=None) -> dict:
    signals_before = signals_received()          # one more by the end: a library swallowed its interrupt
    recorded = peek_sensor(store_path, sensor)   # the store's model (a refusal if sensor= is another)
    if recorded is not None:
        cfg = for_sensor(cfg, recorded)
    # a first analysis on this machine compiles the kernels on every core while the run loads
    with warmup.compiling(cfg.tactile, cfg.workers, console, sensor=recorded):
        run = load_run(store_path, in_memory_frames=cfg.memory.chunk_frames, sensor=sensor)
    if run.sensor_how != "recorded":
        console(f"analysis: sensor model {run.sensor.name} ({run.sensor_how})")
    key, key_parts = analysis_key({**as_dict(cfg), "sensor": run.sensor.sha256}, run.input_sha256)
    name = name or default_name(cfg, key)
    kept = analyses.find(store_path.parent, name)
    if kept is not None and not force:
        if analyses.read_meta(kept).get("key") == key:
            return _reuse(store_path.parent, name, kept, console)
        raise analyses.AnalysisNameTaken(
            f"name={name}: {store_path.parent} already has an analysis {name} made with another code, config or "
            f"store (key {analyses.read_meta(kept).get('key')}, this one {key}); choose another name, or force=true "
            f"to replace it (the old one is kept as {name}~<its id>)")
    model = get_model(cfg.tactile, run.sensor)
    with long_lived_frozen():
        return _analyse(store_path, run, model, cfg, console, signals_before,
                        {"name": name, "key": key, "key_parts": key_parts}, replace=kept is not None, redraw=force)


def _reuse(run_dir: Path, name: str, kept: Path, console) -> dict:
    """Make the kept analysis ``name`` current (same code, config and store); its summary."""
    analyses.make_current(run_dir, name)
    if (run_dir / "run.json").is_file():
        register_quietly(run_dir, console)
    summary = json.loads((kept / analyses.SUMMARY).read_text())
    console(f"analysis {run_dir}: {name} reused (made before with the same code, config and store; "
            f"force=true computes it again)")
    return summary


def _analyse(store_path: Path, run, model, cfg, console, signals_before: int, naming: dict,
             replace: bool = False, redraw: bool = False) -> dict:
    """Compute the analysis and commit it; its figures are linked from an earlier analysis of the
    run where their inputs are the same (:mod:`.figure_reuse`), all drawn with ``redraw``."""
    a = analyse(run, cfg, model)
    run_dir = store_path.parent
    analysis_id = uuid.uuid4().hex
    effective = as_dict(cfg)
    created = datetime.now(timezone.utc).isoformat().replace("+00:00", "Z")
    provenance = {"analysis_id": analysis_id, "schema_version": SCHEMA_VERSION,
                  "created": created, "name": naming["name"], "key": naming["key"],
                  "config": effective, "config_overrides": cfg.raw, "code": code_version(),
                  "input": {"store": store_path.name, "run_id": run.attrs.get("run_id"),
                            "sha256": run.input_sha256, "frames": len(run.time),
                            "dropped_invalid_frames": run.dropped_invalid},
                  "baseline": a.prepared.baseline_source, "baseline_kind": a.prepared.baseline.kind,
                  "contact_method": a.contact_method, "pressure_signal": a.prepared.pressure_name,
                  "sensor": {**run.sensor.summary(), "how": run.sensor_how},
                  "preparation": a.prepared.preparation}
    score = None
    truth = open_truth(run)
    if truth is not None:
        score = scoring.score(a, truth)
        score["analysis_id"] = analysis_id
    summary = {"analysis_id": analysis_id, "analysis": naming["name"], "run": str(store_path),
               "protocol": run.protocol, "run_status": run.status, "scheme": a.scheme, "labels": run.labels,
               "headline": headline(a, score), "provenance": provenance,
               "contacts": {f: [[float(run.time[s]), float(run.time[min(e, len(run.time) - 1)])] for s, e in ivs]
                            for f, ivs in a.contacts.items()},
               "begins_in_contact": {f: ivs[0][0] == 0 for f, ivs in a.contacts.items()},
               "segments": _segments_json(a),
               "estimates": {"crossings": a.crossings, "pour": a.pour, "slip": whole_contact_slips(a)},
               "whole_run": a.whole_run, "skipped": a.skipped, "timing": a.timing}
    with analyses.staging(run_dir) as staging:
        try:
            # with several workers the figures are drawn in forked processes while this one writes
            earlier = {} if redraw or not cfg.figures else figure_reuse.earlier_figures(run_dir)
            with (figs.FigureWriter(a, model, staging / "figures", cfg, cfg.workers or warmup.available_cores(),
                                    earlier) if cfg.figures else contextlib.nullcontext()) as drawing:
                tree = results.to_tree(a, list(model.plans), {"analysis_id": analysis_id,
                                                              "provenance": json.loads(results.dumps(provenance))},
                                       fields=cfg.save_fields)
                labelled.write_tree(tree, staging / analyses.PACKED_STORE)     # one zip file
                if score is not None:
                    (staging / "score.json").write_text(results.dumps(score))
                if drawing is not None:
                    summary["figures"], left_out = drawing.result()
                    if left_out:
                        summary["figures_left_out"] = {
                            "labels": left_out, "reason": f"one flow figure per label, at most max_segment_figures="
                                                          f"{cfg.max_segment_figures}"}
            text = results.dumps(summary)
            (staging / "summary.json").write_text(text)
            if signals_received() > signals_before:
                raise KeyboardInterrupt          # a library swallowed it (OpenCV's loader has a bare except)
            meta = {"analysis_id": analysis_id, "key": naming["key"], "created": created,
                    "run_id": run.attrs.get("run_id"), "input_sha256": run.input_sha256,
                    "config": effective, "code": naming["key_parts"]["code"], "headline": summary["headline"],
                    "figures": bool(cfg.figures), **({"forced": True} if replace else {})}
            if drawing is not None:
                meta[figure_reuse.KEY_FIELD] = {n: k for n, k in drawing.keys.items() if k is not None}
                meta["figures_reused"] = drawing.reused
            analyses.commit(run_dir, staging, naming["name"], meta, replace=replace)
        except BaseException:
            inflight.settle()                    # an interrupt may have left zarr writing into it
            raise
    if (run_dir / "run.json").is_file():
        register_quietly(run_dir, console)      # the catalogue shows its current analysis
    _report(console, run_dir, summary, score, drawing.reused if drawing is not None else [])
    return json.loads(text)


def _report(console, run_dir, summary, score, reused=()) -> None:
    h = summary["headline"]
    msg = f"analysis {run_dir}: {h['segments']} segments, {h['skipped']} skipped"
    if reused:
        msg += f"; {len(reused)} of {len(summary['figures'])} figures as drawn before (same inputs)"
    if h.get("status") == "no_contact":
        msg += " (no contact found: nothing to segment)"
    if score is not None:
        msg += f"; score: {score_line(score)}"
    console(msg + f"; analyses/{summary['analysis']}")


def score_line(score: dict) -> str:
    """The score in a few words: targets met, or which failed and by how much."""
    targets = score.get("targets") or {}
    if not targets:
        return "no target applies (the protocol declares nothing the truth can score)"
    failed = [f"{k} {_num(t['value'])} (target {'≥' if k.endswith('fraction') else '≤'} {_num(t['target'])}"
              + (f", {t['reason']}" if t.get("reason") else "") + ")"
              for k, t in targets.items() if not t["met"]]
    if not failed:
        return f"targets met ({len(targets)} of {len(targets)})"
    return f"targets NOT met ({len(failed)} of {len(targets)}): " + "; ".join(failed)


def _num(v) -> str:
    return "none" if v is None else f"{v:.3g}"


__all__ = ["analyze_run", "AnalysisInputError"]

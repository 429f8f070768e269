"""Analyse one run store and write the results beside it (the ``tactile_flow.analysis`` entry point).

``analyze_run(store_path, analysis_cfg) -> dict`` (the summary) is what ``tactile-run`` calls
when a run ends and what ``tactile-analyze`` calls per run. Outputs in the run directory
(``store_path.parent``): ``analysis.zarr``, ``summary.json``, ``score.json`` (simulated runs,
i.e. stores with a ``truth`` group), ``figures/*.png``, and ``analysis_history.jsonl`` (one line
per replaced analysis: its config, provenance and headline). Everything is written into a
staging directory first and then renamed into place (:func:`analysis.results.swap_in`), so a
failure leaves the previous results untouched and never partial files. The run directory is
locked while it is analysed (``runstore.rundir``: not while the run records, not twice at
once), and what a killed analysis left behind is removed first.
"""

from __future__ import annotations

import contextlib
import json
import shutil
import uuid
from datetime import datetime, timezone
from pathlib import Path


from tactile_flow.cliapp.heap import long_lived_frozen
from tactile_flow.cliapp.runner import signals_received
from tactile_flow.runstore import inflight, labelled, rundir
from tactile_flow.runstore.provenance import git_state
from tactile_flow.tactile import warmup

from . import figures as figs
from . import results
from . import score as scoring
from .config import as_dict, for_sensor, load_config
from .headline import headline, whole_contact_slips
from .load import AnalysisInputError, load_run, open_truth, peek_sensor
from .pipeline import analyse, get_model

SCHEMA_VERSION = "1.0"


def code_version() -> dict:
    """Package version and git commit (``unknown`` outside a git checkout)."""
    from importlib.metadata import PackageNotFoundError, version
    try:
        pkg = version("tactile-flow")
    except PackageNotFoundError:  # pragma: no cover
        pkg = "unknown"
    git = git_state(Path(__file__).resolve().parents[1], paths=("analysis", "tactile"))
    dirty = None if git["dirty"] == "unknown" else bool(git["dirty"] or git["untracked_files"])
    commit = git["commit"]
    return {"package": pkg, "git_commit": commit, "analysis_or_tactile_dirty": dirty}


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


def analyze_run(store_path, analysis_cfg=None, *, console=print, sensor=None) -> dict:
    """Analyse ``store_path`` (a ``run.zarr``) with the ``analysis`` config node; write the outputs
    beside it; return the summary dict. The sensor model is the one the store was recorded
    with; ``sensor`` (a :class:`tactile.sensor.SensorModel`) asks for one, which must be that
    one (:func:`runstore.sensors.require_same_sensor`). Raises :class:`AnalysisInputError`
    (nothing written) when the input cannot be analysed at all, a ``ConfigError``
    (:class:`analysis.config.AnalysisConfigError`, ``tactile.sensor.SensorModelError``) on bad
    parameters or a store of another sensor model."""
    cfg = load_config(analysis_cfg)
    store_path = Path(store_path)
    if not cfg.enabled:
        console(f"analysis: disabled (analysis.enabled=false); {store_path} not analysed")
        return {"headline": {"status": "disabled"}}
    if not (store_path / "zarr.json").is_file():
        return _analyse_and_write(store_path, cfg, console, sensor)   # load_run says what is wrong; nothing to lock
    with rundir.locked(store_path.parent):
        removed = results.remove_debris(store_path.parent)
        if removed:
            console(f"analysis: removed what a killed analysis left in {store_path.parent}: {', '.join(removed)}")
        return _analyse_and_write(store_path, cfg, console, sensor)


def _analyse_and_write(store_path: Path, cfg, console, sensor=None) -> dict:
    signals_before = signals_received()          # one more by the end: a library swallowed its interrupt
    recorded = peek_sensor(store_path, sensor)   # the store's model (a refusal if sensor= is another)
    if recorded is not None:
        cfg = for_sensor(cfg, recorded)
    # a first analysis on this machine compiles the kernels on every core while the run loads
    with warmup.compiling(cfg.tactile, cfg.workers, console, sensor=recorded):
        run = load_run(store_path, in_memory_frames=cfg.memory.chunk_frames, sensor=sensor)
    if run.sensor_how != "recorded":
        console(f"analysis: sensor model {run.sensor.name} ({run.sensor_how})")
    model = get_model(cfg.tactile, run.sensor)
    with long_lived_frozen():
        return _analyse(store_path, run, model, cfg, console, signals_before)


def _analyse(store_path: Path, run, model, cfg, console, signals_before: int) -> dict:
    a = analyse(run, cfg, model)
    run_dir = store_path.parent
    analysis_id = uuid.uuid4().hex
    effective = as_dict(cfg)
    provenance = {"analysis_id": analysis_id, "schema_version": SCHEMA_VERSION,
                  "created": datetime.now(timezone.utc).isoformat().replace("+00:00", "Z"),
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
    summary = {"analysis_id": analysis_id, "run": str(store_path), "protocol": run.protocol,
               "run_status": run.status, "scheme": a.scheme, "labels": run.labels,
               "headline": headline(a, score), "provenance": provenance,
               "contacts": {f: [[float(run.time[s]), float(run.time[min(e, len(run.time) - 1)])] for s, e in ivs]
                            for f, ivs in a.contacts.items()},
               "begins_in_contact": {f: ivs[0][0] == 0 for f, ivs in a.contacts.items()},
               "segments": _segments_json(a),
               "estimates": {"crossings": a.crossings, "pour": a.pour, "slip": whole_contact_slips(a)},
               "whole_run": a.whole_run, "skipped": a.skipped, "timing": a.timing}
    staging = run_dir / f".analysis-staging-{analysis_id[:8]}"
    try:
        staging.mkdir()                          # inside: a signal right after it still removes it
        # with several workers the figures are drawn in forked processes while this one writes
        with (figs.FigureWriter(a, model, staging / "figures", cfg, cfg.workers or warmup.available_cores())
              if cfg.figures else contextlib.nullcontext()) as drawing:
            tree = results.to_tree(a, list(model.plans), {"analysis_id": analysis_id,
                                                          "provenance": json.loads(results.dumps(provenance))},
                                   fields=cfg.save_fields)
            labelled.write_tree(tree, staging / "analysis.zarr")
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
            raise KeyboardInterrupt              # a library swallowed it (OpenCV's loader has a bare except)
        previous = _previous_record(run_dir)
        results.swap_in(staging, run_dir, previous)
    except BaseException:
        inflight.settle()                        # an interrupt may have left zarr writing into it
        shutil.rmtree(staging, ignore_errors=True)
        raise
    _report(console, run_dir, summary, score)
    return json.loads(text)


def _previous_record(run_dir: Path) -> dict | None:
    old = run_dir / "summary.json"
    if not old.exists():
        return None
    try:
        s = json.loads(old.read_text())
    except (OSError, json.JSONDecodeError):
        return {"replaced": datetime.now(timezone.utc).isoformat(), "note": "previous summary.json unreadable"}
    return {"replaced": datetime.now(timezone.utc).isoformat(), "analysis_id": s.get("analysis_id"),
            "provenance": s.get("provenance"), "headline": s.get("headline")}


def _report(console, run_dir, summary, score) -> None:
    h = summary["headline"]
    msg = f"analysis {run_dir}: {h['segments']} segments, {h['skipped']} skipped"
    if h.get("status") == "no_contact":
        msg += " (no contact found: nothing to segment)"
    if score is not None:
        msg += f"; score: {score_line(score)}"
    console(msg)


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

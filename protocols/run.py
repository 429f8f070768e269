"""One run, start to end: plan check, lab, recording, engine, provenance, hand-off.

:func:`run_protocol` is what ``tactile-run`` calls for every job; tests call it directly.
The hand-off to the analysis pipeline goes through the ``tactile_flow.analysis`` entry
point with the path of the run store: ``protocols`` never imports ``analysis``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from importlib.metadata import entry_points
from pathlib import Path

from omegaconf import OmegaConf
from tqdm import tqdm

from hardware.errors import ConfigError
from tactile.frames import DEFAULT_VIEWS
from tactile.geometry import load_taxels
from tactile.pipeline import TactileModel

from . import provenance
from .engine import FAILED, Outcome, RunEngine
from .lab import check_hardware, make_lab
from .live import LiveConfig, LiveMonitor, live_fingers, live_settings, tactile_config, terminal_display, warm_up
from .plan import Plan, format_timeline, make_plan
from .recorder import Recorder
from .steps import ProtocolError
from .store import RunStore, utc_now

ANALYSIS_ENTRY_POINTS = "tactile_flow.analysis"


class RecordingError(RuntimeError):
    """The run store could not be written to the end (e.g. a full disk)."""


@dataclass
class RunResult:
    """What a run left behind. ``status``: success | aborted | failed | planned."""

    status: str
    run_dir: Path
    plan: Plan
    store: Path | None = None
    error: str | None = None
    stats: dict = field(default_factory=dict)
    analysis: dict | None = None


def run_protocol(cfg, run_dir, overrides=(), console=print) -> RunResult:
    """Check the plan, then (unless ``cfg.plan_only``) run it on ``cfg.hardware``.

    Bad config or protocol raises ``ValueError`` (``ProtocolError``/``ConfigError``, naming
    the key) before any hardware is touched. A run that starts always ends with a closed
    store and ``run.json``, whatever its status.
    """
    run_dir = Path(run_dir)
    plan = make_plan(cfg)
    live, model = live_setup(cfg, plan, build=not cfg.plan_only)
    if cfg.plan_only:
        check_hardware(cfg)
        console(format_timeline(plan))
        return RunResult("planned", run_dir, plan)

    lab = make_lab(cfg)
    run_dir.mkdir(parents=True, exist_ok=True)
    store_path = run_dir / "run.zarr"
    with lab:
        prov = provenance.collect(OmegaConf.to_yaml(cfg, resolve=True), list(overrides), lab.identities(),
                                  _calibration(lab), cfg.hardware.get("seed"), protocol=plan.protocol)
        store = RunStore.create(store_path, protocol=plan.protocol, fingers=lab.biotac.fingers,
                                run_id=prov["run_id"], provenance=provenance.summary(prov),
                                attrs={"labels": plan.labels, "plan_duration_s": plan.duration},
                                live=(live_fingers(live, lab.biotac.fingers), model.config.views) if model else None)
        recorder = Recorder(store, {"biotac": lab.biotac.read, "arm": lab.arm.read_states,
                                    "hand": lab.hand.read_states, "pump": lab.pump.read_states,
                                    "scale": lab.scale.read}, lab.clock).start()
        monitor = LiveMonitor(lab.biotac, recorder, model, live, lab.clock,
                              display=None if cfg.progress else terminal_display()) if model else None
        outcome = Outcome(FAILED, "the run engine could not start")
        try:
            outcome = RunEngine(lab, recorder, cfg, plan, progress_factory=_bars(cfg.progress), log=console,
                                live=monitor).run()
        finally:
            attrs = {"error": outcome.error}
            if monitor is not None:
                attrs["live"] = monitor.close()
            truth = lab.truth.to_dict() if getattr(lab, "truth", None) is not None else None
            try:
                stats = recorder.stop(outcome.status, truth=truth, attrs=attrs)
            except Exception as exc:
                cause = recorder.writer_error or exc
                console(f"run {run_dir}: {outcome.status} ({outcome.error})")
                raise RecordingError(f"the run store could not be closed ({type(cause).__name__}: {cause}); it "
                                     f"keeps every sample committed before that; once the disk has room, run "
                                     f"`tactile-recover {store_path}`") from exc
            provenance.write_run_json(run_dir / "run.json", prov, status=outcome.status, end_time=utc_now(),
                                      extra={"error": outcome.error, "store": store_path.name})
    return RunResult(outcome.status, run_dir, plan, store_path, outcome.error, stats)


def live_setup(cfg, plan: Plan, build: bool = True) -> tuple[LiveConfig, TactileModel | None]:
    """The checked ``live`` settings and, when the run computes live flow (``live.enabled``,
    or auto when a step reacts to slip) and ``build``, the online tactile model (else
    ``None``). A protocol that reacts to slip with the live monitor turned off is refused
    here, before anything moves."""
    try:
        live = live_settings(cfg)
    except (ValueError, TypeError) as exc:
        raise ConfigError("live", str(exc)) from None
    reacting = plan.slip_steps()
    if live.enabled is False and reacting:
        raise ProtocolError(reacting[0], "reacts to slip, but live.enabled=false turns the slip detector off; "
                                         "drop live.enabled=false or the step's until: slip / on_slip")
    if not (live.enabled or reacting):
        return live, None
    unknown = [f for f in live.fingers or () if f not in cfg.hardware.fingers]
    if unknown:
        raise ConfigError("live.fingers", f"{unknown} have no sensor in hardware.fingers {list(cfg.hardware.fingers)}")
    try:
        tactile = tactile_config(cfg.get("analysis") or {}, live.views)
    except ValueError as exc:
        raise ConfigError("live", str(exc)) from None
    known = {**DEFAULT_VIEWS, **tactile.custom_views}
    bad = [v for v in live.views if v not in known] or ([] if live.views else ["(none)"])
    if bad:
        raise ConfigError("live.views", f"{bad}: expected one or more of {sorted(known)}")
    if not build:
        return live, None
    model = TactileModel.build(tactile)
    warm_up(model, live.views)
    return live, model


def hand_off(result: RunResult, analysis_cfg, console=print) -> dict | None:
    """Give the run store to the analysis pipeline registered as an entry point."""
    found = entry_points(group=ANALYSIS_ENTRY_POINTS)
    if not found:
        console("analysis: no analysis pipeline installed; skipped")
        return None
    analyze = next(iter(found)).load()
    return analyze(result.store, analysis_cfg)


def _calibration(lab) -> dict:
    baselines = getattr(lab.biotac, "calibration", {}) or {}
    return {"taxels_mm": load_taxels().tolist(),
            "baseline_counts": {f: [float(x) for x in v] for f, v in baselines.items()}}


def _bars(enabled: bool):
    """A progress bar per step, over its expected duration (clock seconds)."""
    if not enabled:
        return None

    def make(planned):
        return tqdm(total=round(max(planned.duration, 0.01), 2), unit="s", leave=False, dynamic_ncols=True,
                    desc=f"step {planned.index:02d} {planned.step.kind:<8}",
                    bar_format="{desc} {percentage:3.0f}%|{bar:24}| {n:.1f}/{total:.1f} s [{elapsed}<{remaining}]")
    return make

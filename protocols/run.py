"""One run, start to end: plan check, lab, recording, engine, provenance, hand-off.

:func:`run_protocol` is what ``tactile-run`` calls for every job; tests call it directly.
The hand-off to the analysis pipeline goes through the ``tactile_flow.analysis`` entry
point with the path of the run store: ``protocols`` never imports ``analysis``.
"""

from __future__ import annotations

import json
import os
import sys
from contextlib import nullcontext
from dataclasses import dataclass, field
from importlib.metadata import entry_points
from pathlib import Path


from tactile_flow.cliapp.heap import long_lived_frozen
from tactile_flow.cliapp.progress import progress_bar
from tactile_flow.tactile.geometry import load_taxels
from tactile_flow.runstore import RunStore, provenance, rundir, utc_now
from tactile_flow.runstore.catalogue import register_quietly
from tactile_flow.runstore.checksum import store_checksum
from tactile_flow.runstore.room import RESERVE_BYTES
from tactile_flow.tactile import warmup
from tactile_flow.tactile.pipeline import TactileModel

from . import record
from .calibration import session_baseline, store_baseline
from .engine import FAILED, Outcome, RunEngine
from .interrupts import Interrupts
from .backends import board_warning, make_lab
from .live import LiveConfig, LiveMonitor, live_fingers, open_viewer, tactile_config, terminal_display, warm_up
from .plan import Plan, format_timeline, make_plan
from .settings import run_settings
from .recorder import Recorder
from .steps import ProtocolError

ANALYSIS_ENTRY_POINTS = "tactile_flow.analysis"


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


def run_protocol(cfg, run_dir, overrides=(), console=print, interrupts: Interrupts | None = None) -> RunResult:
    """Check the plan, then (unless ``plan_only``) run it on the hardware.

    ``cfg``: the run's :class:`~protocols.settings.RunSettings`, or the composed config (checked
    first by :func:`~protocols.settings.run_settings`). Bad config or protocol raises
    ``ValueError`` (``ProtocolError``/``ConfigError``, naming the key) before any hardware is
    touched. A run that starts always ends with a closed
    store and ``run.json``, whatever its status (if the disk allows: the result's error then
    names ``tactile-recover``). The run directory is locked for the run (:mod:`.rundir`);
    ``interrupts`` owns Ctrl-C and SIGTERM (installed here when not given).
    """
    run_dir = Path(run_dir)
    cfg = run_settings(cfg)
    plan = make_plan(cfg)
    live, model = live_setup(cfg, plan, build=not cfg.plan_only, console=console)
    if cfg.plan_only:
        console(format_timeline(plan))
        return RunResult("planned", run_dir, plan)

    mismatch = board_warning(cfg)                   # an emulated lab on another board: said before anything moves
    if mismatch:
        console(mismatch)
    lab = make_lab(cfg)
    baseline = session_baseline(cfg.hardware, lab)
    own = interrupts is None
    interrupts = interrupts or Interrupts(console)
    store_path = run_dir / "run.zarr"
    with (interrupts.installed() if own else nullcontext()), rundir.locked(run_dir), lab:
        prov = provenance.collect(cfg.config_yaml, list(overrides), lab.identities(),
                                  _calibration(lab), getattr(cfg.hardware, "seed", None), protocol=plan.protocol)
        # From the store's creation to the job's end no signal raises: the engine stops the run
        # safely on one, and the store, run.json, the devices' close and the catalogue entry are
        # written whole (a signal raised on the way out would report a closed run as never started).
        interrupts.phase = "writing"
        prov.update(_reproducible(run_dir, cfg))
        store = RunStore.create(store_path, protocol=plan.protocol, fingers=lab.biotac.fingers,
                                run_id=prov["run_id"], provenance=provenance.summary(prov),
                                attrs={"labels": plan.labels, "plan_duration_s": plan.duration,
                                       "tare": cfg.protocol.tare},
                                live=(live_fingers(live, lab.biotac.fingers), model.config.views)
                                if model else None, streams=lab.streams(), room_bytes=RESERVE_BYTES)
        stored = store_baseline(store, baseline, lab.biotac.fingers)
        if getattr(lab, "truth", None) is not None:
            lab.truth.conditions = _conditions(cfg, lab, stored, plan)
        recorder = Recorder(store, lab.sources(), lab.clock)
        monitor, outcome = None, Outcome(FAILED, "the run engine could not start")
        screen = ProgressConsole() if cfg.progress else None
        try:
            with long_lived_frozen():      # shorter collector pauses while the readers run
                if not plan.setup:
                    recorder.start()
                if model:
                    viewer = open_viewer(live.viewer, live_fingers(live, lab.biotac.fingers), model, run_dir, console)
                    monitor = LiveMonitor(lab.biotac, recorder, model, live, lab.clock,
                                          display=screen.live_line() if screen else terminal_display(),
                                          viewer=viewer)
                outcome = RunEngine(lab, recorder, cfg, plan, progress_factory=screen.bar if screen else None,
                                    log=console,
                                    live=monitor, interrupts=interrupts).run(
                    start_recording=recorder.start if plan.setup else None)
        except Exception as exc:              # the engine never raises past its safe stop; this is the rest
            outcome = Outcome(FAILED, f"{type(exc).__name__}: {exc}")
        finally:
            if screen:
                screen.close()
            outcome, stats = _close(run_dir, prov, recorder, monitor, lab, outcome)
            for line in wire_warnings(wire_reports(lab)):
                console(line)
    register_quietly(run_dir, console)            # tactile-runs list finds it (its analysis updates it)
    return RunResult(outcome.status, run_dir, plan, store_path, outcome.error, stats)


def _reproducible(run_dir: Path, cfg) -> dict:
    """What the run keeps to be done again from its directory alone (:mod:`.record`): copies of
    its config files and of the files its values name, the code's state and uncommitted diff,
    the working directory, and the run it reproduces (``tactile-runs reproduce`` says so in
    :data:`runstore.provenance.REPRODUCES_ENV`)."""
    out = {"code": record.record_code(run_dir), "cwd": os.getcwd()}
    inputs = record.record_inputs(run_dir, cfg)
    if inputs is not None:
        out["inputs"] = inputs
    reproduces = os.environ.get(provenance.REPRODUCES_ENV)
    if reproduces:
        try:
            out["reproduces"] = json.loads(reproduces)
        except ValueError:
            pass
    return out


def _close(run_dir: Path, prov: dict, recorder: Recorder, monitor, lab, outcome: Outcome) -> tuple[Outcome, dict]:
    """Close the store and write ``run.json``. A store that could not record everything is
    ``failed`` (never the engine's ``success``); what could not be written is said in the
    error, with what to do. Returns the final outcome and the recorder's stream stats."""
    attrs = {"error": outcome.error, "wire": wire_reports(lab)}
    if monitor is not None:
        try:
            attrs["live"] = monitor.close()
        except Exception as exc:                  # noqa: BLE001 - the store must still be closed
            attrs["live_error"] = f"{type(exc).__name__}: {exc}"
    truth = lab.truth.to_dict() if getattr(lab, "truth", None) is not None else None
    status, error, stats = outcome.status, outcome.error, {}
    store, problems = recorder.store, []
    try:
        stats = recorder.stop(status, truth=truth, attrs=attrs)
    except Exception as exc:                      # noqa: BLE001 - a full disk, a vanished directory...
        cause = recorder.writer_error or exc
        problems.append(f"recording failed ({type(cause).__name__}: {cause}); the store keeps every sample "
                        f"committed before that" + ("" if store.closed else " but could not be closed"))
        status = FAILED
    extra = {"error": "; ".join(problems) or error, "store": store.path.name, "wire": attrs["wire"]}
    if not problems and store.closed:
        try:                                      # what reproducing the run compares (runstore.checksum)
            extra["store_checksum"] = store_checksum(store.path)
        except Exception as exc:                  # noqa: BLE001 - the record matters more than its checksum
            extra["store_checksum_error"] = f"{type(exc).__name__}: {exc}"
    json_written = False
    try:
        provenance.write_run_json(run_dir / "run.json", prov, status=status, end_time=utc_now(), extra=extra)
        json_written = True
    except OSError as exc:
        problems.append(f"run.json could not be written ({type(exc).__name__}: {exc})")
        status = FAILED
    if problems:
        ended = f"the run itself ended {outcome.status}" + (f" ({outcome.error})" if outcome.error else "")
        advice = [] if store.closed and json_written else [f"once the disk has room, run `tactile-recover "
                                                           f"{store.path}` (it closes the store, writes run.json)"]
        error = "; ".join([*problems, ended, *advice])
    return Outcome(status, error, outcome.steps_done), stats


def wire_reports(lab) -> dict:
    """Device → what its driver refused on the wire (:meth:`hardware.device.Device.wire_report`),
    for the devices that report; stored in the store's root attribute ``wire`` and in ``run.json``."""
    out = {}
    for name, device in lab.devices.items():
        try:
            report = device.wire_report()
        except Exception as exc:                  # noqa: BLE001 - a report must never stop the close
            report = {"error": f"{type(exc).__name__}: {exc}"}
        if report is not None:
            out[name] = report
    return out


def wire_warnings(reports: dict) -> list[str]:
    """One line per device that refused messages: how many, why, and the last one."""
    lines = []
    for name, r in reports.items():
        if r.get("refused"):
            reasons = ", ".join(f"{n} {why}" for why, n in (r.get("reasons") or {}).items())
            lines.append(f"warning: {name}: {r['refused']} message(s) refused on the wire ({reasons})"
                         + (f"; the last: {r['last']}" if r.get("last") else ""))
    return lines


def live_setup(cfg, plan: Plan, build: bool = True, console=print) -> tuple[LiveConfig, TactileModel | None]:
    """The checked ``live`` settings and, when the run computes live flow (``live.enabled``,
    or auto when a step reacts to slip) and ``build``, the online tactile model (else
    ``None``), its kernels compiled (on every core, the first time on a machine). A protocol
    that reacts to slip with the live monitor turned off is refused here, before anything
    moves. ``cfg``: :class:`~protocols.settings.RunSettings` (or the composed config)."""
    cfg = run_settings(cfg)
    live = cfg.live
    reacting = plan.slip_steps()
    if not cfg.protocol.tare and (live.enabled or reacting):
        what = f"{reacting[0]} reacts to slip" if reacting else "live.enabled=true"
        raise ProtocolError("protocol.tare", f"false starts the run in contact without a tare, but {what}: the "
                                             f"live monitor needs a tare at rest")
    if live.enabled is False and reacting:
        raise ProtocolError(reacting[0], "reacts to slip, but live.enabled=false turns the slip detector off; "
                                         "drop live.enabled=false or the step's until: slip / on_slip")
    if not (live.enabled or reacting or live.viewer):
        return live, None
    tactile = tactile_config(getattr(cfg.analysis, "tactile", None), live.views)
    if not build:
        return live, None
    warmup.compile_cold(tactile, console=console, groups=warmup.LIVE)
    model = TactileModel.build(tactile)
    warm_up(model, live.views)
    return live, model


def hand_off(result: RunResult, analysis_cfg, console=print) -> dict | None:
    """Give the run store to the analysis pipeline registered as an entry point, with the
    analysis's config (typed, as :class:`~protocols.settings.RunSettings` holds it, or a node)."""
    found = entry_points(group=ANALYSIS_ENTRY_POINTS)
    if not found:
        console("analysis: no analysis pipeline installed; skipped")
        return None
    analyze = next(iter(found)).load()
    return analyze(result.store, analysis_cfg)


def _conditions(cfg, lab, baseline: dict, plan: Plan) -> dict:
    """What the run was told, for the ground truth's ``conditions`` (``press_force_n``: the first
    ``press`` step's force, NaN without one)."""
    surface = lab.surface
    obj = (surface.cfg.name or surface.kind) if surface is not None else ""
    press = next((p.step for p in plan.steps if p.step.kind == "press"), None)
    force = float("nan") if press is None else float(press.force if press.force is not None else
                                                       cfg.protocol.press_force)
    return {"object": obj, "press_force_n": force, "tare": cfg.protocol.tare, "baseline": baseline["method"]}


def _calibration(lab) -> dict:
    baselines = getattr(lab.biotac, "calibration", {}) or {}
    return {"taxels_mm": load_taxels().tolist(),
            "baseline_counts": {f: [float(x) for x in v] for f, v in baselines.items()}}


class ProgressConsole:
    """The console of a run with ``progress=true``: a progress bar per step, over its expected
    duration (clock seconds), and under it the live monitor's operator line (finger, flow
    arrow, slip state) as a status line, both redrawn in place by tqdm, on a terminal only (in a
    file their carriage-return redraws are clutter: :func:`cliapp.progress.progress_bar`)."""

    def __init__(self, stream=None):
        self.stream = stream if stream is not None else sys.stderr
        self.status = None

    def bar(self, planned):
        return progress_bar(total=round(max(planned.duration, 0.01), 2), unit="s", leave=False, dynamic_ncols=True,
                    position=0, file=self.stream, desc=f"step {planned.index:02d} {planned.step.kind:<8}",
                    bar_format="{desc} {percentage:3.0f}%|{bar:24}| {n:.1f}/{total:.1f} s [{elapsed}<{remaining}]")

    def live_line(self):
        """The live monitor's display: the status line (None when not a terminal)."""
        return self._show if self.stream.isatty() else None

    def _show(self, line: str) -> None:
        if self.status is None:
            self.status = progress_bar(total=0, position=1, leave=False, dynamic_ncols=True, file=self.stream,
                               bar_format="{desc}")
        self.status.set_description_str(line)

    def close(self) -> None:
        if self.status is not None:
            self.status.close()
            self.status = None

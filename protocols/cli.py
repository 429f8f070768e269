"""``tactile-run``: run a protocol (Hydra app; ``-m`` for sweeps).

    tactile-run                                   # straws sweep, simulated lab, analysis
    tactile-run protocol=pour_grasp plan_only=true
    tactile-run -m protocol=straws_sweep,sticks_sweep protocol.sweep_speed=5,10
    tactile-run -m +experiment=speeds_by_surface

Exit status: 0 success, 1 failed, 2 bad config or protocol (nothing moved), 3 aborted.
Errors are one line naming the key at fault; ``verbose=true`` adds the traceback.
"""

from __future__ import annotations

import csv
import io
import json
import logging
import sys
from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from hydra.experimental.callback import Callback
from hydra.types import RunMode
from omegaconf import OmegaConf

import tactile_flow.cliapp.jobresults as jobresults
from tactile_flow.cliapp.runner import report
from tactile_flow.conf import DIR as CONF_DIR
from tactile_flow.runstore import RunStatus, analyses, files, paths, rundir, runinfo

from .interrupts import Interrupts
from .schema import register

log = logging.getLogger("tactile-run")
EXIT_CODES = {s.value: int(s.exit_code) for s in RunStatus}
BAD_INPUT = 2


def console(message: str) -> None:
    """A line for the operator, also kept in the run's log file."""
    print(message, flush=True)
    log.info(message)


_interrupts = Interrupts(console)


def run_job(cfg, console=console, interrupts: Interrupts | None = None) -> int:
    """Run one Hydra job; never raises. Returns the exit code.

    The process's :class:`~protocols.interrupts.Interrupts` (installed by :func:`main`) owns
    Ctrl-C and SIGTERM: before anything is written a signal ends the job there; once the
    store exists the run stops safely and closes; during the analysis, the analysis is
    dropped (the recording is complete). After an operator stop, the sweep's remaining jobs
    are skipped. Between and after jobs signals are noted only (files may be being written)."""
    interrupts = interrupts or _interrupts
    hc = HydraConfig.get()
    run_dir = Path(hc.runtime.output_dir)
    if interrupts.count:
        console(f"run {run_dir}: skipped (the sweep was stopped by the operator)")
        return EXIT_CODES["aborted"]
    interrupts.phase = "setup"
    try:
        return _job(cfg, hc, run_dir, interrupts, console)
    except KeyboardInterrupt:                       # raised only while nothing was being written
        console(f"run {run_dir}: interrupted before it started; nothing recorded")
        return EXIT_CODES["aborted"]
    finally:
        interrupts.phase = "writing"


def _job(cfg, hc, run_dir: Path, interrupts: Interrupts, console) -> int:
    from . import resume  # the run store, the simulator, numba: not for --help
    from .run import RunResult, hand_off, run_protocol
    from .settings import run_settings
    verbose = cfg.get("verbose") is True
    try:
        settings = run_settings(cfg)                # the one check of the whole config: typed from here on
        verbose = settings.verbose
        check_run_dir(settings, hc, run_dir)
        _refuse_parallel_hardware(settings, hc)
        decision = "run"
        if settings.resume and not settings.plan_only:
            if hc.mode == RunMode.MULTIRUN:
                resume.check_job_siblings(hc.sweep.dir, hc.job.num, run_dir, settings.config_yaml)
            with interrupts.during("writing"):        # an earlier attempt may be moved aside
                decision = resume.decide(run_dir, settings.config_yaml, analyze=settings.analyze)
        if decision == "run" and not settings.plan_only:
            with interrupts.during("writing"):
                record_config(run_dir, cfg)           # Hydra's record: the composed config as Hydra gave it
            log.info("tactile-run %s", " ".join(hc.overrides.task))     # the log's first line (opens it)
        if decision == "skip":
            console(f"run {run_dir}: skipped (succeeded before with the same config and code)")
            return 0
        if decision == "analyse":
            console(f"run {run_dir}: recorded before with the same config and code; its analysis is missing "
                    f"or incomplete: analysing it again")
            result = RunResult("success", run_dir, None, run_dir / "run.zarr")
        else:
            result = run_protocol(settings, run_dir, overrides=list(hc.overrides.task), console=console,
                                  interrupts=interrupts)
        interrupts.phase = "writing"                  # the run is recorded: a signal now skips the analysis
    except ValueError as exc:                       # ProtocolError, ConfigError, RunDirBusy: bad input
        _report(verbose, exc, "error")
        return BAD_INPUT
    except Exception as exc:
        _report(verbose, exc, "run failed")
        return EXIT_CODES["failed"]
    if result.status == "planned":
        return 0
    detail = f" ({result.error})" if result.error else ""
    code = EXIT_CODES.get(result.status, 1)
    if settings.analyze and interrupts.count and result.status != "failed":
        console(f"run {run_dir}: {result.status}{detail}; not analysed (stopped by the operator): "
                f"`tactile-analyze run={result.store}`")
        return EXIT_CODES["aborted"]               # interrupted, as a Ctrl-C a moment later in the analysis
    if settings.analyze and result.status in ("success", "aborted"):
        try:
            with interrupts.during("analysis"):
                hand_off(result, settings.analysis, console=console)
        except (Exception, KeyboardInterrupt) as exc:
            if isinstance(exc, Exception) and not interrupts.count:     # the recording is safe: say what went wrong
                _report(verbose, exc, "analysis failed")
                console(f"run {run_dir}: {result.status}{detail}, recorded; analysis failed ({type(exc).__name__}); "
                        f"analyse it again with `tactile-analyze run={result.store}`")
                return code or EXIT_CODES["failed"]
            # Ctrl-C, or an error after one (it cut a library's code short and the cleanup raised)
            console(f"run {run_dir}: {result.status}{detail}; analysis interrupted (none of it written); "
                    f"analyse it with `tactile-analyze run={result.store}`")
            return EXIT_CODES["aborted"]
    console(f"run {run_dir}: {result.status}{detail}")
    if code:
        jobresults.note_error(f"run {run_dir}: {result.status}{detail}")
    return code


def check_run_dir(settings, hc, run_dir: Path) -> None:
    """Before anything is written in ``run_dir``: the protocol's name is a plain name, a sweep's
    job directory is inside the sweep directory (:mod:`runstore.paths`), and, unless resuming,
    the directory holds no run (a finished run's record is never rewritten). ``ValueError``.
    ``settings``: the run's :class:`~protocols.settings.RunSettings`."""
    paths.component(settings.protocol.name, "protocol.name")
    if hc.mode == RunMode.MULTIRUN:
        paths.within(hc.sweep.dir, run_dir, "hydra.sweep.subdir")
    if not settings.resume:
        rundir.refuse_finished(run_dir)


def record_config(run_dir: Path, cfg) -> None:
    """Hydra's record of the job in ``run_dir/.hydra/``: ``config.yaml`` (the job's config),
    ``hydra.yaml`` and ``overrides.yaml``, as Hydra writes them (``hydra.output_subdir`` is
    null: the run writes them itself, after its checks, never over a finished run's;
    :mod:`runstore.files`)."""
    hydra_cfg = HydraConfig.instance().cfg
    for name, node in (("config.yaml", cfg), ("hydra.yaml", hydra_cfg),
                       ("overrides.yaml", hydra_cfg.hydra.overrides.task)):
        files.write_text(run_dir, f".hydra/{name}", OmegaConf.to_yaml(node), record=True)


def _report(verbose: bool, exc: Exception, what: str) -> None:
    jobresults.note_error(report(exc, what, verbose))      # a sweep names its job with this line
    log.error(f"{what}: {exc}", exc_info=exc)


def _refuse_parallel_hardware(settings, hc) -> None:
    """One robot: real hardware only with Hydra's sequential launcher."""
    launcher = str(OmegaConf.select(hc, "launcher._target_", default=""))
    if settings.backend != "sim" and launcher and not launcher.endswith("BasicLauncher"):
        raise ValueError(f"hydra/launcher: {launcher} runs jobs in parallel; hardware="
                         f"{settings.backend} drives one robot, so sweeps on it must use the "
                         f"default sequential launcher")


def step_fields(kind: str) -> list[str] | None:
    """The parameters of step kind ``kind`` (None for an unknown kind), for the one-line
    error on a misspelt step key."""
    from dataclasses import fields

    from .steps import STEP_KINDS  # the step registry: imported only on an error
    cls = STEP_KINDS.get(kind)
    return None if cls is None else [f.name for f in fields(cls) if f.name != "key"]


@hydra.main(config_path=str(CONF_DIR), config_name="config", version_base=None)
def _app(cfg) -> None:
    jobresults.record(run_job(cfg))             # with -m on disk, so that any launcher brings it back


def main() -> None:
    from .entry import answer_without_hydra
    answer_without_hydra(sys.argv[1:])
    register()
    paths.register_resolvers()               # ${tf_name:...} in the run directories' names
    logging.raiseExceptions = False          # a log file on a full disk must not print tracebacks
    _interrupts.install()                    # the run owns Ctrl-C and SIGTERM (protocols.interrupts)
    # protocols are data: no Hydra settings, no code; a sweep's exit status is its highest job's
    sys.exit(jobresults.run(_app, step_fields=step_fields))


class RunDirLock(Callback):
    """One run directory, one writer: lock ``hydra.run.dir`` (``hydra.sweep.dir`` with ``-m``)
    before Hydra writes anything there (:mod:`runstore.rundir`); a second ``tactile-run``
    on the same directory is refused with one line, exit 2, leaving the first one's files alone.
    Before that, the directory is checked: inside the root its template starts with
    (``outputs/``, :mod:`runstore.paths`), whatever ``protocol.name`` holds, and not a
    finished run's (unless ``resume=true``). A job that recorded nothing (``plan_only``, a bad
    config, a failed connection) leaves no directory (:func:`runstore.rundir.remove_if_unused`;
    with ``-m`` once the sweep has read its jobs' results, in the process that started it)."""

    def on_run_start(self, config, **kwargs) -> None:
        directory = self._checked(config, "run")
        self._take(directory)                  # a run still recording there: "in use by another process"
        if not config.get("resume"):
            self._refuse(rundir.refuse_finished, directory)

    def on_job_end(self, config, **kwargs) -> None:
        rundir.retire_run_logs()           # the next job's first lines never reach this run's log

    def on_run_end(self, config, **kwargs) -> None:
        rundir.release(config.hydra.run.dir)
        rundir.remove_if_unused(config.hydra.run.dir)      # nothing ran: no empty run directory

    def on_multirun_start(self, config, **kwargs) -> None:
        directory = self._checked(config, "sweep")
        self._take(directory)
        if not config.get("resume"):
            self._refuse(_refuse_finished_sweep, directory)

    def on_multirun_end(self, config, **kwargs) -> None:
        for job in Path(config.hydra.sweep.dir).iterdir():
            if job.is_dir():
                rundir.remove_if_unused(job)
        rundir.release(config.hydra.sweep.dir)
        rundir.remove_if_unused(config.hydra.sweep.dir)

    @classmethod
    def _checked(cls, config, kind: str) -> str:
        """``hydra.<kind>.dir``, refused if it leaves the root its template starts with, or if the
        protocol's name is not a plain name (its directory name is made safe either way)."""
        template = OmegaConf.to_container(config.hydra[kind], resolve=False)["dir"]
        directory = str(config.hydra[kind].dir)
        cls._refuse(paths.within, paths.template_root(str(template)), directory, f"hydra.{kind}.dir")
        if OmegaConf.select(config, "protocol.name", default=None) is not None:
            cls._refuse(paths.component, config.protocol.name, "protocol.name")
        return directory

    @classmethod
    def _take(cls, directory) -> None:
        cls._refuse(rundir.acquire, directory)

    @staticmethod
    def _refuse(check, *args) -> None:
        """``check(*args)``; a ``ValueError`` is one line and exit 2 (Hydra would turn a
        callback's exception into a warning and go on)."""
        try:
            check(*args)
        except ValueError as exc:
            print(f"error: {exc}", file=sys.stderr)
            raise SystemExit(BAD_INPUT) from None


def _refuse_finished_sweep(directory) -> None:
    """A sweep directory whose jobs hold runs is refused unless the sweep is resumed."""
    done = sorted(p.parent.name for p in Path(directory).glob("*/run.json"))
    if done:
        raise rundir.RunFinished(f"hydra.sweep.dir {directory} holds the runs of an earlier sweep "
                                 f"({', '.join(done[:3])}{', ...' if len(done) > 3 else ''}); their records are never "
                                 f"rewritten: resume it with the same command and resume=true, or choose another "
                                 f"hydra.sweep.dir")


class SweepSummary(jobresults.SweepResults):
    """At the end of a multirun, one table of every job that ran: a column per swept
    parameter, status, headline results, from the job directories on disk (any launcher);
    and a figure of each headline metric against each swept parameter (:mod:`.sweepfig`).

    Written to ``summary.csv``, ``summary.md`` and ``sweep.png`` at the sweep's root
    directory; the sweep's exit status is its highest job's (:mod:`cliapp.jobresults`).
    """

    def summarise(self, config, results: list[dict]) -> None:
        root = Path(config.hydra.sweep.dir)
        rows = sweep_rows(root)
        recorded = {r["job"] for r in rows}          # a job that recorded nothing is a row too, saying why
        rows += [{"job": Path(r["dir"]).name, **override_cells(r.get("overrides") or []),
                  "status": jobresults.outcome(r), "error": r.get("error") or ""}
                 for r in results if r["code"] != 0 and Path(r["dir"]).name not in recorded]
        rows.sort(key=lambda r: _job_number(r["job"]))
        if rows:
            write_summary(root, rows)
            figure = ""
            try:
                from .sweepfig import sweep_figure
                figure = ", sweep.png" if sweep_figure(root, rows, swept_columns(rows)) else ""
            except Exception as exc:      # noqa: BLE001 - the table is the record; the figure a view of it
                log.warning(f"sweep figure not drawn: {type(exc).__name__}: {exc}")
            unanalysed = sum(r["status"] == "success" and r.get("analysis") != "complete" for r in rows) \
                if config.get("analyze") else 0
            print(f"sweep {root}: {jobresults.counts(results)}"
                  + (f"; {unanalysed} successful run(s) not (completely) analysed" if unanalysed else "")
                  + f"; summary.md, summary.csv{figure}")



#: overrides that say how a sweep is shown, not what it varies
QUIET_OVERRIDES = ("progress", "verbose", "resume", "analyze", "analysis.progress", "analysis.figures")


def sweep_rows(root: Path) -> list[dict]:
    """One row per job directory under ``root`` that holds a ``run.json``: ``job``, a column per
    override (its key, ``protocol.sweep_speed``; :func:`swept_columns` says which vary),
    ``status``, ``run_id``, ``error``, ``analysis`` (state), ``analysis_name`` and the
    headline of its current analysis (``result.*``; a per-finger ``slip`` as
    ``result.slip.<finger>.<field>`` columns)."""
    from . import resume
    rows = []
    for run_json in sorted(root.glob("*/run.json"), key=lambda p: _job_number(p.parent.name)):
        job = run_json.parent
        info = json.loads(run_json.read_text())
        overrides_file = job / ".hydra" / "overrides.yaml"
        overrides = OmegaConf.load(overrides_file) if overrides_file.exists() else info.get("overrides") or []
        row = {"job": job.name, **override_cells(overrides)}
        row.update({"status": info.get("status"), "run_id": info.get("run_id"), "error": info.get("error") or "",
                    "analysis": resume.analysis_state(job)})
        current = analyses.current_dir(job)
        if current is not None:                          # results only from a whole analysis
            row["analysis_name"] = analyses.current_name(job)
            headline = json.loads((current / analyses.SUMMARY).read_text()).get("headline", {})
            row.update({f"result.{k}": v for k, v in runinfo.flatten(headline).items()})
        rows.append(row)
    return rows


def override_cells(overrides) -> dict[str, str]:
    """A job's overrides as its table's cells: key → value (``protocol.sweep_speed`` → ``20``),
    those that only say how a sweep is shown (:data:`QUIET_OVERRIDES`) left out."""
    cells = {}
    for o in overrides:
        key, _, value = str(o).partition("=")
        if key.lstrip("+~") not in QUIET_OVERRIDES:
            cells[key.lstrip("+~")] = value
    return cells


def swept_columns(rows: list[dict]) -> list[str]:
    """The override columns whose value differs between the rows (every override column of a
    one-job sweep): the sweep's parameters."""
    fixed = {"job", "status", "run_id", "error", "analysis", "analysis_name"}
    keys = [k for k in dict.fromkeys(k for r in rows for k in r) if k not in fixed and not k.startswith("result.")]
    if len(rows) == 1:
        return keys
    return [k for k in keys if len({str(r.get(k)) for r in rows}) > 1]


def _job_number(name: str) -> int:
    head = name.split("_", 1)[0]
    return int(head) if head.isdigit() else 1 << 30


def write_summary(root: Path, rows: list[dict]) -> None:
    """``summary.csv`` and ``summary.md`` at the sweep's root (never through a link): the job,
    a column per swept parameter, then status and results (overrides common to every job are
    left out of the columns: they are in each job's ``.hydra/overrides.yaml``)."""
    swept = swept_columns(rows)
    fixed_overrides = {k for r in rows for k in r} - set(swept) - {"job", "status", "run_id", "error", "analysis",
                                                                    "analysis_name"}
    columns = ["job", *swept] + [k for k in dict.fromkeys(k for r in rows for k in r)
                                 if k not in swept and k != "job" and
                                 (k.startswith("result.") or k not in fixed_overrides)]
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=columns, extrasaction="ignore")
    writer.writeheader()
    writer.writerows(rows)
    files.write_text(root, "summary.csv", text.getvalue())
    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    lines += ["| " + " | ".join(_cell(r.get(c, "")) for c in columns) + " |" for r in rows]
    files.write_text(root, "summary.md", "\n".join(lines) + "\n")


def _cell(value) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value).replace("|", "\\|")

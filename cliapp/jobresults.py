"""A result per Hydra job, on disk, so that a sweep's exit status and table survive any launcher.

With ``-m`` a job runs in this process (Hydra's basic launcher), in a worker process
(``hydra/launcher=joblib``) or in a process of its own, perhaps on another machine
(``hydra/launcher=submitit_local``, ``submitit_slurm``): what a job keeps in a global never
reaches the process that started the sweep. So every job writes ``job_result.json`` into its
own output directory (``hydra.runtime.output_dir``), atomically, twice::

    {"job": 3, "overrides": ["run=['a/run.zarr']"], "pid": 4711, "host": "node7", "code": null}  # started
    {"job": 3, ..., "code": 2, "rows": [{"run": "a/run.zarr", "result": "error: ..."}],
     "error": "error: ..."}                                                                      # ended

and the process that started the sweep reads them back when it ends (:class:`SweepResults`,
``on_multirun_end``): the sweep's exit status is the highest of its jobs' (3 interrupted,
2 bad input, 1 failed, 0 done); every job that did not succeed is named in one line with its
outcome and its error (:func:`failures`), and the sweep's count is of its jobs, not of the runs
they left (:func:`counts`); a job that started and left no result (its process was killed, ran
out of memory or crashed) counts as failed. When the launcher
itself stops the sweep (a worker process died, Ctrl-C), :func:`run` still ends it that way,
from the files there are. A single run (no ``-m``) keeps its result in this process.
"""

from __future__ import annotations

import json
import os
import socket
import sys
from pathlib import Path

from hydra.core.hydra_config import HydraConfig
from hydra.experimental.callback import Callback
from hydra.types import RunMode
from omegaconf import OmegaConf

from tactile_flow.runstore import files
from tactile_flow.runstore.status import ExitCode

from .runner import error_line, run_app, signals_received

RESULT_FILE = "job_result.json"
#: what a job's exit code says happened to it
OUTCOMES = {ExitCode.OK: "succeeded", ExitCode.FAILED: "failed", ExitCode.BAD_INPUT: "refused (bad input)",
            ExitCode.INTERRUPTED: "aborted"}
_process = {"code": 0}                  # a single run's exit code; at the end of a sweep, the sweep's
_open_sweep: dict = {}                  # the config of a sweep that started here and has not ended
_job_error: dict = {}                   # the error line the running job printed (note_error)


def note_error(line: str) -> None:
    """The one line the running job printed for its error, kept with its result."""
    _job_error["line"] = line


def record(code: int, rows: list[dict] = ()) -> None:
    """The job's exit code, its rows for the sweep's table and the error it noted
    (:func:`note_error`): in the job's output directory with ``-m``; a single run's code is
    kept in this process (what :func:`run` returns)."""
    hc = HydraConfig.get()
    error = _job_error.pop("line", None)
    if hc.mode == RunMode.MULTIRUN:
        _write(Path(hc.runtime.output_dir), {**_job(hc), "code": int(code), "rows": list(rows), "error": error})
    else:
        _process["code"] = max(_process["code"], int(code))


def collect(root: Path) -> list[dict]:
    """Every job result under the sweep directory ``root`` (``<job dir>/job_result.json``), in
    job order; one that cannot be read is a job without a result (``code`` None)."""
    results = []
    for path in root.glob(f"*/{RESULT_FILE}"):
        try:
            result = json.loads(path.read_text())
            if not isinstance(result.get("job"), int) or "code" not in result:
                raise ValueError("not a job result")
        except (OSError, ValueError, AttributeError):
            result = {"job": path.parent.name, "code": None}
        results.append({"overrides": [], "rows": [], **result, "dir": str(path.parent)})
    return sorted(results, key=lambda r: (r["job"] if isinstance(r["job"], int) else 1 << 30, r["dir"]))


def sweep_code(results: list[dict]) -> int:
    """The highest exit code of the jobs; a job without a result counts as failed."""
    return max((ExitCode.FAILED if r["code"] is None else r["code"] for r in results), default=0)


def describe(result: dict) -> str:
    """``job 3 (run=...)``: a job, named by its number and overrides, for one line."""
    overrides = " ".join(result.get("overrides") or [])
    return f"job {result['job']}" + (f" ({overrides})" if overrides else "")


def outcome(result: dict) -> str:
    """What happened to a job, in a word or two (a job without a result: failed)."""
    return OUTCOMES.get(result["code"], f"exit {result['code']}") if result["code"] is not None else "failed"


def failures(results: list[dict]) -> list[str]:
    """One line per job that did not succeed: ``job 1 (overrides): refused (bad input): <its error>``."""
    lines = []
    for r in results:
        if r["code"] is None:
            where = f" (pid {r['pid']} on {r.get('host')})" if r.get("pid") else ""
            lines.append(f"{describe(r)}: no result: its process{where} ended before the job did (killed, out "
                         f"of memory or crashed); counted as failed")
        elif r["code"] != ExitCode.OK:
            error = r.get("error")
            lines.append(f"{describe(r)}: {outcome(r)}" + (f": {error}" if error else ""))
    return lines


def counts(results: list[dict]) -> str:
    """``3 jobs: 2 succeeded, 1 refused (bad input)``: every job of the sweep, by outcome."""
    tally: dict[str, int] = {}
    for r in results:
        tally[outcome(r)] = tally.get(outcome(r), 0) + 1
    parts = [f"{n} {word}" for word, n in sorted(tally.items(), key=lambda kv: kv[0] != "succeeded")]
    return f"{len(results)} job{'s' if len(results) != 1 else ''}" + (": " + ", ".join(parts) if parts else "")


class SweepResults(Callback):
    """The results of a sweep's jobs, read from disk in the process that started it.
    A CLI's callback derives from it and draws its table in :meth:`summarise`."""

    def on_multirun_start(self, config, **kwargs) -> None:
        _open_sweep["config"] = config
        for stale in Path(config.hydra.sweep.dir).glob(f"*/{RESULT_FILE}"):   # a sweep dir used again
            stale.unlink(missing_ok=True)

    def on_job_start(self, config, **kwargs) -> None:
        hc = HydraConfig.get()
        if hc.mode == RunMode.MULTIRUN:
            _write(Path(hc.runtime.output_dir), {**_job(hc), "code": None})

    def on_multirun_end(self, config, **kwargs) -> None:
        _open_sweep.pop("config", None)
        results = collect(Path(config.hydra.sweep.dir))
        for line in failures(results):
            print(line, file=sys.stderr)
        self.summarise(config, results)
        _process["code"] = max(_process["code"], sweep_code(results))

    def summarise(self, config, results: list[dict]) -> None:
        """Write the sweep's table from ``results`` (:func:`collect`)."""


def run(app, **run_app_kwargs) -> int:
    """Run a ``@hydra.main`` app with :func:`cliapp.runner.run_app`; the exit code of the run,
    or of the sweep from its job results. A sweep the launcher stops (a worker process died,
    a job could not be submitted, Ctrl-C) is ended from the results there are: its callbacks'
    ``on_multirun_end`` run as Hydra's would have, and the exit status is at least 1 (3 for
    Ctrl-C)."""

    def app_ending_its_sweep() -> None:
        try:
            app()
        except (Exception, KeyboardInterrupt) as exc:
            config = _open_sweep.get("config")
            if config is None:
                raise                                      # before any job: run_app's one line
            interrupted = isinstance(exc, KeyboardInterrupt) or signals_received()
            print("interrupted" if interrupted else f"error: the sweep stopped: {error_line(exc)}",
                  file=sys.stderr)
            from hydra._internal.callbacks import Callbacks
            Callbacks(config).on_multirun_end(config=config)
            _process["code"] = max(_process["code"], ExitCode.INTERRUPTED if interrupted else ExitCode.FAILED)

    run_app(app_ending_its_sweep, **run_app_kwargs)
    return int(_process["code"])


def _job(hc) -> dict:
    return {"job": int(hc.job.num), "overrides": list(OmegaConf.to_container(hc.overrides.task)),
            "pid": os.getpid(), "host": socket.gethostname()}


def _write(directory: Path, result: dict) -> None:
    """``directory/job_result.json``, whole or not at all, never through a link
    (:func:`runstore.files.write_text`: written aside, then renamed)."""
    directory.mkdir(parents=True, exist_ok=True)
    files.write_text(directory, RESULT_FILE, json.dumps(result, default=str) + "\n", fsync=False)

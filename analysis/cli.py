"""``tactile-analyze``: (re-)analyse recorded runs (Hydra app, config group ``analysis``).

    tactile-analyze run=outputs/2026-01-01/12-00-00_straws_sweep/run.zarr
    tactile-analyze run=outputs/2026-01-01 analysis.flow.method=dis    # every run.zarr below
    tactile-analyze -m run=outputs/2026-01-01                          # one job per run.zarr below
    tactile-analyze -m 'run=outputs/**/run.zarr' batch=8 hydra/launcher=joblib   # 8 runs per job

``run=`` names run stores: a ``run.zarr`` (or a packed ``run.zarr.zip``, as ``tactile-import``
writes), a directory (every run store below it), a
shell-style pattern (``*``, ``?``, ``**`` for any depth; :func:`find_stores`), or a list of
these (``run=[A,B]``). Without ``-m`` they are analysed in ``workers`` processes forked
from this one (default: the cores available; the start-up paid once per process), with one
progress line; with ``-m`` they become jobs (one process each unless ``workers=`` is given) (:func:`runs_as_jobs`), ``batch=N`` runs each, for any Hydra
launcher. Each job leaves its result on disk (:mod:`cliapp.jobresults`).

Exit status: 0 analysed, 2 bad input or config (nothing written), 1 analysis failed, 3
interrupted (Ctrl-C or SIGTERM; nothing partial is left); a sweep's is its highest job's.
Errors are one line; ``verbose=true`` adds the traceback. Several runs also write
``analysis_summary.csv`` / ``.md`` (one row per run: the ``headline`` of its summary): in the
directory given as ``run=`` (a pattern: the directory it starts from), or with ``-m`` in the
sweep directory (``multirun/<date>/<time>_analyze/``); nothing goes to the current directory.
"""

from __future__ import annotations

import csv
import glob
import io
import os
import re
import sys
import traceback
from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from hydra.types import RunMode

import tactile_flow.cliapp.jobresults as jobresults
from tactile_flow.cliapp.runner import signals_received
from tactile_flow.cliapp.sensors import composed_sensor
from tactile_flow.cliapp.workers import resolve_workers
from tactile_flow.validation import ConfigError
from tactile_flow.conf import DIR as CONF_DIR
from tactile_flow.runstore import files, packed
from tactile_flow.runstore.analyses import AnalysisNameTaken
from tactile_flow.runstore.paths import PathOutsideRoot
from tactile_flow.runstore.rundir import RunDirBusy

from .load import AnalysisInputError

BAD_INPUT, FAILED, INTERRUPTED = 2, 1, 3
MULTIRUN_FLAGS = ("-m", "--multirun")
PACKED_RUN = packed.packed_name("run.zarr")


def find_stores(spec: str) -> list[Path]:
    """The run stores ``spec`` names: itself if it is a run store; every run store (``run.zarr``,
    or ``run.zarr.zip`` packed) below it
    if it is a directory (sorted); for a shell-style pattern that is not an existing path
    (``*``, ``?``, ``[...]``; ``**`` any depth), the stores of every directory it matches
    (sorted, each once); else ``[spec]`` (its analysis says what is wrong with it)."""
    path = Path(spec)
    if not path.exists() and glob.has_magic(spec):
        matched = (find_stores(m) for m in sorted(glob.glob(spec, recursive=True))
                   if Path(m).is_dir() or packed.is_packed(m))
        return list(dict.fromkeys(s for stores in matched for s in stores))
    if packed.is_store(path) or path.name.endswith((".zarr", ".zarr" + packed.SUFFIX)):
        return [path]
    if path.is_dir():
        return _stores_below(path)
    return [path]


def _stores_below(root: Path) -> list[Path]:
    """Every run store below ``root`` (a ``run.zarr`` directory, or a packed ``run.zarr.zip``),
    sorted; the walk skips the inside of ``*.zarr`` stores (hundreds of chunk directories
    each, and never a run)."""
    found = []
    for here, dirs, names in os.walk(root):
        if "run.zarr" in dirs or PACKED_RUN in names:
            found.append(packed.find(here))
        dirs[:] = [d for d in dirs if not d.endswith(".zarr")]
    return sorted(found)


def table_dir(spec: str) -> Path:
    """Where the table of the runs ``spec`` names goes: the directory itself, or for a pattern
    the directory before its first wildcard."""
    path = Path(spec)
    if path.exists():
        return path
    first = next((i for i, part in enumerate(path.parts) if glob.has_magic(part)), len(path.parts))
    return Path(*path.parts[:first]) if first else Path(".")


def analyse_paths(spec: str, analysis_cfg, verbose: bool = False, console=print,
                  table: bool = True, name: str | None = None, force: bool = False,
                  sensor=None, workers: int = 1) -> tuple[int, list[dict]]:
    """Analyse the run stores ``spec`` names (:func:`find_stores`) into analyses called ``name``
    (default: their key, :func:`analysis.run.default_name`); never raises. The exit code and
    one row per run (``run``, ``analysis`` (its name), ``result``, then the summary's
    ``headline``); with ``table`` and several runs, their table is written (:func:`table_dir`).
    ``sensor``: the :class:`tactile.sensor.SensorModel` asked for (``sensor=``); a store
    recorded with another is refused (bad input), the others analysed.

    Several runs are spread over ``workers`` processes forked from this one
    (:mod:`cliapp.workers`: the start-up paid once per process), each analysis in one process
    (``analysis.workers`` 1 unless given) and without its own progress bars: one progress line
    of runs done, total and rate (on a terminal), each run's lines printed as it ends. The
    results are the same with any number of workers; the rows keep the stores' order."""
    from tactile_flow.cliapp.progress import progress_bar
    from tactile_flow.cliapp.workers import WorkerDied, each_in_workers
    from tactile_flow.runstore.catalogue import kept_open
    from tactile_flow.runstore.provenance import same_code

    from .run import analyze_run  # noqa: F401 - loaded here, before any worker is forked
    stores = find_stores(spec) if spec else []
    if not stores:
        print(f"error: run={spec}: no run.zarr found; expected a run.zarr, a directory or a pattern of runs",
              file=sys.stderr)
        return BAD_INPUT, []
    if len(stores) == 1:
        code, row = analyse_one(stores[0], analysis_cfg, verbose, console, name, force, sensor)
        return code, [row]
    cfg = _one_process_each(analysis_cfg, workers)
    if workers > 1:
        _load_before_forking(stores[0], cfg, sensor)
    code, rows = 0, [None] * len(stores)
    bar = progress_bar(total=len(stores), unit="run", desc="analyse", dynamic_ncols=True)
    say = (lambda line: bar.write(line)) if not bar.disable else console
    _JOB[:] = [_checked(cfg), verbose, name, force, sensor]      # the forked workers inherit it: one path a job
    try:
        with same_code(), kept_open(), bar:
            for i, got in each_in_workers(_analyse_job, stores, workers):
                if isinstance(got, BaseException):           # not one of analyse_one's: a bug; one line
                    got = (FAILED, {"run": str(stores[i]), "analysis": name or "",
                                    "result": f"failed: {type(got).__name__}: {got}"},
                           [("err", f"analysis of {stores[i]} failed: {got}")])
                c, rows[i], lines = got
                for where, line in lines:
                    if where == "err":
                        print(line, file=sys.stderr)
                    else:
                        say(line)
                bar.update(1)
                code = max(code, c)
                if c == INTERRUPTED:                         # one process: the analysis caught the Ctrl-C
                    return INTERRUPTED, [r for r in rows if r is not None]
    except WorkerDied as exc:
        print(f"analysis failed: {exc}; the runs analysed are kept: run the same command again to finish "
              f"(a kept analysis is reused)", file=sys.stderr)
        code = max(code, FAILED)
    except KeyboardInterrupt:                 # Ctrl-C or SIGTERM: the workers are ended, nothing partial is left
        _quiet_after_interrupt()
        left = [s for s, r in zip(stores, rows) if r is None]
        print(f"analysis interrupted: {len(stores) - len(left)} of {len(stores)} runs analysed; the same command "
              f"again analyses the others", file=sys.stderr)
        return INTERRUPTED, [r for r in rows if r is not None]
    rows = [r if r is not None else {"run": str(s), "analysis": name or "", "result": "not analysed"}
            for s, r in zip(stores, rows)]
    if table:
        write_table(table_dir(spec), rows)
    return code, rows


def _load_before_forking(store: Path, analysis_cfg, sensor) -> None:
    """What every worker would load for itself, loaded once here before they are forked: the
    tactile model of the first run's sensor (its frame plans, ~0.7 s) and, with figures on,
    the plotting modules (~0.4 s). Anything wrong is left for the run's own analysis to say."""
    from .config import for_sensor, load_config
    from .load import peek_sensor
    from .pipeline import get_model
    try:
        cfg = load_config(analysis_cfg)
        recorded = peek_sensor(store, sensor)
        if not cfg.enabled or recorded is None:
            return
        get_model(for_sensor(cfg, recorded).tactile, recorded)
        if cfg.figures:
            import matplotlib.figure  # noqa: F401
            import matplotlib.tri  # noqa: F401
            import mpl_toolkits.mplot3d  # noqa: F401

            from . import agg_canvas  # noqa: F401
    except Exception:  # noqa: BLE001 - each run's analysis reports its own problem
        return


def _one_process_each(analysis_cfg, workers: int):
    """The analysis config of a run analysed beside others: no progress bars of its own, and
    beside others in ``workers`` > 1 processes one core each (``analysis.workers`` 1 unless
    given)."""
    from omegaconf import OmegaConf
    if analysis_cfg is None or not OmegaConf.is_config(analysis_cfg):
        analysis_cfg = OmegaConf.create(analysis_cfg or {})
    cfg = OmegaConf.create(OmegaConf.to_container(analysis_cfg, resolve=True))
    if cfg.get("workers") is None and workers > 1:
        cfg.workers = 1
    cfg.progress = False
    return cfg


_JOB: list = []
"""What every run of :func:`analyse_paths`' dataset is analysed with (config, verbose, name,
force, sensor): set before the workers are forked, so a job sent to one is only its store's
path (the config and the sensor model pickled for every run cost ~3 ms of it)."""


def _checked(analysis_cfg):
    """The analysis config validated once for every run (:class:`analysis.config.AnalysisConfig`),
    or as given if it is wrong: each run's analysis then says so."""
    from .config import load_config
    try:
        return load_config(analysis_cfg)
    except Exception:  # noqa: BLE001 - reported per run, as before
        return analysis_cfg


def _analyse_job(store) -> tuple[int, dict, list[tuple[str, str]]]:
    """:func:`analyse_one` of ``store`` (with :data:`_JOB`) in a worker: its output lines kept
    (``("out"|"err", line)``) for the parent to print."""
    cfg, verbose, name, force, sensor = _JOB
    lines: list[tuple[str, str]] = []
    code, row = analyse_one(store, cfg, verbose, lambda line: lines.append(("out", str(line))), name, force,
                               sensor, err=lambda line: lines.append(("err", line)))
    return code, row, lines


def analyse_one(store: Path, analysis_cfg, verbose: bool, console, name, force, sensor,
                err=None) -> tuple[int, dict]:
    """Analyse one store; never raises but for an interrupt's ``KeyboardInterrupt`` turned into
    the exit code :data:`INTERRUPTED`. ``(exit code, row)``; error lines go to ``err``
    (default: stderr)."""
    from .run import analyze_run
    err = err or (lambda line: print(line, file=sys.stderr))
    row = {"run": str(store), "analysis": name or ""}
    code = 0
    try:
        summary = analyze_run(store, analysis_cfg, name=name, force=force, console=console, sensor=sensor)
        row["analysis"] = summary.get("analysis") or row["analysis"]
        row["result"] = "analysed"
        row.update(summary.get("headline", {}))
    except (AnalysisInputError, ConfigError, PathOutsideRoot, RunDirBusy, AnalysisNameTaken) as exc:
        _report(exc, "error", verbose, err)  # bad input: a planted link, a name, a directory in use, another sensor
        row["result"] = f"error: {exc}"
        code = BAD_INPUT
    except Exception as exc:  # noqa: BLE001 - one line per failed run, keep going
        if signals_received():  # a Ctrl-C cut a library's code short and its cleanup raised this
            _quiet_after_interrupt()
            return _interrupted(store, row, err)
        _report(exc, f"analysis of {store} failed", verbose, err)
        row["result"] = f"failed: {type(exc).__name__}: {exc}"
        code = FAILED
    except KeyboardInterrupt:  # Ctrl-C or SIGTERM: stop here; the analysis leaves no partial files
        _quiet_after_interrupt()
        return _interrupted(store, row, err)
    return code, row


def _quiet_after_interrupt() -> None:
    """An interrupt inside zarr's event loop leaves coroutines never awaited; their
    ``RuntimeWarning`` at collection would add lines under the one that says what happened."""
    import warnings
    warnings.filterwarnings("ignore", message=r"coroutine .* was never awaited", category=RuntimeWarning)


def _interrupted(store: Path, row: dict, err) -> tuple[int, dict]:
    err(f"analysis of {store} interrupted; analyse it again with tactile-analyze run={store}")
    row["result"] = "interrupted"
    return INTERRUPTED, row


def _report(exc: Exception, what: str, verbose: bool, err=None) -> None:
    err = err or (lambda line: print(line, file=sys.stderr))
    if verbose:
        err("".join(traceback.format_exception(exc)).rstrip("\n"))
    err(f"{what}: {exc}")


def write_table(root: Path, rows: list[dict]) -> None:
    """``analysis_summary.csv`` and ``analysis_summary.md`` in ``root`` (never through a link:
    :mod:`runstore.files`): one row per analysis, nested values (the per-finger ``slip``) as
    columns of their own (``slip.ff.slip_class``...), never a dict printed as text."""
    from tactile_flow.runstore.runinfo import flatten
    rows = [flatten(r) for r in rows]
    columns = list(dict.fromkeys(k for r in rows for k in r))
    text = io.StringIO()
    w = csv.DictWriter(text, fieldnames=columns)
    w.writeheader()
    w.writerows(rows)
    files.write_text(root, "analysis_summary.csv", text.getvalue())
    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    for r in rows:
        cells = [f"{r.get(c):.4g}" if isinstance(r.get(c), float) else str(r.get(c, "")).replace("|", "\\|")
                 for c in columns]
        lines.append("| " + " | ".join(cells) + " |")
    files.write_text(root, "analysis_summary.md", "\n".join(lines) + "\n")
    print(f"summary of {len(rows)} analyses: {root / 'analysis_summary.md'}")


class SummaryTable(jobresults.SweepResults):
    """After ``-m``: one table of every run of the sweep, from the jobs' results on disk; a
    run its job did not report (the job's process died, the job was interrupted, or the
    launcher stopped the sweep before the job started) is a row saying so."""

    def summarise(self, config, results: list[dict]) -> None:
        rows = []
        swept = _swept(results)
        for r in results:
            params = {k: v for k, v in _params(r["overrides"]).items() if k in swept}
            rows += [{"run": row["run"], **params, **{k: v for k, v in row.items() if k != "run"}}
                     for row in r["rows"]]
            reported = {row["run"] for row in r["rows"]}
            why = (f"failed: its job ({r['job']}) left no result" if r["code"] is None
                   else f"not analysed: its job ({r['job']}) stopped before it")
            rows += [{"run": run, "result": why} for run in run_specs(r["overrides"]) if run not in reported]
        reported = {row["run"] for row in rows}
        rows += [{"run": run, "result": "not analysed: the sweep stopped before its job started"}
                 for run in run_specs(config.hydra.overrides.task) if run not in reported]
        if rows:
            write_table(Path(config.hydra.sweep.dir), rows)


def _params(overrides) -> dict:
    """A job's overrides as ``{key: value}``, ``run=`` and ``batch=`` left out."""
    out = {}
    for o in overrides or []:
        key, _, value = str(o).partition("=")
        if key.lstrip("+~") not in ("run", "batch", "verbose"):
            out[key.lstrip("+~")] = value
    return out


def _swept(results: list[dict]) -> list[str]:
    """The override keys whose value differs between the sweep's jobs (a column each)."""
    params = [_params(r["overrides"]) for r in results]
    keys = list(dict.fromkeys(k for p in params for k in p))
    return [k for k in keys if len({p.get(k) for p in params}) > 1]


@hydra.main(config_path=str(CONF_DIR), config_name="analyze", version_base=None)
def _app(cfg) -> None:
    from omegaconf import OmegaConf
    run = OmegaConf.select(cfg, "run", default=None)
    if run is None or OmegaConf.is_missing(cfg, "run"):
        print("error: run: expected run=PATH (a run.zarr, a directory or a pattern of runs)", file=sys.stderr)
        jobresults.record(BAD_INPUT)
        return
    sweep = HydraConfig.get().mode == RunMode.MULTIRUN          # the sweep's table, not one per job
    try:
        sensor = composed_sensor(cfg, default=None)
    except ConfigError as exc:
        _report(exc, "error", bool(cfg.get("verbose")))
        jobresults.record(BAD_INPUT)
        return
    try:
        workers = 1 if sweep and cfg.get("workers") is None else resolve_workers(cfg.get("workers"), "workers")
    except ValueError as exc:
        _report(exc, "error", False)
        jobresults.record(BAD_INPUT)
        return
    code, rows = 0, []
    for spec in (run if OmegaConf.is_list(run) else [run]):
        c, r = analyse_paths(str(spec), cfg.analysis, bool(cfg.get("verbose")), table=not sweep,
                             name=None if cfg.get("name") is None else str(cfg.name), force=bool(cfg.get("force")),
                             sensor=sensor, workers=workers)
        code, rows = max(code, c), rows + r
        if c == INTERRUPTED:
            break
    jobresults.record(code, rows)


# ----------------------------------------------------------------------------- runs as jobs
def runs_as_jobs(argv: list[str]) -> list[str]:
    """With ``-m``, ``run=`` rewritten before Hydra reads it into one job per ``batch=N`` run
    stores: ``run=[A,B],[C,D],[E]``, a sweep over lists, every path quoted (:func:`quoted`), so
    any character in a path is safe. Every store named, found below a directory or matched by
    a pattern (:func:`find_stores`), in order, each once. Without ``-m`` (or ``run=``), or if
    Hydra's parser refuses the override (Hydra then says why), ``argv`` is returned as it is."""
    at = [i for i, a in enumerate(argv) if _is_run(a)]
    if not at or not set(MULTIRUN_FLAGS) & set(argv):
        return argv
    try:
        specs = run_specs(argv)
    except Exception:                                  # noqa: BLE001 - Hydra's one line says what is wrong
        return argv
    batch = _batch(argv)
    stores = []
    for spec in specs:
        found = find_stores(spec) if spec else []
        if not found:
            _bad(f"run={spec}: no run.zarr found; expected a run.zarr, a directory or a pattern of runs")
        stores += [str(s) for s in found]
    stores = list(dict.fromkeys(stores))
    jobs = [stores[k:k + batch] for k in range(0, len(stores), batch)]
    value = ",".join("[" + ",".join(quoted(s) for s in job) + "]" for job in jobs)
    return [a for i, a in enumerate(argv) if i not in at] + [f"run={value}"]


def run_specs(overrides) -> list[str]:
    """Every value the ``run=`` overrides among ``overrides`` give, as the job will read them
    (Hydra's parser, then OmegaConf's ``\\${`` escape): a value, a list, a sweep of values or
    of lists, flattened in order."""
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from hydra.core.override_parser.types import ChoiceSweep, QuotedString
    specs = []
    for arg in filter(_is_run, overrides):
        value = OverridesParser.create().parse_override(arg).value()
        for v in (value.list if isinstance(value, ChoiceSweep) else [value]):
            specs += [x.text if isinstance(x, QuotedString) else str(x) for x in (v if isinstance(v, list) else [v])]
    return [spec.replace("\\${", "${") for spec in specs]


def _is_run(arg: str) -> bool:
    return arg.lstrip("+").split("=", 1)[0] == "run"


def quoted(text: str) -> str:
    """``text`` as a single-quoted value of Hydra's override grammar: a quote escaped, the
    backslashes before a quote or the closing quote doubled (Hydra reads other backslashes as
    they are), and ``${`` escaped for OmegaConf (no interpolation)."""
    text = text.replace("${", "\\${")
    return "'" + re.sub(r"(\\*)('|$)", lambda m: m[1] * 2 + ("\\'" if m[2] else ""), text) + "'"


def _batch(argv: list[str]) -> int:
    values = [a.split("=", 1)[1] for a in argv if a.lstrip("+").startswith("batch=")]
    if not values:
        return 1
    if not values[-1].isdigit() or int(values[-1]) < 1:
        _bad(f"batch={values[-1]}: expected the number of runs per job, a whole number from 1")
    return int(values[-1])


def _bad(line: str) -> None:
    print(f"error: {line}", file=sys.stderr)
    sys.exit(BAD_INPUT)


def _refuse_misread_runs(argv: list[str]) -> None:
    """Two ways of naming runs that Hydra would misread, refused with the form that does what
    was meant: ``glob(...)`` picks among a key's config options, not files (``run=glob(...)``
    would sweep over nothing and exit 0); a bare path (``tactile-analyze outputs/x``) is not an
    override (Hydra's own message would not say ``run=``)."""
    for before, arg in zip([""] + argv, argv):
        if arg.lstrip("+").startswith("run=glob("):
            pattern = arg.split("glob(", 1)[1].rstrip(")")
            _bad(f"{arg}: Hydra's glob() selects config options, not files; give the pattern itself: "
                 f"-m 'run={pattern}' (one job per run; batch=N for N runs per job)")
        if "=" not in arg and not arg.startswith("-") and not before.startswith("-") and Path(arg).exists():
            _bad(f"{arg}: a run is named by run=PATH; expected: tactile-analyze run={arg}")


def main() -> None:
    _refuse_misread_runs(sys.argv[1:])
    sys.argv[1:] = runs_as_jobs(sys.argv[1:])
    sys.exit(jobresults.run(_app))   # a config file is data: one line for a bad one, exit 2


if __name__ == "__main__":  # pragma: no cover
    main()

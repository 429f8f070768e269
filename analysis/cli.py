"""``tactile-analyze``: (re-)analyse recorded runs (Hydra app, config group ``analysis``).

    tactile-analyze run=outputs/2026-01-01/12-00-00_straws_sweep/run.zarr
    tactile-analyze run=outputs/2026-01-01 analysis.flow.method=dis    # every run.zarr below
    tactile-analyze -m run=A/run.zarr,B/run.zarr                        # a list of runs

Exit status: 0 analysed, 2 bad input or config (nothing written), 1 analysis failed, 3
interrupted (Ctrl-C or SIGTERM; nothing partial is left). Errors are one line; ``verbose=true``
adds the traceback. Several runs also write ``analysis_summary.csv`` / ``.md`` (one row per
run: the ``headline`` of its summary): in the directory given as ``run=``, or with ``-m`` in
the sweep directory (``multirun/<date>/<time>_analyze/``); nothing goes to the current directory.
"""

from __future__ import annotations

import csv
import sys
import traceback
from pathlib import Path

import hydra
from hydra.experimental.callback import Callback

from .config import AnalysisConfigError
from .load import AnalysisInputError

CONF_DIR = Path(__file__).resolve().parents[1] / "conf"
BAD_INPUT, FAILED, INTERRUPTED = 2, 1, 3
_state = {"code": 0, "rows": []}


def find_stores(path: Path) -> list[Path]:
    """``path`` itself if it is a run store, else every ``run.zarr`` below it (sorted)."""
    if (path / "zarr.json").is_file() or path.suffix == ".zarr":
        return [path]
    if path.is_dir():
        return sorted(p for p in path.rglob("run.zarr") if p.is_dir())
    return [path]


def analyse_paths(run: str, analysis_cfg, verbose: bool = False, console=print) -> int:
    """Analyse one run store or every run store under a directory; never raises. Exit code."""
    from .run import analyze_run
    stores = find_stores(Path(run))
    if not stores:
        print(f"error: {run}: no run.zarr found", file=sys.stderr)
        return BAD_INPUT
    code = 0
    for store in stores:
        row = {"run": str(store)}
        try:
            summary = analyze_run(store, analysis_cfg, console=console)
            row["result"] = "analysed"
            row.update({k: v for k, v in summary.get("headline", {}).items()})
        except (AnalysisInputError, AnalysisConfigError) as exc:
            _report(exc, "error", verbose)
            row["result"] = f"error: {exc}"
            code = max(code, BAD_INPUT)
        except Exception as exc:  # noqa: BLE001 - one line per failed run, keep going
            _report(exc, f"analysis of {store} failed", verbose)
            row["result"] = f"failed: {type(exc).__name__}: {exc}"
            code = max(code, FAILED)
        except KeyboardInterrupt:  # Ctrl-C or SIGTERM: stop here; the analysis leaves no partial files
            print(f"analysis of {store} interrupted; analyse it again with tactile-analyze run={store}",
                  file=sys.stderr)
            row["result"] = "interrupted"
            _state["rows"].append(row)
            return INTERRUPTED
        _state["rows"].append(row)
    if len(stores) > 1:
        write_table(Path(run), _state["rows"][-len(stores):])
    return code


def _report(exc: Exception, what: str, verbose: bool) -> None:
    if verbose:
        traceback.print_exception(exc)
    print(f"{what}: {exc}", file=sys.stderr)


def write_table(root: Path, rows: list[dict]) -> None:
    """``analysis_summary.csv`` and ``analysis_summary.md`` in ``root``."""
    columns = list(dict.fromkeys(k for r in rows for k in r))
    with open(root / "analysis_summary.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=columns)
        w.writeheader()
        w.writerows(rows)
    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    for r in rows:
        cells = [f"{r.get(c):.4g}" if isinstance(r.get(c), float) else str(r.get(c, "")).replace("|", "\\|")
                 for c in columns]
        lines.append("| " + " | ".join(cells) + " |")
    (root / "analysis_summary.md").write_text("\n".join(lines) + "\n")
    print(f"summary of {len(rows)} runs: {root / 'analysis_summary.md'}")


class SummaryTable(Callback):
    """After ``-m``: one table of every analysed run."""

    def on_multirun_end(self, config, **kwargs) -> None:
        if len(_state["rows"]) > 1:
            write_table(Path(config.hydra.sweep.dir), _state["rows"])


@hydra.main(config_path=str(CONF_DIR), config_name="analyze", version_base=None)
def _app(cfg) -> None:
    from omegaconf import OmegaConf
    run = OmegaConf.select(cfg, "run", default=None)
    if run is None or OmegaConf.is_missing(cfg, "run"):
        print("error: run: expected run=PATH (a run.zarr or a directory of runs)", file=sys.stderr)
        _state["code"] = BAD_INPUT
        return
    _state["code"] = max(_state["code"], analyse_paths(str(run), cfg.analysis, bool(cfg.get("verbose"))))


def _refuse_glob(argv: list[str]) -> None:
    """Hydra's ``glob(...)`` picks among a key's config options, not files: ``run=glob(...)``
    would sweep over nothing and exit 0. Refuse it with the forms that do what was meant."""
    for arg in argv:
        if arg.lstrip("+").startswith("run=glob("):
            print(f"error: {arg}: Hydra's glob() selects config options, not files; give the runs as "
                  f"-m run=A,B, or a directory: run=DIR analyses every run.zarr below it", file=sys.stderr)
            sys.exit(BAD_INPUT)


def main() -> None:
    from cliapp.runner import run_app
    _refuse_glob(sys.argv[1:])
    run_app(_app)                   # a config file is data: one line for a bad one, exit 2
    sys.exit(_state["code"])


if __name__ == "__main__":  # pragma: no cover
    main()

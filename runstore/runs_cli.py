"""``tactile-runs``: find, compare and redo runs.

    tactile-runs list [FILTER ...] [--format table|csv|json] [--columns ...] [--export FILE]
    tactile-runs show RUN
    tactile-runs diff A B
    tactile-runs reproduce RUN_DIR [--out DIR] [--allow-code-change]
    tactile-runs index [PATH ...] [--rebuild]

The run directories are the truth; the catalogue (an SQLite file, ``runstore/catalogue.py``)
is an index of them that ``index`` rebuilds or refreshes at any time. Runs, imports, analyses
and sweeps register themselves when they close. A RUN is a run directory, a run id (or its
first characters) or a path the catalogue knows.

Filters (``list``), all of them must hold:
    protocol=straws_sweep          a field: protocol, surface, status, kind, analysis, commit,
                                   dirty, host, run_id, seed, path
    protocol.sweep_speed>=10       a config key (config.<key> or its short form)
    score.width_error_mm_median<1  a headline.* or score.* number of the current analysis
    since=2026-11-01  until=2026-11-30   the run's start time
    analysis=dis-3f9a2c1b7d        runs that keep an analysis of that name
    operators: = != < <= > >= ~ (contains); a number compares as a number
Exit status: 0 done (reproduce: reproduced), 1 reproduce: differs or failed, 2 bad input
(one line: not a run directory, a malformed filter, an altered record, another code version,
a locked catalogue), 3 interrupted.
"""

from __future__ import annotations

import sys
from pathlib import Path

BAD_INPUT, DIFFERS, INTERRUPTED = 2, 1, 3

EPILOG = """examples:
  tactile-runs index outputs multirun                 index every run below these directories
  tactile-runs list protocol=straws_sweep protocol.sweep_speed>=10 status=success
  tactile-runs list score.width_error_mm_median<1 since=2026-11-01 --format csv > runs.csv
  tactile-runs list --export runs.parquet              pandas.read_parquet / read_csv / read_json
  tactile-runs show outputs/2026-11-27/11-15-07-687911_straws_sweep_on_straws
  tactile-runs diff RUN_A RUN_B                        config, provenance and results side by side
  tactile-runs reproduce RUN_DIR                       the run again: reproduced: identical, or what differs
  tactile-runs reproduce SWEEP_DIR                     every job of a sweep

catalogue: --catalogue FILE, else $TACTILE_CATALOGUE, else runs.sqlite in the tactile-flow cache
directory ($TACTILE_CACHE_DIR, else ~/.cache/tactile-flow): one per user, on a local disk.
Guide: docs/reproducibility.md."""


def parser():
    from tactile_flow.validation.cli import ArgumentParser
    doc = __doc__.replace("``", "")
    ap = ArgumentParser(prog="tactile-runs", description=doc.split("\nFilters")[0], epilog=EPILOG)
    ap.add_argument("--catalogue", metavar="FILE", help="the catalogue file (default: $TACTILE_CATALOGUE, else "
                                                         "runs.sqlite in the tactile-flow cache directory)")
    ap.add_argument("--verbose", action="store_true", help="tracebacks on errors")
    sub = ap.add_subparsers(dest="command", metavar="{list,show,diff,reproduce,index}")
    sub.required = True
    p = sub.add_parser("list", help="runs matching filters, as a table, CSV or JSON",
                       description="Runs matching every FILTER:\n" + doc.split("all of them must hold:")[-1]
                       .split("Exit status")[0].rstrip(), formatter_class=ap.formatter_class)
    p.add_argument("filters", nargs="*", metavar="FILTER", help="key=value, key>=number, since=DATE ...")
    p.add_argument("--format", choices=("table", "csv", "json"), default="table", help="output format (default table)")
    p.add_argument("--columns", metavar="A,B,...", help="columns to show (default: a summary; 'all' for every one)")
    p.add_argument("--export", metavar="FILE", help="write the matching runs to FILE (.csv, .json, .parquet "
                                                   "with pandas) with every column, for pandas/xarray")
    p.add_argument("--limit", type=int, default=None, help="at most this many runs (newest first)")
    p = sub.add_parser("show", help="one run: what it is, provenance, analyses, results")
    p.add_argument("run", metavar="RUN", help="a run directory, a run id or its first characters")
    p.add_argument("--format", choices=("text", "json"), default="text", help="output format (default text)")
    p = sub.add_parser("diff", help="two runs side by side: config keys that differ, provenance, results")
    p.add_argument("a", metavar="A", help="a run directory or run id")
    p.add_argument("b", metavar="B", help="a run directory or run id")
    p.add_argument("--all", action="store_true", help="also the keys that are the same")
    p = sub.add_parser("reproduce", help="do a recorded run (or every job of a sweep) again and compare")
    p.add_argument("run_dir", metavar="RUN_DIR", help="a run directory or a sweep directory")
    p.add_argument("--out", metavar="DIR", help="where the reproduction goes (default outputs/<date>/<time>_"
                                               "reproduce_<name>, multirun/... for a sweep)")
    p.add_argument("--allow-code-change", action="store_true",
                   help="run it although the code differs from the run's (both versions recorded)")
    p.add_argument("--no-verify-store", action="store_true",
                   help="do not check the run's store against its recorded checksum first (long records)")
    p = sub.add_parser("index", help="add or refresh runs below PATHs; notice moved or deleted ones")
    p.add_argument("paths", nargs="*", metavar="PATH", help="directories to walk (default: the catalogue's "
                                                          "known roots, else ./outputs and ./multirun)")
    p.add_argument("--rebuild", action="store_true", help="start the catalogue again from the directories")
    return ap


def main(argv=None) -> int:
    args = parser().parse_args(argv)
    from .runinfo import RunRecordError
    try:
        return COMMANDS[args.command](args)
    except RunRecordError as exc:
        return _fail(args, exc, BAD_INPUT)
    except ValueError as exc:                  # a filter, a catalogue, a path: bad input
        return _fail(args, exc, BAD_INPUT)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return INTERRUPTED
    except BrokenPipeError:                    # tactile-runs list | head
        return 0
    except Exception as exc:                   # noqa: BLE001 - one line; the traceback with --verbose
        return _fail(args, exc, DIFFERS)


def _fail(args, exc, code: int) -> int:
    if args.verbose:
        import traceback
        traceback.print_exception(exc)
    print(f"tactile-runs {args.command}: error: {exc}", file=sys.stderr)
    return code


def _catalogue(args):
    from . import catalogue
    return catalogue.Catalogue.open(args.catalogue)


def cmd_reproduce(args) -> int:
    from .reproduce import reproduce
    code = reproduce(args.run_dir, out=args.out, allow_code_change=args.allow_code_change,
                     verify_store=not args.no_verify_store)
    return code


def cmd_index(args) -> int:
    cat = _catalogue(args)
    report = cat.index(args.paths or None, rebuild=args.rebuild, console=print)
    print(report)
    return 0


def cmd_list(args) -> int:
    from . import catalogue
    cat = _catalogue(args)
    rows = cat.query(args.filters, limit=args.limit)
    if args.export:
        path = catalogue.export(rows, Path(args.export))
        print(f"{len(rows)} runs written to {path}", file=sys.stderr)
        return 0
    columns = catalogue.columns_for(rows, args.columns)
    print(catalogue.render(rows, columns, args.format))
    return 0


def cmd_show(args) -> int:
    from . import catalogue
    run_dir = catalogue.resolve_run(args.run, args.catalogue)
    text = catalogue.show(run_dir, fmt=args.format)
    print(text)
    return 0


def cmd_diff(args) -> int:
    from . import catalogue
    a = catalogue.resolve_run(args.a, args.catalogue)
    b = catalogue.resolve_run(args.b, args.catalogue)
    print(catalogue.diff(a, b, show_all=args.all))
    return 0


COMMANDS = {"reproduce": cmd_reproduce, "index": cmd_index, "list": cmd_list, "show": cmd_show, "diff": cmd_diff}


def command() -> None:
    """``tactile-runs``: :func:`main`, then its exit status."""
    sys.exit(main())


if __name__ == "__main__":
    command()


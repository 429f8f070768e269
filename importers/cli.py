"""``tactile-import``: bring a ROS bag or CSV recording into a run store (Hydra app, ``conf/import.yaml``).

    tactile-import source=lab/rest.bag                       # -> outputs/imported/rest/run.zarr.zip
    tactile-import source=csvs/ rate_hz=100 baseline=estimate out=outputs/imported/s3
    tactile-import source=press.csv calibration=cal.json fingers=[mf]

Exit status: 0 imported, 2 bad input (one line on stderr naming the file and, for a CSV, the
line and column; nothing written; for a directory: the good files are imported and every
bad one gets its line: unreadable, duplicate-named, a run directory holding something else,
mixed sensor models), 1 other failure (a worker killed: the runs completed are in place), 3
interrupted (Ctrl-C, SIGTERM: the runs completed are in place, no half store). A directory is
imported in ``workers`` processes (default: the cores available), with one progress line on
a terminal; a second import of it skips the files already imported and does the others. A truncated bag imports what it holds
(exit 0) and its output line ends with ``WARNING: truncated bag: ...``. Files are streamed:
memory does not grow with their length (``docs/import.md``). ``verbose=true`` adds the
traceback. The work is :func:`importers.import_source`.
"""

from __future__ import annotations

import sys

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import OmegaConf

from tactile_flow.cliapp.runner import report, run_app
from tactile_flow.cliapp.sensors import composed_sensor
from tactile_flow.cliapp.workers import WorkerDied
from tactile_flow.conf import DIR as CONF_DIR
from tactile_flow.runstore.status import ExitCode

from .importer import ImportIncomplete, ImportSettings, import_source
from .recording import ImportInputError

BAD_INPUT, FAILED = ExitCode.BAD_INPUT, ExitCode.FAILED
_exit = {"code": 0}


def settings_from(cfg) -> ImportSettings:
    """:class:`ImportSettings` from the config node (``fingers`` may be a name or a list)."""
    fingers = cfg.get("fingers")
    if fingers is not None:
        fingers = (str(fingers),) if isinstance(fingers, str) else tuple(str(f) for f in fingers)
    est = cfg.get("estimate") or {}
    columns = cfg.get("columns")
    columns = OmegaConf.to_container(columns) if OmegaConf.is_config(columns) else columns
    relative = cfg.get("relative", "auto")
    return ImportSettings(rate_hz=cfg.get("rate_hz"), calibration=cfg.get("calibration"),
                          baseline=str(cfg.get("baseline", "auto")), fingers=fingers or None,
                          topic=str(cfg.get("topic", "/rh/tactile")),
                          estimate_early_s=float(est.get("early_s", 1.0)),
                          estimate_percentile=float(est.get("percentile", 95.0)),
                          sensor=composed_sensor(cfg, default=None), columns=columns,
                          time_unit=str(cfg.get("time_unit", "auto")), relative=relative,
                          relative_rest_counts=cfg.get("relative_rest_counts", 2500.0))


def run(cfg, overrides=(), console=print) -> int:
    """One import; never raises. Returns the exit code."""
    if OmegaConf.is_missing(cfg, "source"):
        print("import error: source: missing; expected source=PATH (a .bag, a ROS2 bag directory, a .csv "
              "or a directory of them)", file=sys.stderr)
        return BAD_INPUT
    try:
        import_source(cfg.source, cfg.out, settings_from(cfg), config_yaml=OmegaConf.to_yaml(cfg, resolve=True),
                      overrides=overrides, console=console, workers=cfg.get("workers"), progress=True)
    except ImportIncomplete as exc:                 # the good files are imported; one line per bad one
        for _, reason in exc.failures:
            print(f"import error: {reason}", file=sys.stderr)
        print(f"import: {len(exc.results)} of {len(exc.results) + len(exc.failures)} files imported",
              file=sys.stderr)
        return BAD_INPUT
    except WorkerDied as exc:                       # kill -9 of a worker: what was complete is in place
        print(f"import failed: {exc}; the runs completed are in place, the others not: run the same import "
              f"again to finish it", file=sys.stderr)
        return FAILED
    except (ImportInputError, FileExistsError, ValueError) as exc:
        report(exc, "import error", bool(cfg.get("verbose")))
        return BAD_INPUT
    except Exception as exc:  # noqa: BLE001 - one line, then the exit code says it failed
        report(exc, f"import failed ({type(exc).__name__})", bool(cfg.get("verbose")))
        return FAILED
    return 0


@hydra.main(config_path=str(CONF_DIR), config_name="import", version_base=None)
def _app(cfg) -> None:
    _exit["code"] = run(cfg, list(HydraConfig.get().overrides.task))


def main() -> None:
    run_app(_app)                   # a config file is data: one line for a bad one, exit 2
    sys.exit(_exit["code"])


if __name__ == "__main__":
    main()

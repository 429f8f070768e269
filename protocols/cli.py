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
import json
import logging
import sys
import traceback
from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from hydra.experimental.callback import Callback
from omegaconf import OmegaConf

from . import config_guard, resume
from .run import hand_off, run_protocol
from .schema import check_targets, register

log = logging.getLogger("tactile-run")
CONF_DIR = Path(__file__).resolve().parents[1] / "conf"
EXIT_CODES = {"success": 0, "planned": 0, "failed": 1, "aborted": 3}
BAD_INPUT = 2
_exit = {"code": 0}


def console(message: str) -> None:
    """A line for the operator, also kept in the run's log file."""
    print(message, flush=True)
    log.info(message)


def run_job(cfg, console=console) -> int:
    """Run one Hydra job; never raises. Returns the exit code."""
    hc = HydraConfig.get()
    run_dir = Path(hc.runtime.output_dir)
    try:
        check_targets(cfg)
        _refuse_parallel_hardware(cfg, hc)
        if cfg.resume and not cfg.plan_only and resume.decide(run_dir, OmegaConf.to_yaml(cfg, resolve=True)) == "skip":
            console(f"run {run_dir}: skipped (succeeded before with the same config and code)")
            return 0
        result = run_protocol(cfg, run_dir, overrides=list(hc.overrides.task), console=console)
    except ValueError as exc:                       # ProtocolError, ConfigError: bad input
        _report(cfg, exc, "error")
        return BAD_INPUT
    except Exception as exc:
        _report(cfg, exc, "run failed")
        return EXIT_CODES["failed"]
    if result.status == "planned":
        return 0
    if cfg.analyze and result.status in ("success", "aborted"):
        try:
            hand_off(result, cfg.analysis, console=console)
        except Exception as exc:                    # the recording is safe; say what went wrong
            _report(cfg, exc, "analysis failed")
    detail = f" ({result.error})" if result.error else ""
    console(f"run {result.run_dir}: {result.status}{detail}")
    return EXIT_CODES.get(result.status, 1)


def _report(cfg, exc: Exception, what: str) -> None:
    if cfg.get("verbose"):
        traceback.print_exception(exc)
    print(f"{what}: {exc}", file=sys.stderr)
    log.error(f"{what}: {exc}", exc_info=exc)


def _refuse_parallel_hardware(cfg, hc) -> None:
    """One robot: real hardware only with Hydra's sequential launcher."""
    launcher = str(OmegaConf.select(hc, "launcher._target_", default=""))
    if cfg.hardware.get("backend") != "sim" and launcher and not launcher.endswith("BasicLauncher"):
        raise ValueError(f"hydra/launcher: {launcher} runs jobs in parallel; hardware="
                         f"{cfg.hardware.get('backend')} drives one robot, so sweeps on it must use the "
                         f"default sequential launcher")


@hydra.main(config_path=str(CONF_DIR), config_name="config", version_base=None)
def _app(cfg) -> None:
    _exit["code"] = max(_exit["code"], run_job(cfg))


def main() -> None:
    register()
    logging.raiseExceptions = False          # a log file on a full disk must not print tracebacks
    config_guard.run_app(_app)               # protocols are data: no Hydra settings, no code
    sys.exit(_exit["code"])


class SweepSummary(Callback):
    """At the end of a multirun, one table of every job: overrides, status, headline results.

    Written to ``summary.csv`` and ``summary.md`` at the sweep's root directory.
    """

    def on_multirun_end(self, config, **kwargs) -> None:
        root = Path(config.hydra.sweep.dir)
        rows = sweep_rows(root)
        if rows:
            write_summary(root, rows)
            print(f"sweep {root}: {len(rows)} runs, "
                  f"{sum(r['status'] == 'success' for r in rows)} succeeded; summary.md, summary.csv")


def sweep_rows(root: Path) -> list[dict]:
    """One row per job directory under ``root`` that holds a ``run.json``."""
    rows = []
    for run_json in sorted(root.glob("*/run.json"), key=lambda p: _job_number(p.parent.name)):
        job = run_json.parent
        info = json.loads(run_json.read_text())
        overrides_file = job / ".hydra" / "overrides.yaml"
        overrides = OmegaConf.load(overrides_file) if overrides_file.exists() else []
        row = {"job": job.name, "overrides": " ".join(overrides), "status": info.get("status"),
               "run_id": info.get("run_id"), "error": info.get("error") or ""}
        summary = job / "summary.json"
        if summary.exists():
            row.update({f"result.{k}": v for k, v in json.loads(summary.read_text()).get("headline", {}).items()})
        rows.append(row)
    return rows


def _job_number(name: str) -> int:
    head = name.split("_", 1)[0]
    return int(head) if head.isdigit() else 1 << 30


def write_summary(root: Path, rows: list[dict]) -> None:
    columns = list(dict.fromkeys(k for r in rows for k in r))
    with open(root / "summary.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=columns)
        writer.writeheader()
        writer.writerows(rows)
    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    lines += ["| " + " | ".join(_cell(r.get(c, "")) for c in columns) + " |" for r in rows]
    (root / "summary.md").write_text("\n".join(lines) + "\n")


def _cell(value) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value).replace("|", "\\|")

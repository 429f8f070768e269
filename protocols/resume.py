"""Resuming a sweep: ``tactile-run -m ... hydra.sweep.dir=DIR resume=true``.

Re-running the same sweep command into the same sweep directory with ``resume=true``
skips every job whose run ended ``success`` — after checking that its recorded config and
code version (git commit and diff hash) match what this job would run — and runs the
others again, keeping the earlier attempt under ``previous/<n>/`` in the job directory. A
mismatch is refused with the difference shown: resuming must never mix runs of different
configurations or code in one sweep. A skipped job whose analysis is missing or incomplete
(:func:`analysis_state`; killed during the analysis) is analysed again (``"analyse"``).
"""

from __future__ import annotations

import difflib
import json
import os
from pathlib import Path

import yaml

from tactile_flow.runstore import analyses, files
from tactile_flow.runstore.provenance import git_state

IGNORED_KEYS = ("resume", "progress", "verbose")
KEPT = ("previous", ".tactile.lock", "job_result.json")   # never set aside: earlier attempts, the lock, the job's mark


class ResumeMismatch(ValueError):
    """The earlier run of this job used another config or code version."""


def comparable_config(config_yaml: str) -> str:
    """The config as YAML without the keys that do not change what a run does."""
    cfg = yaml.safe_load(config_yaml) or {}
    for key in IGNORED_KEYS:
        cfg.pop(key, None)
    return yaml.safe_dump(cfg, sort_keys=True)


def decide(run_dir, config_yaml: str, git: dict | None = None, analyze: bool = False) -> str:
    """``"skip"`` if ``run_dir`` holds a successful run of the same config and code (and,
    with ``analyze``, its complete analysis), ``"analyse"`` if only the analysis is missing
    or incomplete, ``"run"`` if it holds nothing or an unsuccessful run (moved to
    ``previous/<n>/``). Raises :class:`ResumeMismatch` showing the difference otherwise."""
    run_dir = Path(run_dir)
    run_json = run_dir / "run.json"
    if not run_json.exists():
        _set_aside(run_dir)
        return "run"
    info = json.loads(run_json.read_text())
    if info.get("status") != "success":
        _set_aside(run_dir)
        return "run"
    check_same_config(run_dir, info, config_yaml)
    git = git_state() if git is None else git
    recorded = info.get("git", {})
    for key in ("commit", "diff_sha256"):
        if recorded.get(key) != git.get(key):
            raise ResumeMismatch(f"resume: {run_dir} was run with code {key} {recorded.get(key)}, this job "
                                 f"would run {git.get(key)}; refusing to mix code versions in one sweep")
    return "analyse" if analyze and analysis_state(run_dir) != "complete" else "skip"


def check_same_config(run_dir: Path, info: dict, config_yaml: str) -> None:
    """:class:`ResumeMismatch` showing the difference if the run recorded in ``run_dir``
    (``info``: its ``run.json``) was run with another config than ``config_yaml``."""
    before, now = comparable_config(info.get("config_yaml", "")), comparable_config(config_yaml)
    if before != now:
        diff = "".join(difflib.unified_diff(before.splitlines(True), now.splitlines(True),
                                            "recorded run", "this job", n=1))
        raise ResumeMismatch(f"resume: {run_dir} was run with another config; refusing to mix them in one "
                             f"sweep:\n{diff}")


def check_job_siblings(sweep_dir, job_num: int, run_dir, config_yaml: str) -> None:
    """A resumed sweep whose job ``job_num`` now has another directory name (run directories are
    named by their overrides) must not add a run of another config beside the earlier one:
    :class:`ResumeMismatch` if a ``<job_num>_*`` directory holds a run of another config."""
    for sibling in sorted(Path(sweep_dir).glob(f"{job_num}_*")):
        if sibling != Path(run_dir) and (sibling / "run.json").is_file():
            check_same_config(sibling, json.loads((sibling / "run.json").read_text()), config_yaml)


def analysis_state(run_dir) -> str:
    """``complete``, ``missing`` or ``incomplete``: the state of a run directory's analysis
    (:func:`runstore.analyses.state`: complete when it has a current analysis, each analysis
    being made aside and renamed into place whole; incomplete: only the outputs of an analysis
    killed half-way, in the layout before 0.2)."""
    return analyses.state(run_dir)


def _set_aside(run_dir: Path) -> None:
    """Move an earlier, unsuccessful attempt's files (its ``.hydra/`` record and log too) to
    ``previous/<n>/`` (made without following a link: :mod:`runstore.files`)."""
    leftovers = [p for p in run_dir.iterdir() if p.name not in KEPT]
    if not leftovers:
        return
    n = len(list((run_dir / "previous").iterdir())) if (run_dir / "previous").is_dir() else 0
    target = files.make_dirs(run_dir, f"previous/{n}")
    for p in leftovers:
        os.rename(p, target / p.name)            # the entry itself (a link stays a link), same file system

"""``tactile-runs reproduce RUN_DIR``: a recorded run done again from its directory alone.

1. The record is checked (:func:`check_record`): a run directory of a schema this reader
   knows, its copied config files and ``code.diff`` as recorded (SHA-256), its store's data
   as recorded (``run.json``'s ``store_checksum``). Anything missing or altered: one line.
2. The code is compared with the run's (:func:`code_difference`): commit and uncommitted
   diff. A difference is refused in one line naming it and how to restore the run's code
   (``git checkout <commit> && git apply RUN/code.diff``), unless ``allow_code_change``; then
   the new run records both (its own ``code`` and ``reproduces.code``).
3. ``tactile-run`` runs in a process of its own (:func:`command`), composed from the run's
   copies (``RUN/config/main`` as the primary config directory, ``RUN/config/<n>`` in place of
   each ``hydra.searchpath`` folder), with the run's overrides and seed, the files its values
   named (a calibration) replaced by their copies, in the run's working directory when it
   still exists, into a new directory (default ``outputs/<date>/<time>_reproduce_<name>``).
4. The two are compared (:func:`compare`): the stores' data array by array
   (:mod:`runstore.checksum`), the status, the config key by key, and the headline and score
   of the analyses with the same name (same code, config and store give the same name).
   On the simulated lab everything must be identical; a run of the real lab is compared
   against :data:`TOLERANCES` instead (the recorded calibration is used, the world is not
   the same twice).

A sweep directory reproduces each of its jobs in turn into a new sweep directory.
Runs recorded before the copies existed (no ``inputs`` in ``run.json``) are composed from the
package's config files and the recorded overrides; the config comparison then says whether
that gave the same config.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import signal
import subprocess
import sys
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path

from . import analyses, checksum, packed, provenance, runinfo
from .runinfo import RunRecordError

#: how far a real-lab reproduction may differ from the run and still count as reproduced
#: (the world is never the same twice): absolute for these headline/score keys, else relative
TOLERANCES = {"direction_sensor_deg": 10.0, "texture_angle_deg_median": 10.0, "width_mm_median": 1.0,
              "width_error_mm_median": 1.0, "boundary_error_ms_median": 50.0, "slip_onset_error_ms": 50.0,
              "segments": 0, "crossings": 0}
RELATIVE_TOLERANCE = 0.10
#: config keys that name a place, not what the run did
PLACE_KEYS = ("hydra",)


class ReproduceRefused(RunRecordError):
    """The run cannot be reproduced as asked (its record altered, another code version...)."""


@dataclass
class Comparison:
    """What differs between a run and its reproduction."""

    arrays: list[str] = field(default_factory=list)
    n_arrays: int = 0
    status: tuple | None = None
    config: list[str] = field(default_factory=list)
    numbers: list[str] = field(default_factory=list)
    outside_tolerance: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    real_lab: bool = False

    @property
    def identical(self) -> bool:
        return not (self.arrays or self.status or self.config or self.numbers)

    @property
    def reproduced(self) -> bool:
        if self.real_lab:
            return not (self.status or self.config or self.outside_tolerance)
        return self.identical

    def line(self) -> str:
        if self.real_lab:
            head = ("reproduced: within tolerance" if self.reproduced else "reproduced: outside tolerance")
            parts = self.outside_tolerance or [f"{len(self.numbers)} numbers differ within tolerance"
                                               if self.numbers else "numbers identical"]
        elif self.identical:
            return (f"reproduced: identical ({self.n_arrays} arrays, headline and score)"
                    + (f"; {'; '.join(self.notes)}" if self.notes else ""))
        else:
            head, parts = "reproduced: differs", []
        if self.status:
            parts.append(f"status {self.status[0]} -> {self.status[1]}")
        if self.arrays:
            parts.append(f"arrays {', '.join(self.arrays[:6])}{', ...' if len(self.arrays) > 6 else ''} "
                         f"({len(self.arrays)} of {self.n_arrays})")
        if self.config:
            parts.append("config " + ", ".join(self.config[:6]) + (", ..." if len(self.config) > 6 else ""))
        if self.numbers and not self.real_lab:
            parts.append("; ".join(self.numbers[:8]) + ("; ..." if len(self.numbers) > 8 else ""))
        return f"{head}: " + "; ".join(parts + self.notes)


# ----------------------------------------------------------------------------- the record
def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def check_record(run_dir: Path, info: dict, verify_store: bool = True) -> None:
    """:class:`ReproduceRefused` naming the first recorded file that is missing or altered."""
    inputs = info.get("inputs") or {}
    for f in [*(inputs.get("files") or []), *(inputs.get("value_files") or [])]:
        path = run_dir / f["copy"]
        if not path.is_file() or path.is_symlink():
            raise ReproduceRefused(f"{path}: missing; the run recorded it ({f.get('group') or f.get('key')}) and "
                                   f"cannot be composed again without it")
        if _sha256(path) != f["sha256"]:
            raise ReproduceRefused(f"{path}: altered since the run was recorded (SHA-256 differs from run.json's)")
    code = info.get("code") or {}
    if code.get("diff_file"):
        path = run_dir / code["diff_file"]
        if not path.is_file() or _sha256(path) != code.get("diff_sha256"):
            raise ReproduceRefused(f"{path}: {'missing' if not path.is_file() else 'altered'}; the run's code was "
                                   f"its commit plus this diff")
    store = packed.run_store(run_dir, info)
    if not packed.is_store(store):
        raise ReproduceRefused(f"{store}: missing; expected the run's store")
    recorded = info.get("store_checksum")
    if verify_store and recorded:
        now = checksum.store_checksum(store)
        changed = checksum.differing(recorded, now)
        if changed:
            raise ReproduceRefused(f"{store}: altered since the run was recorded: {', '.join(changed[:4])} "
                                   f"{'differ' if len(changed) > 1 else 'differs'} from run.json's checksum")


def code_difference(info: dict) -> str | None:
    """One line saying how the code now differs from the run's, or None if it is the same
    (commit and uncommitted diff; outside a git checkout, the package version)."""
    recorded = info.get("code")
    if recorded:
        now, _ = provenance.code_state()
        rec_diff, now_diff = recorded.get("diff_sha256"), now.get("diff_sha256")
    else:                                          # recorded before code.diff existed: the whole tree's state
        recorded = info.get("git") or {}
        now = provenance.git_state()
        rec_diff = recorded.get("diff_sha256") if recorded.get("dirty") else None
        now_diff = now.get("diff_sha256") if now.get("dirty") else None
    if recorded.get("commit") == provenance.UNKNOWN or now.get("commit") == provenance.UNKNOWN:
        rec_pkg = recorded.get("package") or (info.get("packages") or {}).get("tactile-flow")
        now_pkg = now.get("package") or provenance.package_versions().get("tactile-flow")
        return None if rec_pkg == now_pkg else f"tactile-flow {rec_pkg} ran it, this is {now_pkg}"
    if recorded.get("commit") == now.get("commit") and rec_diff == now_diff:
        return None
    def say(state, diff):
        return f"commit {str(state.get('commit'))[:10]}" + (f" with uncommitted changes (diff {diff[:8]})" if diff else "")
    restore = f"git checkout {str(recorded.get('commit'))[:10]}"
    if recorded.get("diff_file"):
        restore += f" && git apply RUN/{recorded['diff_file']}"
    elif rec_diff:
        restore += " (its uncommitted changes were not kept: recorded before 0.2)"
    return f"the run's code was {say(recorded, rec_diff)}, this is {say(now, now_diff)} (restore it: {restore})"


# ----------------------------------------------------------------------------- the command
def default_out(run_dir: Path, sweep: bool = False) -> Path:
    now = datetime.now()
    root = "multirun" if sweep else "outputs"
    return Path(root) / now.strftime("%Y-%m-%d") / f"{now.strftime('%H-%M-%S-%f')}_reproduce_{run_dir.name}"


def command(run_dir: Path, info: dict, out: Path) -> tuple[list[str], Path]:
    """The ``tactile-run`` command line that does the run again into ``out``, and the working
    directory to run it in."""
    run_dir = run_dir.resolve()
    inputs = info.get("inputs")
    argv = [sys.executable, "-c", "from tactile_flow.protocols.entry import main; main()"]
    if inputs:
        overrides = list(inputs.get("task_overrides") or [])
        named = {v["key"]: v for v in inputs.get("value_files") or []}
        overrides = [o for o in overrides if o.lstrip("+~").split("=", 1)[0] not in named]
        overrides += [f"{key}={run_dir / v['copy']}" for key, v in named.items()]
        others = [s["name"] for s in inputs.get("sources") or [] if s["name"] != "main"]
        argv += ["--config-path", str(run_dir / "config" / "main"), "--config-name", inputs.get("config_name") or "config"]
        if others:
            argv.append("hydra.searchpath=[" + ",".join(f"file://{run_dir / 'config' / n}" for n in others) + "]")
        cwd = Path(inputs.get("cwd") or info.get("cwd") or ".")
    else:                                          # recorded before 0.2: the package's files, the overrides
        overrides = list(info.get("overrides") or [])
        argv += [a for a in info.get("command") or [] if a.startswith("hydra.searchpath=")]
        cwd = Path(info.get("cwd") or ".")
    argv += overrides + [f"hydra.run.dir={out.resolve()}"]
    return argv, cwd if cwd.is_dir() else Path.cwd()


# ----------------------------------------------------------------------------- comparing
# Settings of an analysis that change how it is drawn or run, not what it finds.
_PRESENTATION = ("figures", "max_segment_figures", "progress", "memory", "workers")


def _settings_differ(a: dict, b: dict) -> int:
    """How many analysis settings two ``analysis.json`` configs both have and set differently."""
    fa, fb = runinfo.flatten(a or {}), runinfo.flatten(b or {})
    return sum(1 for k in set(fa) & set(fb) if fa[k] != fb[k] and not k.startswith(_PRESENTATION))


def _like(run_dir: Path, other: Path | None) -> Path | None:
    """The run's kept analysis made with the settings of the analysis in ``other``: the same
    name (same settings and inputs on the same code), else the one whose settings differ least
    (an analysis's name changes with the code), newest first; None without kept analyses."""
    if other is None:
        return None
    meta = analyses.read_meta(other)
    if meta.get("name") and analyses.find(run_dir, meta["name"]):
        return analyses.find(run_dir, meta["name"])
    kept = analyses.listing(run_dir, legacy=False)
    if not kept:
        return None
    best = min(reversed(kept), key=lambda a: _settings_differ(a.get("config"), meta.get("config")))
    return Path(best["path"])


def _numbers(d: Path | None, run_dir: Path) -> tuple[str | None, dict]:
    """The name and the headline and score numbers of the analysis in ``d`` of a run."""
    if d is None:
        return None, {}
    return ("legacy" if d == run_dir else d.name), runinfo.analysis_numbers(d)


def _close_enough(key: str, a, b) -> bool:
    if a == b:
        return True
    if not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in (a, b)):
        return False
    leaf = key.split(".", 1)[1].removeprefix("score_")      # the headline repeats score numbers as score_*
    if leaf in TOLERANCES:
        return abs(a - b) <= TOLERANCES[leaf]
    return abs(a - b) <= RELATIVE_TOLERANCE * max(abs(a), abs(b), 1e-12)


def _show(v) -> str:
    if isinstance(v, float):
        return "nan" if math.isnan(v) else f"{v:.4g}"
    return str(v)


def compare(original: Path, new: Path, info: dict | None = None) -> Comparison:
    """What differs between the run in ``original`` and its reproduction in ``new``."""
    a = info or runinfo.load(original)
    b = runinfo.load(new)
    c = Comparison(real_lab=(a.get("config") or {}).get("hardware", {}).get("backend", "sim") != "sim")
    sa = a.get("store_checksum") or checksum.store_checksum(packed.run_store(original, a))
    sb = b.get("store_checksum") or checksum.store_checksum(packed.run_store(new, b))
    c.n_arrays = len(sa.get("arrays") or {})
    c.arrays = checksum.differing(sa, sb)
    if a.get("status") != b.get("status"):
        c.status = (a.get("status"), b.get("status"))
    named = {v["key"] for v in (a.get("inputs") or {}).get("value_files") or []}
    fa, fb = runinfo.flatten(a.get("config") or {}), runinfo.flatten(b.get("config") or {})
    c.config = sorted(k for k in set(fa) | set(fb)
                      if fa.get(k) != fb.get(k) and k not in named and not k.startswith(PLACE_KEYS))
    db = analyses.current_dir(new)
    name_b, nb = _numbers(db, new)
    name_a, na = _numbers(_like(original, db) or analyses.current_dir(original), original)
    if name_a != name_b and na:
        c.notes.append(f"the run's analysis {name_a} compared with the reproduction's {name_b}")
    if not na and nb:
        c.notes.append("the run has no analysis to compare")
    for k in sorted(set(na) & set(nb)):
        if na[k] != nb[k]:
            c.numbers.append(f"{k} {_show(na[k])} -> {_show(nb[k])}")
            if not _close_enough(k, na[k], nb[k]):
                c.outside_tolerance.append(f"{k} {_show(na[k])} -> {_show(nb[k])}")
    if c.real_lab:
        c.notes.append("real lab: compared against tolerances (" +
                       ", ".join(f"{k} {v}" for k, v in list(TOLERANCES.items())[:4]) +
                       f", ..., else {RELATIVE_TOLERANCE:.0%})")
    return c


# ----------------------------------------------------------------------------- doing it
def reproduce(run_dir, out=None, allow_code_change: bool = False, console=print, verify_store: bool = True) -> int:
    """Do the run in ``run_dir`` again (or every job of the sweep directory ``run_dir``) and
    say what differs. Exit code: 0 reproduced, 1 differs or the reproduction failed, 2 refused
    (:class:`ReproduceRefused`/:class:`RunRecordError` raised before anything is written),
    3 interrupted."""
    run_dir = Path(run_dir)
    if not runinfo.is_run_dir(run_dir) and runinfo.sweep_jobs(run_dir):
        return _reproduce_sweep(run_dir, out, allow_code_change, console, verify_store)
    info = runinfo.load(run_dir)
    if info.get("importer") or info.get("protocol") == "import":
        src = info.get("source") or {}
        raise ReproduceRefused(f"{run_dir}: an imported recording, not a run of the lab: import its source again "
                               f"(tactile-import source={src.get('path')}; sha256 {str(src.get('sha256'))[:12]})")
    check_record(run_dir, info, verify_store)
    differs = code_difference(info)
    if differs and not allow_code_change:
        raise ReproduceRefused(f"{run_dir}: {differs}; or reproduce it on this code with --allow-code-change")
    return _run_one(run_dir, info, Path(out) if out else default_out(run_dir), differs, console)


def _run_one(run_dir: Path, info: dict, out: Path, differs: str | None, console) -> int:
    out = out.resolve()
    if out.exists() and any(out.iterdir()):
        raise ReproduceRefused(f"{out}: exists and is not empty; choose another --out")
    argv, cwd = command(run_dir, info, out)
    env = dict(os.environ)
    env[provenance.REPRODUCES_ENV] = json.dumps({"run_dir": str(run_dir.resolve()), "run_id": info.get("run_id"),
                                                 "code": info.get("code") or info.get("git"),
                                                 "code_changed": differs,
                                                 "store_sha256": (info.get("store_checksum") or {}).get("sha256")})
    console(f"reproduce {run_dir}: tactile-run {' '.join(argv[3:])}" + (f" (code changed: {differs})" if differs else ""))
    proc = subprocess.Popen(argv, cwd=cwd, env=env)
    try:
        returncode = proc.wait()
    except KeyboardInterrupt:                       # the run stops safely on its own SIGINT, never killed
        proc.send_signal(signal.SIGINT)
        _wait_through_signals(proc)
        console(f"reproduce {run_dir}: interrupted")
        return 3
    if returncode == 3 and not runinfo.is_run_dir(out):
        return 3
    if not runinfo.is_run_dir(out):
        console(f"reproduced: failed: tactile-run ended with exit status {returncode} and recorded nothing "
                f"(its line above says why)")
        return 1
    result = compare(run_dir, out, info)
    if differs:
        result.notes.append("on another code version (--allow-code-change; both recorded in the new run.json)")
    console(f"{out}: " + result.line())
    return 0 if result.reproduced else 1


def _wait_through_signals(proc) -> None:
    """Wait for the run to end (its safe stop, its store closed), whatever more signals come."""
    while True:
        try:
            proc.wait()
            return
        except KeyboardInterrupt:
            proc.send_signal(signal.SIGINT)         # a second Ctrl-C: the run's own "stop at once"


def _reproduce_sweep(sweep: Path, out, allow_code_change: bool, console, verify_store: bool) -> int:
    jobs = runinfo.sweep_jobs(sweep)
    infos = {}
    for job in jobs:                                # every job checked before any is run
        info = runinfo.load(job)
        check_record(job, info, verify_store)
        differs = code_difference(info)
        if differs and not allow_code_change:
            raise ReproduceRefused(f"{job}: {differs}; or reproduce it on this code with --allow-code-change")
        infos[job] = (info, differs)
    root = Path(out) if out else default_out(sweep, sweep=True)
    console(f"reproduce sweep {sweep}: {len(jobs)} runs into {root}")
    code = 0
    for job in jobs:
        info, differs = infos[job]
        c = _run_one(job, info, root / job.name, differs, console)
        code = max(code, c)
        if c == 3:
            break
    return code

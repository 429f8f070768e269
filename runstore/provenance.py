"""Provenance of a run: what ran, from which code, on which machine and hardware.

:func:`collect` gathers it once at the start (JSON-serialisable values only); the engine
passes it to :meth:`runstore.writer.RunStore.create` (root attribute ``provenance``) and
:func:`write_run_json` writes it, with the exit status and end time, to ``run.json`` beside
the store — atomically, so a reader never sees a half-written file.
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import json
import platform
import socket
import subprocess
import sys
import uuid
from contextlib import contextmanager
from copy import deepcopy
from pathlib import Path

from . import files
from .jsonvalues import jsonable, utc_now
from .layout import SCHEMA_VERSION

UNKNOWN = "unknown"
#: set by ``tactile-runs reproduce`` for the run it starts: JSON naming the run reproduced
REPRODUCES_ENV = "TACTILE_REPRODUCES"
PROJECT_ROOT = Path(__file__).resolve().parent.parent


def _git(root: Path, *args: str) -> bytes:
    return subprocess.run(["git", "-C", str(root), *args], capture_output=True, check=True, timeout=20).stdout


_SAME_CODE: dict | None = None
"""While :func:`same_code` is entered: what :func:`git_state`, :func:`code_identity` and
:func:`package_versions` found, by their arguments."""


@contextmanager
def same_code():
    """Within the block, the code's state (git, the package versions) is asked once and reused:
    for a process that imports or analyses many runs with the code it loaded at its start (a
    dataset: ~0.2 s a run otherwise, most of an import of a short record). Nested: the outer
    block's answers."""
    global _SAME_CODE
    outer = _SAME_CODE
    _SAME_CODE = {} if outer is None else outer
    try:
        yield
    finally:
        _SAME_CODE = outer


def _once(key, compute):
    """``compute()``, or inside :func:`same_code` the value it gave the first time (a copy)."""
    if _SAME_CODE is None:
        return compute()
    if key not in _SAME_CODE:
        _SAME_CODE[key] = compute()
    return _copy(_SAME_CODE[key])


def _copy(value):
    """A copy of ``value``'s dicts and lists (their leaves, strings and numbers, are immutable):
    a caller may change what it is given. A third of the time of ``deepcopy``."""
    if isinstance(value, dict):
        return {k: _copy(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_copy(v) for v in value]
    return deepcopy(value) if not isinstance(value, (str, int, float, bool, type(None))) else value


def git_state(root: Path = PROJECT_ROOT, paths: tuple[str, ...] = ()) -> dict:
    """Commit, dirty flag (tracked files changed), SHA-256 of ``git diff HEAD`` and the number
    of untracked files of the git checkout at ``root`` (the diff and the untracked files under
    ``paths`` only, if given); every value ``"unknown"`` if ``root`` is not the top of a git work
    tree (e.g. an installed wheel) or git is missing."""
    return _once(("git_state", str(root), tuple(paths)), lambda: _git_state(root, paths))


def _git_state(root: Path, paths: tuple[str, ...]) -> dict:
    try:
        top = Path(_git(root, "rev-parse", "--show-toplevel").decode().strip()).resolve()
        if top != root.resolve():
            raise ValueError(f"{root} is inside {top}, not a checkout of this project")
        commit = _git(root, "rev-parse", "HEAD").decode().strip()
        diff = _git(root, "diff", "HEAD", "--binary", "--", *paths)
        untracked = _git(root, "ls-files", "--others", "--exclude-standard", "--", *paths).decode().splitlines()
    except (OSError, subprocess.SubprocessError, ValueError):
        return {"commit": UNKNOWN, "dirty": UNKNOWN, "diff_sha256": UNKNOWN, "untracked_files": UNKNOWN}
    return {"commit": commit, "dirty": bool(diff), "diff_sha256": hashlib.sha256(diff).hexdigest(),
            "untracked_files": len(untracked)}


#: the project's code, as folders of the checkout (what a run's code.diff covers)
CODE_PATHS = ("tactile_flow", "tactile", "hardware", "runstore", "protocols", "analysis", "importers", "cliapp",
              "viewer", "validation", "conf", "pyproject.toml")
CODE_DIFF = "code.diff"
MAX_UNTRACKED_BYTES = 1 << 20          # an untracked file larger than this is named, not kept in code.diff


def code_state(root: Path = PROJECT_ROOT, paths: tuple[str, ...] = CODE_PATHS) -> tuple[dict, bytes]:
    """The code that runs, and its uncommitted changes as a patch ``git apply`` restores.

    Returns ``({"package", "commit", "dirty", "diff_sha256", "untracked_left_out"}, patch)``:
    the patch is ``git diff HEAD --binary`` of ``paths`` followed by every untracked (not
    ignored) file under ``paths`` as a new file (files over :data:`MAX_UNTRACKED_BYTES` are
    named in ``untracked_left_out`` instead); ``diff_sha256`` is its SHA-256 (None when the
    tree is clean). Outside a git checkout: ``commit`` ``"unknown"``, an empty patch."""
    from importlib.metadata import PackageNotFoundError, version
    try:
        pkg = version("tactile-flow")
    except PackageNotFoundError:
        pkg = UNKNOWN
    try:
        top = Path(_git(root, "rev-parse", "--show-toplevel").decode().strip()).resolve()
        if top != root.resolve():
            raise ValueError(f"{root} is inside {top}, not a checkout of this project")
        commit = _git(root, "rev-parse", "HEAD").decode().strip()
        patch = _git(root, "diff", "HEAD", "--binary", "--", *paths)
        untracked = [u for u in _git(root, "ls-files", "--others", "--exclude-standard", "-z", "--", *paths)
                     .decode().split("\0") if u]
    except (OSError, subprocess.SubprocessError, ValueError):
        from tactile_flow import build_info          # an installed wheel: the commit it was built from
        built = build_info() if root == PROJECT_ROOT else {}
        if built.get("from") == "build":
            return {"package": pkg, "commit": built.get("commit", UNKNOWN), "dirty": built.get("dirty", UNKNOWN),
                    "diff_sha256": None if built.get("dirty") is False else UNKNOWN, "untracked_left_out": [],
                    "from": "build"}, b""
        return {"package": pkg, "commit": UNKNOWN, "dirty": UNKNOWN, "diff_sha256": UNKNOWN,
                "untracked_left_out": []}, b""
    left_out = []
    for rel in sorted(untracked):
        if (root / rel).stat().st_size > MAX_UNTRACKED_BYTES:
            left_out.append(rel)
            continue
        new = subprocess.run(["git", "-C", str(root), "diff", "--no-index", "--binary", "--", "/dev/null", rel],
                             capture_output=True, timeout=20)
        patch += new.stdout
    return {"package": pkg, "commit": commit, "dirty": bool(patch),
            "diff_sha256": hashlib.sha256(patch).hexdigest() if patch else None,
            "untracked_left_out": left_out}, patch


#: the libraries whose versions can change an analysis's numbers (part of its key)
ANALYSIS_LIBRARIES = ("numpy", "scipy", "opencv-contrib-python-headless", "numba", "zarr", "numcodecs")


def code_identity(paths: tuple[str, ...], libraries: tuple[str, ...] = ANALYSIS_LIBRARIES,
                  root: Path = PROJECT_ROOT) -> dict:
    """What code decides a computation's result: the package's version, the git trees of
    ``paths`` at HEAD (so a commit elsewhere in the project changes nothing) with the SHA-256
    of their uncommitted diff and their untracked files, and ``libraries``' versions. Outside
    a git checkout, the package version and the libraries."""
    return _once(("code_identity", tuple(paths), tuple(libraries), str(root)),
                 lambda: _code_identity(paths, libraries, root))


def _code_identity(paths: tuple[str, ...], libraries: tuple[str, ...], root: Path) -> dict:
    from importlib.metadata import PackageNotFoundError, version

    def ver(name: str) -> str:
        try:
            return version(name)
        except PackageNotFoundError:
            return UNKNOWN
    out = {"package": ver("tactile-flow"), "libraries": {n: ver(n) for n in libraries}}
    state = git_state(root, paths)
    if state["commit"] != UNKNOWN:
        try:
            trees = _git(root, "rev-parse", *(f"HEAD:{p}" for p in paths)).decode().split()
        except (OSError, subprocess.SubprocessError):
            trees = [UNKNOWN] * len(paths)
        out["trees"] = dict(zip(paths, trees))
        out["diff_sha256"] = state["diff_sha256"] if state["dirty"] else None
        out["untracked_files"] = state["untracked_files"]
    return out


def package_versions() -> dict[str, str]:
    """Version of every installed distribution, by name (sorted)."""
    return _once("package_versions", _package_versions)


def _package_versions() -> dict[str, str]:
    out = {}
    for d in importlib.metadata.distributions():
        name = d.metadata["Name"]
        if name:
            out[name] = d.version
    return dict(sorted(out.items(), key=lambda kv: kv[0].lower()))


def _parse_config(config_yaml: str):
    try:
        import yaml
        return yaml.load(config_yaml, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))   # libyaml's: 10× faster
    except Exception:        # noqa: BLE001 - the text itself is always kept
        return None


def collect(config_yaml: str, overrides: list[str], hardware_identities: dict, calibration: dict,
            seed, *, protocol: str | None = None, run_id: str | None = None) -> dict:
    """Everything needed to reproduce the run, as JSON-serialisable values.

    Args:
        config_yaml: the full resolved config (e.g. ``OmegaConf.to_yaml(cfg, resolve=True)``).
        overrides: the command-line overrides (``["protocol.sweep_speed=10", ...]``).
        hardware_identities: ``{device: {model, serial_or_address, firmware}}`` (``lab.identities()``).
        calibration: sensor calibration (taxel positions mm, baselines counts, ...); numpy ok.
        seed: the run's random seed.
    Returns a dict with ``run_id`` (UUID4 unless given), ``protocol``, ``start_time`` (ISO
    8601 UTC), ``config_yaml``, ``config`` (parsed), ``overrides``, ``git``
    (:func:`git_state`), ``python``, ``packages`` (:func:`package_versions`), ``host``,
    ``platform``, ``hardware``, ``calibration``, ``seed``, ``schema_version``, ``command``.
    """
    return jsonable({
        "run_id": run_id or str(uuid.uuid4()),
        "protocol": protocol,
        "start_time": utc_now(),
        "config_yaml": config_yaml,
        "config": _parse_config(config_yaml),
        "overrides": list(overrides),
        "git": git_state(),
        "python": {"version": sys.version.split()[0], "implementation": platform.python_implementation(),
                   "executable": sys.executable},
        "packages": package_versions(),
        "host": socket.gethostname(),
        "platform": platform.platform(),
        "hardware": hardware_identities,
        "calibration": calibration,
        "seed": seed,
        "schema_version": SCHEMA_VERSION,
        "command": list(sys.argv),
    })


def summary(provenance: dict) -> dict:
    """What goes into the store's root attribute ``provenance``: everything :func:`collect`
    gathered (a few kB: the package list and the calibration are the largest parts), so the
    store alone is enough to reproduce the run; ``run.json`` adds the exit status."""
    return jsonable(dict(provenance))


def write_run_json(path, provenance: dict, status: str, end_time: str | None = None,
                   extra: dict | None = None) -> Path:
    """Write ``provenance`` plus ``status``, ``end_time`` (default: now) and ``extra`` (e.g. the
    error) as JSON to ``path`` (a file, or a directory to hold ``run.json``), atomically and
    never through a link (:func:`runstore.files.write_text`: a temporary file in the same
    directory, fsynced, then renamed over the target). Returns the file's path."""
    path = Path(path)
    if path.is_dir():
        path = path / "run.json"
    doc = dict(provenance, **(extra or {}), status=status, end_time=end_time or utc_now())
    text = json.dumps(jsonable(doc), indent=2, sort_keys=True, allow_nan=False)
    return files.write_text(path.parent, path.name, text + "\n")

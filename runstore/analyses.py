"""The analyses of a run: each in its own directory, kept, one of them current.

Layout of a run directory (docs/run_store.md)::

    RUN/
      run.zarr  run.json  .hydra/  tactile-run.log  ...      the run's record (never rewritten)
      analyses/
        farneback-3f9a2c1b7d/      one directory per analysis: analysis.json, summary.json,
        dis-91c2e0aa45/              analysis.zarr.zip (one file; analysis.zarr, a directory,
                                     0.2.0 and before), score.json (simulated runs), figures/
        .staging-<id>/             an analysis being made (removed if its process died)
      analysis -> analyses/dis-91c2e0aa45      the current analysis (a relative link)
      summary.json -> analysis/summary.json    the paths of the layout before 0.2, kept: they
      analysis.zarr -> analysis/analysis.zarr  follow the current analysis
      score.json -> analysis/score.json
      figures -> analysis/figures
      analysis.zarr.zip -> analysis/analysis.zarr.zip   (after 0.2.0) the analysis store, packed
      analysis_history.jsonl                   one line per analysis made, reused or made current

An analysis is made in ``analyses/.staging-<id>/`` and renamed into ``analyses/<name>/``
whole; the run's current analysis is then chosen by one rename (a new ``analysis`` link over
the old one). A process killed at any moment leaves the previous current analysis or the
new one, each complete, never a mix. Replacing an analysis of the same name (``force``)
exchanges the two directories in one step (``renameat2(RENAME_EXCHANGE)``) and keeps the
old one as ``<name>~<its id>``. A file system without links holds the pointer as a small
file ``analysis`` (``analyses/<name>``), written by a rename too.

An analysis's store is packed, one zip file (``analysis.zarr.zip``: :mod:`.packed`; it is
written whole and never appended to); ``RUN/analysis.zarr.zip`` follows the current one as
the other paths do. A link that follows an output the current analysis has not (its
``score.json`` or its store of the other layout) is not made, or removed: no link into
``analysis/`` dangles after a change of the current analysis.

Runs analysed before this layout (``summary.json``, ``analysis.zarr``... as files in the run
directory) read as they are (:func:`current_dir` is the run directory itself); the first new
analysis moves the old one into ``analyses/`` (:func:`adopt_legacy`; files are linked, not
copied, and every step can be redone after a kill).

Several analyses of one run may be computed at once (a sweep over analysis parameters on a
parallel launcher): each takes the run directory's lock shared (:mod:`.rundir`; a recording
or ``tactile-recover`` takes it exclusively), and the short steps that change the directory
(the renames, the journal) take ``analyses/.commit.lock``.
"""

from __future__ import annotations

import ctypes
import errno
import fcntl
import json
import os
import shutil
import time
import uuid
from contextlib import contextmanager
from pathlib import Path

from . import files
from .jsonvalues import jsonable, read_object, utc_now
from .packed import find as find_store, packed_name, read_member
from .paths import component

ANALYSES = "analyses"
CURRENT = "analysis"
META = "analysis.json"
SUMMARY = "summary.json"
HISTORY = "analysis_history.jsonl"
#: the outputs of an analysis, and the run-directory paths of the layout before 0.2 that follow the current one
OUTPUTS = ("analysis.zarr", "summary.json", "score.json", "figures")
#: the analysis store: packed (after 0.2.0), or a directory (0.2.0 and before)
STORE = "analysis.zarr"
PACKED_STORE = packed_name(STORE)
#: the run-directory paths that follow the current analysis: those of the layout before 0.2, and its packed store
FOLLOW = (*OUTPUTS, PACKED_STORE)
#: of those, the ones an analysis may lack (no ground truth; the store of the other layout)
OPTIONAL = ("score.json", STORE, PACKED_STORE)
STAGING = ".staging-"
COMMIT_LOCK = ".commit.lock"
LEGACY_DEBRIS = (".analysis-staging-*", ".analysis-old-*")
STALE_STAGING_S = 60.0           # a staging directory without its lock file, older than this, is debris


class AnalysisNameTaken(ValueError):
    """``name=`` names an analysis made with another code, config or store."""


# ----------------------------------------------------------------------------- reading
def analyses_dir(run_dir) -> Path:
    return Path(run_dir) / ANALYSES


def _pointer(run_dir: Path) -> str | None:
    """The name the ``analysis`` pointer (a link, or a file on a file system without links)
    names, if it is ``analyses/<plain name>``; else None."""
    path = run_dir / CURRENT
    try:
        target = os.readlink(path)
    except OSError:
        if not files.is_plain_file(path):
            return None
        try:
            target = path.read_text(encoding="utf-8").strip()
        except OSError:
            return None
    parts = Path(target).parts
    if len(parts) != 2 or parts[0] != ANALYSES:
        return None
    try:
        return component(parts[1], "analysis")
    except ValueError:
        return None


def is_complete(directory) -> bool:
    """Whether ``directory`` holds a whole analysis: its ``summary.json``, and the same
    ``analysis_id`` in its store (``analysis.zarr.zip``, or ``analysis.zarr`` by 0.2.0 and before) and
    ``score.json`` (when there is one). A directory renamed into ``analyses/`` is whole by
    construction; this also tells a legacy run directory's outputs from an analysis killed
    half-way."""
    directory = Path(directory)
    try:
        ids = {json.loads((directory / SUMMARY).read_text())["analysis_id"]}
        store = find_store(directory, STORE) or directory / STORE
        ids.add(json.loads(read_member(store, "zarr.json"))["attributes"]["analysis_id"])
        if (directory / "score.json").exists():
            ids.add(json.loads((directory / "score.json").read_text())["analysis_id"])
    except (OSError, ValueError, KeyError, TypeError):
        return False
    return len(ids) == 1


def _legacy(run_dir: Path) -> bool:
    """Whether the run directory holds outputs of the layout before 0.2 (files, not links)."""
    return any(os.path.lexists(run_dir / o) and not os.path.islink(run_dir / o) for o in OUTPUTS)


def current_dir(run_dir) -> Path | None:
    """The directory holding the run's current analysis (``summary.json``, ``analysis.zarr``,
    ``score.json``, ``figures/``), or None if it has none:

    - ``RUN/analyses/<name>`` that the ``analysis`` pointer names;
    - ``RUN/analysis`` if it is a real directory (a run copied with its links followed);
    - the newest whole analysis in ``analyses/`` if the pointer names none (never left so by
      these functions; a hand-edited or half-copied run directory);
    - ``RUN`` itself for a run analysed before 0.2 (outputs as files), if they are whole.
    """
    run_dir = Path(run_dir)
    name = _pointer(run_dir)
    if name is not None and (analyses_dir(run_dir) / name).is_dir():
        return analyses_dir(run_dir) / name
    if (run_dir / CURRENT).is_dir() and not os.path.islink(run_dir / CURRENT) and is_complete(run_dir / CURRENT):
        return run_dir / CURRENT
    kept = listing(run_dir, legacy=False)
    if kept:
        return Path(max(kept, key=lambda a: (a.get("created") or "", a["name"]))["path"])
    if _legacy(run_dir) and is_complete(run_dir):
        return run_dir
    return None


def current_name(run_dir) -> str | None:
    """The current analysis's name (``legacy`` for a run analysed before 0.2), or None."""
    d = current_dir(run_dir)
    if d is None:
        return None
    return "legacy" if d == Path(run_dir) else (read_meta(d).get("name") or d.name)


def read_meta(directory) -> dict:
    """``analysis.json`` of an analysis directory (``{}`` if missing or unreadable)."""
    try:
        meta = json.loads((Path(directory) / META).read_text())
        return meta if isinstance(meta, dict) else {}
    except (OSError, ValueError):
        return {}


def find(run_dir, name: str) -> Path | None:
    """``analyses/<name>`` if it is a whole analysis directory (not a link), else None."""
    path = analyses_dir(run_dir) / name
    return path if path.is_dir() and not path.is_symlink() else None


def listing(run_dir, legacy: bool = True) -> list[dict]:
    """Every kept analysis of the run: ``{"name", "path", "current", **analysis.json}``, oldest
    first; with ``legacy``, a run analysed before 0.2 lists its outputs as ``legacy``."""
    run_dir = Path(run_dir)
    out = []
    root = analyses_dir(run_dir)
    if root.is_dir() and not root.is_symlink():
        for d in root.iterdir():
            if d.name.startswith(".") or not d.is_dir() or d.is_symlink():
                continue
            out.append({**read_meta(d), "name": d.name, "path": str(d)})
    if legacy and not out and _legacy(run_dir) and is_complete(run_dir):
        s = read_object(run_dir / SUMMARY)
        out.append({"name": "legacy", "path": str(run_dir), "analysis_id": s.get("analysis_id"),
                    "created": (s.get("provenance") or {}).get("created")})
    out.sort(key=lambda a: (a.get("created") or "", a["name"]))
    if out and legacy:
        cur = current_dir(run_dir)
        for a in out:
            a["current"] = cur is not None and Path(a["path"]) == cur
    return out


def state(run_dir) -> str:
    """``complete``, ``missing`` or ``incomplete``: whether the run has a current analysis
    (``incomplete``: only the outputs of an analysis killed half-way, in the layout before 0.2)."""
    run_dir = Path(run_dir)
    if current_dir(run_dir) is not None:
        return "complete"
    return "incomplete" if _legacy(run_dir) else "missing"



# ----------------------------------------------------------------------------- writing
@contextmanager
def commit_lock(run_dir):
    """``analyses/.commit.lock`` held exclusively (waiting for another process's short commit)."""
    root = files.make_dirs(run_dir, ANALYSES)
    fd = files.open_file(root, COMMIT_LOCK, os.O_RDWR | os.O_CREAT)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)


@contextmanager
def staging(run_dir):
    """A new ``analyses/.staging-<id>/`` to write an analysis into, with its own lock held (so
    that another process's :func:`remove_debris` leaves it alone); removed on any exception."""
    fd = None
    for attempt in range(3):
        path = analyses_dir(run_dir) / f"{STAGING}{uuid.uuid4().hex[:12]}"
        try:
            files.make_dirs(run_dir, ANALYSES)
            path.mkdir()
            fd = os.open(path / ".lock", os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o644)
            break
        except FileNotFoundError:           # another process's remove_debris took analyses/ or our empty
            if attempt == 2:                # directory before its lock was made (:func:`_abandoned`)
                raise
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield path
    except BaseException:
        shutil.rmtree(path, ignore_errors=True)
        try:
            path.parent.rmdir()             # nothing left of an analysis that never came: no empty analyses/
        except OSError:
            pass
        raise
    finally:
        if fd is not None:
            os.close(fd)


def commit(run_dir, staged: Path, name: str, meta: dict, *, replace: bool = False, current: bool = True) -> Path:
    """Make the whole analysis in ``staged`` the run's analysis ``name`` and its current one.

    Writes ``analysis.json`` (``meta`` plus ``name``), renames ``staged`` to ``analyses/<name>``
    (with ``replace`` and an existing ``name``: the two exchanged in one step, the old kept as
    ``<name>~<its id>``), points ``analysis`` at it by one rename, keeps the paths of the
    layout before 0.2 following it, and adds a line to ``analysis_history.jsonl``. Another
    process that committed ``name`` meanwhile wins: ``staged`` is dropped and theirs made
    current. Returns the analysis directory."""
    run_dir = Path(run_dir)
    component(name, "name")
    meta = jsonable({**meta, "name": name})
    (staged / ".lock").unlink(missing_ok=True)
    files.write_text(staged, META, json.dumps(meta, indent=2, sort_keys=True) + "\n")
    with commit_lock(run_dir):
        root = analyses_dir(run_dir)
        target = root / name
        event, kept_as = "made", None
        if os.path.lexists(target) and replace:
            old_id = read_meta(target).get("analysis_id") or uuid.uuid4().hex
            _exchange(staged, target)                   # target now the new one, staged the old
            kept_as = f"{name}~{str(old_id)[:8]}"
            os.rename(staged, root / kept_as)
            event = "replaced"
        elif os.path.lexists(target):
            shutil.rmtree(staged, ignore_errors=True)   # made meanwhile by another process: theirs
            event = "reused"
        else:
            os.rename(staged, target)
        if current:
            _point(run_dir, name)
        _journal(run_dir, {"event": event, "name": name, "analysis_id": read_meta(target).get("analysis_id"),
                           "current": current, **({"kept_as": kept_as} if kept_as else {})})
    return target


def make_current(run_dir, name: str, event: str = "reused") -> Path:
    """Make the kept analysis ``name`` the current one (one rename); a line in the journal."""
    run_dir = Path(run_dir)
    with commit_lock(run_dir):
        target = find(run_dir, name)
        if target is None:
            raise FileNotFoundError(f"{run_dir}: no analysis named {name}")
        _point(run_dir, name)
        _journal(run_dir, {"event": event, "name": name, "analysis_id": read_meta(target).get("analysis_id")})
    return target


def _point(run_dir: Path, name: str) -> None:
    """``analysis`` → ``analyses/<name>`` by one rename (a link, or a pointer file where the
    file system has no links); then the paths of the layout before 0.2 as links through it."""
    target = f"{ANALYSES}/{name}"
    tmp = f".{CURRENT}.{uuid.uuid4().hex[:8]}.tmp"
    fd = os.open(run_dir, os.O_RDONLY | os.O_DIRECTORY)
    try:
        existing = run_dir / CURRENT
        if existing.is_dir() and not existing.is_symlink():      # a run copied with its links followed
            os.rename(existing, analyses_dir(run_dir) / f".replaced-{uuid.uuid4().hex[:8]}")
        try:
            os.symlink(target, tmp, dir_fd=fd)
            linked = True
        except OSError as exc:
            if exc.errno not in (errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.ENOSYS):
                raise
            files.write_text(run_dir, tmp, target + "\n")
            linked = False
        if linked:      # before the pointer: a process killed between the two leaves no analysis without them
            _old_paths_follow(run_dir, analyses_dir(run_dir) / name)
        os.replace(tmp, CURRENT, src_dir_fd=fd, dst_dir_fd=fd)
        os.fsync(fd)
    finally:
        os.close(fd)
    for debris in analyses_dir(run_dir).glob(".replaced-*"):
        shutil.rmtree(debris, ignore_errors=True)


def _old_paths_follow(run_dir: Path, coming: Path) -> None:
    """``summary.json``, ``analysis.zarr``, ``score.json``, ``figures``, ``analysis.zarr.zip``
    in the run directory as links into ``analysis/`` (made once; a legacy file there is
    adopted first). Those an analysis may lack (:data:`OPTIONAL`: a run without ground truth
    has no score; an analysis has its store in one layout) are linked only when ``coming``
    (the analysis made current next, or the current one) has them, and such a link of ours is
    removed when it has not (it would dangle). A link there that is not ours (planted, or
    pointing out of the run) is replaced by ours — by one rename, never writing through it —
    or removed where ``coming`` lacks the file: these paths always read the current analysis."""
    fd = os.open(run_dir, os.O_RDONLY | os.O_DIRECTORY)
    try:
        for name in FOLLOW:
            ours = f"{CURRENT}/{name}"
            has = name not in OPTIONAL or os.path.lexists(coming / name)
            if os.path.lexists(run_dir / name):
                if os.path.islink(run_dir / name) and not has:
                    os.unlink(name, dir_fd=fd)
                elif os.path.islink(run_dir / name) and os.readlink(run_dir / name) != ours:
                    aside = f".{name}.{os.getpid()}.link"
                    os.symlink(ours, aside, dir_fd=fd)
                    os.rename(aside, name, src_dir_fd=fd, dst_dir_fd=fd)
                continue
            if not has:
                continue
            try:
                os.symlink(ours, name, dir_fd=fd)
            except FileExistsError:
                pass
    finally:
        os.close(fd)


def _journal(run_dir: Path, record: dict) -> None:
    files.append_text(run_dir, HISTORY, json.dumps(jsonable({"time": utc_now(), **record}), sort_keys=True) + "\n")


_RENAME_EXCHANGE = 2


def _exchange(a: Path, b: Path) -> None:
    """Swap two directories in one step (Linux ``renameat2(RENAME_EXCHANGE)``); where the
    system cannot, two renames (a reader in between finds the newest whole analysis)."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        fn = libc.renameat2
        fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
        if fn(-100, os.fsencode(a), -100, os.fsencode(b), _RENAME_EXCHANGE) == 0:
            return
        err = ctypes.get_errno()
        if err not in (errno.EINVAL, errno.ENOSYS, errno.ENOTSUP):
            raise OSError(err, os.strerror(err), str(a))
    except AttributeError:
        pass
    aside = b.with_name(f".exchange-{uuid.uuid4().hex[:8]}")
    os.rename(b, aside)
    os.rename(a, b)
    os.rename(aside, a)


# ----------------------------------------------------------------------------- repair
def remove_debris(run_dir) -> list[str]:
    """Remove what killed analyses left: ``analyses/.staging-*`` whose process is gone (its lock
    free), ``.exchange-*``/``.replaced-*`` leftovers, the layout before 0.2's
    ``.analysis-staging-*`` and ``.analysis-old-*``, temporary pointers. Returns their names."""
    run_dir = Path(run_dir)
    found = []
    root = analyses_dir(run_dir)
    if root.is_dir() and not root.is_symlink():
        for d in root.iterdir():
            if d.name.startswith(STAGING) and _abandoned(d):
                found.append(d)
            elif d.name.startswith((".replaced-",)):
                found.append(d)
    for pattern in (*LEGACY_DEBRIS, f".{CURRENT}.*.tmp"):
        found += list(run_dir.glob(pattern))
    for p in sorted(found):
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p, ignore_errors=True)
        else:
            p.unlink(missing_ok=True)
    return [p.name for p in sorted(found)]


def _abandoned(staged: Path) -> bool:
    lock = staged / ".lock"
    try:
        fd = os.open(lock, os.O_RDONLY | os.O_NOFOLLOW)
    except FileNotFoundError:               # killed between the directory and its lock: empty
        try:
            return not any(staged.iterdir()) or time.time() - staged.stat().st_mtime > STALE_STAGING_S
        except OSError:
            return False
    except OSError:
        return True
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        return True
    except BlockingIOError:
        return False
    finally:
        os.close(fd)


def adopt_legacy(run_dir) -> str | None:
    """Move an analysis of the layout before 0.2 (outputs as files in the run directory) into
    ``analyses/legacy-<id>/``, making it current if the run has no other, and leave links in
    its place (:func:`_old_paths_follow`). Files are hard-linked (copied across file systems),
    so every step can be redone after a kill; outputs of an analysis killed half-way (not
    whole) are removed. Returns the adopted analysis's name, or None."""
    run_dir = Path(run_dir)
    if not _legacy(run_dir):
        return None
    name = None
    if is_complete(run_dir):
        s = read_object(run_dir / SUMMARY)
        name = f"legacy-{str(s.get('analysis_id'))[:8]}"
        if find(run_dir, name) is None:
            with staging(run_dir) as staged:
                for o in OUTPUTS:
                    src = run_dir / o
                    if os.path.lexists(src) and not os.path.islink(src):
                        _link_tree(src, staged / o)
                prov = s.get("provenance") or {}
                meta = {"analysis_id": s.get("analysis_id"), "created": prov.get("created"),
                        "config": prov.get("config"), "code": prov.get("code"), "adopted": utc_now(),
                        "input_sha256": (prov.get("input") or {}).get("sha256")}
                pointed = _pointer(run_dir)
                other_current = pointed is not None and find(run_dir, pointed) is not None
                commit(run_dir, staged, name, meta, current=not other_current)
    with commit_lock(run_dir):
        trash = analyses_dir(run_dir) / f".replaced-{uuid.uuid4().hex[:8]}"
        trash.mkdir()
        for o in OUTPUTS:
            src = run_dir / o
            if os.path.lexists(src) and not os.path.islink(src):
                os.rename(src, trash / o)
        shutil.rmtree(trash, ignore_errors=True)
        if _pointer(run_dir) is not None:
            _old_paths_follow(run_dir, run_dir / CURRENT)
    return name


def _link_tree(src: Path, dst: Path) -> None:
    """``dst`` as a copy of ``src`` made of hard links (copies across file systems)."""
    if src.is_dir():
        shutil.copytree(src, dst, copy_function=_link_or_copy, symlinks=True)
    else:
        _link_or_copy(src, dst)


def _link_or_copy(src, dst) -> None:
    try:
        os.link(src, dst, follow_symlinks=False)
    except OSError:
        shutil.copy2(src, dst, follow_symlinks=False)

"""``tactile-recover PATH``: close a run store left open by a killed run.

A run killed mid-write (SIGKILL, power loss, a crash) leaves its store at its last commit
(see docs/run_store.md): the consolidated metadata describes consistent, complete data, but
some arrays' own metadata and chunks may run ahead of it, the status is still ``running``
and there is no end time nor ``run.json``. Recovery

1. trims every array back to its committed length (rows written after the last commit
   are dropped: they were never published, and a group must keep one length per dim);
2. records the true end — the time of the last committed sample of any stream — and
   marks the status ``crashed``;
3. re-commits the store and writes ``run.json`` from the provenance kept in the store,

so the run opens and analyses like any other. Groups and arrays that no commit published
(a ``truth`` group half-written at the kill) are deleted, not published. A store that is not
``running`` is left alone (``run.json`` is written if it is missing). A run that is still
recording (its process holds the run directory's lock, :mod:`.rundir`) is refused.
Exit status: 0 recovered (or nothing to do), 2 not a run store or still recording, 1 the
recovery could not be written (a full disk; nothing is lost), 3 interrupted (run it again).
"""

from __future__ import annotations

import signal
import sys
import threading
import warnings
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import zarr

from tactile_flow.hardware.errors import brief

from . import rundir
from .provenance import write_run_json
from .jsonvalues import utc_now
from .status import ExitCode, RunStatus
from .room import release_left_behind, room_path
from .writer import remove_debris


def recover(path) -> dict:
    """Recover the run store at ``path``; returns what was done (for the console and tests).

    Raises ``ValueError`` if ``path`` is not a run store (or its metadata is unreadable), or
    if the run is still being recorded (:mod:`.rundir`: its process holds the lock);
    ``OSError`` if the recovery cannot be written (a full disk: nothing is lost, run it again).
    """
    path = Path(path)
    if not (path / "zarr.json").exists():
        raise ValueError(f"{path}: not a run store (no zarr.json); expected the run.zarr directory of a run")
    with rundir.locked(path.parent):             # never a store that a live run is writing
        return _recover(path)


def _recover(path: Path) -> dict:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            committed = zarr.open_group(str(path), mode="r", use_consolidated=True)
            status, run_id = committed.attrs.get("status"), committed.attrs.get("run_id")
        except Exception as exc:                # noqa: BLE001 - a corrupt zarr.json in any form
            raise ValueError(f"{path}: not a readable run store: its zarr.json cannot be read "
                             f"({type(exc).__name__}: {brief(str(exc), 120)})") from None
        if status is None or run_id is None:
            raise ValueError(f"{path}: not a run store (no run_id/status attributes)")
        debris = [p.name for p in remove_debris(path.parent)]
        if release_left_behind(path):            # the room a killed run kept to close: recovery's now
            debris.append(room_path(path).name)
        if status != RunStatus.RUNNING:
            written = _run_json_of_closed(path, committed.attrs)
            return {"path": str(path), "status": status, "action": "none: the run was closed",
                    **({"run_json": "written"} if written else {}), **({"removed": debris} if debris else {})}
        trimmed, end = {}, 0.0
        names = dict(_walk(committed))
        for name, arr in names.items():
            live = zarr.open_array(str(path), path=name, mode="r+")
            if live.shape != arr.shape:
                trimmed[name] = int(live.shape[0] - arr.shape[0])
                live.resize(arr.shape)
            if _is_time_coord(name, arr) and arr.shape[0]:
                try:
                    end = max(end, float(np.asarray(arr[-1])))
                except Exception as exc:        # noqa: BLE001 - a chunk that does not decode
                    raise ValueError(f"{path}/{name}: its last chunk cannot be read ({type(exc).__name__}: "
                                     f"{brief(str(exc), 120)}); the store is damaged") from None
        unpublished = _drop_unpublished(path, set(names) | set(_groups(committed)))
        attrs = {"status": RunStatus.CRASHED, "end_time": utc_now(), "recovered": True, "last_sample_s": end}
        zarr.open_group(str(path), mode="r+", use_consolidated=True).update_attributes(attrs)
        zarr.consolidate_metadata(str(path))
    provenance = dict(committed.attrs.get("provenance") or {})
    provenance.setdefault("run_id", run_id)
    write_run_json(path.parent / "run.json", provenance, status=RunStatus.CRASHED, end_time=attrs["end_time"],
                   extra={"store": path.name, "recovered": True, "last_sample_s": end})
    return {"path": str(path), "status": RunStatus.CRASHED, "last_sample_s": end, "trimmed": trimmed,
            "dropped_unpublished": unpublished, "action": "recovered", **({"removed": debris} if debris else {})}


def _is_time_coord(name: str, arr) -> bool:
    """Whether ``arr`` is a stream's time coordinate: its own (only) dimension, in seconds —
    known from the store itself, so streams added later are covered (:data:`~runstore.layout.TIME_COORDS`)."""
    leaf = name.rsplit("/", 1)[-1]
    return tuple(arr.metadata.dimension_names or ()) == (leaf,) and arr.attrs.get("units") == "s"


def _drop_unpublished(path: Path, published: set[str]) -> list[str]:
    """Delete the groups and arrays on disk that no commit published (e.g. a ``truth`` group
    half-written when the run was killed): re-consolidating would publish them as if whole."""
    root = zarr.open_group(str(path), mode="r+", use_consolidated=False)
    dropped = []

    def visit(group, prefix):
        for name, _ in list(group.arrays()) + list(group.groups()):
            full = f"{prefix}{name}"
            if full not in published:
                del group[name]
                dropped.append(full)
            elif full in published and isinstance(group[name], zarr.Group):
                visit(group[name], f"{full}/")
    visit(root, "")
    return dropped


def _run_json_of_closed(path: Path, attrs) -> bool:
    """Write ``run.json`` of a closed store that has none (the disk filled as the run ended);
    returns whether it was written."""
    target = path.parent / "run.json"
    if target.exists():
        return False
    provenance = dict(attrs.get("provenance") or {})
    provenance.setdefault("run_id", attrs["run_id"])
    write_run_json(target, provenance, status=attrs["status"], end_time=attrs.get("end_time"),
                   extra={"store": path.name, "error": attrs.get("error"), "run_json_written_by": "tactile-recover"})
    return True


def _groups(group, prefix=""):
    for name, sub in group.groups():
        yield f"{prefix}{name}"
        yield from _groups(sub, f"{prefix}{name}/")


def _walk(group, prefix=""):
    for name, arr in group.arrays():
        yield f"{prefix}{name}", arr
    for name, sub in group.groups():
        yield from _walk(sub, f"{prefix}{name}/")


EPILOG = """examples:
  tactile-recover outputs/2026-01-01/12-00-00-000000_straws_sweep     # a run directory
  tactile-recover outputs/*/*/run.zarr                                 # stores: closed ones are left alone

exit status: 0 recovered (or nothing to do), 2 not a run store or still recording (one line),
1 the recovery could not be written (a full disk; nothing is lost), 3 interrupted (Ctrl-C or
SIGTERM; run it again to finish)."""


def describe(result: dict) -> str:
    """One sentence for the operator from :func:`recover`'s result."""
    if result["action"] != "recovered":
        extra = "; its run.json was written" if result.get("run_json") else ""
        return f"{result['path']}: nothing to do, the run was closed ({result['status']}){extra}"
    trimmed = sum(result["trimmed"].values())
    text = (f"{result['path']}: recovered as crashed; its data ends at {result['last_sample_s']:.2f} s of run time"
            + (f"; {trimmed} rows written after the last commit were dropped" if trimmed else "")
            + (f"; {len(result['dropped_unpublished'])} unpublished groups or arrays deleted"
               if result["dropped_unpublished"] else "") + "; run.json written")
    return text


def main(argv=None) -> int:
    from tactile_flow.validation.cli import ArgumentParser
    parser = ArgumentParser(prog="tactile-recover", description=__doc__.replace("``", "").split("\nExit status")[0],
                            epilog=EPILOG)
    parser.add_argument("paths", nargs="+", help="run.zarr directories (or run directories holding one)")
    args = parser.parse_args(argv)
    code = 0
    with _signals_as_ctrl_c():
        for p in args.paths:
            p = Path(p)
            store = p / "run.zarr" if (p / "run.zarr").exists() else p
            try:
                result = recover(store)
            except KeyboardInterrupt:           # every step can be done again: the next run finishes it
                print(f"interrupted: {store} is as it was or recovered; run tactile-recover on it again",
                      file=sys.stderr)
                return int(ExitCode.INTERRUPTED)
            except ValueError as exc:
                print(f"error: {exc}", file=sys.stderr)
                code = max(code, 2)
                continue
            except OSError as exc:              # a full disk, a read-only mount: nothing is lost
                print(f"error: {store}: the recovery could not be written ({type(exc).__name__}: {exc}); "
                      f"nothing was lost: run tactile-recover again once it can write", file=sys.stderr)
                code = max(code, 1)
                continue
            print(describe(result))
    return code


@contextmanager
def _signals_as_ctrl_c():
    """SIGINT and SIGTERM raise ``KeyboardInterrupt`` in the block (main thread only; a
    signal ignored, as SIGINT in a program started in the background, stays ignored)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def interrupt(signum, frame):
        raise KeyboardInterrupt
    before = {s: signal.signal(s, interrupt) for s in (signal.SIGINT, signal.SIGTERM)
              if signal.getsignal(s) != signal.SIG_IGN}
    try:
        yield
    finally:
        for s, handler in before.items():
            signal.signal(s, handler)


def command() -> None:
    """``tactile-recover``: :func:`main`, then its exit status; a signal once the work is done
    (the interpreter's exit joins zarr's threads) is ignored, not a late ``KeyboardInterrupt``."""
    code = main()
    for s in (signal.SIGINT, signal.SIGTERM):
        signal.signal(s, signal.SIG_IGN)
    sys.exit(code)


if __name__ == "__main__":
    command()

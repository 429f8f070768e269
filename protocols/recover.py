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

so the run opens and analyses like any other. A store that is not ``running`` is left
alone. Exit status: 0 recovered (or nothing to do), 2 not a run store.
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings
from pathlib import Path

import numpy as np
import zarr

from .provenance import write_run_json
from .store import utc_now

TIME_COORDS = ("time", "time_pac", "time_arm", "time_hand", "time_pump", "time_scale")


def recover(path) -> dict:
    """Recover the run store at ``path``; returns what was done (for the console and tests).

    Raises ``ValueError`` if ``path`` is not a run store.
    """
    path = Path(path)
    if not (path / "zarr.json").exists():
        raise ValueError(f"{path}: not a run store (no zarr.json); expected the run.zarr directory of a run")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        committed = zarr.open_group(str(path), mode="r", use_consolidated=True)
        status = committed.attrs.get("status")
        if status is None or "run_id" not in committed.attrs:
            raise ValueError(f"{path}: not a run store (no run_id/status attributes)")
        if status != "running":
            return {"path": str(path), "status": status, "action": "none: the run was closed"}
        trimmed, end = {}, 0.0
        for name, arr in _walk(committed):
            live = zarr.open_array(str(path), path=name, mode="r+")
            if live.shape != arr.shape:
                trimmed[name] = int(live.shape[0] - arr.shape[0])
                live.resize(arr.shape)
            if name.rsplit("/", 1)[-1] in TIME_COORDS and arr.shape[0]:
                end = max(end, float(np.asarray(arr[-1])))
        attrs = {"status": "crashed", "end_time": utc_now(), "recovered": True, "last_sample_s": end}
        zarr.open_group(str(path), mode="r+", use_consolidated=True).update_attributes(attrs)
        zarr.consolidate_metadata(str(path))
    provenance = dict(committed.attrs.get("provenance") or {})
    provenance.setdefault("run_id", committed.attrs["run_id"])
    write_run_json(path.parent / "run.json", provenance, status="crashed", end_time=attrs["end_time"],
                   extra={"store": path.name, "recovered": True, "last_sample_s": end})
    return {"path": str(path), "status": "crashed", "last_sample_s": end, "trimmed": trimmed,
            "action": "recovered"}


def _walk(group, prefix=""):
    for name, arr in group.arrays():
        yield f"{prefix}{name}", arr
    for name, sub in group.groups():
        yield from _walk(sub, f"{prefix}{name}/")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="tactile-recover", description=__doc__.splitlines()[0])
    parser.add_argument("paths", nargs="+", help="run.zarr directories (or run directories holding one)")
    args = parser.parse_args(argv)
    code = 0
    for p in args.paths:
        p = Path(p)
        store = p / "run.zarr" if (p / "run.zarr").exists() else p
        try:
            result = recover(store)
        except ValueError as exc:
            print(f"error: {exc}", file=sys.stderr)
            code = 2
            continue
        print(json.dumps(result))
    return code


if __name__ == "__main__":
    sys.exit(main())

"""Open a run's ``run.zarr`` and ``analysis.zarr`` with xarray and plot one result.

    python examples/open_run.py RUN_DIR [--finger ff] [--out PNG]

Both stores are zarr v3 groups that xarray opens as one ``DataTree`` each
(``xr.open_datatree(path, engine="zarr")``; layouts in docs/run_store.md and docs/analysis.md),
in either layout: a directory (``run.zarr`` of a recording) or packed, one zip file
(``run.zarr.zip`` of an import, ``analysis.zarr.zip`` of an analysis, after 0.2.0), which xarray
opens by the URL ``zip::PATH`` (fsspec's zip file system; :func:`store_url`).
This example prints the run's steps (from ``run.zarr`` ``/events``) and its segments with their
slip estimates (``analysis.zarr`` ``/segments`` and ``/estimates/slip``), and saves one figure:
a finger's pressure (PDC above its tare, from ``run.zarr`` ``/biotac``) with the segments as
bands and the slip displacement of each segment (default ``open_run.png`` in the current directory:
nothing is written into the run directory).

xarray gotcha: ``tree["events"].name`` is the *group's* name (``"events"``), not the events'
``name`` variable; read variables from the group's dataset, ``tree["events"].to_dataset()["name"]``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402


def store_url(directory: Path, name: str) -> str | None:
    """What ``xr.open_datatree`` is given for the store ``name`` in ``directory``: the path of
    the directory store ``name``, or ``zip::PATH`` of the packed ``name.zip``; None if neither."""
    if (directory / name).is_dir():
        return str(directory / name)
    if (directory / f"{name}.zip").is_file():
        return f"zip::{(directory / f'{name}.zip').resolve()}"
    return None


def analysis_dir(run_dir: Path) -> Path:
    """The run's current analysis: ``RUN/analysis/`` (every analysis is kept in
    ``RUN/analyses/<name>/``; ``tactile-runs show RUN`` lists them), or the run directory
    itself for a run analysed before tactile-flow 0.2."""
    return run_dir / "analysis" if store_url(run_dir / "analysis", "analysis.zarr") else run_dir


def open_stores(run_dir: Path) -> tuple[xr.DataTree, xr.DataTree]:
    """The run's recording and its current analysis, each as a DataTree (lazy: arrays load on access)."""
    return (xr.open_datatree(store_url(run_dir, "run.zarr"), engine="zarr"),
            xr.open_datatree(store_url(analysis_dir(run_dir), "analysis.zarr"), engine="zarr"))


def steps(run: xr.DataTree) -> list[tuple[str, float, float]]:
    """(name, start s, end s) of every protocol step, from the ``step_start``/``step_end`` events."""
    events = run["events"].to_dataset()          # not run["events"].name: that is "events"
    # text arrays come back as numpy's variable-width StringDType: .tolist() gives Python strings
    kind, name, time = events["kind"].values.tolist(), events["name"].values.tolist(), events["time"].values
    starts = {n: float(t) for k, n, t in zip(kind, name, time) if k == "step_start"}
    ends = {n: float(t) for k, n, t in zip(kind, name, time) if k == "step_end"}
    return [(n, s, ends.get(n, float("nan"))) for n, s in starts.items()]


def pressure(run: xr.DataTree, finger: str) -> tuple[np.ndarray, np.ndarray]:
    """Time (s) and the finger's PDC above its tare (counts; above the record's 5th percentile
    without a tare event, e.g. an imported record)."""
    biotac = run["biotac"].to_dataset()
    pdc = biotac["pdc"].sel(finger=finger).values.astype(float)
    events = run["events"].to_dataset()
    rest = None
    for kind, detail in zip(events["kind"].values.tolist(), events["detail"].values.tolist()):
        if kind == "tare":
            rest = json.loads(detail)["pdc"].get(finger)
    return biotac["time"].values, pdc - (np.percentile(pdc, 5) if rest is None else rest)


def segment_table(analysis: xr.DataTree) -> list[dict]:
    """One row per segment: id, finger, label, start and end (s), and the slip estimate where the
    analysis made one (class, displacement mm, direction deg)."""
    seg = analysis["segments"].to_dataset()
    has_slip = "estimates" in analysis.children and "slip" in analysis["estimates"].children
    slip = analysis["estimates/slip"].to_dataset() if has_slip else None
    rows = []
    for i in seg["segment"].values:
        s = seg.sel(segment=i)
        row = {"id": int(i), "finger": str(s["finger"].values), "label": str(s["label"].values),
               "start": float(s["start"].values), "end": float(s["end"].values),
               "slip_class": None, "displacement": None, "direction": None}
        if slip is not None and i in slip["segment"].values:
            e = slip.sel(segment=i)
            direction = float(e["slip_direction_sensor"].values)      # NaN for a touch or a turn: no direction
            row.update(slip_class=str(e["slip_class"].values), displacement=float(e["slip_displacement"].values),
                       direction=direction if np.isfinite(direction) else None)
        rows.append(row)
    return rows


def plot(t, p, rows, finger: str, title: str, out: Path) -> None:
    """``finger``'s pressure ``p`` (counts) over ``t`` (s), its segments as bands, saved to ``out``."""
    colours = {}
    fig, ax = plt.subplots(figsize=(10, 3.6), layout="constrained")
    for r in rows:
        if r["finger"] != finger:
            continue
        first = r["label"] not in colours
        c = colours.setdefault(r["label"], f"C{len(colours) % 10}")
        ax.axvspan(r["start"], r["end"], color=c, alpha=0.18, lw=0, label=r["label"] if first else None)
        if r["displacement"] is not None:
            ax.text((r["start"] + r["end"]) / 2, 1.0, f"{r['displacement']:.2f}", transform=ax.get_xaxis_transform(),
                    ha="center", va="bottom", fontsize=7)
    ax.plot(t, p, color="k", lw=0.8, label="PDC above tare")
    ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=8)
    ax.set(xlabel="time since run start (s)", ylabel="PDC above tare (counts)")
    ax.set_title(f"{title}: segments, slip displacement (mm) above each", pad=14)
    fig.savefig(out, dpi=100)
    plt.close(fig)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("run_dir", type=Path, help="a run directory holding run.zarr and an analysis")
    parser.add_argument("--finger", default=None, help="the finger to plot (default: the protocol's)")
    parser.add_argument("--out", type=Path, default=None, help="PNG to write (default open_run.png here)")
    args = parser.parse_args(argv)
    if not store_url(args.run_dir, "run.zarr") or not store_url(analysis_dir(args.run_dir), "analysis.zarr"):
        print(f"error: {args.run_dir} holds no run.zarr and analysis (analyse it with "
              f"tactile-analyze run={args.run_dir}/run.zarr)", file=sys.stderr)
        return 2
    run, analysis = open_stores(args.run_dir)
    fingers = [str(f) for f in run["biotac"].to_dataset()["finger"].values]
    protocol_cfg = (run.attrs.get("provenance") or {}).get("config", {}).get("protocol") or {}
    finger = args.finger or protocol_cfg.get("finger") or fingers[0]
    if finger not in fingers:
        print(f"error: --finger {finger}: the run recorded {fingers}", file=sys.stderr)
        return 2
    print(f"run {args.run_dir}: protocol {run.attrs['protocol']}, status {run.attrs['status']}, fingers {fingers}")
    for name, start, end in steps(run):
        print(f"step {name}: {start:.3f}-{end:.3f} s")
    rows = segment_table(analysis)
    for r in rows:
        heading = "no direction" if r["direction"] is None else f"{r['direction']:.2f} deg"
        if r["slip_class"] is None:
            slip = ""
        elif not r["slip_class"]:                   # too short or unusable: summary.json says why
            slip = " slip undecided"
        else:
            slip = f" slip {r['slip_class']} {r['displacement']:.4f} mm {heading}"
        print(f"segment {r['id']} {r['finger']} {r['label']}: {r['start']:.4f}-{r['end']:.4f} s{slip}")
    t, p = pressure(run, finger)
    out = args.out or Path("open_run.png")
    plot(t, p, rows, finger, f"{run.attrs['protocol']}, {finger}", out)
    print(f"figure {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

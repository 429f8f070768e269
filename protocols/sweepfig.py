"""The figure of a sweep: each headline metric against each swept parameter (``sweep.png``).

One panel per (metric, parameter): the parameter's values along x (numbers in order, names as
categories), one line per combination of the other swept parameters, the mean over repeats
(a swept ``*seed*`` is a repeat, never an axis) with the spread (± one standard deviation)
as error bars, and the score's target as a dashed line where the metric has one
(``score_width_error_mm_median`` ≤ ``targets.width_error_mm_median.target`` of ``score.json``).
"""

from __future__ import annotations

import io
import json
import math
from collections import defaultdict
from pathlib import Path

from tactile_flow.runstore import analyses, files

MAX_METRICS = 8


def _number(v):
    if isinstance(v, bool) or v is None:
        return None
    try:
        x = float(v)
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) else None


def _targets(root: Path) -> dict:
    """``{headline key: target}`` from the first job's ``score.json`` that has targets."""
    for job in sorted(root.glob("*/run.json")):
        current = analyses.current_dir(job.parent)
        try:
            score = json.loads((current / "score.json").read_text()) if current else {}
        except (OSError, ValueError):
            continue
        out = {f"result.score_{k}": t.get("target") for k, t in (score.get("targets") or {}).items()
               if isinstance(t, dict) and _number(t.get("target")) is not None}
        if out:
            return out
    return {}


def sweep_figure(root: Path, rows: list[dict], swept: list[str]) -> bool:
    """Draw ``root/sweep.png`` (never through a link); False when there is nothing to draw (no
    swept parameter but repeats, or no numeric metric)."""
    axes_params = [p for p in swept if "seed" not in p.rsplit(".", 1)[-1]]
    metrics = [k for k in dict.fromkeys(k for r in rows for k in r if k.startswith("result.")
                                        and not k.startswith("result.slip."))
               if any(_number(r.get(k)) is not None for r in rows)
               and len({_number(r.get(k)) for r in rows if _number(r.get(k)) is not None}) > 1][:MAX_METRICS]
    if not axes_params or not metrics:
        return False
    import matplotlib
    matplotlib.use("Agg")
    from matplotlib.figure import Figure
    targets = _targets(root)
    fig = Figure(figsize=(3.6 * len(axes_params), 2.4 * len(metrics)), dpi=90)
    grid = fig.subplots(len(metrics), len(axes_params), squeeze=False)
    for j, param in enumerate(axes_params):
        values = list(dict.fromkeys(str(r.get(param)) for r in rows))
        numeric = all(_number(v) is not None for v in values)
        order = sorted(values, key=lambda v: _number(v)) if numeric else values
        others = [p for p in axes_params if p != param]
        for i, metric in enumerate(metrics):
            ax = grid[i][j]
            series = defaultdict(lambda: defaultdict(list))
            for r in rows:
                y = _number(r.get(metric))
                if y is not None:
                    label = ", ".join(f"{o.rsplit('.', 1)[-1]}={r.get(o)}" for o in others)
                    series[label][str(r.get(param))].append(y)
            for label, points in series.items():
                xs = [v for v in order if v in points]
                pos = [_number(v) if numeric else order.index(v) for v in xs]
                means = [sum(points[v]) / len(points[v]) for v in xs]
                spread = [math.sqrt(sum((y - m) ** 2 for y in points[v]) / (len(points[v]) - 1))
                          if len(points[v]) > 1 else 0.0 for v, m in zip(xs, means)]
                ax.errorbar(pos, means, yerr=spread, marker="o", ms=3, capsize=3, lw=1, label=label or None)
            if metric in targets:
                ax.axhline(targets[metric], ls="--", color="0.3", lw=1, label="target")
            if not numeric:
                ax.set_xticks(range(len(order)), order, fontsize=7)
            if i == len(metrics) - 1:
                ax.set_xlabel(param, fontsize=8)
            if j == 0:
                ax.set_ylabel(metric.removeprefix("result."), fontsize=7)
            ax.tick_params(labelsize=7)
            if i == 0 and (len(series) > 1 or metric in targets):
                ax.legend(fontsize=6)
    fig.suptitle(f"{root.name}: {len(rows)} runs (mean ± s.d. over repeats)", fontsize=9)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    files.write_bytes(root, "sweep.png", buf.getvalue())
    return True

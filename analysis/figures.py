"""Figures (PNG, matplotlib Agg): what a researcher would put in a paper.

- ``electrodes.png``: raw vs Kalman+RTS smoothed activation of the most active taxels;
- ``pressure.png``: pressure per finger with its coloured segment bands (a sweep also marks the
  peaks of the features crossed), and markers where the live slip detector fired and the
  protocol's reactions were issued (one legend for the panels, beside the top one);
- ``taxels.png``: every taxel's smoothed activation (kΩ) over time with the segment bands above
  it, and the curves under the bands;
- ``ellipsoid.png``: the interpolated activation on the fitted ellipsoid (a shaded surface) at
  peak pressure, with the taxels on it;
- ``flow_<label>.png``: one figure per segment label, one row per finger (its middle segment of
  that label), one panel per view: the tactile frame at the segment's middle, the mean dynamic
  flow (orange quiver) and the segment's aggregated flow (cyan arrow), both drawn to one scale,
  the arrow left out below the flow's noise; every segment of the label is summarised in a
  line under its row.

Figures are built on :class:`matplotlib.figure.Figure` objects (no pyplot state) with fixed
margins (no ``tight_layout``: it costs a draw per figure); legends sit beside the axes, never
over the curves. Stacked time panels share one time range, labelled under the bottom panel.
They are drawn by :class:`.agg_canvas.Canvas` (each text line one cached bitmap, the PNG written
directly): matplotlib's own text and PNG paths were half of the figures' cost. With several
workers, :class:`FigureWriter` draws them in processes forked from the analysis.
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import sys
from collections.abc import Callable
from functools import partial
from pathlib import Path

import numpy as np

from tactile_flow.cliapp.workers import signals_deferred, stop_workers, worker_init
from tactile_flow.tactile import flow as tflow
from tactile_flow.tactile import surface

from . import flows as fl

log = logging.getLogger(__name__)

COLOURS = {"approach": "#c7c7c7", "before": "#4c72b0", "during": "#dd8452", "after": "#55a868", "lift": "#7f7f7f",
           "pour": "#4c72b0", "initial_slip": "#c44e52", "rotation": "#8172b3", "downward": "#dd8452",
           "full_slip": "#937860", "held": "#55a868", "contact": "#55a868", "no_contact": "#dddddd", "all": "#ffffff"}
TAXEL_COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e")
TAXEL_STYLES = ("-", "--", "-.", ":", (0, (5, 1, 1, 1)))
NO_FLOW_FIGURE = ("approach", "lift", "no_contact")
FLOW_KEY = ("The frame at a segment's middle (grey), the fingertip's outline in each view (green), the mean dynamic "
            "flow (orange) and the segment's\naggregated flow (cyan): the motion of the pressed pattern, which is "
            "opposite to the finger's.")
"""A flow figure's key under its title: the same lines in every flow figure (drawn once a run)."""
FLOW_PAIRS = 8
"""Frame pairs whose flow fields are averaged for a panel's quiver (spread over the segment)."""
LEGEND = dict(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
WIDE = dict(left=0.07, right=0.80)           # time-series figures: the legend in the right margin
DPI = 90
TITLE = dict(fontsize=10, y=1.0)
"""A time-series panel's title: a fixed ``y`` spares matplotlib placing it above the tick labels
(a layout pass per panel); there are none above a panel."""


def _figure(w: float, h: float):
    from matplotlib.figure import Figure

    from .agg_canvas import Canvas
    fig = Figure(figsize=(w, h))
    Canvas(fig)
    return fig


def _bands(ax, a, finger, labels: bool = True, y: tuple[float, float] = (0.0, 1.0), alpha: float = 0.3):
    """The finger's segments as bands from ``y[0]`` to ``y[1]`` (fractions of the axes' height),
    one collection per label (one patch per segment cost a sweep's figure more than its curves)."""
    from matplotlib.collections import PolyCollection
    t = a.run.time
    spans: dict[str, list] = {}
    for sg in a.segments:
        if sg.finger == finger and sg.label != "all":
            t0, t1 = t[sg.start], t[min(sg.stop, len(t) - 1)]
            spans.setdefault(sg.label, []).append([(t0, y[0]), (t0, y[1]), (t1, y[1]), (t1, y[0])])
    for label, boxes in spans.items():
        ax.add_collection(PolyCollection(boxes, transform=ax.get_xaxis_transform(), facecolors=COLOURS.get(label, "#eeeeee"),
                                         alpha=alpha, linewidths=0, label=label if labels else None), autolim=False)


def _reactions(ax, a) -> None:
    """Vertical markers at the live slip detections and the reactions they triggered (the
    detection dashed over the reaction, which follows it within a frame or two)."""
    for kind, style in (("reaction", dict(color="C2", ls="-", lw=2.5, alpha=0.6)),
                        ("slip", dict(color="C3", ls="--", lw=1.2, zorder=5))):
        for i, (t, name, detail) in enumerate(a.run.events.of_kind(kind)):
            what = (f"live slip\n{t:.2f} s ({name},\n{detail.get('cause', '?')})" if kind == "slip"
                    else f"reactions\n{t:.2f} s")
            ax.axvline(t, **style, label=what if i == 0 else None)


def _main_finger(a) -> tuple[str, int]:
    if a.contacts:
        k = int(np.argmax([np.abs(a.prepared.pressure[:, a.run.fingers.index(f)]).max() if f in a.contacts else -1
                           for f in a.run.fingers]))
        return a.run.fingers[k], k
    return a.run.fingers[0], 0


def _rows(n: int, height: float, top_in: float = 0.45, bottom_in: float = 0.55):
    """A one-column figure of ``n`` panels ``height`` in tall with fixed margins in inches, and
    its ``n`` axes (time along x: see :func:`_time_axes`)."""
    fig = _figure(11, n * height + top_in + bottom_in)
    h = fig.get_figheight()
    fig.subplots_adjust(top=1 - top_in / h, bottom=bottom_in / h, hspace=0.35, **WIDE)
    return fig, fig.subplots(n, 1, squeeze=False)[:, 0]


def _in_view():
    """An :class:`~matplotlib.ticker.AutoLocator` returning only the values inside the axis' view
    (matplotlib builds a tick, ~1 ms of Python, for every value a locator returns)."""
    from matplotlib.ticker import AutoLocator

    class InView(AutoLocator):
        def __call__(self):
            lo, hi = sorted(self.axis.get_view_interval())
            v, tol = np.asarray(super().__call__()), 1e-9 * (hi - lo)
            return v[(v >= lo - tol) & (v <= hi + tol)]
    return InView()


def _time_axes(axes, t: np.ndarray) -> None:
    """Panels stacked over one time axis ``t`` (s): the same x range; time tick labels under the
    bottom one; the panels above get their tick marks as one collection each (matplotlib's
    ticks cost ~1 ms apiece)."""
    import matplotlib as mpl
    from matplotlib.collections import LineCollection
    from matplotlib.ticker import NullLocator
    for ax in axes:
        ax.set_xlim(min(t[0], 0.0), t[-1])
        ax.yaxis.set_major_locator(_in_view())
    bottom = axes[-1]
    bottom.xaxis.set_major_locator(_in_view())
    bottom.set_xlabel("time since run start (s)")
    ticks = bottom.xaxis.get_major_locator()()
    size, width = (mpl.rcParams[f"xtick.major.{k}"] for k in ("size", "width"))       # pt
    for ax in axes[:-1]:
        ax.xaxis.set_major_locator(NullLocator())
        h_pt = ax.get_position().height * ax.get_figure().get_figheight() * 72
        ax.add_collection(LineCollection([[(x, 0), (x, -size / h_pt)] for x in ticks], colors="k", linewidths=width,
                                         transform=ax.get_xaxis_transform(), clip_on=False), autolim=False)


FIGURE_BINS = 800
"""Stretches a time series is drawn by (each by its lowest and highest value): about one per
pixel column of an 11-inch figure at 90 dpi; more points would draw the same picture slower."""


def _decimated(t: np.ndarray, y: np.ndarray, bins: int = FIGURE_BINS) -> tuple[np.ndarray, np.ndarray]:
    """``(t, y)`` with at most ``2·bins`` points: each stretch of frames by its lowest and highest
    value, in time order (a line drawn through them looks, at a figure's resolution, as the
    whole record would); a record of at most ``2·bins`` frames as it is."""
    if len(t) <= 2 * bins:
        return t, y
    edges = np.unique(np.linspace(0, len(t), bins + 1).astype(np.int64))
    return _interleave(t, edges, np.minimum.reduceat(y, edges[:-1]), np.maximum.reduceat(y, edges[:-1]))


def _interleave(t: np.ndarray, edges: np.ndarray, low: np.ndarray, high: np.ndarray, bins: int = FIGURE_BINS):
    """The (2·n,) times and values of stretches ``edges`` drawn by their lowest then highest
    value, neighbouring stretches merged to at most ``bins``."""
    if len(low) > bins:
        g = np.unique(np.linspace(0, len(low), bins + 1).astype(np.int64))
        edges, low, high = edges[g], np.minimum.reduceat(low, g[:-1]), np.maximum.reduceat(high, g[:-1])
    tt = np.repeat(t[edges[:-1]], 2)
    tt[1::2] = t[edges[1:] - 1]
    yy = np.empty((2 * len(low),) + low.shape[1:])
    yy[0::2], yy[1::2] = low, high
    return tt, yy


def electrodes(a):
    fingers = list(a.contacts) or [a.run.fingers[0]]
    fig, axes = _rows(len(fingers), 2.8)
    t, env = a.run.time, a.prepared.envelope
    for ax, f in zip(axes, fingers):
        k = a.run.fingers.index(f)
        top = np.argsort(-env.peak[k])[:5]
        tr, raw = _interleave(t, env.edges, env.raw_min[:, k][:, top], env.raw_max[:, k][:, top])
        ts, act = _interleave(t, env.edges, env.act_min[:, k][:, top], env.act_max[:, k][:, top])
        for j, tx in enumerate(top):
            c, ls = TAXEL_COLOURS[j], TAXEL_STYLES[j]
            ax.plot(tr, raw[:, j], color=c, lw=0.5, alpha=0.35)
            ax.plot(ts, act[:, j], color=c, ls=ls, lw=1.5, label=f"taxel {tx + 1}")
        ax.set_ylabel("activation (kΩ)")
        ax.set_title(f"{f}: raw (thin) vs Kalman+RTS smoothed (thick), the 5 most active taxels", **TITLE)
        ax.legend(**LEGEND)
    _time_axes(axes, t)
    return fig


def pressure(a):
    fingers = list(a.contacts) or list(a.run.fingers)
    fig, axes = _rows(len(fingers), 2.6)
    t = a.run.time
    unit = "PDC above rest" if a.prepared.pressure_name == "pdc" else "Σ activation (kΩ)"
    for ax, f in zip(axes, fingers):
        k = a.run.fingers.index(f)
        p = a.prepared.pressure[:, k]
        _bands(ax, a, f)
        ax.plot(*_decimated(t, p), color="k", lw=1, label="pressure")
        ex = a.extrema.get(f)
        if ex is not None and a.scheme == "sweep":      # the features crossed; a pour's are its phase bands
            ax.plot(t[ex.peaks], p[ex.peaks], "v", color="C3", label="peaks")
        if f in a.thresholds:
            ax.axhline(a.thresholds[f], color="C7", ls=":", lw=1, label="contact\nthreshold")
        _reactions(ax, a)
        ax.set_ylabel(unit)
        ax.set_title(f"{f}: pressure and segments ({a.scheme} labels)", **TITLE)
    _time_axes(axes, t)
    _legend(fig, axes)
    return fig


def _legend(fig, axes) -> None:
    """One legend beside the top panel for every entry of ``axes`` (each label once): the panels
    share their colours and markers."""
    entries: dict[str, object] = {}
    for ax in axes:
        for handle, label in zip(*ax.get_legend_handles_labels()):
            entries.setdefault(label, handle)
    box = axes[0].get_position()
    fig.legend(entries.values(), entries.keys(), **{**LEGEND, "bbox_to_anchor": (box.x1 + 0.01, box.y1)})


def taxels(a):
    f, k = _main_finger(a)
    t = a.run.time
    fig = _figure(11, 6.2)
    fig.subplots_adjust(top=0.93, bottom=0.09, hspace=0.12, **WIDE)
    ax, ax2 = fig.subplots(2, 1, gridspec_kw={"height_ratios": [2, 1]})
    env = a.prepared.envelope                    # a long record: each stretch of frames by its highest value
    n = env.act_max.shape[2]
    im = ax.imshow(env.act_max[:, k].T, aspect="auto", origin="lower", extent=(t[0], t[-1], 0.5, n + 0.5),
                   cmap="magma", interpolation="nearest")
    _bands(ax, a, f, labels=False, y=(0.97, 1.0), alpha=1.0)      # the bands as a strip along the heatmap's top
    box = ax.get_position()
    cax = fig.add_axes([box.x1 + 0.01, box.y0, 0.012, box.height])
    fig.colorbar(im, cax=cax, label="activation (kΩ)")
    ax.set_ylabel(f"taxel (1..{n})")
    ax.set_title(f"{f}: smoothed taxel activations (impedance above rest); segments along the top", **TITLE)
    _bands(ax2, a, f)
    ax2.plot(*_interleave(t, env.edges, env.act_min[:, k], env.act_max[:, k]), lw=0.6)
    ax2.set_ylabel("activation (kΩ)")
    _time_axes([ax, ax2], t)
    if ax2.get_legend_handles_labels()[0]:                  # no bands when nothing was segmented
        ax2.legend(**{**LEGEND, "bbox_to_anchor": (1.09, 1.0)}, title="segments")
    return fig


def ellipsoid(a, model):
    from matplotlib import cm, colors
    from matplotlib.ticker import MaxNLocator
    from matplotlib.tri import Triangulation
    f, k = _main_finger(a)
    i = int(np.argmax(a.prepared.proxy[:, k]))
    values = surface.interpolate(a.prepared.activation[i:i + 1, k], model.weights)[0]
    pts, tris = model.mesh.points, model.mesh.triangles
    fig = _figure(8.5, 6.0)
    fig.subplots_adjust(left=0.0, right=0.86, top=0.95, bottom=0.0)
    ax = fig.add_subplot(projection="3d", computed_zorder=False)   # the taxels drawn over the surface
    norm = colors.Normalize(vmin=0.0, vmax=max(float(values.max()), 1e-6))
    surf = ax.plot_trisurf(Triangulation(pts[:, 0], pts[:, 1], tris), pts[:, 2], lw=0, antialiased=False,
                           shade=True, cmap="magma", norm=norm)
    surf.set_array(values[tris].mean(axis=1))
    ax.scatter(*model.taxels.T, color="cyan", edgecolor="k", lw=0.4, s=22, depthshade=False, zorder=3)
    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
        axis.set_major_locator(MaxNLocator(4))
    ax.set_xlabel("x (mm, along finger)", labelpad=14)
    ax.set_ylabel("y (mm, lateral)", labelpad=16)
    ax.set_zlabel("z (mm, pad normal)", labelpad=14)
    ax.tick_params(axis="both", pad=2, labelsize=8)
    extent = np.ptp(pts, axis=0)
    ax.set_box_aspect(np.maximum(extent, 0.05 * extent.max()), zoom=0.95)     # a flat sensor: a thin box
    ax.view_init(elev=-35, azim=-60)
    name = model.sensor.name if model.sensor is not None else "the sensor"
    fig.suptitle(f"{f}: activation on the fingertip at t = {a.run.time[i]:.2f} s (its peak);\n"
                 f"cyan: the {model.n_taxels} taxels of {name}", fontsize=10)
    cax = fig.add_axes([0.9, 0.22, 0.02, 0.5])
    fig.colorbar(cm.ScalarMappable(norm=norm, cmap="magma"), cax=cax, label="activation (kΩ)")
    return fig


def _mean_field(cf, view, s: int, e: int, estimator) -> np.ndarray | None:
    """Mean dynamic flow field (H, W, 2) px/frame over up to :data:`FLOW_PAIRS` frame pairs of
    [s, e) (window-relative)."""
    vr = cf.views[view]
    first = max(s, 1)
    if e - first < 1:
        return None
    pairs = np.unique(np.linspace(first, e - 1, min(FLOW_PAIRS, e - first)).astype(int))
    return np.mean([estimator(vr.frames[p - 1], vr.frames[p]) for p in pairs], axis=0)


def _axis(v) -> str:
    names = ["x", "y", "z"]
    i = int(np.argmax(np.abs(v)))
    return ("+" if v[i] > 0 else "−") + names[i]


def _summary_line(segments, rows, mm_s_per_px: float) -> str:
    """Every segment of a label in the bottom view: each one's aggregated |flow| (px/frame: the
    aggregates' mm/s divided by ``mm_s_per_px``, the bottom view's pixel size × the rate) and
    image direction (up to four), or their range and circular mean (more)."""
    aggs = [(sg, (rows.get(sg.id) or {}).get("flows", {}).get(("bottom", "dynamic"))) for sg in segments]
    found = [g for _, g in aggs if g is not None]
    head = f"Bottom view, the finger's {len(segments)} segment(s) of this label (image angle): "
    if len(segments) <= 4:
        return head + "; ".join(
            f"s{sg.id}" + (f" f{sg.feature}" if sg.feature >= 0 else "") + ": "
            + (f"{g['magnitude'] / mm_s_per_px:.3f} px/frame at {np.degrees(g['direction']) % 360:.0f}°" if g else "–")
            for sg, g in aggs)
    if not found:
        return head + "no flow"
    mags = [g["magnitude"] / mm_s_per_px for g in found]
    angle = np.degrees(np.angle(np.mean([np.exp(1j * g["direction"]) for g in found]))) % 360
    return head + (f"|flow| {min(mags):.3f}–{max(mags):.3f} px/frame (median {np.median(mags):.3f}), "
                   f"mean direction {angle:.0f}°")


def _outline(mask: np.ndarray) -> np.ndarray:
    """The boundary of a (H, W) bool mask as (N, 2, 2) segments (column, row) along pixel edges."""
    m = np.pad(mask, 1)
    r, c = np.nonzero(m[1:, 1:-1] != m[:-1, 1:-1])                  # edge above pixel (r, c)
    horizontal = np.stack([np.c_[c - 0.5, r - 0.5], np.c_[c + 0.5, r - 0.5]], axis=1)
    r, c = np.nonzero(m[1:-1, 1:] != m[1:-1, :-1])                  # edge left of pixel (r, c)
    vertical = np.stack([np.c_[c - 0.5, r - 0.5], np.c_[c - 0.5, r + 0.5]], axis=1)
    return np.concatenate([horizontal, vertical])


def _segments_patch(segments: np.ndarray, **style):
    """(N, 2, 2) line segments as one path (a patch): one Path object, not one per segment (an
    outline has ~100 pixel edges a view)."""
    from matplotlib.patches import PathPatch
    from matplotlib.path import Path
    codes = np.tile(np.array([Path.MOVETO, Path.LINETO], Path.code_type), len(segments))
    return PathPatch(Path(segments.reshape(-1, 2), codes), fill=False, **style)


def flow_panels(a, model, segments: list, estimator):
    """What a label's flow figure shows: ``(by_finger, picked, fields)``, the label's segments per
    finger, each finger's middle segment as (segment, its contact flow, start, stop in the
    window), and its mean dynamic flow field per view; ``None`` if no segment has flow. The
    fields are OpenCV's work, done here so that :func:`flow_label` only draws."""
    by_finger: dict[str, list] = {}
    for sg in segments:
        if fl.find(a.flows, sg.finger, sg.start, sg.stop) is not None:
            by_finger.setdefault(sg.finger, []).append(sg)
    if not by_finger:
        return None
    fields, picked = [], []
    for f, sgs in by_finger.items():
        sg = sgs[len(sgs) // 2]
        cf = fl.find(a.flows, f, sg.start, sg.stop)
        s, e = sg.start - cf.window[0], sg.stop - cf.window[0]
        picked.append((sg, cf, s, e))
        fields.append({v: _mean_field(cf, v, s, e, estimator) for v in model.plans if v in cf.views})
    return by_finger, picked, fields


def flow_label(a, model, label: str, panels, rows: dict):
    """One figure for every segment called ``label``: a row per finger (its middle segment);
    ``panels``: :func:`flow_panels`."""
    by_finger, picked, fields = panels
    views = list(model.plans)
    n = len(by_finger)
    rate = a.run.rate_hz
    # one scale for every arrow: the largest (field or aggregate) spans a quarter of a frame
    h_px, w_px = next(iter(model.plans.values())).shape
    biggest = max([np.abs(m).max() for fs in fields for m in fs.values() if m is not None] +
                  [agg["magnitude"] / (model.plans[v].mm_per_px * rate)
                   for sg, *_ in picked for (v, kind), agg in (rows.get(sg.id) or {}).get("flows", {}).items()
                   if kind == "dynamic"] + [1e-6])
    scale = biggest / (0.25 * min(h_px, w_px))               # px/frame per drawn px
    bottom_mm_s_per_px = model.plans["bottom"].mm_per_px * rate if "bottom" in model.plans else float("nan")
    # Fixed layout in inches: a heading per view (its axes), then per row a title, the frame and
    # the summary line. Every panel is drawn on one axes spanning the figure, in frame pixels
    # (one axes per panel made matplotlib's own overhead most of the figure's cost).
    top_in, row_in, img_in, col_in = 1.05, 2.55, 1.85, 3.6
    W, H = col_in * len(views), top_in + row_in * n + 0.1
    px_in = min((col_in - 0.75) / w_px, img_in / h_px)              # inches per frame pixel
    fig = _figure(W, H)
    ax = fig.add_axes([0, 0, 1, 1])
    ax.set_axis_off()
    ax.set_xlim(-0.5, W / px_in - 0.5)
    ax.set_ylim(H / px_in - 0.5, -0.5)                               # rows down, as in an image

    def corner(r: int, j: int) -> tuple[int, int]:
        """(column, row) in the figure's pixel grid of panel (row r, view j)'s pixel (0, 0)."""
        return round((0.55 + col_in * j) / px_in), round((top_in + row_in * r + 0.3) / px_in)

    for j, v in enumerate(views):
        plan = model.plans[v]
        fig.text((0.55 + col_in * j) / W, (H - top_in + 0.12) / H,
                 f"{v} view: → sensor {_axis(plan.cols)} ({plan.shape[1] * plan.mm_per_px:.0f} mm wide), "
                 f"↓ sensor {_axis(plan.rows)}", fontsize=8, va="bottom")
    canvas = np.full((round(H / px_in) + 1, round(W / px_in) + 1), 255, np.uint8)
    outlines, borders, quiver = [], [], []
    noise = model.config.noise
    for r, ((sg, cf, s, e), mean) in enumerate(zip(picked, fields)):
        row = rows.get(sg.id) or {}
        for j, v in enumerate(views):
            if v not in cf.views:
                continue
            plan = model.plans[v]
            c0, r0 = corner(r, j)
            canvas[r0:r0 + h_px, c0:c0 + w_px] = cf.views[v].frames[(s + e - 1) // 2]
            borders.append([(c0 - 0.5, r0 - 0.5), (c0 + w_px - 0.5, r0 - 0.5), (c0 + w_px - 0.5, r0 + h_px - 0.5),
                            (c0 - 0.5, r0 + h_px - 0.5), (c0 - 0.5, r0 - 0.5)])
            outlines.extend(_outline(plan.mask) + (c0, r0))
            m = mean.get(v)
            if m is not None:
                yy, xx = np.mgrid[0:h_px:3, 0:w_px:3]
                keep = plan.mask[::3, ::3]
                quiver.append((xx[keep] + c0, yy[keep] + r0, m[::3, ::3, 0][keep], m[::3, ::3, 1][keep]))
            agg = row.get("flows", {}).get((v, "dynamic"))
            title = sg.finger
            if agg is not None:
                px = agg["magnitude"] / (plan.mm_per_px * rate)       # px/frame
                title += f": {px:.3f} px/frame, conf {agg['confidence']:.2f}"
                if px >= noise and agg["confidence"] > 0:
                    vec = np.array([np.cos(agg["direction"]), np.sin(agg["direction"])]) * px / scale
                    mid = np.array([c0 + w_px / 2, r0 + h_px / 2])
                    ax.annotate("", xy=tuple(mid + vec), xytext=tuple(mid), gid=f"aggregate:{px!r}", zorder=4,
                                arrowprops=dict(color="cyan", width=2.0, headwidth=7, shrink=0.0))
                else:
                    title += " (no arrow: below noise)"
            ax.text(c0 + w_px / 2 - 0.5, r0 - 0.5 - 0.08 / px_in, title, fontsize=8, ha="center", va="bottom")
        t0, t1 = a.run.time[sg.start], a.run.time[min(sg.stop, len(a.run.time) - 1)]
        fig.text(0.1 / W, (H - top_in - row_in * (r + 1) + 0.12) / H,
                 f"{sg.finger} segment {sg.id}, {t0:.2f}–{t1:.2f} s. " + _summary_line(by_finger[sg.finger], rows,
                                                                                   bottom_mm_s_per_px),
                 fontsize=7, va="bottom")
    ax.imshow(canvas, cmap="gray", vmin=0, vmax=255, interpolation="nearest", aspect="auto",
              extent=(-0.5, canvas.shape[1] - 0.5, canvas.shape[0] - 0.5, -0.5))
    from matplotlib.collections import LineCollection
    ax.add_collection(LineCollection(borders, colors="k", linewidths=0.8))
    ax.add_artist(_segments_patch(np.asarray(outlines), edgecolor="C2", lw=0.8))   # add_patch walks its vertices
    if quiver:
        x, y, u, v = (np.concatenate(c) for c in zip(*quiver))
        ax.quiver(x, y, u, v, color="C1", angles="xy", scale_units="xy", scale=scale, width=0.0016, zorder=3)
    fig.suptitle(f"'{label}' segments; arrows to scale: a quarter of a frame is {biggest:.3f} px/frame.\n" + FLOW_KEY,
                 fontsize=8, y=1 - 0.1 / H, va="top")
    fig.flow_scale = scale                    # px/frame per drawn px (tests check the arrows against it)
    return fig


# ----------------------------------------------------------------------------- what each figure reads
# Every value a builder draws from, for its content address (:mod:`.figure_reuse`): two figures
# with the same inputs and drawing code are the same file. A builder added without an entry in
# READS gets no key (always drawn); one that reads something more must list it here.
def _common(a) -> dict:
    return {"fingers": list(a.run.fingers), "contacts": list(a.contacts), "time": a.run.time}


def _segment_spans(a) -> list:
    return [(sg.finger, sg.label, sg.start, sg.stop) for sg in a.segments]


def _electrodes_reads(a) -> dict:
    return {**_common(a), "envelope": a.prepared.envelope}


def _pressure_reads(a) -> dict:
    return {**_common(a), "pressure": a.prepared.pressure, "pressure_name": a.prepared.pressure_name,
            "scheme": a.scheme, "segments": _segment_spans(a), "thresholds": dict(a.thresholds),
            "peaks": {f: ex.peaks for f, ex in a.extrema.items()},
            "events": [(t, name, str(detail.get("cause", "?"))) for kind in ("reaction", "slip")
                       for t, name, detail in a.run.events.of_kind(kind)]}


def _taxels_reads(a) -> dict:
    return {**_common(a), "main": _main_finger(a), "envelope": a.prepared.envelope, "segments": _segment_spans(a)}


def _ellipsoid_reads(a, model) -> dict:
    f, k = _main_finger(a)
    i = int(np.argmax(a.prepared.proxy[:, k]))
    return {"main": f, "t": float(a.run.time[i]), "activation": np.asarray(a.prepared.activation[i:i + 1, k]),
            "weights": model.weights, "points": model.mesh.points, "triangles": model.mesh.triangles,
            "taxels": model.taxels, "sensor": model.sensor.name if model.sensor is not None else None}


def _flow_label_reads(a, model, label, panels, rows) -> dict:
    by_finger, picked, fields = panels
    views = list(model.plans)
    shown = [sg for sgs in by_finger.values() for sg in sgs]
    return {"label": label, "time": a.run.time, "rate": a.run.rate_hz, "noise": model.config.noise,
            "plans": [(v, p.shape, p.mm_per_px, p.cols, p.rows, p.mask) for v, p in model.plans.items()],
            "by_finger": {f: [(sg.id, sg.finger, sg.feature, sg.start, sg.stop) for sg in sgs]
                          for f, sgs in by_finger.items()},
            "picked": [(sg.id, s, e, {v: cf.views[v].frames[(s + e - 1) // 2] for v in views if v in cf.views})
                       for sg, cf, s, e in picked],
            "fields": fields, "rows": {sg.id: (rows.get(sg.id) or {}).get("flows", {}) for sg in shown}}


READS = {electrodes: _electrodes_reads, pressure: _pressure_reads, taxels: _taxels_reads,
         ellipsoid: _ellipsoid_reads, flow_label: _flow_label_reads}
"""Builder → the function returning what it reads (called with the builder's arguments)."""


def job_key(name: str, build, code: str | None = None) -> str | None:
    """The content address of the figure ``name`` that ``build`` (a ``functools.partial`` of a
    builder) draws: :func:`.figure_reuse.figure_key` of what it reads (``code``: its
    ``code_digest``, if computed already); None for a builder without an entry in :data:`READS`."""
    reads = READS.get(getattr(build, "func", None))
    if reads is None:
        return None
    from .figure_reuse import figure_key
    try:
        return figure_key(name, reads(*build.args, **build.keywords), code)
    except TypeError as e:                       # an input of a type the hash does not know: drawn every time
        log.warning("figures: %s has no content address (%s); it is drawn every time", name, e)
        return None


def plan(a, cfg) -> tuple[list[tuple[str, list]], list[str]]:
    """The flow figures to draw: [(label, its segments)] in order of first appearance, at most
    ``cfg.max_segment_figures``; and the labels left out by that cap."""
    by_label: dict[str, list] = {}
    for sg in a.segments:
        if sg.label not in NO_FLOW_FIGURE:
            by_label.setdefault(sg.label, []).append(sg)
    items = list(by_label.items())
    return items[:cfg.max_segment_figures], [k for k, _ in items[cfg.max_segment_figures:]]


def figure_jobs(a, model, cfg) -> tuple[list[tuple[str, Callable]], list[str]]:
    """Every figure to draw (of the kinds ``cfg.figures`` names, or all), as (file name, builder)
    pairs in order (a builder returns the Figure; a label none of whose segments has flow gets
    none), and the flow labels the cap left out. The builders only draw: what needs OpenCV (the flow figures' mean fields) is
    computed here, so they can run in processes forked from this one."""
    from .config import FIGURE_KINDS
    kinds = FIGURE_KINDS if cfg.figures is True else cfg.figures or ()
    jobs = [(f"{kind}.png", partial(build, *args)) for kind, build, args in (
        ("electrodes", electrodes, (a,)), ("pressure", pressure, (a,)), ("taxels", taxels, (a,)),
        ("ellipsoid", ellipsoid, (a, model))) if kind in kinds]
    if "flow" not in kinds:
        return jobs, []
    rows = {r["segment"]: r for r in a.aggregates}
    drawn, left_out = plan(a, cfg)
    estimator = tflow.FlowEstimator(cfg.tactile.flow)
    for label, segments in drawn:
        panels = flow_panels(a, model, segments, estimator)
        if panels is not None:
            jobs.append((f"flow_{label}.png", partial(flow_label, a, model, label, panels, rows)))
    return jobs, left_out


def build_all(a, model, cfg):
    """Every figure: [(file name, Figure)] and the flow labels the cap left out."""
    jobs, left_out = figure_jobs(a, model, cfg)
    return [(name, build()) for name, build in jobs], left_out


def _save(fig, path: Path) -> None:
    """Write ``fig`` as a PNG through the fast canvas; if that fails (it uses matplotlib's private
    text API, which a newer matplotlib may change), through matplotlib's own: slower, never lost.
    A fault of the figure itself fails there again and is raised."""
    try:
        fig.canvas.save_png(path, DPI)
    except Exception as e:                       # noqa: BLE001 - retried on the stock canvas below
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        log.warning("figures: the fast canvas failed (%s: %s); %s drawn by matplotlib's own",
                    type(e).__name__, e, path.name)
        FigureCanvasAgg(fig)
        fig.savefig(path, dpi=DPI)


def make_all(a, model, out_dir: Path, cfg, workers: int = 1, earlier: dict | None = None
             ) -> tuple[list[str], list[str]]:
    """Write every figure into ``out_dir`` (:class:`FigureWriter`). Returns the file names and the
    segment labels whose flow figure the cap ``max_segment_figures`` left out."""
    with FigureWriter(a, model, out_dir, cfg, workers, earlier) as writer:
        return writer.result()


_JOBS: list = []
"""The figure jobs of the running :class:`FigureWriter`: its forked workers inherit them."""


class FigureWriter:
    """Draws a run's figures into ``out_dir`` (PNG), in ``workers`` processes forked from this
    one while the caller goes on (writing ``analysis.zarr``), or here in :meth:`result` with
    one worker or where the platform cannot fork. The files are the same bytes either way.

    ``earlier``: figure key → a file drawn before with that key (:func:`.figure_reuse.earlier_figures`
    of the run): a figure whose key (:func:`job_key`) is there is linked from it, not drawn.
    ``keys`` (file name → key or None) and ``reused`` (the file names linked) say what was done.

    Use as a context manager: leaving it normally waits for every figure; leaving it on an
    error or an interrupt cancels the pool and ends its workers (SIGKILL) before returning, so
    ``out_dir`` can be removed safely and no worker outlives the analysis. So does an interrupt
    while the workers are being started (else the exit would wait for them forever)."""

    def __init__(self, a, model, out_dir: Path, cfg, workers: int = 1, earlier: dict | None = None):
        self.out_dir = Path(out_dir)
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self.jobs, self.left_out = figure_jobs(a, model, cfg)
        self.names = [name for name, _ in self.jobs]
        from .figure_reuse import code_digest
        code = code_digest()
        self.keys = {name: job_key(name, build, code) for name, build in self.jobs}
        self.reused = []
        if earlier:
            from .figure_reuse import link
            for name, _ in self.jobs:
                src = earlier.get(self.keys[name])
                try:
                    if src is not None:
                        link(src, self.out_dir / name)
                        self.reused.append(name)
                except OSError as e:             # removed meanwhile, unreadable: drawn instead
                    log.info("figures: %s not reused from %s (%s); drawn", name, src, e)
            self.jobs = [(name, build) for name, build in self.jobs if name not in self.reused]
        self.pool, self.futures = None, []
        workers = min(workers, len(self.jobs))
        if workers > 1 and "fork" in multiprocessing.get_all_start_methods():
            from concurrent.futures import ProcessPoolExecutor

            import matplotlib.figure  # noqa: F401 - imported once, here, not in every worker
            import matplotlib.tri  # noqa: F401
            from . import agg_canvas  # noqa: F401
            _JOBS[:] = self.jobs
            for stream in (sys.stdout, sys.stderr):
                stream.flush()                   # else a worker would flush this process's buffered output too
            self._others = set(multiprocessing.active_children())
            try:
                with signals_deferred():
                    self.pool = ProcessPoolExecutor(workers, multiprocessing.get_context("fork"), worker_init,
                                                    (os.getpid(),))
                    self.futures = [self.pool.submit(_draw_job, i, self.out_dir) for i in range(len(self.jobs))]
            except BaseException:                # Ctrl-C as the workers started: there is no __exit__
                self._stop_workers()
                raise

    def result(self) -> tuple[list[str], list[str]]:
        """The file names written (in order) and the flow labels the cap left out; raises what a
        figure raised."""
        if self.pool is not None:
            for f in self.futures:
                f.result()
        else:
            from . import agg_canvas
            try:
                for name, build in self.jobs:
                    _save(build(), self.out_dir / name)
            finally:
                agg_canvas.clear_text_cache()    # a run's figures share their labels, not the next run's
        return list(self.names), self.left_out

    def __enter__(self):
        return self

    def __exit__(self, exc_type, *exc) -> None:
        if self.pool is None:
            return
        drawn = False
        try:
            if exc_type is None:
                self.pool.shutdown(wait=True)
                drawn = True
        finally:
            if not drawn:                        # an error or an interrupt, before or during the wait
                self._stop_workers()
            _JOBS.clear()

    def _stop_workers(self) -> None:
        """Cancel what is queued and end the workers now (their figures are not wanted: the
        caller removes ``out_dir``): :func:`~tactile_flow.cliapp.workers.stop_workers`. A second
        Ctrl-C landing in a pool's orderly shutdown could leave a worker waiting and the process
        hanging at exit; one caught between a worker's start and the pool's bookkeeping counts too."""
        stop_workers(self.pool, self._others)


def _draw_job(i: int, out_dir: Path) -> None:
    name, build = _JOBS[i]
    _save(build(), out_dir / name)

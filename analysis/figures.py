"""Figures (PNG, matplotlib Agg): what a researcher would put in a paper.

- ``electrodes.png``: raw vs Kalman+RTS smoothed activation of the most active taxels;
- ``pressure.png``: pressure per finger with its peaks/troughs and coloured segment bands, and
  markers where the live slip detector fired and the protocol's reactions were issued;
- ``taxels.png``: every taxel's smoothed activation (kΩ) over time, with the same bands;
- ``ellipsoid.png``: the interpolated activation on the fitted ellipsoid (3D) at peak pressure;
- ``flow_<finger>_s<id>_<label>.png``: per segment, one panel per view: the tactile frame at the
  segment's middle, the mean dynamic flow over the segment (quiver) and an arrow for the
  aggregated direction.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from tactile import flow as tflow  # noqa: E402
from tactile import surface  # noqa: E402

from . import flows as fl  # noqa: E402

COLOURS = {"approach": "#bbbbbb", "before": "#4c72b0", "during": "#dd8452", "after": "#55a868", "lift": "#999999",
           "pour": "#4c72b0", "initial_slip": "#c44e52", "rotation": "#8172b3", "downward": "#dd8452",
           "full_slip": "#937860", "held": "#55a868", "contact": "#55a868", "no_contact": "#dddddd", "all": "#ffffff"}


def _bands(ax, a, finger):
    seen = set()
    for sg in a.segments:
        if sg.finger != finger or sg.label == "all":
            continue
        t0 = a.run.time[sg.start]
        t1 = a.run.time[min(sg.stop, len(a.run.time) - 1)]
        ax.axvspan(t0, t1, color=COLOURS.get(sg.label, "#eeeeee"), alpha=0.25, lw=0,
                   label=None if sg.label in seen else sg.label)
        seen.add(sg.label)


def _reactions(ax, a) -> None:
    """Vertical markers at the live slip detections and the reactions they triggered (the
    detection dashed over the reaction, which follows it within a frame or two)."""
    for kind, style in (("reaction", dict(color="C2", ls="-", lw=2.5, alpha=0.6)),
                        ("slip", dict(color="C3", ls="--", lw=1.2, zorder=5))):
        for i, (t, name, detail) in enumerate(a.run.events.of_kind(kind)):
            what = (f"live slip detected {t:.2f} s ({name}, {detail.get('cause', '?')})" if kind == "slip"
                    else f"reactions issued {t:.2f} s")
            ax.axvline(t, **style, label=what if i == 0 else None)


def _main_finger(a) -> tuple[str, int]:
    if a.contacts:
        k = int(np.argmax([np.abs(a.prepared.pressure[:, a.run.fingers.index(f)]).max() if f in a.contacts else -1
                           for f in a.run.fingers]))
        return a.run.fingers[k], k
    return a.run.fingers[0], 0


def electrodes(a, path: Path) -> None:
    fingers = list(a.contacts) or [a.run.fingers[0]]
    fig, axes = plt.subplots(len(fingers), 1, figsize=(11, 3.2 * len(fingers)), squeeze=False, sharex=True)
    t = a.run.time
    for ax, f in zip(axes[:, 0], fingers):
        k = a.run.fingers.index(f)
        top = np.argsort(-np.abs(a.prepared.activation[:, k]).max(axis=0))[:5]
        for j, tx in enumerate(top):
            c = f"C{j}"
            ax.plot(t, a.prepared.raw_activation[:, k, tx], color=c, lw=0.5, alpha=0.45)
            ax.plot(t, a.prepared.activation[:, k, tx], color=c, lw=1.6, label=f"taxel {tx + 1}")
        ax.set_ylabel("activation (kΩ)")
        ax.set_title(f"{f}: raw (thin) vs Kalman+RTS smoothed (thick) activation, 5 most active taxels")
        ax.legend(fontsize=8, ncol=5, loc="upper left")
    axes[-1, 0].set_xlabel("time since run start (s)")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def pressure(a, path: Path) -> None:
    fingers = list(a.contacts) or list(a.run.fingers)
    fig, axes = plt.subplots(len(fingers), 1, figsize=(11, 3.0 * len(fingers)), squeeze=False, sharex=True)
    t = a.run.time
    unit = "PDC counts above rest" if a.prepared.pressure_name == "pdc" else "Σ activation (kΩ, PDC proxy)"
    for ax, f in zip(axes[:, 0], fingers):
        k = a.run.fingers.index(f)
        p = a.prepared.pressure[:, k]
        _bands(ax, a, f)
        ax.plot(t, p, color="k", lw=1, label="pressure")
        ex = a.extrema.get(f)
        if ex is not None:
            ax.plot(t[ex.peaks], p[ex.peaks], "v", color="C3", label="peaks")
            ax.plot(t[ex.troughs], p[ex.troughs], "^", color="C0", label="troughs")
        if f in a.thresholds:
            ax.axhline(a.thresholds[f], color="C7", ls=":", lw=1, label="contact threshold")
        _reactions(ax, a)
        ax.set_ylabel(unit)
        ax.set_title(f"{f}: pressure, peaks and segments ({a.scheme} labels)")
        ax.legend(fontsize=8, ncol=4, loc="upper left")
    axes[-1, 0].set_xlabel("time since run start (s)")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def taxels(a, path: Path) -> None:
    f, k = _main_finger(a)
    t = a.run.time
    fig, (ax, ax2) = plt.subplots(2, 1, figsize=(11, 7), sharex=True, gridspec_kw={"height_ratios": [2, 1]})
    act = a.prepared.activation[:, k]
    im = ax.imshow(act.T, aspect="auto", origin="lower", extent=(t[0], t[-1], 0.5, 24.5), cmap="magma",
                   interpolation="nearest")
    fig.colorbar(im, ax=[ax, ax2], label="activation (kΩ)", shrink=0.8)
    ax.set_ylabel("taxel (1..24)")
    ax.set_title(f"{f}: smoothed taxel activations (impedance above rest)")
    _bands(ax2, a, f)
    ax2.plot(t, act, lw=0.6)
    ax2.set_ylabel("activation (kΩ)")
    ax2.set_xlabel("time since run start (s)")
    if ax2.get_legend_handles_labels()[0]:                  # no bands when nothing was segmented
        ax2.legend(fontsize=8, ncol=6, loc="upper left", title="segments")
    fig.savefig(path, dpi=90)
    plt.close(fig)


def ellipsoid(a, model, path: Path) -> None:
    f, k = _main_finger(a)
    i = int(np.argmax(a.prepared.proxy[:, k]))
    values = surface.interpolate(a.prepared.activation[i:i + 1, k], model.weights)[0]
    pts = model.mesh.points
    fig = plt.figure(figsize=(8, 6))
    ax = fig.add_subplot(projection="3d")
    sc = ax.scatter(pts[:, 0], pts[:, 1], pts[:, 2], c=values, cmap="magma", s=6)
    ax.scatter(*model.taxels.T, color="cyan", s=18, marker="o", label="taxels")
    ax.set_xlabel("x (mm, along finger)")
    ax.set_ylabel("y (mm, lateral)")
    ax.set_zlabel("z (mm, pad normal)")
    ax.set_title(f"{f}: interpolated activation on the ellipsoid at t = {a.run.time[i]:.2f} s (peak)")
    ax.view_init(elev=-35, azim=-60)
    fig.colorbar(sc, ax=ax, label="activation (kΩ)", shrink=0.7)
    ax.legend(loc="upper left")
    fig.savefig(path, dpi=90)
    plt.close(fig)


def segment_flow(a, model, sg, row, path: Path, cfg) -> bool:
    cf = fl.find(a.flows, sg.finger, sg.start, sg.stop)
    if cf is None:
        return False
    views = list(cf.views)
    fig, axes = plt.subplots(1, len(views), figsize=(4.6 * len(views), 4.0), squeeze=False)
    est = tflow.FlowEstimator(cfg.tactile.flow)
    s, e = sg.start - cf.window[0], sg.stop - cf.window[0]
    pairs = np.unique(np.linspace(max(s, 1), e - 1, min(20, max(e - max(s, 1), 1))).astype(int))
    for ax, v in zip(axes[0], views):
        vr, plan = cf.views[v], model.plans[v]
        mid = (s + e - 1) // 2
        ax.imshow(vr.frames[mid], cmap="gray", vmin=0, vmax=255, origin="upper")
        mean = np.mean([est(vr.frames[p - 1], vr.frames[p]) for p in pairs], axis=0) if len(pairs) else None
        if mean is not None:
            step = 3
            yy, xx = np.mgrid[0:mean.shape[0]:step, 0:mean.shape[1]:step]
            m = plan.mask[::step, ::step]
            u, w = mean[::step, ::step, 0], mean[::step, ::step, 1]
            ax.quiver(xx[m], yy[m], u[m], w[m], color="C1", angles="xy", scale_units="xy",
                      scale=max(np.abs(mean).max() / 2.5, 1e-6), width=0.006)
        agg = (row or {}).get("flows", {}).get((v, "dynamic"))
        if agg is not None:
            vec = np.array([np.cos(agg["direction"]), np.sin(agg["direction"])])
            c0, r0 = plan.shape[1] / 2, plan.shape[0] / 2
            ax.annotate("", xy=(c0 + 8 * vec[0], r0 + 8 * vec[1]), xytext=(c0, r0),
                        arrowprops=dict(color="cyan", width=2.5, headwidth=9))
            ax.set_title(f"{v}: |flow| {agg['magnitude']:.2f} mm/s, conf {agg['confidence']:.2f}", fontsize=9)
        else:
            ax.set_title(v, fontsize=9)
        ax.contour(plan.mask, levels=[0.5], colors="C2", linewidths=0.8)
        ax.set_xlabel(f"col (px, {plan.mm_per_px:.2f} mm/px) → sensor {_axis(plan.cols)}")
        ax.set_ylabel(f"row (px) → sensor {_axis(plan.rows)}")
    t0, t1 = a.run.time[sg.start], a.run.time[min(sg.stop, len(a.run.time) - 1)]
    fig.suptitle(f"{sg.finger} segment {sg.id} '{sg.label}'" + (f" feature {sg.feature}" if sg.feature >= 0 else "")
                 + f", {t0:.2f}–{t1:.2f} s: frame at the middle, mean dynamic flow (orange), "
                 f"aggregated direction (cyan)", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return True


def _axis(v) -> str:
    names = ["x", "y", "z"]
    i = int(np.argmax(np.abs(v)))
    return ("+" if v[i] > 0 else "−") + names[i]


def make_all(a, model, out_dir: Path, cfg) -> list[str]:
    """Write every figure into ``out_dir``; returns the file names."""
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for name, fn in (("electrodes.png", lambda p: electrodes(a, p)), ("pressure.png", lambda p: pressure(a, p)),
                     ("taxels.png", lambda p: taxels(a, p)), ("ellipsoid.png", lambda p: ellipsoid(a, model, p))):
        fn(out_dir / name)
        written.append(name)
    rows = {r["segment"]: r for r in a.aggregates}
    n = 0
    for sg in a.segments:
        if n >= cfg.max_segment_figures:
            break
        if sg.label in ("approach", "lift", "no_contact"):
            continue
        name = f"flow_{sg.finger}_s{sg.id:03d}_{sg.label}.png"
        if segment_flow(a, model, sg, rows.get(sg.id), out_dir / name, cfg):
            written.append(name)
            n += 1
    return written

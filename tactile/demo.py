"""``tactile-demo``: tactile flow of a synthetic contact sliding across a BioTac SP.

A Gaussian pressure bump moves along +x across the 24 taxels; the demo runs the whole
method (Kalman + RTS, geodesic kernel interpolation, tactile surface, z-buffered frames,
Farnebäck flow, aggregation), prints the direction of motion it finds in the sensor frame,
and saves a figure of frames and flow to ``outputs/tactile_demo.png``.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from . import aggregate, synthetic
from .pipeline import TactileConfig, TactileModel, process_view


EPILOG = """examples:
  tactile-demo                          # 10 mm/s along +x; figure outputs/tactile_demo.png
  tactile-demo --speed 20 --angle 90    # 20 mm/s along +y
  tactile-demo --figure ''              # print the result only

exit status: 0 done, 2 bad option (one line)."""


def main(argv: list[str] | None = None) -> int:
    from tactile_flow.validation.cli import ArgumentParser, help_text
    parser = ArgumentParser(prog="tactile-demo", description=help_text(__doc__), epilog=EPILOG)
    parser.add_argument("--speed", type=float, default=10.0, help="sliding speed, mm/s (default 10)")
    parser.add_argument("--angle", type=float, default=0.0,
                        help="direction of motion in the pad plane, degrees from +x (default 0)")
    parser.add_argument("--figure", default="outputs/tactile_demo.png", help="output PNG ('' for none; "
                        "default outputs/tactile_demo.png)")
    args = parser.parse_args(argv)

    t0 = time.perf_counter()
    print("building the sensor model (ellipsoid fit, mesh, geodesic kernel; cached after the first run)...")
    model = TactileModel.build(TactileConfig())
    heading = np.deg2rad(args.angle)
    direction = np.array([np.cos(heading), np.sin(heading), 0.0])
    duration = 16.0 / max(args.speed, 1e-3)               # cross 16 mm of the pad
    rng = np.random.default_rng(0)
    clean = synthetic.moving_bump(model.taxels, start=-8 * direction, velocity=args.speed * direction,
                                  duration=duration)
    noisy = clean + rng.normal(0, 0.07, clean.shape)      # ~ the electrodes' resting noise, kΩ
    activation = model.smooth(noisy)

    result = process_view(model, activation, "bottom", keep_fields=True)
    plan = model.plans["bottom"]
    loaded = np.flatnonzero(activation.sum(axis=1) > 2.0)
    summary = aggregate.window(result.dynamic, int(loaded[0]) + 1, int(loaded[-1]) + 1)
    vec = plan.image_to_sensor([summary["mean_col"], summary["mean_row"]])
    found = np.degrees(np.arctan2(vec[1], vec[0]))
    speed = summary["magnitude"] * plan.mm_per_px * 100.0
    print(f"true motion: {args.angle:+.1f}° at {args.speed:.1f} mm/s; tactile flow (bottom view): "
          f"{found:+.1f}° from +x, mean {speed:.1f} mm/s on the view plane, "
          f"confidence {summary['confidence']:.2f}  [{time.perf_counter() - t0:.1f} s]")
    if args.figure:
        _figure(model, activation, result, args.figure)
        print(f"figure: {args.figure}")
    return 0


def _figure(model, activation, result, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fields = result.dynamic_field
    plan = model.plans["bottom"]
    picks = np.linspace(len(activation) * 0.2, len(activation) * 0.8, 4).astype(int)
    fig, axs = plt.subplots(1, 4, figsize=(12, 3.2), constrained_layout=True)
    yy, xx = np.mgrid[0:plan.shape[0]:2, 0:plan.shape[1]:2]
    keep = plan.mask[::2, ::2]
    gain = 2.5 / max(float(np.abs(fields[picks]).max()), 1e-6)     # longest arrow ≈ 2.5 px
    for ax, t in zip(axs, picks):
        ax.imshow(np.ma.masked_where(~plan.mask, result.frames[t]), cmap="magma", vmin=0, vmax=255)
        f = fields[t, ::2, ::2]
        ax.quiver(xx[keep], yy[keep], f[..., 0][keep], f[..., 1][keep], color="cyan", angles="xy",
                  scale_units="xy", scale=1 / gain)
        ax.set_title(f"t = {t / 100:.2f} s")
        ax.set_xlabel("+x (cols)")
        ax.set_ylabel("+y (rows)")
    fig.suptitle(f"Tactile frames (bottom view, 8-bit, 0–{model.config.intensity_range[1]:g} kΩ) and dynamic "
                 f"tactile flow (arrows ×{gain:.0f})")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(f".{path.name}.partial")
    try:                                   # whole or not at all: an interrupt leaves no half-written PNG
        fig.savefig(partial, dpi=110, format=path.suffix.lstrip(".") or "png")
        partial.replace(path)
    finally:
        partial.unlink(missing_ok=True)
        plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())

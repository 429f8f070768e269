"""Check a sensor model by eye and by numbers (docs/sensors.md): its taxels on their surface,
and the tactile frames of a synthetic press sliding across it.

    python docs/make_sensor_figures.py                             # the shipped models → docs/figures/sensors/
    python docs/make_sensor_figures.py --sensor my_pad.yaml --out /tmp/check   # a model of your own

For each model it reads the file (the same checks every command makes: a bad file is one
line naming the field), prints one line of numbers — taxels, the surface and how far the
taxels lie off it, how far the file's normals turn from the surface's, the pad's taxels, the
views and their frame size — and draws two figures:

- ``<name>_taxels.png``: the surface from below (x–y) and from the side (x–z) with the taxels,
  their names, their normals (from the side), the lowest point and the pad's circle;
- ``<name>_press.png``: a Gaussian press (3 mm wide, 4 kΩ) sliding 10 mm along +x across the
  lowest point, rendered in every view of the model at four moments (the frames the analysis
  computes tactile flow on), with the dense flow from the third to the fourth.

Exit 1 with one line for a model that cannot be read.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "figures" / "sensors"


def load(arg: str):
    from tactile_flow.tactile.sensor import builtin_sensor, load_sensor_file
    return load_sensor_file(arg) if arg.endswith((".yaml", ".yml")) else builtin_sensor(arg)


def numbers(sensor) -> str:
    """The model in one line: what to compare with the sensor's datasheet."""
    from tactile_flow.tactile.sensor import _surface_normals
    s = sensor.shape
    normals = _surface_normals(s, sensor.taxels)
    turn = np.degrees(np.arccos(np.clip(np.sum(normals * sensor.normals, axis=1), -1, 1)))
    pad = sensor.pad
    extent = ", ".join(f"{v:.2f}" for v in s.extent)
    return (f"{sensor.name}: {sensor.n_taxels} taxels; {s.kind} ({sensor.surface.fit}) centre "
            f"{np.round(s.centre, 2).tolist()} mm, {'semi-axes' if s.kind == 'ellipsoid' else 'size'} [{extent}] mm, "
            f"taxels off it rms {s.rms_mm:.3f} mm; normals ({sensor.normals_source}) off the surface's: median "
            f"{np.median(turn):.1f} deg, max {turn.max():.1f} deg; lowest point {np.round(s.pole, 2).tolist()} mm; "
            f"pad {'every taxel' if pad is None else f'{int(pad.sum())} taxels within {sensor.surface.pad_radius_mm:g} mm'}"
            f"; views {', '.join(sensor.views)}; frames {list(sensor.frame_size or (28, 40))} px; "
            f"sha256 {sensor.sha256[:12]}")


def taxel_figure(sensor, path: Path) -> None:
    import matplotlib.pyplot as plt

    from tactile_flow.tactile.surface import mesh_of
    mesh = mesh_of(sensor.shape, 0.9)
    t, n, pole = sensor.taxels, sensor.normals, sensor.shape.pole
    pad = sensor.pad if sensor.pad is not None else np.ones(sensor.n_taxels, bool)
    fig, (top, side) = plt.subplots(2, 1, figsize=(8.0, 7.0), gridspec_kw={"height_ratios": [1.3, 1]})
    for ax, (i, j), what in ((top, (0, 1), "from below (x–y)"), (side, (0, 2), "from the side (x–z)")):
        ax.scatter(mesh.points[:, i], mesh.points[:, j], s=2, color="0.8", zorder=1, label="surface (mesh vertices)")
        ax.scatter(t[pad, i], t[pad, j], s=36, color="tab:cyan", edgecolor="k", zorder=3, label="pad taxels")
        if (~pad).any():
            ax.scatter(t[~pad, i], t[~pad, j], s=36, color="white", edgecolor="k", zorder=3, label="other taxels")
        for name, p in zip(sensor.taxel_names, t):
            ax.annotate(name, (p[i], p[j]), textcoords="offset points", xytext=(4, 4), fontsize=7, zorder=4)
        ax.plot(pole[i], pole[j], "r+", ms=12, mew=2, zorder=5, label="lowest point")
        ax.set_aspect("equal")
        ax.set_xlabel("x (mm, along the finger)")
        ax.set_ylabel("y (mm, lateral)" if j == 1 else "z (mm, pad normal)")
        ax.set_title(what, fontsize=9)
    side.quiver(t[:, 0], t[:, 2], n[:, 0], n[:, 2], angles="xy", scale=12, width=0.004, color="tab:blue", zorder=2,
                label=f"normals ({sensor.normals_source})")
    if sensor.surface.pad_radius_mm is not None:
        top.add_patch(plt.Circle(pole[:2], sensor.surface.pad_radius_mm, fill=False, ls="--", color="r"))
    top.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    side.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.suptitle(f"{sensor.name}: {sensor.n_taxels} taxels on their {sensor.shape.kind} "
                 f"({sensor.surface.fit}; rms {sensor.shape.rms_mm:.2f} mm)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def press_figure(sensor, path: Path) -> None:
    import matplotlib.pyplot as plt

    from tactile_flow.tactile import flow, synthetic
    from tactile_flow.tactile.pipeline import TactileConfig, TactileModel
    config = TactileConfig(views=tuple(sensor.views), size=tuple(sensor.frame_size or (28, 40)))
    model = TactileModel.build(config, sensor=sensor)
    pole = sensor.shape.pole
    act = synthetic.moving_bump(sensor.taxels, start=pole - [5.0, 0, 0], velocity=(10.0, 0, 0), duration=1.0)
    moments = [10, 40, 60, 90]
    views = list(sensor.views)
    fig, axes = plt.subplots(len(views), len(moments) + 1, figsize=(2.3 * (len(moments) + 1), 1.9 * len(views)),
                             squeeze=False)
    for r, v in enumerate(views):
        frames = model.render_uint8(act, v, (0.0, 4.0))           # 0..4 kΩ (the press's peak) → 0..255
        for c, k in enumerate(moments):
            ax = axes[r, c]
            ax.imshow(frames[k], cmap="magma", vmin=0, vmax=255)
            ax.set_xticks([])
            ax.set_yticks([])
            if r == 0:
                ax.set_title(f"t = {k / 100:.1f} s (press at x = {pole[0] - 5 + k / 10:.1f} mm)", fontsize=7)
            if c == 0:
                ax.set_ylabel(v)
        field = flow.static_flow(frames[moments[-1]:moments[-1] + 1], frames[moments[-2]])[0]   # 0.3 s: 3 mm
        ax = axes[r, -1]
        ax.imshow(frames[moments[-1]], cmap="gray", vmin=0, vmax=255)
        h, w = field.shape[:2]
        yy, xx = np.mgrid[0:h:2, 0:w:2]
        ax.quiver(xx, yy, field[::2, ::2, 0], field[::2, ::2, 1], color="cyan", angles="xy", scale_units="xy",
                  scale=1.0)
        ax.set_xticks([])
        ax.set_yticks([])
        if r == 0:
            ax.set_title(f"flow from t = {moments[-2] / 100:.1f} s to {moments[-1] / 100:.1f} s", fontsize=7)
    fig.suptitle(f"{sensor.name}: a press sliding along +x through the lowest point, "
                 f"{model.plans[views[0]].shape[0]} x {model.plans[views[0]].shape[1]} px frames", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    from tactile_flow.tactile.sensor import SensorModelError, builtin_sensors
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--sensor", action="append", help="a model name or a .yaml (repeatable); default every shipped model")
    p.add_argument("--out", type=Path, default=OUT)
    a = p.parse_args(argv)
    a.out.mkdir(parents=True, exist_ok=True)
    for arg in a.sensor or list(builtin_sensors()):
        try:
            sensor = load(arg)
        except SensorModelError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 1
        print(numbers(sensor))
        taxel_figure(sensor, a.out / f"{sensor.name}_taxels.png")
        press_figure(sensor, a.out / f"{sensor.name}_press.png")
        print(f"  {a.out / f'{sensor.name}_taxels.png'}, {a.out / f'{sensor.name}_press.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

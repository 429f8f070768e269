"""The figure gallery (docs/gallery.md): the default protocols' figures, made fresh.

    python docs/make_figures.py                               # all four protocols → docs/figures/gallery/
    python docs/make_figures.py --only straws_sweep --out DIR # some of them, elsewhere

Runs each protocol of :data:`GALLERY` with ``tactile-run`` on the simulated lab (default
config, seed 0) in a temporary directory, then copies the figures named there into the
gallery as ``<protocol>_<name>.png``, re-encoded with a 256-colour palette (plots lose
nothing visible and shrink to about a third). Prints one line per figure; exit 1 if a run
fails or a figure is missing (naming it and the figures the run made).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

from PIL import Image

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "figures" / "gallery"
TACTILE_RUN = Path(sys.executable).parent / "tactile-run"

# protocol -> [(gallery name, glob in the run's figures/)]; of several matches the middle one
GALLERY = {
    "straws_sweep": [("pressure", "pressure.png"), ("flow_during", "flow_during.png")],
    "sticks_sweep": [("taxels", "taxels.png"), ("ellipsoid", "ellipsoid.png")],
    "pour_grasp": [("pressure", "pressure.png"), ("taxels", "taxels.png")],
    "pour_grasp_reactive": [("pressure", "pressure.png"), ("electrodes", "electrodes.png")],
}


def run_protocol(protocol: str, work: Path) -> Path:
    """``tactile-run protocol=<protocol>`` into ``work/<protocol>``; the run directory."""
    run_dir = work / protocol
    proc = subprocess.run([str(TACTILE_RUN), f"protocol={protocol}", "progress=false", f"hydra.run.dir={run_dir}"],
                          cwd=work, capture_output=True, text=True)
    if proc.returncode != 0:
        raise SystemExit(f"tactile-run protocol={protocol} failed (exit {proc.returncode}): "
                         f"{proc.stderr.strip().splitlines()[-1:] or proc.stdout.strip().splitlines()[-1:]}")
    return run_dir


def pick(figures: Path, pattern: str) -> Path:
    found = sorted(figures.glob(pattern))
    if not found:
        made = sorted(p.name for p in figures.glob("*.png"))
        raise SystemExit(f"{figures}: no figure matches {pattern!r}; the run made {made}")
    return found[len(found) // 2]


def save_small(src: Path, dst: Path) -> None:
    """``src`` as a palette PNG (256 colours), optimised."""
    with Image.open(src) as im:
        im.convert("RGB").quantize(colors=256, method=Image.Quantize.MEDIANCUT).save(dst, optimize=True)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", help="comma-separated protocols (default: all of the gallery)")
    parser.add_argument("--out", type=Path, default=OUT, help=f"where the PNGs go (default {OUT.relative_to(ROOT)})")
    args = parser.parse_args(argv)
    protocols = args.only.split(",") if args.only else list(GALLERY)
    unknown = [p for p in protocols if p not in GALLERY]
    if unknown:
        parser.error(f"--only: {unknown} not in the gallery; expected some of {list(GALLERY)}")
    args.out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="tactile-gallery-") as tmp:
        for protocol in protocols:
            run_dir = run_protocol(protocol, Path(tmp))
            for name, pattern in GALLERY[protocol]:
                src = pick(run_dir / "figures", pattern)
                dst = args.out / f"{protocol}_{name}.png"
                save_small(src, dst)
                print(f"{dst}: {src.name} of {protocol}, {dst.stat().st_size / 1024:.0f} kB", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())

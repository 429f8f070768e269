"""Where is the board? Read a ``first_touch`` run and compare the first contact with the config.

    python examples/first_touch.py RUN_DIR

``examples/conf/protocol/first_touch.yaml`` lowers the finger slowly onto the middle feature
until its PDC rises; the engine records the TCP pose at that moment (a ``criterion`` event).
This script turns that pose into the position of the pad's lowest point (the same geometry the
planner uses: ``hardware.fingertips`` and the BioTac ellipsoid, :class:`protocols.plan.Geometry`)
and compares its height with the top of the tallest feature as the run's surface config puts it
(``surface.origin_m`` z + the feature height). Everything is read from the run directory:
``run.json`` (the config the run used) and ``run.zarr`` (the events).

Prints one line per finding; exit 0 when a contact was found, 1 when none was (the board is
lower than configured by more than the approach's depth, or not under the finger), 2 when the
run directory cannot be read.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import xarray as xr
from omegaconf import OmegaConf

from tactile_flow.hardware.surfaces import load_surface
from tactile_flow.protocols.plan import Geometry


def first_contact(run_dir: Path) -> dict:
    """The first ``criterion`` event of a PDC-rise approach: time (s), TCP pose, pad position (m),
    and the configured top of the tallest feature (m); ``pose`` is None without one."""
    config = json.loads((run_dir / "run.json").read_text())["config"]
    tree = xr.open_datatree(run_dir / "run.zarr", engine="zarr")
    # tree["events"].name is the group's name ("events"): the variable is read from the dataset
    events = tree["events"].to_dataset()
    hw = OmegaConf.create(config["hardware"])
    surface = load_surface(config["surface"])
    geometry = Geometry(hw, surface, config["protocol"]["finger"])
    out = {"top_z": surface.max_z, "pose": None, "pad": None, "time": None, "protocol": config["protocol"]["name"]}
    for t, kind, detail in zip(events["time"].values, events["kind"].values, events["detail"].values):
        d = json.loads(str(detail) or "{}")
        if str(kind) == "criterion" and "pdc_rise" in d.get("until", ""):
            pose = np.asarray(d["pose"], float)
            out.update(time=float(t), pose=pose, pad=geometry.pad_of(pose) + 0.0)   # no "-0.0000"
            break
    return out


def main(argv=None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1:
        print("usage: python examples/first_touch.py RUN_DIR", file=sys.stderr)
        return 2
    run_dir = Path(args[0])
    try:
        found = first_contact(run_dir)
    except (OSError, KeyError, ValueError) as exc:
        print(f"error: {run_dir} is not a readable run directory ({type(exc).__name__}: {exc})", file=sys.stderr)
        return 2
    top = found["top_z"]
    if found["pose"] is None:
        print(f"{found['protocol']}: no contact during the approach. The board's top is lower than the "
              f"configured {top:.4f} m by more than the approach's depth, or not under the finger: "
              f"check surface.origin_m")
        return 1
    pad = found["pad"]
    offset_mm = (pad[2] - top) * 1e3
    print(f"{found['protocol']}: first contact at {found['time']:.2f} s, TCP at "
          f"[{found['pose'][0]:.4f}, {found['pose'][1]:.4f}, {found['pose'][2]:.4f}] m")
    print(f"pad's lowest point at [{pad[0]:.4f}, {pad[1]:.4f}, {pad[2]:.4f}] m; configured top of the "
          f"tallest feature z = {top:.4f} m")
    side = "above" if offset_mm >= 0 else "below"
    print(f"contact {abs(offset_mm):.2f} mm {side} the configured top (offset_mm={offset_mm:+.2f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""``tactile-view``: a recorded run in the Rerun viewer, every stream on the run's timeline.

    tactile-view RUN_DIR                     # the native viewer (needs a display)
    tactile-view RUN_DIR --web               # serve the web viewer; open the printed address
    tactile-view RUN_DIR --save run.rrd      # write the recording, show nothing (share it, open it with `rerun run.rrd`)
    tactile-view RUN_DIR --fps 100           # every tactile frame (default 25 per second)

Exit status: 0 shown or saved, 2 bad input (not a run directory, no tactile data, bad
option, the ``[view]`` extra not installed), 1 anything else. Errors are one line;
``--verbose`` adds the traceback.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import traceback
import uuid
from pathlib import Path

from . import INSTALL_HINT

BAD_INPUT = 2


def parse_args(argv=None) -> argparse.Namespace:
    from tactile_flow.validation.cli import ArgumentParser, help_text
    ap = ArgumentParser(prog="tactile-view", description=help_text(__doc__))
    ap.add_argument("run_dir", metavar="RUN_DIR", help="a run directory (holding run.zarr) or a run.zarr")
    out = ap.add_mutually_exclusive_group()
    out.add_argument("--save", metavar="FILE.rrd", help="write the recording to FILE.rrd instead of showing it")
    out.add_argument("--web", action="store_true", help="serve the web viewer (no display needed)")
    ap.add_argument("--fps", type=float, default=25.0, help="tactile frames shown per second (default 25)")
    ap.add_argument("--arrow-gain", type=float, help="px drawn per px/frame of flow (default: from the run)")
    ap.add_argument("--port", type=int, default=9090, help="--web: the web viewer's HTTP port (default 9090)")
    ap.add_argument("--verbose", action="store_true", help="tracebacks on errors")
    return ap.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(argv)
    try:
        import rerun  # noqa: F401 - the optional [view] extra
    except ImportError:
        print(f"tactile-view: the viewer needs rerun-sdk, not installed: {INSTALL_HINT}", file=sys.stderr)
        return BAD_INPUT
    from .scene import SceneError
    try:
        check(args)
        return show(args)
    except SceneError as exc:
        return fail(args, exc, BAD_INPUT)
    except KeyboardInterrupt:
        return 0
    except Exception as exc:  # noqa: BLE001 - one line for the user, the traceback with --verbose
        return fail(args, exc, 1)


def check(args) -> None:
    """The run directory, then options that are wrong whatever the run: :class:`viewer.scene.SceneError`
    naming what is wrong."""
    from .scene import SceneError, find_store
    find_store(args.run_dir)
    if args.save is not None and Path(args.save).suffix != ".rrd":
        raise SceneError(f"--save {args.save}: expected a file name ending in .rrd")
    if args.save is not None and not Path(args.save).resolve().parent.is_dir():
        raise SceneError(f"--save {args.save}: its directory does not exist")
    if args.arrow_gain is not None and not args.arrow_gain > 0:
        raise SceneError(f"--arrow-gain: expected a gain > 0, got {args.arrow_gain}")
    if not args.save and not args.web and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise SceneError("no display to open the viewer on ($DISPLAY unset): use --web (and open the printed "
                         "address in a browser) or --save FILE.rrd")


def show(args) -> int:
    import rerun as rr

    from . import layout
    from .record import record_scene
    from .scene import load_scene
    started = time.perf_counter()
    scene = load_scene(args.run_dir, fps=args.fps)
    rec = rr.RecordingStream("tactile-flow", recording_id=uuid.uuid4())
    rec.send_recording_name(f"{scene.run.protocol or 'run'} {scene.run_dir.name}")
    blueprint = layout.replay(scene.active_fingers(), list(scene.model.plans), has_pour=pumped(scene),
                              has_live=scene.live is not None)
    partial = None
    if args.save:
        partial = Path(args.save).with_suffix(".rrd.partial")
        rec.save(partial, default_blueprint=blueprint)
    elif args.web:
        url = rr.serve_grpc(recording=rec, default_blueprint=blueprint)
        rr.serve_web_viewer(connect_to=url, open_browser=False, web_port=args.port)
    else:
        rr.spawn(recording=rec, default_blueprint=blueprint)
    gain = record_scene(rec, scene, arrow_gain=args.arrow_gain)
    rec.flush()
    what = (f"{len(scene.shown)} frames × {len(scene.run.fingers)} fingers × {len(scene.model.plans)} views, "
            f"arrows ×{gain:g}, {time.perf_counter() - started:.1f} s")
    if partial is not None:
        rec.disconnect()
        partial.replace(args.save)
        print(f"tactile-view: {scene.run_dir} → {args.save} ({what})")
    elif args.web:
        print(f"tactile-view: {scene.run_dir} at http://localhost:{args.port} ({what}); Ctrl-C to stop", flush=True)
        while True:
            time.sleep(3600)
    else:
        print(f"tactile-view: {scene.run_dir} sent to the viewer ({what})")
    return 0


def pumped(scene) -> bool:
    """Whether the run poured (the pump dispensed something): only then the pour panel is shown."""
    p = scene.pour or {}
    return len(p.get("dispensed", ())) > 0 and float(max(p["dispensed"])) > 0


def fail(args, exc: Exception, code: int) -> int:
    if args.verbose:
        traceback.print_exception(exc)
    print(f"tactile-view: {exc}", file=sys.stderr)
    if args.save:
        Path(args.save).with_suffix(".rrd.partial").unlink(missing_ok=True)
    return code


if __name__ == "__main__":
    sys.exit(main())

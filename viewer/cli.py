"""``tactile-view``: a recorded run in the Rerun viewer, every stream on the run's timeline.

    tactile-view RUN_DIR                     # the native viewer (needs a display)
    tactile-view RUN_DIR --web               # serve the web viewer on this machine; open the printed address
    tactile-view RUN_DIR --web --bind 0.0.0.0   # ... to the network (anyone who can reach it sees the run)
    tactile-view RUN_DIR --save run.rrd      # write the recording, show nothing (share it, open it with `rerun run.rrd`)
    tactile-view RUN_DIR --fps 100           # every tactile frame (default 25 per second)

The web viewer listens on the loopback interface (127.0.0.1) unless ``--bind`` names another
address, which prints a warning. Ctrl-C stops serving (exit 0); before the run is shown or
saved it is ``interrupted``, exit 3, and no partial file is left.

Exit status: 0 shown or saved, 2 bad input (not a run directory, no tactile data, bad
option, the ``[view]`` extra not installed), 3 interrupted, 1 anything else. Errors are one
line; ``--verbose`` adds the traceback.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import traceback
import uuid
import warnings
from pathlib import Path

from tactile_flow.cliapp.startup import INTERRUPTED, end_at_once_on_signals, interrupts_raise

from . import INSTALL_HINT

BAD_INPUT = 2
WEB_PORT = 9091             # not 9090: that is rosbridge's (tactile-emulate's) and Rerun's own default


def parse_args(argv=None) -> argparse.Namespace:
    from tactile_flow.validation.cli import ArgumentParser, help_text
    ap = ArgumentParser(prog="tactile-view", description=help_text(__doc__))
    ap.add_argument("run_dir", metavar="RUN_DIR", help="a run directory (holding run.zarr) or a run.zarr")
    out = ap.add_mutually_exclusive_group()
    out.add_argument("--save", metavar="FILE.rrd", help="write the recording to FILE.rrd instead of showing it")
    out.add_argument("--web", action="store_true", help="serve the web viewer (no display needed)")
    ap.add_argument("--fps", type=float, default=25.0, help="tactile frames shown per second (default 25)")
    ap.add_argument("--arrow-gain", type=float, help="px drawn per px/frame of flow (default: from the run)")
    ap.add_argument("--port", type=int, default=WEB_PORT,
                    help=f"--web: the web viewer's HTTP port (default {WEB_PORT}; 9090 is rosbridge's)")
    ap.add_argument("--bind", default="127.0.0.1", metavar="ADDRESS",
                    help="--web: the address to serve on (default 127.0.0.1: this machine only; another "
                         "address, such as 0.0.0.0, serves the network, with a warning)")
    ap.add_argument("--verbose", action="store_true", help="tracebacks on errors")
    return ap.parse_args(argv)


def main(argv=None) -> int:
    end_at_once_on_signals()                  # Ctrl-C while Rerun and numpy load: one line, exit 3
    args = parse_args(argv)
    try:
        import rerun  # noqa: F401 - the optional [view] extra
    except ImportError:
        print(f"tactile-view: the viewer needs rerun-sdk, not installed: {INSTALL_HINT}", file=sys.stderr)
        return BAD_INPUT
    from .scene import SceneError
    from .serve import ServeError
    warnings.formatwarning = one_line_warning    # a library's warning is one line, not its source code
    interrupts_raise()                        # from here a signal raises KeyboardInterrupt, cleaned up below
    try:
        check(args)
        return show(args)
    except (SceneError, ServeError) as exc:
        return fail(args, exc, BAD_INPUT)
    except KeyboardInterrupt:
        discard_partial(args)
        print("tactile-view: interrupted", file=sys.stderr)
        return INTERRUPTED
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
    if not 0 < args.port < 65536:
        raise SceneError(f"--port {args.port}: expected a TCP port in 1..65535")
    from .serve import check_address
    check_address(args.bind)
    if not args.save and not args.web and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise SceneError("no display to open the viewer on ($DISPLAY unset): use --web (and open the printed "
                         "address in a browser) or --save FILE.rrd")


def show(args) -> int:
    import rerun as rr

    from . import layout
    from .record import record_scene
    from .scene import load_scene
    from .serve import LOOPBACK, NATIVE_PORT, WebServer, exposure_warning, spawn_native_viewer
    started = time.perf_counter()
    scene = load_scene(args.run_dir, fps=args.fps)
    rec = rr.RecordingStream("tactile-flow", recording_id=uuid.uuid4())
    rec.send_recording_name(f"{scene.run.protocol or 'run'} {scene.run_dir.name}")
    blueprint = layout.replay(scene.active_fingers(), list(scene.model.plans), has_pour=pumped(scene),
                              has_live=scene.live is not None)
    partial, server = None, None
    try:
        if args.save:
            partial = Path(args.save).with_suffix(".rrd.partial")
            rec.save(partial, default_blueprint=blueprint)
        elif args.web:
            server = WebServer(args.bind, args.port).start()
            warning = exposure_warning(args.bind, (server.web_port, server.grpc_port))
            if warning:
                print(f"tactile-view: {warning}", file=sys.stderr)
            rec.connect_grpc(server.grpc_url, default_blueprint=blueprint)
        else:
            spawn_native_viewer(NATIVE_PORT)          # on loopback (Rerun's own spawn listens everywhere)
            rec.connect_grpc(f"rerun+http://{LOOPBACK}:{NATIVE_PORT}/proxy", default_blueprint=blueprint)
        gain = record_scene(rec, scene, arrow_gain=args.arrow_gain)
        rec.flush()
        what = (f"{len(scene.shown)} frames × {len(scene.run.fingers)} fingers × {len(scene.model.plans)} views, "
                f"arrows ×{gain:g}, {time.perf_counter() - started:.1f} s")
        if partial is not None:
            rec.disconnect()
            partial.replace(args.save)
            print(f"tactile-view: {scene.run_dir} → {args.save} ({what})")
        elif server is not None:
            print(f"tactile-view: {scene.run_dir} at {server.viewer_url} ({what}); Ctrl-C to stop", flush=True)
            try:
                while server.process.poll() is None:
                    time.sleep(0.5)
            except KeyboardInterrupt:           # the way to stop serving
                return 0
            raise RuntimeError(f"the web viewer's server ended (exit {server.process.returncode})")
        else:
            print(f"tactile-view: {scene.run_dir} sent to the viewer ({what})")
        return 0
    finally:
        if server is not None:
            rec.disconnect()                          # before its server goes: no "connection severed" errors
            server.stop()


def one_line_warning(message, category, filename, lineno, line=None) -> str:
    return f"tactile-view: warning: {' '.join(str(message).split())}\n"


def discard_partial(args) -> None:
    """Remove what ``--save`` had begun to write."""
    if getattr(args, "save", None):
        Path(args.save).with_suffix(".rrd.partial").unlink(missing_ok=True)


def pumped(scene) -> bool:
    """Whether the run poured (the pump dispensed something): only then the pour panel is shown."""
    p = scene.pour or {}
    return len(p.get("dispensed", ())) > 0 and float(max(p["dispensed"])) > 0


def fail(args, exc: Exception, code: int) -> int:
    if args.verbose:
        traceback.print_exception(exc)
    print(f"tactile-view: {exc}", file=sys.stderr)
    discard_partial(args)
    return code


if __name__ == "__main__":
    sys.exit(main())

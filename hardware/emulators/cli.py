"""``tactile-emulate``: the whole emulated lab on loopback, for a rehearsal without hardware.

    tactile-emulate                      # UR controller on 127.0.0.1, rosbridge on :9090,
                                         # BioTac bridge, pump and scale on ptys linked
                                         # under /tmp/tactile-emulate/
    tactile-run hardware=lab_emulated    # in another terminal

Every emulator runs as a separate process (:class:`hardware.emulators.process.EmulatorProcess`).
"""

from __future__ import annotations

import os
import signal
import sys
import time
from pathlib import Path

from tactile_flow.conf import DIR as CONF_DIR

from .touch import POSE_FILE, WORLD_FILES

HOME_POSE = (0.3, 0.0, 0.2, 3.141592653589793, 0.0, 0.0)    # hardware.arm.home_pose of conf/hardware/lab.yaml
DEFAULT_LINK_DIR = os.environ.get("TACTILE_EMULATE_DIR", "/tmp/tactile-emulate")
PUMP_MAX_RATE_ML_MIN = 600.0    # conf/hardware/lab_emulated.yaml: a rehearsal pours faster than the real pump


def _ur_emulator(host: str, home_pose, pose_file: str | None = None):
    """The UR controller emulator process (hardware/emulators/ur_controller.py), if present."""
    try:
        from .ur_controller import URControllerProcess
    except ImportError:
        return None
    return URControllerProcess(host, initial_pose=tuple(home_pose), pose_file=pose_file)


def write_board(link_dir, surface: str) -> None:
    """Say in ``link_dir`` which board the emulated BioTacs press on (``tactile-run
    hardware=lab_emulated`` warns when its protocol's board is another one)."""
    import json

    from tactile_flow.hardware.lab import EMULATOR_FILE
    from tactile_flow.validation import to_plain
    board = None
    if surface != "none":
        import yaml

        from tactile_flow.hardware.surfaces import load_surface
        from .touch import SURFACES_DIR
        board = to_plain(load_surface(yaml.safe_load((SURFACES_DIR / f"{surface}.yaml").read_text())).cfg)
    d = Path(link_dir)
    d.mkdir(parents=True, exist_ok=True)
    tmp = d / f".{EMULATOR_FILE}.{os.getpid()}"
    tmp.write_text(json.dumps({"surface_name": surface, "surface": board}) + "\n")
    os.replace(tmp, d / EMULATOR_FILE)


def remove_links(link_dir) -> None:
    """Remove what the emulated lab left in ``link_dir`` (its pty links, the world's shared
    files and the board it emulates), and the directory if that leaves it empty."""
    from tactile_flow.hardware.lab import EMULATOR_FILE
    d = Path(link_dir)
    for name in ("biotac", "pump", "scale", *WORLD_FILES, EMULATOR_FILE):
        p = d / name
        if p.is_symlink() or p.is_file():
            p.unlink()
    try:
        d.rmdir()
    except OSError:
        pass


def _interrupt(signum, frame):
    raise KeyboardInterrupt


def _alive(emulator) -> bool:
    proc = getattr(emulator, "proc", None)
    return proc is None or proc.poll() is None


EPILOG = """exit status: 0 stopped by Ctrl-C or SIGTERM, 1 an emulator exited or could not start,
2 bad option (one line)."""


def build_parser():
    """``tactile-emulate``'s options."""
    from tactile_flow.validation.cli import ArgumentParser
    parser = ArgumentParser(prog="tactile-emulate", description=__doc__.replace("``", "").split("\n\nEvery")[0],
                            epilog=EPILOG)
    parser.add_argument("--host", default="127.0.0.1", help="loopback address for the UR controller emulator")
    parser.add_argument("--rosbridge-port", type=int, default=9090, help="rosbridge websocket port (default 9090)")
    parser.add_argument("--link-dir", default=DEFAULT_LINK_DIR,
                        help="directory of stable symlinks to the ptys (biotac, pump, scale)")
    parser.add_argument("--no-ur", action="store_true", help="do not start the UR controller emulator")
    parser.add_argument("--seed", type=int, default=0, help="seed of the emulated sensors' noise (default 0)")
    parser.add_argument("--surface", default="straws",
                        help="the board the emulated BioTacs press on, following the emulated arm "
                             "(conf/surface/NAME.yaml; the protocol's surface; 'none': no board)")
    parser.add_argument("--sensor", default="biotac_sp",
                        help="the emulated BioTacs' sensor model: biotac_sp (default), biotac (classic, 19 "
                             "electrodes) or a sensor .yaml; run protocols with the same sensor=")
    parser.add_argument("--pump-max-rate", type=float, default=PUMP_MAX_RATE_ML_MIN,
                        help=f"the emulated pump's fastest flow, ml/min (default {PUMP_MAX_RATE_ML_MIN:g}, "
                             "hardware.pump.max_rate_ml_min of lab_emulated.yaml: rehearse pours faster)")
    parser.add_argument("--shear-kohm-per-n", type=float, default=None,
                        help="the emulated BioTacs' shear response, kΩ per N (default: the simulator's); run "
                             "protocols with the same hardware.sensor.shear_kohm_per_n=")
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    from .process import emulated_sensor, sensor_model_config
    emulated_sensor(args.sensor, parser)                 # a bad model is refused here, not in a child
    sensor_model_config(args.shear_kohm_per_n, parser)
    surfaces = sorted(p.stem for p in (CONF_DIR / "surface").glob("*.yaml"))
    if args.surface != "none" and args.surface not in surfaces:
        parser.error(f"--surface {args.surface}: expected one of {', '.join(surfaces)} or none")

    from .rosbridge_server import RosbridgeEmulator
    from .serial_devices import SerialDevicesEmulator

    started = []
    # the world the BioTacs feel: the board under the arm, the bottle in the hand, filled by the pump
    world_dir = str(args.link_dir)
    pose_file = None if args.no_ur else str(Path(world_dir) / POSE_FILE)
    Path(world_dir).mkdir(parents=True, exist_ok=True)
    try:
        ur = None if args.no_ur else _ur_emulator(args.host, HOME_POSE, pose_file)
        if ur is not None:
            started.append(ur.start())
            print(f"UR controller   {args.host}  (RTDE 30004, dashboard 29999, script 30003)")
        elif not args.no_ur:
            print("UR controller   not available (hardware/emulators/ur_controller.py missing)")
        ros = RosbridgeEmulator(host="127.0.0.1", port=args.rosbridge_port, seed=args.seed, world_dir=world_dir,
                                surface=args.surface, sensor=args.sensor,
                                shear_kohm_per_n=args.shear_kohm_per_n).start()
        started.append(ros)
        print(f"rosbridge       {ros.url}  (/rh/tactile at 100 Hz, /joint_states, "
              f"/rh_trajectory_controller/command)")
        serial = SerialDevicesEmulator(link_dir=args.link_dir, seed=args.seed, world_dir=world_dir,
                                       surface=args.surface, pump_max_rate_ml_min=args.pump_max_rate,
                                       sensor=args.sensor, shear_kohm_per_n=args.shear_kohm_per_n).start()
        started.append(serial)
        for name in ("biotac", "pump", "scale"):
            print(f"{name:<15} {Path(args.link_dir) / name} -> {serial.ports[name]}")
        write_board(args.link_dir, args.surface)
        print(f"board           {args.surface}" + ("" if args.surface == "none" or pose_file is None else
                                                   "  (the BioTacs press on it following the arm: run protocols "
                                                   f"with surface={args.surface})"))
        print("bottle          between ff, mf and th: held when the hand closes on it, filled by the pump, "
              "slipping as in the simulated lab")
        env = "" if args.link_dir == "/tmp/tactile-emulate" else f"TACTILE_EMULATE_DIR={args.link_dir} "
        print(f"sensor          {args.sensor}")
        print(f"\nIn another terminal:  {env}tactile-run hardware=lab_emulated"
              + ("" if args.sensor == "biotac_sp" else f" sensor={args.sensor}")
              + ("" if args.shear_kohm_per_n is None else
                 f" hardware.sensor.shear_kohm_per_n={args.shear_kohm_per_n:g}")
              + ("" if args.rosbridge_port == 9090 else f" hardware.rosbridge.url={ros.url}")
              + ("" if args.host == "127.0.0.1" else f" hardware.arm.host={args.host}"))
        print("Ctrl-C stops the emulated lab.", flush=True)
        signal.signal(signal.SIGTERM, _interrupt)
        while all(_alive(e) for e in started):
            time.sleep(0.5)
        print("an emulator exited; stopping the others", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 0
    finally:
        for e in reversed(started):
            try:
                e.stop()
            except Exception as exc:  # stop every emulator even if one fails to stop
                print(f"warning: stopping {type(e).__name__}: {exc}", file=sys.stderr)
        remove_links(args.link_dir)


if __name__ == "__main__":
    sys.exit(main())

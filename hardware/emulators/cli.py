"""``tactile-emulate``: the whole emulated lab on loopback, for a rehearsal without hardware.

    tactile-emulate                      # UR controller on 127.0.0.1, rosbridge on :9090,
                                         # BioTac bridge, pump and scale on ptys linked
                                         # under /tmp/tactile-emulate/
    tactile-run hardware=lab_emulated    # in another terminal

Every emulator runs as a separate process (:class:`hardware.emulators.process.EmulatorProcess`).
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import time
from pathlib import Path

HOME_POSE = (0.3, 0.0, 0.2, 3.141592653589793, 0.0, 0.0)    # hardware.arm.home_pose of conf/hardware/lab.yaml
DEFAULT_LINK_DIR = os.environ.get("TACTILE_EMULATE_DIR", "/tmp/tactile-emulate")


def _ur_emulator(host: str, home_pose):
    """The UR controller emulator process (hardware/emulators/ur_controller.py), if present."""
    try:
        from .ur_controller import URControllerProcess
    except ImportError:
        return None
    return URControllerProcess(host, initial_pose=tuple(home_pose))


def _interrupt(signum, frame):
    raise KeyboardInterrupt


def _alive(emulator) -> bool:
    proc = getattr(emulator, "proc", None)
    return proc is None or proc.poll() is None


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="tactile-emulate", description=__doc__.split("\n")[0])
    parser.add_argument("--host", default="127.0.0.1", help="loopback address for the UR controller emulator")
    parser.add_argument("--rosbridge-port", type=int, default=9090)
    parser.add_argument("--link-dir", default=DEFAULT_LINK_DIR,
                        help="directory of stable symlinks to the ptys (biotac, pump, scale)")
    parser.add_argument("--no-ur", action="store_true", help="do not start the UR controller emulator")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)

    from .rosbridge_server import RosbridgeEmulator
    from .serial_devices import SerialDevicesEmulator

    started = []
    try:
        ur = None if args.no_ur else _ur_emulator(args.host, HOME_POSE)
        if ur is not None:
            started.append(ur.start())
            print(f"UR controller   {args.host}  (RTDE 30004, dashboard 29999, script 30003)")
        elif not args.no_ur:
            print("UR controller   not available (hardware/emulators/ur_controller.py missing)")
        ros = RosbridgeEmulator(host="127.0.0.1", port=args.rosbridge_port, seed=args.seed).start()
        started.append(ros)
        print(f"rosbridge       {ros.url}  (/rh/tactile at 100 Hz, /joint_states, "
              f"/rh_trajectory_controller/command)")
        serial = SerialDevicesEmulator(link_dir=args.link_dir, seed=args.seed).start()
        started.append(serial)
        for name in ("biotac", "pump", "scale"):
            print(f"{name:<15} {Path(args.link_dir) / name} -> {serial.ports[name]}")
        env = "" if args.link_dir == "/tmp/tactile-emulate" else f"TACTILE_EMULATE_DIR={args.link_dir} "
        print(f"\nIn another terminal:  {env}tactile-run hardware=lab_emulated"
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


if __name__ == "__main__":
    sys.exit(main())

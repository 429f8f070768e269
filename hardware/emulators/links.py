"""Cutting one link of the emulated lab, as a pulled cable or a crashed bridge would.

:func:`cut` loses one device's link: ``arm`` (the UR controller emulator killed: its sockets
close), ``hand`` / ``biotac`` (the rosbridge emulator closes the websocket of that device's
client), ``biotac_serial`` / ``pump`` / ``scale`` (the serial emulator closes that device's
pty). :func:`at` does it, or anything else, a given time after a run's store appears, on a
thread of its own (the run itself blocks the caller). Used by the link-loss tests and
``benchmarks/bench_link_loss.py``.
"""

from __future__ import annotations

import os
import signal
import threading
import time
from pathlib import Path

LINKS = ("arm", "hand", "biotac", "biotac_serial", "pump", "scale")


def cut(link: str, *, ur=None, rosbridge=None, serial=None) -> None:
    """Lose ``link`` (one of :data:`LINKS`) on the emulators given."""
    if link == "arm":
        os.kill(ur.proc.pid, signal.SIGKILL)
    elif link in ("hand", "biotac"):
        rosbridge.command(f"disconnect {'/joint_states' if link == 'hand' else '/rh/tactile'}")
    elif link in ("biotac_serial", "pump", "scale"):
        serial.command(f"disconnect {'biotac' if link == 'biotac_serial' else link}")
    else:
        raise ValueError(f"link: expected one of {', '.join(LINKS)}, got {link!r}")


def at(run_dir, delay_s: float, action, timeout_s: float = 60.0) -> tuple[threading.Thread, dict]:
    """Start a thread that calls ``action()`` ``delay_s`` (wall) after ``run_dir/run.zarr``
    appears; returns it and a dict that gets ``done_at`` (``time.monotonic()`` just before the
    action) once it ran."""
    said: dict = {}

    def wait_then_act():
        store = Path(run_dir) / "run.zarr" / "zarr.json"
        end = time.monotonic() + timeout_s
        while not store.exists():
            if time.monotonic() > end:
                return
            time.sleep(0.005)
        time.sleep(delay_s)
        said["done_at"] = time.monotonic()
        action()

    thread = threading.Thread(target=wait_then_act, name="link-cut", daemon=True)
    thread.start()
    return thread, said

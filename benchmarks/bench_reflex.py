"""The reflex end to end through the real drivers: emulated reactive pours, stage by stage.

    python benchmarks/bench_reflex.py                       # 10 pours, BioTacs through rosbridge
    python benchmarks/bench_reflex.py --source serial --pours 12

Starts the emulated lab (UR controller, rosbridge and serial emulators, the simulated world
they share: ``hardware/emulators/touch.py``) and runs ``pour_grasp_reactive`` on
``hardware=lab_emulated`` ``--pours`` times, in-process (:func:`protocols.run.run_protocol`,
the code ``tactile-run`` calls; ``progress=false analyze=false``), pouring at ``--pour-rate``
ml/min and holding 2 s after the reaction. Everything runs on the wall clock; the emulators'
world and the run share the host's monotonic clock, so every time below is on one axis.

Per pour (one JSON line, ``"measure": "pour"``), from the slip onset in the world of the
BioTac emulator whose frames were recorded (``stats``) to the first hand command the rosbridge
emulator received after it (``stats``: ``hand_command_times``):

- ``detect_ms``: onset → the firing frame sent by the emulator (``frames A B``): the frames the
  detector needed to see the slip (0 when the frame of the onset fired);
- ``wire_ms``: sent → the driver's receipt stamp (``live/time_live`` + ``t0_clock_s``): the
  websocket or pty, the driver's reading thread, and the part of decoding before the stamp
  (roslibpy's JSON parse; the serial frame parse);
- ``queue_ms``: receipt → the monitor started on the frame (the engine polls once a BioTac
  period; root attribute ``live.detection.waited_ms``);
- ``flow_ms``, ``detector_ms``: the online flow and the slip detector on that frame
  (``live.detection``);
- ``command_ms``: verdict → the hand emulator received the ``tighten`` trajectory (the
  engine issues it, roslibpy publishes it, the emulator reads it);
- ``end_to_end_ms``: onset → the hand emulator received it (the sum of the above);
- ``held``: the bottle still in the hand when the run released it.

``decode_ms`` (``"measure": "decode"``) times the drivers' own decoding of the emulators'
own messages apart (median of 2000): ``RosbridgeBiotacs`` turning a BiotacAll message (parsed
JSON) into a frame, and the serial ``FrameParser`` plus the frame's construction; the
rosbridge decode follows the receipt stamp (it is inside ``queue_ms``), the serial parse
precedes it (inside ``wire_ms``).

The summary (``"summary": "reflex"``): median / max of each stage and of the end to end
(target: median ≤ 30 ms, max ≤ 60 ms), pours held, and ``uptime``'s load before and after:
the machine is shared, so read the figures with the load beside them.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

os.environ.setdefault("MPLBACKEND", "Agg")

HOME = (0.3, 0.0, 0.2, 3.141592653589793, 0.0, 0.0)        # hardware.arm.home_pose of lab.yaml


def emit(**record) -> None:
    print(json.dumps(record), flush=True)


def load() -> float:
    return round(os.getloadavg()[0], 2)


def free_loopback() -> str:
    from tactile_flow.hardware.emulators.process import free_loopback as emulated_loopback
    host = emulated_loopback(random.randint(100, 200))
    if host is None:
        raise SystemExit("no free loopback address for the UR controller emulator")
    return host


def compose(overrides):
    from hydra import compose as hydra_compose, initialize_config_dir

    from tactile_flow.conf import DIR
    from tactile_flow.protocols.schema import register
    register()
    with initialize_config_dir(config_dir=str(DIR), version_base=None):
        return hydra_compose("config", overrides=list(overrides))


def taken_away(emulator, before: int, timeout_s: float = 2.0) -> tuple[dict, dict | None]:
    """The emulator's ``stats`` once its world has taken away the bottle the run released (the
    world notices the open hand at its next frame), and that bottle (None: never released)."""
    end = time.monotonic() + timeout_s
    while True:
        stats = emulator.stats()
        bottles = (stats.get("world") or {}).get("bottles") or []
        if len(bottles) > before or time.monotonic() > end:
            return stats, (bottles[-1] if len(bottles) > before else None)
        time.sleep(0.05)


def bottles_taken(emulator) -> int:
    return len((emulator.stats().get("world") or {}).get("bottles") or [])


def one_pour(k: int, emulators, overrides, source: str, rate: float, out: Path) -> dict:
    import xarray as xr

    from tactile_flow.protocols.run import run_protocol

    ros, ser = emulators
    cfg = compose(["hardware=lab_emulated", "protocol=pour_grasp_reactive", f"protocol.pour_rate={rate}",
                   "protocol.steps.3.hold.duration=2", f"hardware.biotac.source={source}", "progress=false",
                   "analyze=false", *overrides])
    run_dir = out / f"pour_{k:02d}"
    emulator = ros if source == "rosbridge" else ser
    before = bottles_taken(emulator)
    result = run_protocol(cfg, run_dir, console=lambda *a: None)
    rec = {"measure": "pour", "pour": k, "source": source, "status": result.status, "load": load()}
    _, bottle = taken_away(emulator, before)
    stats_ros = ros.stats()
    tree = xr.open_datatree(result.store, engine="zarr")
    live_attr = tree.attrs.get("live") or {}
    det = live_attr.get("detection")
    onset = None if bottle is None else bottle.get("slip_onset")
    rec.update(held=bool(bottle and bottle["held"]), water_ml=bottle and bottle["water_ml"])
    if result.status != "success" or det is None or onset is None:
        rec["error"] = result.error or ("no detection" if det is None else "no slip onset in the world")
        return rec
    t0 = float(tree.attrs["t0_clock_s"])
    sent = float(json.loads(emulator.command(f"frames {det['seq']} {det['seq']}"))[str(det["seq"])])
    received = t0 + det["received_s"]
    verdict = t0 + det["processed_s"]
    after = [t for t in stats_ros["hand_command_times"] if t >= onset]
    if not after:
        rec["error"] = "no hand command after the onset"
        return rec
    command = after[0]
    ms = lambda dt: round(1e3 * dt, 3)
    rec.update(detect_ms=ms(sent - onset), wire_ms=ms(received - sent), queue_ms=det["waited_ms"],
               flow_ms=det["flow_ms"], detector_ms=det["detector_ms"], command_ms=ms(command - verdict),
               end_to_end_ms=ms(command - onset))
    return rec


def decode_times(n: int = 2000) -> dict:
    """Median per-frame decode (ms) of the two BioTac drivers on the emulators' own messages."""
    from tactile_flow.hardware.emulators.rosbridge_server import BiotacSource
    from tactile_flow.hardware.rosbridge import RosbridgeConfig
    from tactile_flow.hardware.serial_biotac import FrameParser, encode_frame
    from tactile_flow.hardware.shadow import RosbridgeBiotacConfig, RosbridgeBiotacs

    fingers = ("ff", "mf", "rf", "lf", "th")
    src = BiotacSource()
    msgs = [json.loads(json.dumps(src.message(time.time()))) for _ in range(64)]
    drv = RosbridgeBiotacs(RosbridgeBiotacConfig(RosbridgeConfig("ws://127.0.0.1:9")))
    ros = []
    for i in range(n):
        m = msgs[i % len(msgs)]
        c = time.perf_counter()
        drv._decode(m, 0.0)
        ros.append(time.perf_counter() - c)
    rng = np.random.default_rng(0)
    frames = [encode_frame(i + 1, 10_000 * i, fingers, rng.integers(1000, 3000, (5, 24)), rng.integers(1000, 3000, 5),
                           rng.integers(1000, 3000, 5), rng.integers(1000, 3000, 5),
                           rng.integers(1000, 3000, (5, 22))) for i in range(64)]
    parser = FrameParser()
    ser = []
    for i in range(n):
        c = time.perf_counter()
        parser.feed(frames[i % len(frames)])
        ser.append(time.perf_counter() - c)
    return {"rosbridge_ms": round(1e3 * float(np.median(ros)), 4), "serial_ms": round(1e3 * float(np.median(ser)), 4)}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--pours", type=int, default=10)
    p.add_argument("--source", choices=["rosbridge", "serial"], default="rosbridge",
                   help="the BioTac driver recorded (hardware.biotac.source)")
    p.add_argument("--pour-rate", type=float, default=600.0, help="ml/min (the emulated pump's limit is 600)")
    p.add_argument("--out", default=None, help="keep the runs here (default: a temporary directory)")
    a = p.parse_args(argv)

    from tactile_flow.hardware.emulators.rosbridge_server import RosbridgeEmulator
    from tactile_flow.hardware.emulators.serial_devices import SerialDevicesEmulator
    from tactile_flow.hardware.emulators.touch import POSE_FILE
    from tactile_flow.hardware.emulators.ur_controller import URControllerProcess

    emit(measure="decode", **decode_times())
    with tempfile.TemporaryDirectory(prefix="bench_reflex_") as tmp:
        out = Path(a.out) if a.out else Path(tmp)
        world = Path(tmp) / "world"
        world.mkdir()
        host = free_loopback()
        load_before = load()
        with URControllerProcess(host, initial_pose=HOME, pose_file=str(world / POSE_FILE)), \
                RosbridgeEmulator(world_dir=str(world), surface="flat") as ros, \
                SerialDevicesEmulator(world_dir=str(world), surface="flat", pump_max_rate_ml_min=a.pour_rate) as ser:
            overrides = [f"hardware.arm.host={host}", f"hardware.rosbridge.url={ros.url}",
                         f"hardware.biotac.port={ser.ports['biotac']}", f"hardware.pump.port={ser.ports['pump']}",
                         f"hardware.scale.port={ser.ports['scale']}", f"hardware.pump.max_rate_ml_min={a.pour_rate}"]
            records = []
            for k in range(a.pours):
                rec = one_pour(k, (ros, ser), overrides, a.source, a.pour_rate, out)
                records.append(rec)
                emit(**rec)
                print(f"pour {k + 1}/{a.pours}: {rec.get('end_to_end_ms', rec.get('error'))} ms", file=sys.stderr)
        stages = ["detect_ms", "wire_ms", "queue_ms", "flow_ms", "detector_ms", "command_ms", "end_to_end_ms"]
        ok = [r for r in records if "end_to_end_ms" in r]
        summary = {s: {"median": round(float(np.median([r[s] for r in ok])), 3),
                       "max": round(float(np.max([r[s] for r in ok])), 3)} for s in stages} if ok else {}
        emit(summary="reflex", source=a.source, pours=a.pours, measured=len(ok),
             held=sum(bool(r.get("held")) and r["status"] == "success" for r in records), pour_rate_ml_min=a.pour_rate,
             load_before=load_before, load_after=load(), cores=os.cpu_count(), **summary)
    return 0


if __name__ == "__main__":
    sys.exit(main())

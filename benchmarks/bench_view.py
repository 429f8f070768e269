"""The viewer's cost: opening a 60 s five-finger run, and the live viewer's load on the live monitor (JSON lines).

    python benchmarks/bench_view.py [--keep DIR] [--seconds 20] [--only view|live]

The run: benchmarks/bench_analysis.py's 60 s store (a simulated straws sweep tiled to 60 s,
every finger carrying the sweeping finger's data: five fingers in contact, the worst case for
frames and flow).

- ``view``: ``tactile-view RUN --save FILE.rrd`` in a fresh process, at 25 frames per second
  (the default) and at every frame (100): wall time of each phase (reading and preparing the
  run; the time series sent, which is when a spawned viewer shows the run; everything sent),
  the process's peak memory (RSS) and the size of the recording.
- ``live``: the live monitor (:class:`protocols.live.LiveMonitor`) fed the same run's frames,
  five fingers, one view (the default) and three views, without and with the live viewer
  (writing ``live.rrd``, no window): ``flat_out`` pushes ``--seconds`` of frames as fast as the
  monitor takes them (``realtime_margin`` = data seconds / wall seconds, the engine's headroom);
  ``paced`` delivers them at 100 Hz on the wall clock, as a run does, and reports the monitor's
  time per engine period (median, p99, max) and the rows the viewer dropped. Each case runs
  ``--repeats`` times, with and without the viewer alternately; the line gives the medians.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))


def emit(**row):
    """One JSON line, with the machine's load average (1 min) at the time: the machine is shared."""
    print(json.dumps({**row, "load_avg_1min": round(os.getloadavg()[0], 2)}), flush=True)


# ----------------------------------------------------------------------------- opening a run

def view_child(run_dir: str, rrd: str, fps: float) -> None:
    """(In a fresh process.) tactile-view's work, phase by phase, then the peak RSS."""
    t0 = time.perf_counter()
    import rerun as rr

    from tactile_flow.viewer import record
    from tactile_flow.viewer.scene import load_scene
    t_import = time.perf_counter()
    scene = load_scene(run_dir, fps=fps)
    t_load = time.perf_counter()
    rec = rr.RecordingStream("tactile-flow")
    rec.save(rrd)
    record.send_series(rec, scene)           # what tactile-view sends first
    t_series = time.perf_counter()
    record.send_tactile(rec, scene)
    rec.flush()
    rec.disconnect()
    t_end = time.perf_counter()
    print(json.dumps({"import_s": t_import - t0, "load_prepare_s": t_load - t_import,
                      "time_series_sent_s": t_series - t0, "total_s": t_end - t0,
                      "frames_shown": int(len(scene.shown)), "fingers": len(scene.run.fingers),
                      "views": len(scene.model.plans), "run_s": float(scene.run.time[-1]),
                      "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))


def bench_view(store: Path, work: Path) -> None:
    for fps in (25.0, 100.0):
        rrd = work / f"view_{int(fps)}.rrd"
        out = subprocess.run([sys.executable, __file__, "--view-child", str(store.parent), str(rrd), str(fps)],
                             capture_output=True, text=True, check=True)
        row = json.loads(out.stdout.strip().splitlines()[-1])
        emit(bench="view", fps=fps, **{k: round(v, 2) if isinstance(v, float) else v for k, v in row.items()},
             rrd_mb=round(rrd.stat().st_size / 2**20, 1))


# ----------------------------------------------------------------------------- the live monitor

class RecordedSensors:
    """A recorded run's BioTac stream delivered frame by frame to the monitor's tap (the part of
    :class:`hardware.biotac.TactileSensors` the monitor uses)."""

    def __init__(self, frames, fingers, rate_hz):
        from tactile_flow.hardware.biotac import FrameTap
        self.frames, self.fingers, self.rate_hz = frames, tuple(fingers), rate_hz
        self._taps: list[FrameTap] = []

    def tap(self, maxlen):
        from tactile_flow.hardware.biotac import FrameTap
        tap = FrameTap(maxlen)
        self._taps.append(tap)
        return tap

    def untap(self, tap):
        self._taps.remove(tap)

    def publish(self, frame):
        for tap in self._taps:
            tap.put(frame)


class Rows:
    """Where the monitor's rows and events go (the recorder's ``live``/``event``/``now``/``t0``)."""

    t0 = 0.0

    def __init__(self, clock):
        self.clock, self.rows = clock, 0

    def live(self, rows):
        self.rows += len(rows["time_live"])

    def event(self, *args):
        pass

    def now(self):
        return self.clock.now()


class Clock:
    t = 0.0

    def now(self):
        return self.t


def load_frames(store: Path, seconds: float):
    import xarray as xr

    from tactile_flow.hardware.biotac import BiotacFrame
    b = xr.open_datatree(str(store), engine="zarr")["biotac"].to_dataset()
    n = min(b.sizes["time"], int(seconds * 100) + 50)
    e = b.electrodes.values[:n]
    z = np.zeros(e.shape[1], np.int32)
    frames = [BiotacFrame(seq=int(i), device_time=float(t), host_time=float(t), electrodes=e[i], pdc=z, tdc=z, tac=z,
                          pac=np.zeros((e.shape[1], 0), np.int16)) for i, t in enumerate(b.time.values[:n])]
    return frames, [str(f) for f in b.finger.values]


def run_monitor(frames, fingers, views, with_viewer: bool, paced: bool, work: Path) -> dict:
    from tactile_flow.protocols.live import LiveConfig, LiveMonitor, tactile_config, warm_up
    from tactile_flow.tactile.pipeline import TactileModel
    from tactile_flow.viewer.live import LiveViewer
    model = TactileModel.build(tactile_config(None, views))
    warm_up(model, views)
    sensors, clock = RecordedSensors(frames, fingers, 100.0), Clock()
    viewer = LiveViewer(fingers, views, model, work, spawn=False) if with_viewer else None
    monitor = LiveMonitor(sensors, Rows(clock), model, LiveConfig(views=list(views)), clock, viewer=viewer)
    tare = 50
    for fr in frames[:tare]:
        sensors.publish(fr)
    monitor.begin()
    periods = np.empty(len(frames) - tare)
    start = time.perf_counter()
    for i, fr in enumerate(frames[tare:]):
        if paced:                                  # a frame every 10 ms of wall time, as the sensor sends them
            delay = start + i * 0.01 - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
        clock.t = fr.host_time
        sensors.publish(fr)
        t0 = time.perf_counter()
        monitor.poll(still=True)
        periods[i] = time.perf_counter() - t0
    wall = time.perf_counter() - start
    counts = monitor.close()
    data_s = (len(frames) - tare) / 100.0
    out = {"fingers": len(fingers), "views": list(views), "viewer": with_viewer, "data_s": data_s,
           "frames": counts["frames"], "poll_ms_median": round(float(np.median(periods)) * 1e3, 3),
           "poll_ms_p99": round(float(np.percentile(periods, 99)) * 1e3, 3),
           "poll_ms_max": round(float(periods.max()) * 1e3, 3)}
    if not paced:
        out["realtime_margin"] = round(data_s / wall, 2)
    if with_viewer:
        v = counts["viewer"]
        out.update(rows_offered=v["rows_offered"], rows_shown=v["rows_shown"], rows_dropped=v["rows_dropped"])
    return out


def bench_live(store: Path, work: Path, seconds: float, repeats: int) -> None:
    """Without and with the viewer, alternately, ``repeats`` times each (the machine is shared:
    alternating spreads its load over both); one line per case with the medians."""
    frames, fingers = load_frames(store, seconds)
    for views in (("bottom",), ("bottom", "left", "right")):
        for paced in (False, True):
            runs = {False: [], True: []}
            for _ in range(repeats):
                for with_viewer in (False, True):
                    runs[with_viewer].append(run_monitor(frames, fingers, views, with_viewer, paced, work))
            for with_viewer, rows in runs.items():
                med = {k: round(float(np.median([r[k] for r in rows])), 3) for k, v in rows[0].items()
                       if isinstance(v, (int, float)) and not isinstance(v, bool)}
                extra = {}
                if "realtime_margin" in med:
                    extra["realtime_margin_each"] = [r["realtime_margin"] for r in rows]
                if with_viewer:
                    extra["rows_dropped_each"] = [r["rows_dropped"] for r in rows]
                emit(bench="live", mode="paced" if paced else "flat_out", views=list(views), viewer=with_viewer,
                     repeats=repeats, **med, **extra)


def main() -> None:
    if len(sys.argv) == 5 and sys.argv[1] == "--view-child":
        view_child(sys.argv[2], sys.argv[3], float(sys.argv[4]))
        return
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--keep", help="work directory (kept); default: a temporary one")
    ap.add_argument("--seconds", type=float, default=20.0, help="live: seconds of frames per measurement")
    ap.add_argument("--only", choices=["view", "live"], help="run one part only")
    ap.add_argument("--repeats", type=int, default=3, help="live: runs of each case, with and without alternating")
    args = ap.parse_args()
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    from bench_analysis import make_store
    work = Path(args.keep or tempfile.mkdtemp(prefix="bench-view-"))
    work.mkdir(parents=True, exist_ok=True)
    store = work / "bench" / "run.zarr"
    if not store.exists():
        store = make_store(work)
    if args.only != "live":
        bench_view(store, work)
    if args.only != "view":
        bench_live(store, work, args.seconds, args.repeats)


if __name__ == "__main__":
    main()

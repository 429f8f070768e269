"""The live viewer: the live monitor's results in Rerun while a run goes (``live.viewer=rerun``).

:class:`LiveViewer` is fed by :class:`protocols.live.LiveMonitor` — the rows it has just
recorded (the ``live`` group's columns) and, a few times a second, copies of the latest tactile
frames and flow fields — plus the engine's events, through a bounded queue. Its own thread
drains the queue every :data:`DRAIN_S` and sends what it found to Rerun in columns (one call
per entity and drain: the thread's cost is in the calls, not the rows). The engine
never waits for it: :meth:`LiveViewer.offer` only copies a few small arrays and puts them on the
queue, and when the queue is full (the viewer fell ``QUEUE_ITEMS`` engine periods behind) the
rows are dropped and counted. :meth:`LiveViewer.close` returns the counts, which the run keeps
in its root attribute ``live.viewer``.

The stream goes to a native Rerun viewer when there is a display (one is started, or the one
already listening on :data:`PORT` is reused), and always to ``RUN_DIR/live.rrd``: the view the
operator had, to replay with ``rerun RUN_DIR/live.rrd``. Entities are those of the replay
(:mod:`viewer.record`): ``live/...``, ``tactile/<finger>/<view>/...``, ``events``,
``protocol/step``.

Imported only through the ``tactile_flow.live_viewer`` entry point (``protocols`` never imports
``viewer``); it needs no analysis code.
"""

from __future__ import annotations

import json
import os
import queue
import threading
import time
import uuid
from pathlib import Path

import numpy as np

from . import INSTALL_HINT, TIMELINE, draw
from .serve import NATIVE_PORT, spawn_native_viewer

QUEUE_ITEMS = 256        # engine periods of backlog (2.56 s at 100 Hz) before rows are dropped
DRAIN_S = 0.1            # the viewer's thread sends what is queued 10 times a second (its CPU: a few %)
PORT = NATIVE_PORT       # the native viewer's gRPC port (Rerun's default)
LIVE_ARROW_GAIN = 20.0   # px drawn per px/frame: a slip (≥ 0.1 px/frame) shows, sensor noise hardly
LIVE_FILE = "live.rrd"


class ViewerUnavailable(RuntimeError):
    """The live viewer cannot start (rerun-sdk not installed); the run goes on without it."""


class LiveViewer:
    """Streams a run's live monitor to Rerun from its own thread (see the module docstring).

    Args:
        fingers, views: the monitor's fingers and views (the rows' F and V axes).
        model: the monitor's :class:`tactile.pipeline.TactileModel` (frame shapes, footprints).
        run_dir: where ``live.rrd`` is written.
        fps: tactile frames shown per second.
        spawn: start (or reuse) a native viewer when there is a display.

    Attributes:
        warning: one sentence for the operator when there is no display (else ``None``).
        path: the ``live.rrd`` file.
    """

    def __init__(self, fingers, views, model, run_dir, fps: float = 25.0, spawn: bool = True):
        try:
            import rerun as rr
        except ImportError:
            raise ViewerUnavailable(f"rerun-sdk is not installed ({INSTALL_HINT})") from None
        from . import layout
        self.rr = rr
        self.fingers, self.views, self.model = tuple(fingers), tuple(views), model
        self.period = 1.0 / fps
        self.noise = model.config.noise
        self.path = Path(run_dir) / LIVE_FILE
        self.rec = rr.RecordingStream("tactile-flow", recording_id=uuid.uuid4())
        self.rec.send_recording_name(f"live {Path(run_dir).name}")
        sinks = [rr.FileSink(str(self.path))]
        self.display = bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
        self.warning = None
        if self.display and spawn:
            spawn_native_viewer(PORT)              # on loopback only (Rerun's own spawn listens everywhere)
            sinks.insert(0, rr.GrpcSink(f"rerun+http://127.0.0.1:{PORT}/proxy"))
        elif not self.display:
            self.warning = (f"live.viewer=rerun: no display ($DISPLAY unset), so no viewer window; the live view "
                            f"is written to {self.path} (open it with `rerun {self.path}`)")
        self.rec.set_sinks(*sinks, default_blueprint=layout.live(self.fingers, self.views))
        self.grids = {v: draw.arrow_grid(model.plans[v].mask, 3) for v in self.views}
        self._log_static()
        self.queue: queue.Queue = queue.Queue(maxsize=QUEUE_ITEMS)
        self.offered = self.dropped = self.events_dropped = 0     # the engine's thread counts these
        self.shown = self.lost = 0                                # the viewer's thread these
        self._next_image = -np.inf
        self._slip = None                          # the latched verdict last sent
        self._stop = threading.Event()
        self.error: str | None = None
        self.thread = threading.Thread(target=self._drain, name="live-viewer", daemon=True)
        self.thread.start()

    # ------------------------------------------------------------------ engine thread: never blocks
    def offer(self, rows: dict, flow) -> None:
        """Queue the rows the monitor just recorded (``rows``: the ``live`` columns, (n, ...)
        arrays, read only) and, if a frame is due, copies of each finger's latest frame and flow
        field (``flow``: the monitor's :class:`tactile.online.OnlineFlow`). Drops when full."""
        n = len(rows["time_live"])
        self.offered += n
        t = float(rows["time_live"][-1])
        images = None
        if t >= self._next_image:
            self._next_image = t + self.period
            images = (t, [(f, v, flow.frame(f, v).copy(), draw.sample_field(flow.flow_field(f, v), self.grids[v]))
                          for f in self.fingers for v in self.views])
        try:
            self.queue.put_nowait(("rows", rows, images))
        except queue.Full:
            self.dropped += n

    def event(self, t: float, kind: str, name: str, detail=None) -> None:
        """Queue one engine event (s since run start); dropped (and counted) when full."""
        try:
            self.queue.put_nowait(("event", t, kind, name, detail))
        except queue.Full:
            self.events_dropped += 1

    def close(self, timeout_s: float = 30.0) -> dict:
        """Send what is queued, stop the thread, close and compact the file; the counts for the
        run's attrs."""
        self._stop.set()
        self.thread.join(timeout_s)
        left = 0                                   # what a stuck thread never took
        while True:
            try:
                item = self.queue.get_nowait()
            except queue.Empty:
                break
            left += len(item[1]["time_live"]) if item[0] == "rows" else 0
        self.rec.flush(timeout_sec=timeout_s)
        self.rec.disconnect()
        compact(self.path)
        return {"name": "rerun", "file": self.path.name, "display": self.display, "rows_offered": self.offered,
                "rows_shown": self.shown, "rows_dropped": self.dropped + self.lost + left,
                "events_dropped": self.events_dropped, "queue_items": QUEUE_ITEMS, "error": self.error}

    # ------------------------------------------------------------------ the viewer's thread
    def _drain(self) -> None:
        while True:
            stopping = self._stop.is_set()
            items = []
            while True:
                try:
                    items.append(self.queue.get_nowait())
                except queue.Empty:
                    break
            if items and self.error is None:
                try:
                    self._send(items)
                except Exception as exc:  # noqa: BLE001 - the viewer must never take the run down
                    self.error = f"{type(exc).__name__}: {exc}"
            if self.error is not None:            # after an error nothing more is sent: count it lost
                self.lost += sum(len(it[1]["time_live"]) for it in items if it[0] == "rows")
            if stopping:
                return
            time.sleep(DRAIN_S)

    def _send(self, items) -> None:
        rows = [it[1] for it in items if it[0] == "rows"]
        if rows:
            batch = {k: np.concatenate([r[k] for r in rows]) for k in rows[0]}
            self._slip = send_live(self.rec, batch, self.fingers, self.views, self.noise, self._slip)
        images = [it[2] for it in items if it[0] == "rows" and it[2] is not None]
        if images:
            self._send_images(images)
        events = [it[1:] for it in items if it[0] == "event"]
        if events:
            send_events(self.rec, events)
        self.shown += sum(len(r["time_live"]) for r in rows)      # counted once all of it is sent

    def _log_static(self) -> None:
        rr = self.rr
        for v in self.views:
            h, w = self.model.plans[v].shape
            fmt = rr.components.ImageFormat(width=w, height=h, color_model="RGB", channel_datatype="U8")
            for f in self.fingers:
                base = f"tactile/{f}/{v}"
                self.rec.log(f"{base}/frame", rr.Image.from_fields(format=fmt, magnification_filter="Nearest"),
                             static=True)
                self.rec.log(f"{base}/flow", rr.Arrows2D.from_fields(origins=draw.arrow_origins(self.grids[v]),
                                                                     colors=[draw.FLOW_COLOUR], radii=0.12), static=True)
        self.rec.log("run", rr.TextDocument(f"Live view: flow arrows ×{LIVE_ARROW_GAIN:g} (px drawn per px/frame); "
                                            f"frames at {1 / self.period:g} per second."), static=True)

    def _send_images(self, images) -> None:
        """Frames and flow arrows of every finger × view, one call each for all the queued times."""
        rr = self.rr
        col = [rr.TimeColumn(TIMELINE, duration=[t for t, _ in images])]
        for k, (f, v, _, vectors) in enumerate(images[0][1]):
            frames = np.stack([per_view[k][2] for _, per_view in images])
            arrows = np.stack([per_view[k][3] for _, per_view in images]) * LIVE_ARROW_GAIN
            base = f"tactile/{f}/{v}"
            self.rec.send_columns(f"{base}/frame", col,
                                  rr.Image.columns(buffer=draw.colour_frames(frames).reshape(len(images), -1)))
            self.rec.send_columns(f"{base}/flow", col, rr.Arrows2D.columns(vectors=arrows.reshape(-1, 2))
                                  .partition([len(vectors)] * len(images)))


def compact(path: Path) -> None:
    """Merge the many small chunks a live stream leaves in ``path`` (one per entity and drain:
    ~10 MB for 30 s of three fingers) into a few large ones (~2 MB), in place, with Rerun's own
    ``rerun rrd optimize``; a failure leaves the file as it was."""
    import subprocess
    import sys
    tmp = path.with_suffix(".rrd.partial")
    try:
        done = subprocess.run([sys.executable, "-m", "rerun_cli", "rrd", "optimize", str(path), "-o", str(tmp)],
                              capture_output=True, timeout=300)
        if done.returncode == 0 and tmp.is_file():
            tmp.replace(path)
    except (OSError, subprocess.SubprocessError):
        pass
    tmp.unlink(missing_ok=True)


def send_live(rec, rows: dict, fingers, views, noise: float, previous: bool | None = None) -> bool | None:
    """The live monitor's rows — the ``live`` group's columns, (L, ...) — as four multi-series
    entities, one series per finger (× view): ``live/magnitude`` (px/frame), ``live/direction``
    (deg), ``live/activation_total`` (kΩ), ``live/slip_cause`` (0 none, 1 release, 2 creep,
    3 rotation); and the latched verdict as the state lane ``live/slip`` ("watching" / "slip",
    sent where it changes from ``previous``; ``None``: the first call, which also names the
    series). Returns the last verdict. Used live, and to replay a recorded ``live`` group."""
    import rerun as rr
    t = np.asarray(rows["time_live"], np.float64)
    n, col = len(t), [rr.TimeColumn(TIMELINE, duration=t)]
    mag = np.asarray(rows["magnitude"], np.float64).reshape(n, -1)               # (L, F·V), finger-major
    series = {"magnitude": mag,
              "direction": draw.direction_deg(np.asarray(rows["direction"]).reshape(n, -1), mag, noise),
              "activation_total": np.asarray(rows["activation_total"], np.float64),
              "slip_cause": np.asarray(rows["slip_cause"], np.float64)}
    if previous is None:
        per_view = [f"{f} {v}" for f in fingers for v in views]
        for name, names in (("magnitude", per_view), ("direction", per_view), ("activation_total", list(fingers)),
                            ("slip_cause", list(fingers))):
            rec.log(f"live/{name}", rr.SeriesLines(names=names), static=True)
        rec.log("live/slip", rr.StateConfiguration(values=["watching", "slip"], colors=[0x55A868FF, 0xC44E52FF]),
                static=True)
    for name, values in series.items():
        rec.send_columns(f"live/{name}", col, rr.Scalars.columns(scalars=values.ravel()).partition([values.shape[1]] * n))
    detected = np.asarray(rows["slip_detected"], bool)
    before = np.r_[not detected[0] if previous is None else previous, detected[:-1]]
    change = np.flatnonzero(detected != before)
    if change.size:
        rec.send_columns("live/slip", [rr.TimeColumn(TIMELINE, duration=t[change])],
                         rr.StateChange.columns(state=["slip" if detected[i] else "watching" for i in change]))
    return bool(detected[-1]) if n else previous


LEVELS = {"interlock": "ERROR", "fault": "ERROR", "error": "ERROR", "abort": "ERROR", "protective_stop": "ERROR",
          "gap": "WARN", "invalid": "WARN", "slip": "WARN", "reaction": "WARN", "timeout": "WARN",
          "step_start": "DEBUG", "step_end": "DEBUG"}
"""Event kind → text-log level (everything else INFO): what the operator should not miss."""


def send_events(rec, events) -> None:
    """Events ``(t, kind, name, detail)`` as the ``events`` text log, and the protocol's steps
    (``step_start`` / ``step_end``) as the state lane ``protocol/step``."""
    import rerun as rr
    t = np.array([e[0] for e in events], np.float64)
    text = [f"{k} {n}" + (f" {json.dumps(d, default=str)}" if d else "") for _, k, n, d in events]
    rec.send_columns("events", [rr.TimeColumn(TIMELINE, duration=t)],
                     rr.TextLog.columns(text=text, level=[LEVELS.get(k, "INFO") for _, k, _, _ in events]))
    for ts, kind, name, _ in events:
        if kind in ("step_start", "step_end"):
            rec.set_time(TIMELINE, duration=float(ts))
            rec.log("protocol/step", rr.StateChange(state=name) if kind == "step_start" else rr.StateChange.cleared())
    rec.reset_time()

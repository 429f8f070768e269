"""Tactile flow computed live during a run, the slip detector on it, and the operator's view.

:class:`LiveMonitor` taps the BioTac stream (:meth:`hardware.biotac.TactileSensors.tap`: the
recorder still receives every frame), and on every engine period (:meth:`poll`, called by
:class:`protocols.engine.RunContext` once per BioTac frame) processes the frames received
since the last period, one at a time: the online tactile-flow pipeline
(:class:`tactile.online.OnlineFlow`: Kalman filter, tactile frames of the configured views,
flow against the previous frame, aggregates) and the slip detector
(:class:`tactile.slip.SlipDetector`). Every processed frame becomes one row of the run
store's ``live`` group, so a reaction can be audited afterwards against what the monitor
saw, and when.

The rest impedance (the zero of the activation) is the mean over the frames received during
the engine's tare, as the offline analysis takes it from the same tare window.

Configured by the ``live`` node of the run config (:class:`LiveConfig`).
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass, field, fields, replace
from typing import Optional

import numpy as np

from tactile_flow.tactile._lazy import lazy_import
from tactile_flow.tactile.flow import FlowConfig
from tactile_flow.tactile.pipeline import TactileConfig, TactileModel
from tactile_flow.tactile.slip import CAUSES, SlipConfig, SlipDetector

signals, online = lazy_import("tactile_flow.tactile.signals"), lazy_import("tactile_flow.tactile.online")   # numba: on first use

ARROWS = "→↘↓↙←↖↑↗"          # image directions: +col is right, +row is down
VIEWER_ENTRY_POINTS = "tactile_flow.live_viewer"     # live.viewer=NAME names one of these
RESTART_FRAMES = 10          # frames numbered below the newest seen before a counter restart is believed


@dataclass
class LiveConfig:
    """The ``live`` node of the run config.

    Attributes:
        enabled: ``None`` (auto): on when a protocol step reacts to slip (``until: slip``
            or ``on_slip``); ``true``: always (the live group is recorded); ``false``: off
            (a protocol that reacts to slip is then refused before anything moves).
        fingers: fingers processed online and watched for slip (default: every connected one).
        views: tactile-frame views computed online; by default the pad's (``bottom``), which
            is the one a grasped object slips across: every view adds its flow's cost (about
            0.25 ms per finger and frame), and on a loaded lab PC three views per finger can
            fall behind the stream.
        console_hz: updates per second of the operator's live line (0: none).
        slip: the detector's thresholds (:class:`tactile.slip.SlipConfig`).
        viewer: ``None``, or the name of a live viewer (entry point group
            :data:`VIEWER_ENTRY_POINTS`; ``rerun``: docs/viewer.md) that shows the monitor's
            results as they come; it turns the monitor on. A viewer that cannot start (not
            installed, no display) is one warning, and the run goes on.
    """

    enabled: Optional[bool] = None
    fingers: Optional[list[str]] = None
    views: list[str] = field(default_factory=lambda: ["bottom"])
    console_hz: float = 4.0
    slip: SlipConfig = field(default_factory=SlipConfig)
    viewer: Optional[str] = None


def live_fingers(cfg: LiveConfig, connected) -> tuple[str, ...]:
    """The fingers processed online, in Shadow order: ``cfg.fingers`` or every connected one."""
    chosen = set(cfg.fingers or connected)
    return tuple(f for f in connected if f in chosen)


def viewer_names() -> list[str]:
    """The live viewers installed (``live.viewer`` values)."""
    from importlib.metadata import entry_points
    return sorted(ep.name for ep in entry_points(group=VIEWER_ENTRY_POINTS))


def open_viewer(name: str | None, fingers, model: TactileModel, run_dir, warn=print):
    """The live viewer ``name`` (an entry point of :data:`VIEWER_ENTRY_POINTS`) for these fingers
    and the model's views, or ``None``: none asked for, or it could not start (``warn`` gets one
    line saying why; the run goes on without it)."""
    if not name:
        return None
    from importlib.metadata import entry_points
    found = {ep.name: ep for ep in entry_points(group=VIEWER_ENTRY_POINTS)}
    try:
        viewer = found[name].load()(fingers, model.config.views, model, run_dir)
    except Exception as exc:  # noqa: BLE001 - a viewer must never stop the run
        warn(f"live.viewer={name}: cannot start ({exc}); the run goes on without it")
        return None
    if getattr(viewer, "warning", None):
        warn(viewer.warning)
    return viewer


def warm_up(model: TactileModel, views) -> None:
    """Run the online pipeline on a few made-up frames, so that its compiled kernels are
    loaded before the run starts, not while the first frames queue up. (On a machine's first
    run :func:`tactile.warmup.compile_cold` has compiled them on every core just before.)"""
    n = model.n_taxels
    flow = online.OnlineFlow(model, np.full((1, n), 10.0), ("ff",), views)
    for i in range(3):
        flow.push(i, 0.01 * i, np.full((1, n), 3000 - 100 * i))


def tactile_config(offline: TactileConfig | None, views) -> TactileConfig:
    """The online pipeline's parameters: the offline analysis's (``offline``, the typed
    ``analysis.tactile``; None: the defaults) so live and offline frames are the same, the
    live ``views``, no smoother, and the flow without its offline-only settings.

    A live stream cannot scale each contact to its own peak before the contact has ended:
    with ``intensity_range: contact`` (the offline default) the live frames keep the fixed
    0–8 kΩ scale the slip detector was tuned on (the analysis config's ``intensity_range``
    field holds it then)."""
    offline = offline or TactileConfig()
    flow = FlowConfig(**{f.name: getattr(offline.flow, f.name) for f in fields(FlowConfig)
                         if f.name not in ("dis", "tvl1")})          # not the offline-only keys
    return replace(offline, smooth=False, views=tuple(views), flow=flow)


class LiveMonitor:
    """Online tactile flow and slip detection over one run (see the module docstring).

    Args:
        biotac: the lab's :class:`~hardware.biotac.TactileSensors`.
        recorder: receives the ``live`` rows (:meth:`protocols.recorder.Recorder.live`).
        model: the tactile model built with :func:`tactile_config`.
        cfg: the :class:`LiveConfig`.
        clock: the lab's clock (``now()``).
        display: callable taking the live line (or ``None``).
        viewer: a live viewer (:func:`open_viewer`) offered every processed row and the engine's
            events; it must return at once (it queues, and drops when behind), or ``None``.
    """

    def __init__(self, biotac, recorder, model: TactileModel, cfg: LiveConfig, clock, display=None, viewer=None):
        self.cfg, self.recorder, self.model, self.clock, self.display = cfg, recorder, model, clock, display
        self.viewer = viewer
        self.fingers = live_fingers(cfg, biotac.fingers)
        self.views = tuple(model.config.views)
        self.rows = [biotac.fingers.index(f) for f in self.fingers]
        self.biotac = biotac
        self.tap = biotac.tap(maxlen=int(10 * biotac.rate_hz))        # 10 s: a stalled engine drops, never grows
        self.detector = SlipDetector(len(self.fingers), cfg.slip)
        self.flow: online.OnlineFlow | None = None
        self._rest_sum = np.zeros((len(self.fingers), model.n_taxels))
        self._impedance = model.sensor.impedance if model.sensor is not None else signals.counts_to_impedance
        self._rest_n = 0
        self._next_display = -math.inf
        self.frames = 0
        self.still = True
        self.hand_still = True
        self._step = None                               # the newest OnlineStep
        self._newest_seq = None                         # highest frame number seen
        self._behind = 0                                # frames in a row numbered below it
        self._timing = np.zeros((2, 3))                 # flow, detector: total s, max s, frames
        self._device_offset = math.inf                  # run time − device time, least over the frames
        from tactile_flow.hardware.device import WallClock
        self.wakes = isinstance(clock, WallClock)       # the engine may wait for frames (wait_frame)
        self.detection = None                           # the stages of the newest detection's frame

    # ------------------------------------------------------------------ lifecycle
    def begin(self) -> None:
        """End of the tare: the rest impedance is the mean over the frames seen so far."""
        self.poll()
        if self._rest_n == 0:
            raise RuntimeError("live: no valid BioTac frame during the tare; cannot set the rest impedance")
        rest = self._rest_sum / self._rest_n
        self.flow = online.OnlineFlow(self.model, rest, self.fingers, self.views)

    def close(self) -> dict:
        """Stop tapping the stream; return what the monitor did, for the store's root attribute
        ``live``: frames processed, per-finger counters of processed and skipped samples,
        frames the tap dropped, the views, the thresholds."""
        self.biotac.untap(self.tap)
        out = {"fingers": list(self.fingers), "views": list(self.views), "frames": self.frames,
               "tap_overflows": self.tap.overflows, "slip": dict(vars(self.detector.config))}
        if self.flow is not None:
            out["counters"] = self.flow.counters()
        if self._timing[0, 2]:
            out["timing_ms"] = {k: {"mean": round(1e3 * tot / n, 4), "max": round(1e3 * mx, 4)}
                                for k, (tot, mx, n) in zip(("flow", "detector"), self._timing)}
        if self.detection is not None:
            out["detection"] = self.detection
        if self.viewer is not None:
            out["viewer"] = self.viewer.close()
            if out["viewer"].get("rows_dropped"):
                self.recorder.event("info", "live_viewer", out["viewer"])
        return out

    def event(self, kind: str, name: str, detail=None) -> None:
        """An engine event, passed on to the viewer (the recorder has it already)."""
        if self.viewer is not None:
            self.viewer.event(self.recorder.now(), kind, name, detail)

    # ------------------------------------------------------------------ per period
    def wait_frame(self, timeout_s: float) -> bool:
        """On the wall clock: block until a frame has arrived since the last :meth:`poll` (True)
        or ``timeout_s`` s have passed (False), so the engine polls as soon as a frame is in."""
        return self.tap.wait(timeout_s)

    def frame_time(self, fr, received: float) -> float:
        """The frame's time on the run's axis (s) as the sensor's own clock dates it: its device
        time plus the least (receipt − device time) seen so far, so never after its receipt
        ``received``. The online flow and the detector pace themselves by it (trends, noise,
        pauses longer than ``max_gap_s``): frames delayed or bunched on the wire are then not
        a pause of the sensor. A device time that is not finite leaves the receipt time."""
        d = fr.device_time
        if not math.isfinite(d):
            return received
        self._device_offset = min(self._device_offset, received - d)
        return d + self._device_offset

    def poll(self, still: bool | None = None, hand_still: bool | None = None):
        """Process every frame received since the last call; returns the detector's state.
        ``still``: neither arm nor hand moves; ``hand_still``: the hand does not (default: as
        ``still``)."""
        if still is not None:
            self.still = still
            self.hand_still = still if hand_still is None else hand_still
        frames = self.tap.drain()
        if self.flow is None:                          # tare: accumulate the rest impedance
            for fr in frames:
                if fr.is_valid():
                    self._rest_sum += self._impedance(fr.electrodes[self.rows])
                    self._rest_n += 1
            return None
        if frames:
            rows = self._process(frames)
            self.recorder.live(rows)
            if self.viewer is not None:
                self.viewer.offer(rows, self.flow)
        self._show()
        return self.detector.state

    def _process(self, frames) -> dict[str, np.ndarray]:
        n, F, V = len(frames), len(self.fingers), len(self.views)
        cols = {"time_live": np.empty(n), "processed_time": np.empty(n), "seq": np.empty(n, np.int64),
                "processed": np.zeros((n, F), bool), "activation_total": np.empty((n, F)),
                "activation_contact": np.empty((n, F)),
                **{k: np.empty((n, F, V)) for k in ("flow_col", "flow_row", "magnitude", "direction",
                                                     "divergence", "curl", "confidence")},
                "slip_fired": np.zeros((n, F), bool), "slip_cause": np.zeros((n, F), np.int8),
                "slip_detected": np.zeros(n, bool)}
        t0 = self.recorder.t0
        for i, fr in enumerate(frames):
            t = fr.host_time - t0
            if self._follow_restarts(fr.seq):
                self._device_offset = math.inf
            t_frame = self.frame_time(fr, t)
            first = self.detector.state.first
            c0 = time.perf_counter()
            step = self._step = self.flow.push(fr.seq, t_frame, fr.electrodes[self.rows])
            c1 = time.perf_counter()
            mean = np.stack([step.mean_col, step.mean_row], axis=-1)
            state = self.detector.update(t_frame, step.processed, step.activation_total, mean, step.curl,
                                         step.confidence, still=self.still, contact=step.activation_contact,
                                         hand_still=self.hand_still)
            c2 = time.perf_counter()
            cols["time_live"][i], cols["seq"][i] = t, fr.seq
            cols["processed_time"][i] = self.clock.now() - t0
            self._time(c1 - c0, c2 - c1)
            if state.first is not None and state.first is not first:
                self.detection = {"seq": int(fr.seq), "received_s": round(t, 6),
                                  "processed_s": round(float(cols["processed_time"][i]), 6),
                                  "flow_ms": round(1e3 * (c1 - c0), 4), "detector_ms": round(1e3 * (c2 - c1), 4),
                                  "waited_ms": round(1e3 * (cols["processed_time"][i] - t) - 1e3 * (c2 - c0), 4)}
            cols["processed"][i], cols["activation_total"][i] = step.processed, step.activation_total
            cols["activation_contact"][i] = step.activation_contact
            for k, name in (("flow_col", "mean_col"), ("flow_row", "mean_row"), ("magnitude", "magnitude"),
                            ("direction", "direction"), ("divergence", "divergence"), ("curl", "curl"),
                            ("confidence", "confidence")):
                cols[k][i] = getattr(step, name)
            cols["slip_fired"][i], cols["slip_cause"][i] = state.fired, state.cause
            cols["slip_detected"][i] = state.detected
            self.frames += 1
        return cols

    def _time(self, flow_s: float, detector_s: float) -> None:
        for k, dt in enumerate((flow_s, detector_s)):
            row = self._timing[k]
            row[0] += dt
            row[1] = max(row[1], dt)
            row[2] += 1

    def _follow_restarts(self, seq: int) -> bool:
        """A sensor whose frame counter restarted (a reconnected bridge) would otherwise be
        skipped as late for good: after :data:`RESTART_FRAMES` frames in a row numbered below
        the newest seen, start the online pipeline and the detector afresh (returns True)."""
        if self._newest_seq is not None and seq <= self._newest_seq:
            self._behind += 1
            if self._behind < RESTART_FRAMES:
                return False
            self.flow.reset()
            for f in range(len(self.fingers)):
                self.detector.reset(f)
            self.recorder.event("info", "live", {"message": f"BioTac frame counter restarted (seq {seq} after "
                                                            f"{self._newest_seq}): online flow restarted"})
            restarted = True
        else:
            restarted = False
        self._newest_seq, self._behind = seq, 0
        return restarted

    # ------------------------------------------------------------------ operator
    def line(self) -> str:
        """``ff ↓ 0.021 | mf · 0.002 | th ↓ 0.030 | slip: ff release at 20.26 s`` (px/frame, first view)."""
        step = self._step
        if step is None:
            return "live: taring" if self.flow is None else "live: waiting for frames"
        parts = []
        for k, f in enumerate(self.fingers):
            if not step.processed[k]:
                parts.append(f"{f} -- skipped")
                continue
            mag, ang = step.magnitude[k, 0], step.direction[k, 0]
            arrow = "·" if mag < self.model.config.noise / 2 else ARROWS[int(round(ang / (math.pi / 4))) % 8]
            parts.append(f"{f} {arrow} {mag:.3f}")
        first = self.detector.state.first
        slip = "-" if first is None else f"{self.fingers[first[1]]} {CAUSES[first[2]]} at {first[0]:.2f} s"
        return " | ".join(parts) + f" | slip: {slip}"

    def _show(self) -> None:
        if self.display is None or self.cfg.console_hz <= 0:
            return
        now = self.clock.now()
        if now >= self._next_display:
            self._next_display = now + 1.0 / self.cfg.console_hz
            self.display(self.line())


def replay(model: TactileModel, rest_impedance, seq, t, electrodes, fingers, slip: SlipConfig = SlipConfig(),
           still=None) -> dict:
    """Run the online flow and the slip detector over a recorded stream, frame by frame, as a
    run would have (to measure false alarms on recordings, or tune thresholds).

    Args:
        rest_impedance: (F, N) kΩ. seq: (T,) frame numbers. t: (T,) s. electrodes: (T, F, N)
        counts. fingers: the F names. still: (T,) bool, the robot still (default: always).
    Returns ``detections`` [(t, finger, cause)] of every frame that fired, ``first`` (or
    None), ``frames``, and the online pipeline's per-finger ``counters``.
    """
    flow = online.OnlineFlow(model, rest_impedance, fingers)
    det = SlipDetector(len(fingers), slip)
    hits = []
    for i in range(len(t)):
        step = flow.push(int(seq[i]), float(t[i]), electrodes[i])
        state = det.update(float(t[i]), step.processed, step.activation_total,
                           np.stack([step.mean_col, step.mean_row], axis=-1), step.curl, step.confidence,
                           still=True if still is None else bool(still[i]), contact=step.activation_contact)
        hits += [(float(t[i]), fingers[k], CAUSES[state.cause[k]]) for k in np.flatnonzero(state.fired)]
    return {"detections": hits, "first": hits[0] if hits else None, "frames": len(t), "counters": flow.counters()}


def terminal_display(stream=sys.stderr):
    """A display that rewrites one terminal line in place (nothing when not a terminal)."""
    if not stream.isatty():
        return None

    def show(line: str) -> None:
        stream.write("\r\x1b[2K" + line)
        stream.flush()
    return show

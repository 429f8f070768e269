"""The recorder: acquire every stream on its own thread, write the run store as data arrive.

    store = RunStore.create(run_dir / "run.zarr", protocol="straws_sweep", fingers=lab.biotac.fingers,
                            streams=lab.streams())
    with Recorder(store, lab.sources(), lab.clock) as rec:
        rec.event("step_start", "sweep")
        ...
    # or rec.start() ... rec.stop("success", truth=lab.truth.to_dict())

What a stream's samples become (columns, dtypes, its time coordinate and raw time columns) is
its sample type's declaration (:mod:`hardware.streams`), kept by the store (``store.streams``).
One acquisition thread per stream polls its device's non-blocking drain method every
``poll_interval_s`` of the device clock (``clock.sleep``, so simulated time is respected)
and queues the samples; a device error becomes a ``fault`` event and marks the stream
stale, and the thread keeps retrying. A writer thread converts the queued samples to
arrays, stamps them with the stream's clock model (:mod:`runstore.clockmodel`), appends
them and commits the store every ``flush_interval_s`` of wall time or :data:`RUN_FLUSH_S` of
the run's own clock time, whichever comes first; a simulated clock faster than real time is
held back while the last commit is :data:`MAX_BEHIND_S` behind (:meth:`Recorder.keep_up`),
so a crash loses less than a second of either. (Each commit rewrites the last partial chunk
of every array: commits every 0.75 s of run time cost a fast simulated run about 15–20 % of
its speed, docs/run_store.md.) :meth:`Recorder.stop` drains every stream, flushes, refits each clock
model on the whole run, rewrites the time coordinates and closes the store.

Times in the store are seconds since run start: ``t0 = clock.now()`` at :meth:`start`,
the same time base as every sample's ``host_time``.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np


from tactile_flow.runstore import RunStatus, RunStore, utc_now
from tactile_flow.runstore.clockmodel import OnlineClockModel, latency_stats, sequence_gaps
from tactile_flow.runstore.layout import event_columns

log = logging.getLogger(__name__)

WAKE_S = 0.02                 # wall s between the writer's looks at the clocks
RUN_FLUSH_S = 0.75            # run s between commits of a clock faster than the wall (a simulated lab)
MAX_BEHIND_S = 0.9            # run s a free-running (simulated) clock may run ahead of the last commit


# ----------------------------------------------------------------------------- state
@dataclass
class StreamStats:
    """Counters of one stream (updated by its acquisition thread and the writer)."""

    samples: int = 0
    gaps: int = 0
    missing: int = 0
    invalid: int = 0
    faults: int = 0
    last_host_time: float | None = None
    error: str | None = None                  # set while the source is failing
    pending: list = field(default_factory=list)
    drained_to: float | None = None           # clock time its last read began: what came before is pending


class Recorder:
    """Acquire ``sources`` into ``store`` (see module docstring).

    Args:
        store: a freshly created :class:`RunStore` (the recorder closes it in :meth:`stop`);
            its ``streams`` (the sample types' declarations, :mod:`hardware.streams`) say how
            samples become columns.
        sources: stream name (``biotac``, ``arm``, ``hand``, ``pump``, ``scale``, ``stage``, or
            any other stream the store declares) → the device's non-blocking drain method
            (``lab.biotac.read``, ``lab.arm.read_states``, ...).
        clock: the devices' :class:`~hardware.device.Clock` (``now()``, ``sleep()``).
        flush_interval_s: wall-clock seconds between commits (with :data:`RUN_FLUSH_S` of
            clock time, whichever comes first: about the most a crash loses).
        poll_interval_s: clock seconds between polls of a source. Only how often the device
            buffers are drained: a sample's time is its device's receipt time, and commits come
            every ``flush_interval_s``. Each poll wakes a thread (every 10 ms made five times the
            wake-ups and context switches, which cost a simulated run on a few cores).
        retry_interval_s: clock seconds between retries of a failing source.
        min_latency_s: known minimum transport latency per stream (s) subtracted by the
            clock models (a float for every stream, or a dict); 0 keeps the receipt envelope.
        clock_window_s: window of the clock model's lower envelope (device s).
    """

    def __init__(self, store: RunStore, sources: dict[str, Callable[[], list]], clock,
                 flush_interval_s: float = 0.5, poll_interval_s: float = 0.05,
                 retry_interval_s: float = 0.2, min_latency_s: float | dict = 0.0,
                 clock_window_s: float = 1.0):
        declared = {s.source_name for s in store.streams.values()}
        unknown = set(sources) - declared
        if unknown:
            raise ValueError(f"recorder: unknown stream(s) {sorted(unknown)}; expected some of {sorted(declared)}")
        # each source's streams, its own first (biotac, then the biotac_pac derived from its frames)
        self.streams = {src: sorted((s for s in store.streams.values() if s.source_name == src),
                                    key=lambda s: s.name != src) for src in sources}
        if not 0 < flush_interval_s <= 1.0:
            raise ValueError(f"flush_interval_s: expected in (0, 1] s, got {flush_interval_s}")
        self.store, self.sources, self.clock = store, dict(sources), clock
        self.flush_interval_s = flush_interval_s
        self.poll_interval_s = poll_interval_s
        self.retry_interval_s = retry_interval_s
        lat = min_latency_s if isinstance(min_latency_s, dict) else {s: min_latency_s for s in sources}
        self.models = {s: OnlineClockModel(clock_window_s, min_latency_s=float(lat.get(s, 0.0)))
                       for s in sources}
        self._stats = {s: StreamStats() for s in sources}
        self._events: list[tuple] = []
        self._live: list[dict] = []                       # rows of the online flow (protocols.live)
        self._outbox: dict[str, list[dict]] = {}          # block -> column dicts not yet appended
        self._last_seq: int | None = None                 # newest BioTac frame written
        self._last_device: dict[str, tuple] = {}          # block -> (device, run) time of its last sample
        self._last_frame_time: float | None = None
        self._lock = threading.Lock()                     # stats, pending samples, events
        self._flush_lock = threading.Lock()               # one flush at a time
        self._stopping = threading.Event()
        self._writer_stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._writer: threading.Thread | None = None
        self.t0: float | None = None
        self.commit_wall_times: list[float] = []          # wall (monotonic) time of each commit
        self.flush_durations: list[float] = []            # wall s per flush (convert+append+commit)
        self.writer_error: BaseException | None = None
        self.stopped = False
        self._committed = threading.Condition()
        self._committed_clock: float | None = None        # clock time up to which every sample is committed

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> "Recorder":
        """Set the run's time origin, start the acquisition threads and the writer."""
        if self.t0 is not None:
            raise RuntimeError("recorder already started")
        self.t0 = float(self.clock.now())
        self._start_wall = time.monotonic()
        self.store.set_attrs(t0_clock_s=self.t0, recording_start_time=utc_now(),
                             streams_recorded=sorted(self.sources))
        for name, source in self.sources.items():
            t = threading.Thread(target=self._acquire, args=(name, source), name=f"rec-{name}", daemon=True)
            t.start()
            self._threads.append(t)
        self._writer = threading.Thread(target=self._write_loop, name="rec-writer", daemon=True)
        self._writer.start()
        return self

    def stop(self, status: str = RunStatus.SUCCESS, truth: dict | None = None, attrs: dict | None = None) -> dict:
        """Drain every source, flush, refit the clock models, rewrite the time coordinates,
        write ``truth`` (the simulator's ground truth, if given) and close the store with
        ``status`` and ``attrs``. Returns :meth:`stats`. Idempotent.

        If any of that fails (a full disk...) the store is closed ``failed`` — a run that
        could not record everything it received is never ``success`` — with the error in
        ``recorder_error`` (and ``error``), and the first error is re-raised; if even the
        close fails the store stays at its last commit (``running``: ``tactile-recover``)."""
        if self.stopped:
            return self.stats()
        if self.t0 is None:                       # never started: just close the store
            self.store.close(status, **(attrs or {}))
            self.stopped = True
            return self.stats()
        self._stopping.set()
        for t in self._threads:
            t.join()
        self._writer_stop.set()
        if self._writer is not None:
            self._writer.join()
        # every step is attempted so the store is closed whatever fails; the first error is re-raised
        errors = []

        def attempt(fn):
            try:
                return fn()
            except Exception as e:               # noqa: BLE001
                log.exception("recorder: %s failed while stopping", getattr(fn, "__name__", fn))
                errors.append(e)

        attempt(self._flush)
        attempt(self._refit)
        summary = attempt(self._summary) or {}
        if truth is not None:
            attempt(lambda: self.store.write_tree("truth", truth, attrs={
                "long_name": "simulator ground truth",
                "time_base": "simulated clock (s); subtract the root attribute t0_clock_s for time since run start"}))
        attrs = dict(attrs or {})
        if errors:
            status = RunStatus.FAILED
            attrs["recorder_error"] = f"{type(errors[0]).__name__}: {errors[0]}"
            attrs["error"] = "; ".join(filter(None, [f"recording failed: {attrs['recorder_error']}",
                                                     attrs.get("error")]))
        self.store.close(status, streams=summary, **attrs)
        self.stopped = True
        if errors:
            raise errors[0]
        return self.stats()

    def __enter__(self) -> "Recorder":
        return self.start()

    def __exit__(self, exc_type, exc, tb) -> None:
        if self.stopped:
            return
        if exc_type is None:
            self.stop(RunStatus.SUCCESS)
        else:
            if exc is not None:
                self.event("fault", "exception", {"type": exc_type.__name__, "message": str(exc)})
            self.stop(RunStatus.ABORTED if issubclass(exc_type, KeyboardInterrupt) else RunStatus.FAILED)

    # ------------------------------------------------------------------ engine API
    def now(self) -> float:
        """Seconds since run start (the store's time base)."""
        return float(self.clock.now()) - self._require_started()

    def event(self, kind: str, name: str, detail=None) -> None:
        """Record an event now (thread-safe). ``detail``: anything JSON-serialisable."""
        t = self.now()
        with self._lock:
            self._events.append((t, kind, name, detail))

    def live(self, columns: dict[str, np.ndarray]) -> None:
        """Queue rows of the ``live`` block (the online tactile flow; thread-safe)."""
        with self._lock:
            self._live.append(columns)

    def last_sample_age(self, stream: str) -> float:
        """Clock seconds since the newest sample of ``stream`` was received (since the start
        if none yet)."""
        st = self._stats[stream]
        ref = st.last_host_time if st.last_host_time is not None else self._require_started()
        return max(0.0, float(self.clock.now()) - ref)

    def keep_up(self, max_behind_s: float = MAX_BEHIND_S, timeout_s: float = 2.0) -> None:
        """Hold back the driver of a free-running clock (a simulated lab faster than real time:
        its clock has ``realtime = False``) while the last commit is more than ``max_behind_s``
        of run time behind, so a crash loses no more run time than that even when the writer
        lags. Returns at once for real clocks (time cannot wait), after ``timeout_s`` of wall
        time at most, and while the writer is failing (the ``recording_failed`` interlock's case)."""
        if getattr(self.clock, "realtime", True) or self.t0 is None:
            return
        deadline = time.monotonic() + timeout_s
        with self._committed:
            while (float(self.clock.now()) - (self._committed_clock or self.t0) > max_behind_s
                   and self.writer_error is None and not self._writer_stop.is_set()):
                if not self._committed.wait(max(0.0, deadline - time.monotonic())):
                    return

    def write_failure(self, max_age_s: float = 2.0) -> str | None:
        """Why the store has not been committed for ``max_age_s`` of wall time (a full disk,
        a vanished directory...), or ``None`` while recording is healthy."""
        if self.writer_error is None or self.t0 is None:
            return None
        last = self.commit_wall_times[-1] if self.commit_wall_times else self._start_wall
        if time.monotonic() - last < max_age_s:
            return None
        return f"{type(self.writer_error).__name__}: {self.writer_error}"

    def stale_streams(self, max_age_s: float | None = None) -> set[str]:
        """Streams whose source is failing, or (with ``max_age_s``) whose newest sample is older."""
        return {s for s, st in self._stats.items()
                if st.error is not None or (max_age_s is not None and self.last_sample_age(s) > max_age_s)}

    def stats(self) -> dict[str, dict]:
        """Per stream: samples, gaps, missing, invalid, faults, error, last_sample_age_s."""
        with self._lock:
            out = {s: {"samples": st.samples, "gaps": st.gaps, "missing": st.missing, "invalid": st.invalid,
                       "faults": st.faults, "error": st.error} for s, st in self._stats.items()}
        if self.t0 is not None:
            for s in out:
                out[s]["last_sample_age_s"] = self.last_sample_age(s)
        return out

    def newest_sample_time(self, stream: str) -> float | None:
        """Host receipt time (s since run start) of the newest sample received, or None."""
        h = self._stats[stream].last_host_time
        return None if h is None or self.t0 is None else h - self.t0

    def _require_started(self) -> float:
        if self.t0 is None:
            raise RuntimeError("recorder not started")
        return self.t0

    # ------------------------------------------------------------------ acquisition
    def _acquire(self, name: str, source) -> None:
        st = self._stats[name]
        while True:
            last = self._stopping.is_set()       # one more drain after stop is requested
            began = float(self.clock.now())
            try:
                samples = source()
            except Exception as e:               # noqa: BLE001 - any device error is recorded
                self._on_fault(name, e)
                if last:
                    return
                self.clock.sleep(self.retry_interval_s)
                continue
            with self._lock:
                st.drained_to = began
                if samples:
                    st.pending.extend(samples)
                    st.samples += len(samples)
                    st.last_host_time = float(samples[-1].host_time)
                if st.error is not None:
                    self._events.append((self.now(), "info", name, {"message": f"{name}: source recovered"}))
                    st.error = None
            if last:
                return
            self.clock.sleep(self.poll_interval_s)

    def _on_fault(self, name: str, e: Exception) -> None:
        msg = f"{type(e).__name__}: {e}"
        with self._lock:
            st = self._stats[name]
            if st.error == msg:
                return                            # same error again: one event per failure streak
            st.error = msg
            st.faults += 1
            self._events.append((self.now(), "fault", name, {"error": type(e).__name__, "message": str(e)}))
        log.warning("recorder: %s source failed: %s", name, msg)

    # ------------------------------------------------------------------ writing
    def _write_loop(self) -> None:
        # A commit is due flush_interval_s of wall time or RUN_FLUSH_S of the run's own (clock)
        # time after the previous one started, whichever comes first: a simulated run several
        # times faster than real time would otherwise lose seconds of its own time to a crash.
        # Deadlines run from the previous flush's start, so a slow flush does not add to them.
        wall_due = time.monotonic() + self.flush_interval_s
        run_due = float(self.clock.now()) + RUN_FLUSH_S
        while not self._writer_stop.wait(min(self.flush_interval_s, WAKE_S)):
            if time.monotonic() < wall_due and float(self.clock.now()) < run_due:
                continue
            wall_due = time.monotonic() + self.flush_interval_s
            run_due = float(self.clock.now()) + RUN_FLUSH_S
            try:
                self._flush()
            except Exception as e:               # noqa: BLE001 - keep the samples, retry next time
                self.writer_error = e
                log.exception("recorder: flush failed (samples kept for the next flush)")

    def _flush(self) -> None:
        """Convert every queued sample and event to columns, append them, commit."""
        with self._flush_lock:
            w0, c0 = time.monotonic(), float(self.clock.now())
            with self._lock:
                taken = {s: st.pending for s, st in self._stats.items()}
                # Samples received since a source's last read are not taken yet (its thread reads
                # every poll_interval_s): this commit holds what every healthy source received
                # before the earliest of those reads, which is what keep_up() waits for.
                c0 = min([c0] + [st.drained_to for st in self._stats.values()
                                 if st.drained_to is not None and st.error is None])
                for st in self._stats.values():
                    st.pending = []
            for name, samples in taken.items():
                if samples:
                    self._convert(name, samples)
            with self._lock:
                events, self._events = self._events, []
                live, self._live = self._live, []
            if live:
                self._outbox.setdefault("live", []).extend(live)
            if events:
                self._outbox.setdefault("events", []).append(event_columns(events))
            if self._outbox:
                self.store.append_many({b: _concat(c) for b, c in self._outbox.items()})
                self._outbox = {}          # kept for the next flush if the append failed
            self.store.commit()
            self.commit_wall_times.append(time.monotonic())
            self.flush_durations.append(time.monotonic() - w0)
            self.writer_error = None                       # recording is healthy again
            with self._committed:
                self._committed_clock = c0                 # every sample received before c0 is in
                self._committed.notify_all()

    def _convert(self, name: str, samples: list) -> None:
        """Columns of every stream of source ``name`` (as its declaration says), stamped with
        the source's clock model (fitted on its own stream's device and host times)."""
        own, *derived = self.streams[name]
        model = self.models[name]
        for stream in (own, *derived):
            cols = stream.to_columns(samples, self._last_device.get(stream.name, (None,))[0])
            if stream is own:
                model.update(cols[own.device_time.name], cols[own.host_time])
                own_cols = cols
            self._stamp(cols, stream, model)
            self._outbox.setdefault(stream.name, []).append(cols)
        if name == "biotac":
            self._check_frames(own_cols)

    def _stamp(self, cols: dict, stream, model: OnlineClockModel) -> None:
        """Times since run start of a batch, from the current clock model, never before the
        batch before (the model is refitted as the run goes: a new fit must not move time
        back across a flush; the final refit at :meth:`stop` rewrites all times on one fit)."""
        d = cols[stream.device_time.name]
        t = model.map(d) - self.t0
        last = self._last_device.get(stream.name)
        if last is not None and len(d):
            t = np.maximum(t, last[1] + (d - last[0]))             # continue from the last sample
        if len(d):
            self._last_device[stream.name] = (float(d[-1]), float(t[-1]))
        cols[stream.time] = t
        cols[stream.host_time] = cols[stream.host_time] - self.t0

    def _check_frames(self, cols: dict) -> None:
        """Count and record sequence gaps and invalid frames as events."""
        st = self._stats["biotac"]
        events = []
        for i, before, missing in sequence_gaps(cols["seq"], self._last_seq):
            detail = {"after_seq": before, "next_seq": int(cols["seq"][i]), "missing": missing}
            prev_t = cols["time"][i - 1] if i > 0 else self._last_frame_time
            if prev_t is not None:
                detail["gap_s"] = float(cols["time"][i] - prev_t)
            events.append((float(cols["time"][i]), "gap", "biotac", detail))
            if missing > 0:
                st.gaps += 1
                st.missing += missing
        self._last_seq = int(cols["seq"][-1])
        self._last_frame_time = float(cols["time"][-1])
        bad = np.flatnonzero(~cols["valid"])
        for i in bad:
            events.append((float(cols["time"][i]), "invalid", "biotac", {"seq": int(cols["seq"][i])}))
        with self._lock:
            st.invalid += len(bad)
            self._events.extend(events)

    # ------------------------------------------------------------------ close
    def _refit(self) -> None:
        """Final clock-model fit on the whole run; rewrite every time coordinate with it."""
        for name, model in self.models.items():
            fit = model.final()
            if fit is None:
                continue
            for s in self.streams[name]:
                self.store.transform(s.name, s.time, s.device_time.name, lambda d, fit=fit: fit(d) - self.t0)
        self.store.commit()

    def _summary(self) -> dict:
        """Per-stream clock model and counters for the store attributes (JSON values)."""
        out = {}
        for name, st in self.stats().items():
            entry = {k: st[k] for k in ("samples", "gaps", "missing", "invalid", "faults")}
            fit = self.models[name].current()
            if fit is not None:
                own = self.streams[name][0]
                step = max(1, self.store.length(own.name) // 100_000)      # bounded memory
                d = self.store.read(own.name, own.device_time.name, step)
                h = self.store.read(own.name, own.host_time, step) + self.t0
                entry["clock_model"] = {"offset_s": fit.offset_s, "drift_ppm": fit.drift * 1e6,
                                        "windows": fit.n_windows, "windows_used": fit.n_used,
                                        "min_latency_s": self.models[name].min_latency_s,
                                        "residual_latency": latency_stats(fit, d, h)}
            out[name] = entry
            group = self.streams[name][0].group
            shared = sum(s.group == group for s in self.store.streams.values()) > 1     # pour: pump and scale
            self.store.set_group_attrs(group, **{f"{name}_stream": entry} if shared else {"stream": entry})
        return out


def _concat(cols: list[dict]) -> dict[str, np.ndarray]:
    if len(cols) == 1:
        return cols[0]
    return {k: np.concatenate([c[k] for c in cols]) for k in cols[0]}



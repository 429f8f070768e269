"""The run engine: executes a checked plan against the hardware interfaces.

Lifecycle (as Bluesky's RunEngine): ``running`` → one of

- ``success``: every step ended;
- ``aborted``: the operator stopped the run (Ctrl-C or SIGTERM once: the current motion is
  stopped, the finger retracted, the store closed; Ctrl-C twice: stop at once, no retract;
  a signal before the first step: the run stops there); the signals are owned by the run's
  :class:`~protocols.interrupts.Interrupts` from its start to the last byte written;
- ``failed``: a step raised (device fault, protective stop, criterion never met...): motion
  stopped, the pump stopped, a retract if the arm is free to move, the error recorded.

Every step is framed by ``step_start``/``step_end`` events in the run store. The engine
runs on the thread that built the lab: in simulation that thread drives simulated time.
Steps poll once per BioTac period, watching the stop request and their criteria; with the
live monitor (:mod:`protocols.live`) each poll also processes the frames received since the
last one, so ``on_slip`` reactions are issued in the period after the frame that fired.
"""

from __future__ import annotations

from contextlib import nullcontext
from dataclasses import dataclass

import numpy as np

from tactile_flow.hardware.errors import DeviceError, ProtectiveStopError
from tactile_flow.runstore.status import RunStatus
from tactile_flow.tactile.slip import CAUSES
from .interlocks import InterlockTripped, Interlocks, LinkLost
from .interrupts import Interrupts
from .plan import Geometry, Limits, Plan, PlannedStep
from .settings import RunSettings, run_settings
from .steps import Criterion

SUCCESS, ABORTED, FAILED = RunStatus.SUCCESS, RunStatus.ABORTED, RunStatus.FAILED
RETRACT_MM = 20.0
RETRACT_SPEED = 0.02        # m/s
SETTLE_S = 5.0              # s, the most a stop may take before we call it a fault
TARE_S = 0.5


class RunAborted(Exception):
    """The operator asked the run to stop."""


@dataclass
class Outcome:
    status: str
    error: str | None = None
    steps_done: int = 0


class RunContext(Geometry):
    """What a step's ``run`` sees: the lab, the recorder, parameters and helpers."""

    def __init__(self, lab, recorder, settings: RunSettings, progress=None, live=None,
                 interrupts: Interrupts | None = None):
        super().__init__(settings.hardware, lab.surface, settings.protocol.finger, lab.biotac.sensor_model)
        self.live = live                          # a protocols.live.LiveMonitor, or None
        self.hand_targets: dict[str, float] = {}  # joint angles commanded so far (rad)
        self.hand_until = -np.inf                 # clock time the commanded hand motion ends
        self.lab, self.recorder, self.params = lab, recorder, settings.protocol
        self.limits = Limits.from_hardware(settings.hardware)
        self.clock = lab.clock
        self.poll = 1.0 / lab.biotac.rate_hz
        self.stop_requested = False
        self.interrupts = interrupts or Interrupts()
        self.progress = progress
        self.fingers = list(lab.biotac.fingers)
        self.finger_index = self.fingers.index(settings.protocol.finger)
        self.tare_pdc = np.zeros(len(self.fingers))
        self.interlocks = Interlocks(settings.safety, self.limits, self.fingers, lab.biotac.rate_hz, self.clock)

    @property
    def pose(self) -> np.ndarray:
        return np.asarray(self.lab.arm.tcp_pose(), float)

    def event(self, kind: str, name: str, detail=None) -> None:
        self.recorder.event(kind, name, detail)
        if self.live is not None:                 # the live viewer shows the steps and reactions
            self.live.event(kind, name, detail)

    def _tick(self) -> None:
        """Advance one poll period; raise :class:`RunAborted` on a stop request and
        :class:`~protocols.interlocks.InterlockTripped` when a safety limit is breached."""
        t0 = self.clock.now()
        if self.live is not None and self.live.wakes:   # wall clock: poll the moment a frame is in
            self.live.wait_frame(self.poll)
        else:
            self.clock.sleep(self.poll)
        self.interrupts.raise_deferred()          # a second Ctrl-C that a finaliser dropped
        self.recorder.keep_up()                   # a simulated clock waits for the store to keep up
        if self.progress:
            self.progress(self.clock.now() - t0)
        if self.stop_requested:
            raise RunAborted("stopped by the operator")
        if self.lab.arm.is_protective_stopped():
            raise ProtectiveStopError("arm: protective stop")
        self.interlocks.check(self.lab, self.recorder)
        if self.live is not None:
            hand_still = self.clock.now() >= self.hand_until
            self.live.poll(still=hand_still and not self.lab.arm.is_moving(), hand_still=hand_still)

    def hand_move(self, targets: dict[str, float], duration: float) -> None:
        """Command hand joints (rad) over ``duration`` s without waiting; remembered as the
        commanded angles (what ``tighten`` adds to) and as motion (no creep-slip meanwhile)."""
        self.lab.hand.move_to(targets, duration, wait=False)
        self.hand_targets.update(targets)
        self.hand_until = self.clock.now() + duration

    def slip_detected(self) -> bool:
        return self.live is not None and self.live.detector.state.detected

    def react(self, reactions) -> None:
        """Run the ``on_slip`` reactions now, recording the detection and each reaction."""
        t_frame, k, cause = self.live.detector.state.first
        finger = self.live.fingers[k]
        self.event("slip", finger, {"cause": CAUSES[cause], "frame_time": round(t_frame, 4)})
        for r in reactions:
            r.react(self)
            self.event("reaction", r.kind, {"key": r.key, "params": r.describe(), "finger": finger,
                                            "after_frame_s": round(self.recorder.now() - t_frame, 4)})

    def tare(self, seconds: float = TARE_S) -> None:
        """Average PDC at rest, the zero of the contact criteria (and of the analysis)."""
        t0 = self.clock.now()
        samples = []
        while self.clock.now() - t0 < seconds:
            self._tick()
            frame = self.lab.biotac.latest()
            if frame is not None and frame.is_valid():
                samples.append(frame.pdc.astype(float))
        if not samples:
            raise DeviceError("biotac: no valid frame during the tare; is the sensor streaming?")
        self.tare_pdc = self.interlocks.tare_pdc = np.mean(samples, axis=0)
        self.event("tare", "tare", {"start": t0 - self.recorder.t0, "end": self.clock.now() - self.recorder.t0,
                                    "pdc": dict(zip(self.fingers, np.round(self.tare_pdc, 1).tolist()))})

    def pdc_rise(self) -> np.ndarray | None:
        """(F,) PDC above the tare, counts, from the newest valid frame; ``None`` without one."""
        frame = self.lab.biotac.latest()
        if frame is None or not frame.is_valid():
            return None
        return frame.pdc.astype(float) - self.tare_pdc

    def criterion_met(self, crit: Criterion | None, touched: set | None = None) -> bool:
        """Whether ``crit`` holds now; ``contact_lost`` needs the fingers that were ``touched``."""
        if crit is None:
            return False
        if crit.slip and self.slip_detected():
            return True
        rise = self.pdc_rise()
        if rise is not None:
            if crit.pdc_rise is not None and rise[self.finger_index] > crit.pdc_rise:
                return True
            if crit.contact_lost is not None and touched and all(rise[i] < crit.contact_lost for i in touched):
                return True
        return crit.force is not None and float(np.linalg.norm(self.lab.arm.tcp_wrench()[:3])) > crit.force

    def move(self, target, speed_mm_s: float, until: Criterion | None = None) -> bool:
        """Straight move to ``target``; with ``until``, stop as soon as it holds. Returns
        whether the criterion ended the move."""
        self.limits_check(target)
        self.lab.arm.move_linear(np.asarray(target, float), speed_mm_s * 1e-3, self.params.accel * 1e-3,
                                 asynchronous=True)
        while self.lab.arm.is_moving():
            self._tick()
            if self.criterion_met(until):
                self.lab.arm.stop(self.limits.max_accel)
                self.event("criterion", "move", {"until": until.describe(), "pose": self.pose.round(5).tolist()})
                while self.lab.arm.is_moving():
                    self._tick()
                return True
        return False

    def wait(self, seconds: float, until: Criterion | None = None, on_slip=None) -> bool:
        """Keep still for ``seconds``, or until ``until`` holds (returns True then); run the
        ``on_slip`` reactions the moment the slip detector fires (once)."""
        end = self.clock.now() + seconds
        touched: set[int] = set()
        reacting = bool(on_slip) or (until is not None and bool(until.slip))
        if reacting:
            if self.live is None:
                raise RuntimeError("a step reacts to slip but the live monitor is off (live.enabled)")
            self.live.detector.rearm()            # only slips from now on count
        while self.clock.now() < end - 1e-9:
            self._tick()
            if on_slip and self.slip_detected():
                self.react(on_slip)
                on_slip = None
            if until is not None and until.contact_lost is not None:
                rise = self.pdc_rise()
                if rise is not None:
                    touched |= set(np.flatnonzero(rise > until.contact_lost).tolist())
            if self.criterion_met(until, touched):
                return True
        return False

    def limits_check(self, target) -> None:
        self.lab.arm.check_pose(np.asarray(target, float))

    def tcp_force(self) -> float:
        """Magnitude of the force on the tool now (N)."""
        return float(np.linalg.norm(np.asarray(self.lab.arm.tcp_wrench(), float)[:3]))

    def stage_move(self, start) -> None:
        """Call ``start()`` (an asynchronous object stage command) and tick until the stage is still."""
        start()
        while self.lab.stage.is_moving():
            self._tick()


class _Unrecorded:
    """Where the engine's events go before the recording starts (the setup of a run that starts
    in contact): kept, then summarised in one ``setup`` event at the recording's start."""

    def __init__(self, clock):
        self.clock, self.events, self.t0 = clock, [], clock.now()

    def event(self, kind: str, name: str, detail=None) -> None:
        self.events.append((round(self.clock.now(), 4), kind, name, detail))

    def write_failure(self, max_age_s: float = 2.0) -> None:
        return None

    def keep_up(self) -> None:
        return None


class RunEngine:
    """Runs a :class:`~protocols.plan.Plan` on a connected lab, recording as it goes.

    ``cfg``: the run's :class:`~protocols.settings.RunSettings` (a composed config is checked
    first). ``interrupts``: the run's :class:`~protocols.interrupts.Interrupts` (installed by
    the caller); without one the engine installs its own for the duration of :meth:`run`."""

    def __init__(self, lab, recorder, cfg, plan: Plan, progress_factory=None, log=print, live=None,
                 interrupts: Interrupts | None = None):
        cfg = run_settings(cfg)
        self.lab, self.recorder, self.settings, self.plan = lab, recorder, cfg, plan
        self.progress_factory = progress_factory
        self.log = log
        self._own_interrupts = interrupts is None
        self.interrupts = interrupts or Interrupts(log)
        self.ctx = RunContext(lab, recorder, cfg, live=live, interrupts=self.interrupts)
        self.done = 0                              # steps ended so far
        self._pump_failure: str | None = None      # the pump stop's last error, said once

    def run(self, start_recording=None) -> Outcome:
        """Run the plan; never raises past the safe stop (the outcome says what happened).
        The recorder is started already, or (``start_recording``, a callable) after the plan's
        setup steps, which then run unrecorded (a run that starts in contact)."""
        self.done = 0
        installed = self.interrupts.installed() if self._own_interrupts else nullcontext()
        with installed, self.interrupts.during("motion", on_stop=self._request_stop):
            if self.interrupts.count:
                self.ctx.event("abort", "operator", {"reason": "signal before the first step", "step": 0})
                self._stop_pump()
                return Outcome(ABORTED, "stopped by the operator before the first step", 0)
            try:
                return self._run_plan(start_recording)
            except KeyboardInterrupt:      # the second Ctrl-C landed while the first was being handled
                self._make_safe(retract=False, reason="second Ctrl-C")
                return Outcome(ABORTED, "stopped at once by a second Ctrl-C", self.done)

    def _run_plan(self, start_recording=None) -> Outcome:
        try:
            if start_recording is not None:
                recorder, self.ctx.recorder = self.ctx.recorder, _Unrecorded(self.ctx.clock)
                for planned in self.plan.steps[:self.plan.setup]:
                    self._run_step(planned)
                    self.done += 1
                self._start_recording(recorder, start_recording)
            if self.settings.protocol.tare:
                self.ctx.tare()
            if self.ctx.live is not None:
                self.ctx.live.begin()
            for planned in self.plan.steps[self.done:]:
                self._run_step(planned)
                self.done += 1
            return Outcome(SUCCESS, steps_done=self.done)
        except InterlockTripped as exc:
            self.ctx.event("interlock", exc.name, {**exc.detail, "step": self.done})
            self._make_safe(retract=True, reason=f"interlock {exc.name}")
            return Outcome(ABORTED, str(exc), self.done)
        except LinkLost as exc:                # a device's link is down: the safe stop at once, then fail
            self.ctx.event("interlock", "link_lost", {"device": exc.device, "error": str(exc), "step": self.done})
            self._make_safe(retract=exc.device != "arm" and self._arm_free(), reason=f"{exc.device} link lost")
            return Outcome(FAILED, f"{exc.device} link lost: {exc}", self.done)
        except RunAborted as exc:
            self.ctx.event("abort", "operator", {"reason": str(exc), "step": self.done})
            self._make_safe(retract=True, reason="operator")
            reason = "stopped at once by a second Ctrl-C" if self.interrupts.motion_signals > 1 else str(exc)
            return Outcome(ABORTED, reason, self.done)
        except KeyboardInterrupt:
            self.ctx.event("abort", "operator", {"reason": "second Ctrl-C: immediate stop", "step": self.done})
            self._make_safe(retract=False, reason="second Ctrl-C")
            return Outcome(ABORTED, "stopped at once by a second Ctrl-C", self.done)
        except Exception as exc:  # a failing step must still leave the robot safe
            message = f"{type(exc).__name__}: {exc}"
            step = self.plan.steps[self.done].name if self.done < len(self.plan.steps) else "engine"
            self.ctx.event("error", step, {"error": message, "step": self.done})
            self._make_safe(retract=self._arm_free(), reason=f"error in {step}")
            return Outcome(FAILED, message, self.done)
        finally:
            self._stop_pump()

    def _request_stop(self) -> None:
        self.ctx.stop_requested = True

    def _arm_free(self) -> bool:
        """Whether the arm can be moved away: not in a protective stop, and still answering
        (a lost link is no reason to skip the stop, but it is one not to retract)."""
        try:
            return not self.lab.arm.is_protective_stopped()
        except Exception as exc:                # noqa: BLE001 - whatever the driver raises
            self.log(f"warning: the arm does not answer ({type(exc).__name__}: {exc}); not retracting")
            return False

    def _start_recording(self, recorder, start) -> None:
        """Drop what the devices buffered during the setup, start the recorder, and record the
        setup as one ``setup`` event (its steps' events, clock times relative to the start)."""
        setup = self.ctx.recorder
        for read in recorder.sources.values():
            read()
        start()
        self.ctx.recorder = recorder
        t0 = recorder.t0
        events = [(round(t - t0, 4), kind, name, detail) for t, kind, name, detail in setup.events]
        self.ctx.event("info", "setup", {"steps": self.plan.setup, "events": events,
                                         "pose": self.ctx.pose.round(5).tolist(),
                                         "force_n": round(self.ctx.tcp_force(), 3)})

    def _run_step(self, planned: PlannedStep) -> None:
        step = planned.step
        self.ctx.event("step_start", planned.name, {"key": step.key, "params": step.describe(),
                                                    "expected_s": round(planned.duration, 3)})
        bar = self.progress_factory(planned) if self.progress_factory else None
        self.ctx.progress = bar.update if bar else None
        try:
            try:
                step.run(self.ctx)
            except ProtectiveStopError as exc:
                if self.ctx.interlocks.cfg.on_protective_stop != "recover":
                    raise
                # Every step goes to absolute targets, so running it again from where the arm
                # stopped finishes it (a sweep continues to its end point at the same height).
                self.ctx.event("protective_stop", planned.name, {"error": str(exc), "action": "recover"})
                self.lab.arm.recover()
                self.ctx.event("recovered", planned.name, {"pose": self.ctx.pose.round(5).tolist()})
                step.run(self.ctx)
        finally:
            if bar:
                bar.close()
            self.ctx.progress = None
        self.ctx.event("step_end", planned.name, {"key": step.key})

    def _make_safe(self, retract: bool, reason: str = "") -> None:
        """Stop motion and the pump; optionally back the finger away along the approach.
        Never raises: what could not be done is logged (the reason we stop comes first). A
        ``safe_stop`` event marks its start (the reaction time of an interlock is measured to it)."""
        try:
            self.ctx.event("safe_stop", reason or "stop", {"retract": bool(retract)})
        except Exception:                         # noqa: BLE001 - the recorder may be gone: stop anyway
            pass
        arm = self.lab.arm
        try:
            arm.stop(self.ctx.limits.max_accel)
        except KeyboardInterrupt:                 # the second Ctrl-C cut the command: once more, no retract
            arm.stop(self.ctx.limits.max_accel)   # (a third signal is only noted)
            retract = False
        except Exception as exc:                  # noqa: BLE001 - e.g. the link is gone
            self.log(f"warning: could not stop the arm: {exc}")
            retract = False
        self._stop_pump()
        self._stop_devices()
        if not retract:
            return
        try:
            self.ctx.stop_requested = False          # the retract itself must be allowed to run
            self._wait_still(SETTLE_S)
            target = self.ctx.pose
            target[2] += RETRACT_MM * 1e-3
            if self.ctx.limits.workspace_max[2] >= target[2]:
                arm.move_linear(target, RETRACT_SPEED, self.ctx.limits.max_accel / 2, asynchronous=True)
                self._wait_still(SETTLE_S + RETRACT_MM * 1e-3 / RETRACT_SPEED)
                self.ctx.event("retract", "retract", {"mm": RETRACT_MM})
        except KeyboardInterrupt:             # second Ctrl-C during the retract: stop where we are
            arm.stop(self.ctx.limits.max_accel)
            self.log("retract interrupted: stopped at once")
        except Exception as exc:  # never mask the reason we are stopping
            self.log(f"warning: could not retract safely: {exc}")

    def _stop_devices(self) -> None:
        """Stop every other device that moves (the object stage, the hand: held where it is,
        never opened), each on its own: a failure is logged and recorded as a ``fault`` event
        and the next device is still stopped (as Bluesky's ``_stop_movable_objects``)."""
        for name, device in self.lab.devices.items():
            stop = getattr(device, "stop", None)
            if name in ("arm", "pump") or stop is None:   # stopped first, with their own handling
                continue
            try:
                stop()
            except Exception as exc:              # noqa: BLE001 - never mask the reason we stop
                self.log(f"warning: could not stop the {name}: {type(exc).__name__}: {exc}")
                try:
                    self.ctx.event("fault", name, {"action": "stop", "error": type(exc).__name__,
                                                   "message": str(exc)})
                except Exception:                 # noqa: BLE001 - the recorder may be gone too
                    pass

    def _wait_still(self, timeout_s: float) -> None:
        """Wait (clock time) until the arm is at rest; a bounded wait, never a hang."""
        end = self.ctx.clock.now() + timeout_s
        while self.lab.arm.is_moving():
            if self.ctx.clock.now() > end:
                raise DeviceError(f"arm: still moving {timeout_s:.1f} s after the stop command")
            self.ctx.clock.sleep(self.ctx.poll)
            self.interrupts.raise_deferred()

    def _stop_pump(self) -> None:
        """Stop the pump (again at the end of every run: the stop is idempotent); a failure is
        said once, not again when the retry at the end fails the same way."""
        for _ in range(2):                        # a Ctrl-C may cut the command: once more
            try:
                self.lab.pump.stop()
                return
            except KeyboardInterrupt:
                continue
            except Exception as exc:
                if str(exc) != self._pump_failure:
                    self._pump_failure = str(exc)
                    self.log(f"warning: could not stop the pump: {exc}")
                return

"""Simulated devices: the hardware interfaces implemented on a shared :class:`SimWorld`.

Each device buffers the samples the world produces while it is connected (a ring
buffer of ``buffer_s`` seconds; ``overflows`` counts samples lost to a full buffer) and
hands them out on ``read()``/``read_states()``, with a device timestamp on its own
drifting clock and ``host_time`` = simulated receipt time (sample time + latency).
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from ..arm import Arm, ArmState, Workspace
from ..biotac import BiotacFrame, TactileSensors
from ..device import DeviceIdentity, SampleBuffer
from ..errors import (DeviceDisconnectedError, NotConnectedError, ProtectiveStopError, SafetyError)
from ..hand import JOINT_NAMES, Hand, HandState, check_joint_names
from ..pour import Pump, PumpState, Scale, ScaleReading
from . import motion
from .clock import SimClock
from .sensor import BiotacModel, SensorInputs
from .world import SimWorld

FIRMWARE = "hardware.sim 1"


class _SimDevice:
    """Connection state, fault-injected disconnects, timestamps, buffer."""

    kind = "device"
    model = "Sim"

    def __init__(self, world: SimWorld, clock: SimClock, rate_hz: float):
        self.world, self.clock, self.cfg = world, clock, world.cfg
        self.rng = world.rngs[self.kind]
        self._connected = False
        self.buffer = SampleBuffer(world.cfg.buffer_s * rate_hz)
        self._clock_offset = float(self.rng.uniform(100.0, 10000.0))
        self._clock_rate = 1.0 + float(self.rng.uniform(-1, 1)) * world.cfg.sensor.clock_drift_ppm * 1e-6
        self._last_host = -math.inf
        self._latest = None

    # -- connection ------------------------------------------------------------------
    @property
    def identity(self) -> DeviceIdentity:
        return DeviceIdentity(self.model, f"sim://{self.kind}?seed={self.cfg.seed}", FIRMWARE)

    @property
    def is_connected(self) -> bool:
        return self._connected and self.kind not in self.world.lost

    def connect(self) -> None:
        if self.kind in self.world.lost:
            raise DeviceDisconnectedError(self._lost_message())
        if not self._connected:
            self.buffer.clear()
            self._connected = True

    def close(self) -> None:
        self._connected = False

    def _lost_message(self) -> str:
        t = self.cfg.faults.disconnect.get(self.kind)
        return (f"{self.kind}: link lost at t={t} s (fault injected by "
                f"hardware.faults.disconnect.{self.kind})")

    def check_link(self) -> None:
        self._require_connected()

    def _require_connected(self) -> None:
        if self.kind in self.world.lost:
            raise DeviceDisconnectedError(self._lost_message())
        if not self._connected:
            raise NotConnectedError(f"{self.kind}: not connected (call connect() first)")

    # -- samples ---------------------------------------------------------------------
    def device_time(self, t: float) -> float:
        return self._clock_offset + t * self._clock_rate

    def host_time(self, t: float) -> float:
        """Receipt time: sample time + latency with a little jitter, never decreasing."""
        lat = self.cfg.sensor.latency_s * (1.0 + 0.2 * float(self.rng.random()))
        self._last_host = max(self._last_host, t + lat)
        return self._last_host

    def _producing(self) -> bool:
        return self._connected and self.kind not in self.world.lost

    @property
    def overflows(self) -> int:
        """Samples lost to a full buffer (a consumer that did not drain for ``buffer_s``)."""
        return self.buffer.overflows

    def _push(self, sample) -> None:
        self.buffer.put(sample)
        self._latest = sample

    def _drain(self) -> list:
        self._require_connected()
        return self.buffer.drain()


# ====================================================================== arm
class SimArm(_SimDevice, Arm):
    """UR10-like arm moving the TCP along closed-form motion profiles."""

    kind = "arm"
    model = "SimArm (UR10-like)"

    def __init__(self, world, clock):
        super().__init__(world, clock, 1.0 / world.dt)
        self.workspace = Workspace(list(self.cfg.workspace.min_m), list(self.cfg.workspace.max_m),
                                   key="hardware.workspace")
        world.add_sink(world.dt, self._sample)

    def _sample(self, t: float) -> None:
        if not self._producing():
            return
        w = self.world
        p, R, v = w.arm_now
        pose = w.arm_motion.pose_of(p, R)
        wrench = w.wrench() + self.rng.normal(0, self.cfg.arm.wrench_noise_n, 6)
        self._push(ArmState(self.host_time(t), self.device_time(t), pose, v, wrench, w.protective_stopped))

    def tcp_pose(self):
        self._require_connected()
        return self.world.arm_motion.pose(self.world.time)

    def tcp_wrench(self):
        self._require_connected()
        return self.world.wrench()

    def tcp_speed(self):
        self._require_connected()
        return np.asarray(self.world.arm_state(self.world.time)[2], float)

    def controller_time(self) -> float:
        self._require_connected()
        return self.device_time(self.world.time)

    def check_pose(self, pose) -> None:
        self.workspace.check(pose, "pose")

    def _check_motion(self, speed: float, accel: float) -> None:
        a = self.cfg.arm
        if not 0 < speed <= a.max_speed_m_s:
            raise SafetyError(f"speed {speed} m/s outside (0, hardware.arm.max_speed_m_s={a.max_speed_m_s}]")
        if not 0 < accel <= a.max_accel_m_s2:
            raise SafetyError(f"accel {accel} m/s² outside (0, hardware.arm.max_accel_m_s2={a.max_accel_m_s2}]")

    def _require_ready(self) -> None:
        self._require_connected()
        if self.world.protective_stopped:
            raise ProtectiveStopError("arm: protective stop active; call recover() first")

    def _wait(self, t_end: float) -> None:
        w = self.world
        self.clock.sleep_until(t_end, stop_when=lambda: w.protective_stopped or self.kind in w.lost)
        self._require_connected()
        if w.protective_stopped:
            raise ProtectiveStopError(f"arm: protective stop at t={w.time:.3f} s during a move")

    def move_linear(self, pose, speed: float = 0.05, accel: float = 0.5, asynchronous: bool = False) -> None:
        self._require_ready()
        pose = np.asarray(pose, float)
        self.check_pose(pose)
        self._check_motion(speed, accel)
        with self.world.lock:
            m = self.world.arm_command(lambda t, p, R, v: motion.linear(t, p, R, pose, speed, accel))
        if not asynchronous:
            self._wait(m.t_end)

    def speed_linear(self, velocity, accel: float = 0.5, duration: float = 0.0) -> None:
        self._require_ready()
        vel = np.asarray(velocity, float)
        if vel.shape != (6,) or not np.all(np.isfinite(vel)):
            raise ValueError(f"velocity: expected 6 finite numbers (m/s, rad/s), got {velocity!r}")
        if duration < 0:
            raise ValueError(f"duration: expected >= 0 s, got {duration}")
        speed = float(np.linalg.norm(vel[:3]))
        if speed > self.cfg.arm.max_speed_m_s:
            raise SafetyError(f"speed {speed:.3f} m/s above hardware.arm.max_speed_m_s={self.cfg.arm.max_speed_m_s}")
        self._check_motion(self.cfg.arm.max_speed_m_s, accel)
        with self.world.lock:
            t = self.world.time
            m = motion.velocity(t, *self.world.arm_state(t), vel, accel, duration)
            if duration > 0:
                self.check_pose(m.pose(m.t_end))
            self.world.arm_motion = m

    def stop(self, accel: float = 2.0) -> None:
        self._require_connected()
        with self.world.lock:
            self.world.arm_command(lambda t, p, R, v: motion.stopping(t, p, R, v, accel))

    def is_moving(self) -> bool:
        self._require_connected()
        return self.world.arm_motion.is_moving(self.world.time)

    def wait_until_stopped(self) -> None:
        """Block (simulated time) until the current motion ends."""
        self._require_connected()
        if self.world.arm_motion.t_end > self.world.time:
            self._wait(self.world.arm_motion.t_end)

    def is_protective_stopped(self) -> bool:
        self._require_connected()
        return self.world.protective_stopped

    def is_emergency_stopped(self) -> bool:
        self._require_connected()
        return self.world.emergency_stopped

    def recover(self) -> None:
        self._require_connected()
        w = self.world
        with w.lock:
            if w.protective_stopped:
                p, R, v = w.arm_state(w.time)
                w.arm_motion = motion.hold(w.time, p, R) if not np.any(v) else w.arm_motion
                w.protective_stopped = False

    def read_states(self) -> list[ArmState]:
        return self._drain()


# ====================================================================== hand
class SimHand(_SimDevice, Hand):
    kind = "hand"
    model = "SimHand (Shadow Dexterous Hand, right)"

    def __init__(self, world, clock):
        super().__init__(world, clock, world.cfg.hand_rate_hz)
        world.add_sink(1.0 / world.cfg.hand_rate_hz, self._sample)

    def _sample(self, t):
        if self._producing():
            w = self.world
            self._push(HandState(self.host_time(t), self.device_time(t), w.hand_positions(t), w._hand[2].copy()))

    def positions(self) -> dict[str, float]:
        self._require_connected()
        q = self.world.hand_positions(self.world.time)
        return dict(zip(JOINT_NAMES, q.tolist()))

    def move_to(self, targets: dict, duration: float, wait: bool = True) -> None:
        self._require_connected()
        check_joint_names(targets, "targets")
        if not duration >= 0:
            raise ValueError(f"duration: expected >= 0 s, got {duration}")
        with self.world.lock:
            q = self.world.hand_desired(self.world.time)
            dq = max((abs(v - q[JOINT_NAMES.index(n)]) for n, v in targets.items()), default=0.0)
            vmax = self.cfg.hand.max_velocity_rad_s
            if dq > vmax * max(duration, 1e-9):
                raise SafetyError(f"hand: moving {dq:.2f} rad in {duration} s exceeds "
                                  f"hardware.hand.max_velocity_rad_s={vmax}")
            t_end = self.world.hand_move(targets, duration)
        if wait:
            self.clock.sleep_until(t_end)
            self._require_connected()

    def read_states(self) -> list[HandState]:
        return self._drain()


# ====================================================================== biotac
class SimBiotac(_SimDevice, TactileSensors):
    kind = "biotac"
    model = "SimBiotac (BioTac SP)"

    def __init__(self, world, clock):
        super().__init__(world, clock, world.cfg.biotac_rate_hz)
        self._fingers = tuple(world.fingers)
        self.sensor = BiotacModel(self._fingers, world.cfg.sensor, self.rng, world.frame_dt)
        self._session = self.sensor.session_calibration(world.rngs["calibration"])
        self.seq = 0
        f = world.cfg.faults
        self._dropout = [tuple(w) for w in f.biotac_dropout]
        self._corrupt = sorted(f.biotac_corrupt)
        world.add_sink(world.frame_dt, self._sample)

    @property
    def fingers(self):
        return self._fingers

    @property
    def rate_hz(self) -> float:
        return self.cfg.biotac_rate_hz

    def latest(self):
        self._require_connected()
        return self._latest

    @property
    def calibration(self) -> dict:
        """Per-finger resting electrode baselines (counts) of this simulated sensor set."""
        return {f: self.sensor.baseline[i].copy() for i, f in enumerate(self._fingers)}

    @property
    def session_calibration(self) -> dict:
        """Per-finger unloaded counts as the lab's calibration measured them before the run
        (:meth:`BiotacModel.session_calibration`: a short rest, plus the drift since)."""
        return {f: self._session[i].copy() for i, f in enumerate(self._fingers)}

    def _sample(self, t):
        if not self._producing():
            return
        w = self.world
        self.seq += 1
        c = [w.contacts[f] for f in self._fingers]
        inp = SensorInputs(np.array([x.load for x in c]), np.array([x.force for x in c]),
                           np.array([w.force_rate[f] for f in self._fingers]),
                           np.array([x.friction for x in c]), np.array([x.shear_load for x in c]))
        e, pdc, tdc, tac, pac = self.sensor.frame(t, inp)
        if any(t0 <= t < t1 for t0, t1 in self._dropout):
            return
        half = w.frame_dt / 2
        if self._corrupt and any(abs(tc - t) < half for tc in self._corrupt):
            F = len(self._fingers)
            e = self.rng.integers(-32768, 32767, (F, 24))
            pdc = self.rng.integers(-32768, 32767, F)
            w.truth.fault("biotac_corrupt", t, f"seq={self.seq}")
        frame = BiotacFrame(self.seq, self.device_time(t), self.host_time(t), e.astype(np.int16),
                            pdc.astype(np.int32), tdc.astype(np.int32), tac.astype(np.int32), pac.astype(np.int16))
        self._push(frame)
        self._publish(frame)

    def read(self) -> list[BiotacFrame]:
        return self._drain()


# ====================================================================== pour
class SimPump(_SimDevice, Pump):
    kind = "pump"
    model = "SimPump (peristaltic)"

    def __init__(self, world, clock):
        super().__init__(world, clock, world.cfg.pump.rate_hz)
        world.add_sink(1.0 / world.cfg.pump.rate_hz, self._sample)

    def _state(self, t) -> PumpState:
        w = self.world
        return PumpState(self.host_time(t), self.device_time(t), w.pump_rate, w.dispensed_ml, w.pump_rate > 0)

    def _sample(self, t):
        if self._producing():
            self._push(self._state(t))

    def _check_rate(self, rate) -> float:
        mx = self.cfg.pump.max_rate_ml_min
        if not 0 <= rate <= mx:
            raise ValueError(f"pump rate {rate} ml/min outside [0, hardware.pump.max_rate_ml_min={mx}]")
        return float(rate)

    def set_rate(self, ml_per_min: float) -> None:
        self._require_connected()
        with self.world.lock:
            self.world.pump_set(self._check_rate(ml_per_min))

    def dispense(self, volume_ml: float, ml_per_min: float | None = None) -> None:
        self._require_connected()
        if not volume_ml > 0:
            raise ValueError(f"volume_ml: expected > 0, got {volume_ml}")
        rate = self._check_rate(self.cfg.pump.max_rate_ml_min if ml_per_min is None else ml_per_min)
        with self.world.lock:
            self.world.pump_set(rate, volume_ml)

    def stop(self) -> None:
        self._require_connected()
        with self.world.lock:
            self.world.pump_set(0.0)

    def status(self) -> PumpState:
        self._require_connected()
        return self._state(self.world.time)

    def read_states(self) -> list[PumpState]:
        return self._drain()


class SimScale(_SimDevice, Scale):
    """Scale under the reservoir the pump draws from: the reading falls as water is pumped."""

    kind = "scale"
    model = "SimScale"

    def __init__(self, world, clock):
        super().__init__(world, clock, world.cfg.scale.rate_hz)
        sc = world.cfg.scale
        self._tare = 0.0
        self._history = deque(maxlen=max(2, int(round(sc.settle_s * sc.rate_hz)) + 1))
        self._last = None
        world.add_sink(1.0 / sc.rate_hz, self._sample)

    def _true_mass(self) -> float:
        return self.cfg.scale.reservoir_g - self.world.dispensed_ml   # water: 1 g/ml

    def _sample(self, t):
        sc = self.cfg.scale
        m = self._true_mass()
        self._history.append(m)
        if not self._producing():
            return
        stable = abs(self._history[-1] - self._history[0]) < 2 * sc.resolution_g
        noisy = m - self._tare + self.rng.normal(0, sc.noise_g)
        reading = round(noisy / sc.resolution_g) * sc.resolution_g
        self._last = ScaleReading(self.host_time(t), self.device_time(t), reading, stable)
        self._push(self._last)

    def mass(self) -> float:
        self._require_connected()
        return self._last.mass_g if self._last else self._true_mass() - self._tare

    @property
    def stable(self) -> bool:
        self._require_connected()
        return self._last.stable if self._last else True

    def tare(self) -> None:
        self._require_connected()
        self._tare = self._true_mass()

    def read(self) -> list[ScaleReading]:
        return self._drain()

"""The simulated world: one time base, the physics, and the samples devices report.

:class:`SimWorld` owns simulated time (an integer tick count of ``step_s``), the arm's
motion profile, the hand's joint trajectory, the pump, the held bottle, the board and
the fingertip contacts, and the fault schedule. It never sleeps: :meth:`advance_to`
steps it as fast as the CPU allows (:class:`~hardware.sim.clock.SimClock` paces it for
``realtime``). Every ``step_s`` the arm is sampled; every BioTac frame (10 ms) the
contacts, the grasp and the pump are resolved and the ground truth updated; devices
registered with :meth:`add_sink` are called at their own periods to buffer samples.
"""

from __future__ import annotations

import heapq
import itertools
import math
import threading
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..biotac import FINGERS
from ..hand import JOINT_INDEX, JOINT_NAMES
from . import grasp, motion, skin
from .config import SimConfig
from .contact import Fingertip, build_fingertip, point_forces, shear_loads
from ..transforms import pose_to_matrix, rotvec_to_matrix
from .stage import StageMotion
from ..surfaces import Surface
from .truth import GroundTruth

DEVICE_STREAMS = ("arm", "hand", "biotac", "pump", "scale", "world", "stage", "calibration")


@lru_cache(maxsize=4)
def _fingertip(n_theta: int, n_phi: int, sigma: float, sensor) -> Fingertip:
    return build_fingertip(n_theta, n_phi, sigma, sensor)


@dataclass
class FingerContact:
    """One finger's contact at one frame (sensor frame unless stated).

    ``load``: (N,) normal load in each taxel's footprint, N; ``shear_load``: (N,) shear load
    N-equivalent; ``force``: normal force N; ``friction``: sliding friction N;
    ``force_world``/``point_world``: (3,) for the wrench.
    """

    load: np.ndarray
    force: float = 0.0
    friction: float = 0.0
    force_world: np.ndarray = None
    point_world: np.ndarray = None
    shear: float = 0.0        # tangential load of a held object on the pad, N
    shear_load: np.ndarray = None

    def __post_init__(self):
        if self.shear_load is None:
            self.shear_load = np.zeros_like(self.load)


class SimWorld:
    def __init__(self, cfg: SimConfig, surface: Surface | None, sensor=None):
        """``sensor``: the :class:`tactile.sensor.SensorModel` of the fingertips (default the BioTac SP)."""
        if sensor is None:
            from tactile_flow.tactile.sensor import builtin_sensor
            sensor = builtin_sensor()
        self.cfg, self.surface, self.sensor = cfg, surface, sensor
        self.dt = cfg.step_s
        self.tick = 0
        self.lock = threading.RLock()
        # threads waiting for simulated time (the recorder's pollers): a heap of (tick, n, event)
        # woken by the stepping thread once their tick is stepped, each alone, on a lock of
        # their own (not the world's); waking them all at every frame cost two to three
        # context switches per poller per frame
        self._wakeups: list[tuple[int, int, threading.Event]] = []
        self._wakeup_order = itertools.count()
        self._wakeup_lock = threading.Lock()
        seeds = np.random.SeedSequence(cfg.seed).spawn(len(DEVICE_STREAMS))
        self.rngs = {name: np.random.default_rng(s) for name, s in zip(DEVICE_STREAMS, seeds)}
        self.frame_ticks = round(1.0 / (cfg.biotac_rate_hz * self.dt))
        self.frame_dt = self.frame_ticks * self.dt
        self.fingers = tuple(cfg.fingers)
        c = cfg.contact
        self.tip = _fingertip(c.mesh_theta, c.mesh_phi, cfg.sensor.kernel_sigma_mm, sensor)
        self._pole_m = self.tip.pole * 1e-3            # (3,) the pad's lowest point, sensor frame, m
        self._reach_m = self.tip.reach_mm * 1e-3       # the surface's bounding sphere radius, m
        self.T_tcp_sensor = {f: pose_to_matrix(np.asarray(cfg.fingertips[f], float)) for f in self.fingers}
        # arm
        home = np.asarray(cfg.arm.home_pose, float)
        self.arm_motion = motion.hold(0.0, home[:3], rotvec_to_matrix(home[3:]))
        self.protective_stopped = False
        self.emergency_stopped = False
        self.arm_now = self.arm_motion.state(0.0)
        self._ws_min = np.asarray(cfg.workspace.min_m, float)
        self._ws_max = np.asarray(cfg.workspace.max_m, float)
        # hand: desired trajectory q(t) = q0 + (q1 - q0)·smoothstep((t - t0)/T)
        q = np.zeros(len(JOINT_NAMES))
        for name, v in cfg.hand.default_positions.items():
            q[JOINT_INDEX[name]] = v
        self._hand = (0.0, q.copy(), q.copy(), 0.0)
        # pour
        self.pump_rate = 0.0
        self.pump_target_ml = math.inf
        self.dispensed_ml = 0.0
        self.grasp = grasp.GraspState()
        self.carried = False
        self._patch_cache: dict = {}
        self._pad_idx = np.flatnonzero(self.tip.points[:, 2] < self.tip.pole[2] + 4.0)
        self.grip = {f: 0.0 for f in cfg.pour.grasp_fingers}
        g = np.asarray(cfg.pour.gravity_sensor, float)
        g[2] = 0.0
        self.g_sensor = g / (np.linalg.norm(g) or 1.0)
        # contacts (latest frame) and the previous forces for dF/dt
        self.contacts = {f: FingerContact(np.zeros(self.tip.n_taxels)) for f in FINGERS}
        self._prev_force = {f: 0.0 for f in FINGERS}
        self._prev_shear = {f: 0.0 for f in FINGERS}
        self.force_rate = {f: 0.0 for f in FINGERS}
        self.truth = GroundTruth(self.fingers, surface)
        # the object stage under the surface, and the skin each finger presses on it
        self.stage = StageMotion(cfg.stage, self.rngs["stage"]) if cfg.stage is not None else None
        self.skin = {f: skin.Skin() for f in FINGERS}
        # faults: (time, kind, device)
        fl = cfg.faults
        self.faults = []
        if fl.protective_stop_s is not None:
            self.faults.append((fl.protective_stop_s, "protective_stop", "arm"))
        for dev, t in fl.disconnect.items():
            self.faults.append((t, "disconnect", dev))
        self.faults.sort()
        self.lost = set()          # devices whose link is lost
        self._wrench = np.zeros(6)
        self._sinks = []           # (period ticks, callback(t))

    # ------------------------------------------------------------------ time
    @property
    def time(self) -> float:
        """Simulated time (s)."""
        return self.tick * self.dt

    def tick_at(self, t: float) -> int:
        """The first tick at or after simulated time ``t`` (s)."""
        return int(math.ceil(t / self.dt - 1e-9))     # never wake before t

    def add_sink(self, period_s: float, callback) -> None:
        """Call ``callback(t)`` every ``period_s`` (a whole number of steps) after stepping."""
        ticks = round(period_s / self.dt)
        if ticks < 1 or abs(ticks * self.dt - period_s) > 1e-9:
            raise ValueError(f"sink period {period_s} s is not a whole number of step_s ({self.dt} s)")
        self._sinks.append((ticks, callback))

    def advance_to(self, t_target: float, stop_when=None, pace=None) -> bool:
        """Step until ``t_target`` (s); False if ``stop_when()`` became true first.

        The lock is released between frames so other threads can read buffers; ``pace(t)``
        (realtime mode) is called between frames, outside the lock.
        """
        n_target = self.tick_at(t_target)
        while True:
            stopped = False
            with self.lock:
                if self.tick >= n_target:
                    return True
                stop = min(n_target, (self.tick // self.frame_ticks + 1) * self.frame_ticks)
                while self.tick < stop:
                    self.tick += 1
                    self._step(self.tick)
                    if stop_when is not None and stop_when():
                        stopped = True
                        break
            self._wake()
            if stopped:
                return False
            if pace is not None:
                pace(self.time)

    def wait_until_tick(self, tick: int | None, timeout_s: float) -> None:
        """Block a thread that does not step the world until ``tick`` has been stepped (``None``:
        until the next frame has), or for ``timeout_s`` s of wall time at most."""
        woken = threading.Event()
        with self._wakeup_lock:
            if tick is not None and self.tick >= tick:
                return
            heapq.heappush(self._wakeups, (-1 if tick is None else tick, next(self._wakeup_order), woken))
        woken.wait(timeout_s)

    def _wake(self) -> None:
        """Wake the waiters whose tick has been stepped (and those waiting for any frame)."""
        with self._wakeup_lock:
            while self._wakeups and self._wakeups[0][0] <= self.tick:
                heapq.heappop(self._wakeups)[2].set()

    def _step(self, tick: int) -> None:
        t = tick * self.dt
        while self.faults and self.faults[0][0] <= t + 1e-12:
            _, kind, dev = self.faults.pop(0)
            self._fire(kind, dev, t)
        self.arm_now = self.arm_motion.state(t)
        self._arm_safety(t)
        if tick % self.frame_ticks == 0:
            self._frame(t)
        for period, cb in self._sinks:
            if tick % period == 0:
                cb(t)

    def _fire(self, kind: str, dev: str, t: float) -> None:
        if kind == "protective_stop":
            self.protective_stop(t, "hardware.faults.protective_stop_s")
        elif kind == "disconnect":
            self.lost.add(dev)
            self.truth.fault("disconnect", t, dev)

    # ------------------------------------------------------------------ arm
    def arm_state(self, t: float):
        """TCP position (3,), rotation (3, 3), velocity (6,) at ``t``."""
        return self.arm_motion.state(t)

    def arm_command(self, make) -> motion.Motion:
        """Replace the motion with ``make(t, p, R, v)`` built from the current state."""
        t = self.time
        p, R, v = self.arm_state(t)
        self.arm_motion = make(t, p, R, v)
        return self.arm_motion

    def protective_stop(self, t: float, reason: str) -> None:
        if self.protective_stopped:
            return
        self.protective_stopped = True
        p, R, v = self.arm_state(t)
        self.arm_motion = motion.stopping(t, p, R, v, self.cfg.arm.stop_accel_m_s2)
        self.truth.fault("protective_stop", t, reason)

    def _arm_safety(self, t: float) -> None:
        if self.protective_stopped or not self.arm_motion.is_moving(t):
            return
        p = self.arm_now[0]
        if (p < self._ws_min).any() or (p > self._ws_max).any():
            self.protective_stop(t, "TCP left hardware.workspace")
            self.arm_now = self.arm_motion.state(t)

    def wrench(self) -> np.ndarray:
        """(6,) force (N) and torque (N·m) the environment exerts on the tool, base frame,
        as of the latest frame (contacts are resolved at the BioTac frame rate)."""
        return self._wrench.copy()

    def _compute_wrench(self, p) -> np.ndarray:
        w = np.zeros(6)
        for f in self.fingers:
            c = self.contacts[f]
            if c.force_world is not None:
                w[:3] += c.force_world
                w[3:] += np.cross(c.point_world - p, c.force_world)
        w[2] -= self.grasp.shear_n
        return w

    # ------------------------------------------------------------------ hand
    def hand_desired(self, t: float) -> np.ndarray:
        t0, q0, q1, T = self._hand
        s = 1.0 if T <= 0 else min(max((t - t0) / T, 0.0), 1.0)
        s = s * s * (3 - 2 * s)
        return q0 + (q1 - q0) * s

    def hand_positions(self, t: float) -> np.ndarray:
        q = self.hand_desired(t)
        if self.cfg.pour.bottle_in_hand and not self.grasp.fallen:
            q = grasp.clamp_to_contact(q, self.cfg.pour.grasp_fingers, self.cfg.pour)
        return q

    def hand_move(self, targets: dict, duration: float) -> float:
        """Start a joint trajectory; returns its end time (s)."""
        t = self.time
        q0 = self.hand_desired(t)
        q1 = q0.copy()
        for name, v in targets.items():
            q1[JOINT_INDEX[name]] = v
        self._hand = (t, q0, q1, float(duration))
        return t + float(duration)

    # ------------------------------------------------------------------ pump
    def pump_set(self, rate_ml_min: float, volume_ml: float = math.inf) -> None:
        self.pump_rate = float(rate_ml_min)
        self.pump_target_ml = self.dispensed_ml + volume_ml

    # ------------------------------------------------------------------ per frame
    def _frame(self, t: float, dt: float | None = None) -> None:
        dt = self.frame_dt if dt is None else dt
        # pump
        if self.pump_rate > 0:
            self.dispensed_ml = min(self.dispensed_ml + self.pump_rate / 60.0 * dt, self.pump_target_ml)
            if self.dispensed_ml >= self.pump_target_ml:
                self.pump_rate = 0.0
        # grasp: grip from the commanded closure, then friction and slip
        pc = self.cfg.pour
        held = pc.bottle_in_hand and not self.grasp.fallen
        self.grip = grasp.grip_forces(self.hand_desired(t), pc.grasp_fingers, pc) if held else \
            {f: 0.0 for f in pc.grasp_fingers}
        N = sum(self.grip.values())
        # the bottle stands on its support until a closing grasp has settled (the hand's
        # trajectory ended with a grip); from then on the grasp carries its weight
        if not self.carried and N > 0 and t >= self._hand[0] + self._hand[3]:
            self.carried = True
        if not self.carried:
            N = 0.0
        if pc.bottle_in_hand:
            grasp.step(self.grasp, t, dt, N, self.pump_rate if N > 0 else 0.0, pc)
            self.truth.update_pour(self.grasp.times)
        if self.stage is not None:
            self.stage.step(t, dt)
        self._fingertips(t, dt, N)
        self._wrench = self._compute_wrench(self.arm_now[0])
        total = sum(self.contacts[f].force for f in self.fingers)
        if total > self.cfg.arm.max_contact_force_n:
            self.protective_stop(t, f"contact force {total:.1f} N above hardware.arm.max_contact_force_n")

    def follow(self, t: float, dt: float, pose=None, velocity=None, hand=None, pump_ml_min: float = 0.0) -> None:
        """One frame of the world driven from outside, at time ``t`` (s) and ``dt`` (s) after
        the last: what the emulated lab's BioTacs feel (:mod:`hardware.emulators.touch`). The
        devices are other processes, so the world does not move them; it takes their state:

        - ``pose`` ``[x, y, z, rx, ry, rz]`` (m, rad) and ``velocity`` (3,) m/s: the TCP (the
          UR emulator's; ``None``: where it was);
        - ``hand``: ``(q, t_end)``: the joint angles (24,) rad the hand is commanded to now and
          the time (s) its trajectory ends (the rosbridge emulator's; ``None``: unchanged);
        - ``pump_ml_min``: the pump's flow into the held bottle (the pump emulator's).

        Then the pour, the grasp and its slip, and the fingertip contacts are resolved as
        every frame of the simulated lab (:meth:`_frame`); :attr:`contacts`, :attr:`grasp` and
        :attr:`truth` hold the result."""
        if pose is not None:
            pose = np.asarray(pose, float)
            v = np.zeros(6) if velocity is None else np.r_[np.asarray(velocity, float)[:3], 0.0, 0.0, 0.0]
            self.arm_now = (pose[:3], rotvec_to_matrix(pose[3:]), v)
        if hand is not None:
            q, t_end = hand
            self._hand = (float(t_end), np.asarray(q, float).copy(), np.asarray(q, float).copy(), 0.0)
        self.pump_rate, self.pump_target_ml = max(float(pump_ml_min), 0.0), math.inf
        self._frame(t, dt)

    def _fingertips(self, t: float, dt: float, N: float) -> None:
        p, R, v = self.arm_now
        for f in self.fingers:
            T = self.T_tcp_sensor[f]
            Rs = R @ T[:3, :3]
            ps = p + R @ T[:3, 3]
            c = self._surface_contact(t, f, ps, Rs, v[:3])
            if self.grip.get(f, 0.0) > 0 and N > 0:
                self._add_grasp_contact(c, f, self.grip[f], N)
            self.contacts[f] = c
            # PAC sees rapid pressure changes: normal edges and sudden tangential releases
            d_shear = c.shear - self._prev_shear[f]
            self.force_rate[f] = (c.force - self._prev_force[f] + min(d_shear, 0.0)) / dt
            self._prev_force[f] = c.force
            self._prev_shear[f] = c.shear

    def _surface_contact(self, t, finger, ps, Rs, v_world) -> FingerContact:
        tip, cc, sc = self.tip, self.cfg.contact, self.cfg.sensor
        pts = tip.points_m
        surf, stage = self.surface, self.stage
        lift = stage.lift if stage is not None else 0.0
        pole_w = ps + Rs @ self._pole_m
        on_object = stage.to_object if stage is not None else (lambda x, y: (x, y))
        pole_u = float(surf.to_board(*on_object(pole_w[0], pole_w[1]))[0]) if surf is not None else 0.0
        # bounding sphere of the ellipsoid first: most frames of most fingers touch nothing
        top = surf.max_z + lift if surf is not None else 0.0
        far = surf is None or (ps[2] + Rs[2] @ tip.centre * 1e-3 - self._reach_m >= top)
        z = None if far else ps[2] + pts @ Rs[2]
        if far or z.min() >= top:
            return self._no_contact(t, finger, pole_u, v_world, Rs)
        x = ps[0] + pts @ Rs[0]
        y = ps[1] + pts @ Rs[1]
        # the height map only where the skin is below the tallest feature: nowhere else can it press
        low = np.flatnonzero(z < top)
        h, idx = surf.height_and_feature(*on_object(x[low], y[low]))
        d_mm = np.zeros(len(z))                                    # (M,) indentation, mm
        d_mm[low] = np.maximum(h + lift - z[low], 0.0) * 1e3
        pressed = d_mm > 0
        if not pressed.any():
            return self._no_contact(t, finger, pole_u, v_world, Rs)
        fp = point_forces(d_mm, tip.area, cc.stiffness_n_mm2, cc.exponent)
        F = float(fp.sum())
        centre = fp @ tip.points / F
        v_s = Rs.T @ v_world
        v_t = v_s.copy()
        v_t[2] = 0.0          # tangential to the pad (contact normal ≈ sensor z)
        speed = float(np.linalg.norm(v_t))
        slide = math.tanh(speed / cc.slip_speed_m_s)
        friction = cc.friction * F * slide
        shear = np.zeros(tip.n_taxels)
        if speed > 0:
            u = v_t / speed
            shear = shear_loads(tip.taxels, centre, u, friction, sc.shear_gain, sc.shear_length_mm)
        vw_t = v_world.copy()
        vw_t[2] = 0.0
        sw = float(np.linalg.norm(vw_t))
        f_world = np.array([0.0, 0.0, F]) - (friction * vw_t / sw if sw > 0 else 0.0)
        if stage is None:
            load = tip.kernel @ fp
        else:
            load, traction, stage_shear, slid = self._skin_contact(t, finger, pressed, fp, F, centre, ps, Rs)
            shear = shear + stage_shear
            f_world = f_world + traction
            friction += cc.friction * F if slid else 0.0
        touching = set(np.unique(idx[pressed[low]]).tolist()) - {-1}
        self.truth.update_finger(t, finger, F, touching, pole_u, v_world, Rs, speed > 1e-4)
        return FingerContact(load, F, friction, f_world, ps + Rs @ (centre * 1e-3), shear_load=shear)

    def _no_contact(self, t, finger, pole_u, v_world, Rs) -> FingerContact:
        self.skin[finger].relax()
        self.truth.update_finger(t, finger, 0.0, set(), pole_u, v_world, Rs, False)
        return FingerContact(np.zeros(self.tip.n_taxels))

    def _skin_contact(self, t, finger, pressed, fp, F, centre, ps, Rs):
        """The skin on the object stage (:mod:`hardware.sim.skin`): step its stick/slip state by
        the object's motion at the contact since the last frame and return the footprint loads
        of the carried pressure (N,) N, the traction on the finger (3,) N (base frame), the
        shear loads (N,) and whether the skin broke away."""
        tip, cc, sc, sk = self.tip, self.cfg.contact, self.cfg.sensor, self.skin[finger]
        c_world = ps + Rs @ (centre * 1e-3)
        moved, turned = self.stage.moved(c_world[:2])
        move_mm = (Rs.T @ np.r_[moved, 0.0])[:2] * 1e3
        radius = math.sqrt(float(tip.area[pressed].sum()) / math.pi)
        slid = skin.step(sk, move_mm, turned * Rs[2, 2], F, radius, cc.friction_static, cc.friction,
                         cc.skin_shear_modulus_n_mm2, cc.stick_slip)
        if slid:
            self.truth.slipped(finger, t)
        points = tip.points[pressed]
        load = skin.footprint_loads(tip.taxels, skin.displaced(points, centre, sk), fp[pressed], sc.kernel_sigma_mm)
        shear = np.zeros(tip.n_taxels)
        n = float(np.hypot(*sk.stretch))
        if n > 0:
            shear = shear_loads(tip.taxels, centre, np.r_[sk.stretch / n, 0.0], sk.traction_n, sc.shear_gain,
                                sc.shear_length_mm)
        if sk.twist:
            shear = shear + skin.torsion_loads(tip.taxels, centre, points, fp[pressed],
                                               math.copysign(sk.torque_n_mm, sk.twist), sc.shear_gain,
                                               sc.shear_length_mm)
        traction = Rs @ np.r_[sk.stretch / n * sk.traction_n, 0.0] if n > 0 else np.zeros(3)
        return load, traction, shear, slid

    def stage_command(self, kind: str, amount, speed: float) -> float:
        """Start a stage motion (``translate``: (dx, dy) m; ``rotate``: rad about +z) and record it
        in the ground truth; returns its end time (s)."""
        t = self.time
        end = self.stage.command(t, kind, amount, speed)
        forces = {f: self.contacts[f].force for f in self.fingers}
        finger = max(forces, key=forces.get) if forces else ""
        Rs = self.arm_now[1] @ self.T_tcp_sensor[finger][:3, :3] if finger else np.eye(3)
        self.truth.object_motion(kind, t, end, finger, forces.get(finger, 0.0), amount, speed, Rs)
        return end

    def _grasp_patch(self, stretch_mm: float, rotation_rad: float):
        """(N,) taxel loads of a unit-force bottle patch, its centre (sensor, mm) and the bottle
        axis on the pad (3,), cached: the patch is elongated along the bottle's axis (gravity),
        shifted by the skin stretch and turned with the bottle (the skin under the contact
        sticks to it)."""
        key = (round(stretch_mm, 3), round(rotation_rad, 4))
        hit = self._patch_cache.get(key)
        if hit is not None:
            return hit
        tip, g = self.tip, self.g_sensor
        ca, sa = math.cos(rotation_rad), math.sin(rotation_rad)
        axis = np.array([ca * g[0] - sa * g[1], sa * g[0] + ca * g[1], 0.0])
        perp = np.array([-axis[1], axis[0], 0.0])
        centre = tip.pole + stretch_mm * g
        idx = self._pad_idx
        off = tip.points[idx] - centre
        a, b = off @ axis, off @ perp
        w = np.exp(-0.5 * (a * a / 6.0 ** 2 + b * b / 2.5 ** 2 + (off[:, 2] / 1.5) ** 2))
        hit = (tip.kernel[:, idx] @ (w / w.sum()), centre, axis)
        if len(self._patch_cache) > 4096:
            self._patch_cache.clear()
        self._patch_cache[key] = hit
        return hit

    def _add_grasp_contact(self, c: FingerContact, finger: str, n_f: float, N: float) -> None:
        """Add the bottle's pressure patch and its shear (share ``n_f / N``) to ``c``.

        The shear the electrodes see is the skin's stretch (released in part when the bottle
        first gives), pulling along the bottle's axis as the skin under the contact has turned
        with it; the thumb faces the fingers, so it sees the bottle's turn mirrored. The normal
        load loses ``normal_scale`` in the skin's recoil. Rapid changes of the tangential load
        (the release of stored strain) ring the PAC like normal-force edges."""
        sc, gs, pc = self.cfg.sensor, self.grasp, self.cfg.pour
        rot = -gs.rotation_rad if finger == "th" else gs.rotation_rad
        unit, centre, axis = self._grasp_patch(gs.stretch_mm, rot)
        share = n_f / N
        shear = gs.skin_shear_n(pc) * share
        n_on = n_f * gs.normal_scale
        slipping = not math.isnan(gs.times["slip_onset"])
        c.load = c.load + n_on * unit
        c.shear_load = c.shear_load + shear_loads(self.tip.taxels, centre, axis, shear, sc.shear_gain,
                                                  sc.shear_length_mm)
        c.force += n_on
        c.shear = shear
        # slip drives PAC: stick-slip of the sliding bottle excites it more than a smooth
        # sweep (×3); partial slip at the contact edges a little (×0.2)
        c.friction += gs.shear_n * share * (3.0 if gs.slide_speed_mm_s > 0 else 0.2 if slipping else 0.0)

"""A bottle held in a precision grasp while it is filled: grip, friction, slip stages.

Pure functions: :func:`grip_forces` turns the hand's commanded closure into normal
forces; :func:`step` advances the :class:`GraspState` by ``dt``. Stages, in the order a
rising weight W meets a fixed grip N (μ = static friction):

1. stick with micro-slip: shear builds, the skin stretches (``stretch_mm``);
2. partial slip (``slip_onset``): W ≥ ``partial_slip_ratio``·μN, the contact edges slip;
3. rotation (``rotation``): the gravity torque W·``com_offset_m`` exceeds the grip's
   torsional capacity μN·``torsion_arm_m``; the bottle turns (damped) up to ``max_rotation_rad``;
4. downward slide (``downward``): W > μN, the bottle creeps down (viscous, ``slide_damping``);
5. full slip (``full_slip``): the slide passes ``full_slip_mm``: the bottle leaves the grasp.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..hand import JOINT_INDEX
from .config import PourConfig

G = 9.81

FLEX_JOINTS = {"ff": ("rh_FFJ2", "rh_FFJ3"), "mf": ("rh_MFJ2", "rh_MFJ3"), "rf": ("rh_RFJ2", "rh_RFJ3"),
               "lf": ("rh_LFJ2", "rh_LFJ3"), "th": ("rh_THJ1", "rh_THJ2")}


def grip_forces(q_desired: np.ndarray, fingers, cfg: PourConfig) -> dict[str, float]:
    """Normal force (N) of each grasp finger from the commanded joint angles (24,) rad.

    The finger stops on the bottle at ``contact_flexion_rad`` (sum of its two flexion
    joints); the position controller then presses with ``grip_n_per_rad`` per rad of
    commanded closure beyond it.
    """
    out = {}
    for f in fingers:
        flex = sum(q_desired[JOINT_INDEX[j]] for j in FLEX_JOINTS[f])
        out[f] = cfg.grip_n_per_rad * max(0.0, flex - cfg.contact_flexion_rad)
    return out


def clamp_to_contact(q_desired: np.ndarray, fingers, cfg: PourConfig) -> np.ndarray:
    """Measured joint angles: the grasp fingers' flexion stops at the bottle."""
    q = q_desired.copy()
    for f in fingers:
        idx = [JOINT_INDEX[j] for j in FLEX_JOINTS[f]]
        flex = q[idx].sum()
        if flex > cfg.contact_flexion_rad > 0:
            q[idx] *= cfg.contact_flexion_rad / flex
    return q


@dataclass
class GraspState:
    """State of the held bottle. Lengths mm, angles rad, times s (NaN: not yet)."""
    water_ml: float = 0.0
    stretch_mm: float = 0.0
    rotation_rad: float = 0.0
    slide_mm: float = 0.0
    slide_speed_mm_s: float = 0.0
    shear_n: float = 0.0          # total tangential load carried by the grip
    fallen: bool = False
    times: dict = field(default_factory=lambda: {k: math.nan for k in
                                                 ("pour_start", "slip_onset", "rotation", "downward", "full_slip")})

    def weight_n(self, cfg: PourConfig) -> float:
        return (cfg.bottle_empty_g + self.water_ml) * 1e-3 * G


def step(s: GraspState, t: float, dt: float, normal_n: float, pump_ml_min: float, cfg: PourConfig) -> GraspState:
    """Advance by ``dt`` s at time ``t``: fill at ``pump_ml_min`` and resolve friction.

    ``normal_n``: total grip normal force (N). Water only lands in the bottle while it is
    held; the state is mutated and returned.
    """
    held = normal_n > 0 and not s.fallen
    if not held:
        s.shear_n = 0.0
        return s
    if pump_ml_min > 0 and math.isnan(s.times["pour_start"]):
        s.times["pour_start"] = t
    s.water_ml += pump_ml_min / 60.0 * dt
    W = s.weight_n(cfg)
    cap = cfg.friction_static * normal_n
    s.shear_n = min(W, cap)
    s.stretch_mm = min(cfg.stretch_mm_per_n * s.shear_n, cfg.max_stretch_mm)
    if W >= cfg.partial_slip_ratio * cap and math.isnan(s.times["slip_onset"]):
        s.times["slip_onset"] = t
    torque, t_cap = W * cfg.com_offset_m, cap * cfg.torsion_arm_m
    if torque > t_cap:
        if math.isnan(s.times["rotation"]):
            s.times["rotation"] = t
        s.rotation_rad = min(s.rotation_rad + (torque - t_cap) / cfg.rotation_damping_n_m_s * dt,
                             cfg.max_rotation_rad)
    if W > cap:
        if math.isnan(s.times["downward"]):
            s.times["downward"] = t
        s.slide_speed_mm_s = (W - cap) / cfg.slide_damping_n_s_m * 1e3
        s.slide_mm += s.slide_speed_mm_s * dt
    else:
        s.slide_speed_mm_s = 0.0
    if s.slide_mm >= cfg.full_slip_mm:
        s.fallen = True
        s.times["full_slip"] = t
        s.shear_n = 0.0
        s.slide_speed_mm_s = 0.0
    return s

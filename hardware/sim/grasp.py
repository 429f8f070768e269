"""A bottle held in a precision grasp while it is filled: grip, friction, slip stages.

Pure functions: :func:`grip_forces` turns the hand's commanded closure into normal
forces; :func:`step` advances the :class:`GraspState` by ``dt``. Stages, in the order a
rising weight W meets a fixed grip N (μs static friction, μk = ``kinetic_ratio``·μs):

1. stick with micro-slip: shear builds, the skin stretches (``stretch_mm``) with the load;
2. partial slip (``slip_onset``): W ≥ ``partial_slip_ratio``·μsN, the contact edges slip and
   the bottle first gives: part of the stored skin stretch is released (``slip_release``) and
   the skin's elastic recoil briefly takes load off the pads (``slip_normal_dip``), both
   recovering with ``recoil_tau_s`` (``recoil``); the sudden release rings the PAC;
3. rotation (``rotation``): the gravity torque W·``com_offset_m``·cos θ exceeds the grip's
   static torsional capacity μsN·``torsion_arm_m``; the bottle breaks away and turns (damped)
   against the kinetic capacity towards the angle where the torques balance (its centre of
   mass swings under the grasp), at most ``max_rotation_rad``. The skin under each pad
   sticks to the bottle and turns with it;
4. downward slide (``downward``): W > μsN, the contact breaks away: the pads now carry only
   the kinetic friction μkN (the skin stretch drops) and the bottle creeps down at
   (W − μkN) / ``slide_damping``;
5. full slip (``full_slip``): the slide passes ``full_slip_mm``: the bottle leaves the grasp.

The thumb opposes the fingers: with the thumb among the grasp fingers, the two sides press
the free bottle until their forces balance (two springs in series), so the thumb carries as
much normal force as the fingers together.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..hand import JOINT_INDEX
from .config import PourConfig

G = 9.81

FLEX_JOINTS = {"ff": ("rh_FFJ2", "rh_FFJ3"), "mf": ("rh_MFJ2", "rh_MFJ3"), "rf": ("rh_RFJ2", "rh_RFJ3"),
               "lf": ("rh_LFJ2", "rh_LFJ3"), "th": ("rh_THJ2", "rh_THJ5")}
# the thumb's two closing joints are those the protocols command (protocols.steps.FLEX_JOINTS)


def grip_forces(q_desired: np.ndarray, fingers, cfg: PourConfig) -> dict[str, float]:
    """Normal force (N) of each grasp finger from the commanded joint angles (24,) rad.

    The finger stops on the bottle at ``contact_flexion_rad`` (sum of its two flexion
    joints); the position controller then presses with ``grip_n_per_rad`` per rad of
    commanded closure beyond it.

    With the thumb opposing other fingers the bottle is pressed between two sides: it
    settles where they balance, so each side presses with the series combination
    S = 2·A·B/(A + B) of the fingers' (A) and the thumb's (B) commanded forces (no thumb
    closure, no squeeze); the fingers share S in proportion to their closure.
    """
    out = {}
    for f in fingers:
        flex = sum(q_desired[JOINT_INDEX[j]] for j in FLEX_JOINTS[f])
        out[f] = cfg.grip_n_per_rad * max(0.0, flex - cfg.contact_flexion_rad)
    if "th" in out and len(out) > 1:
        A = sum(v for f, v in out.items() if f != "th")
        B = out["th"]
        S = 2.0 * A * B / (A + B) if A > 0 and B > 0 else 0.0
        out = {f: (S if f == "th" else (S * v / A if A > 0 else 0.0)) for f, v in out.items()}
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
    recoil: float = 0.0           # 1 when the bottle first gives, decaying with recoil_tau_s
    normal_scale: float = 1.0     # fraction of the grip's normal load on the pads (skin recoil)
    rotating: bool = False
    sliding: bool = False
    fallen: bool = False
    times: dict = field(default_factory=lambda: {k: math.nan for k in
                                                 ("pour_start", "slip_onset", "rotation", "downward", "full_slip")})

    def weight_n(self, cfg: PourConfig) -> float:
        return (cfg.bottle_empty_g + self.water_ml) * 1e-3 * G

    def skin_shear_n(self, cfg: PourConfig) -> float:
        """The tangential load the skin's stretch corresponds to (what the electrodes see)."""
        return self.stretch_mm / cfg.stretch_mm_per_n if cfg.stretch_mm_per_n > 0 else self.shear_n


def step(s: GraspState, t: float, dt: float, normal_n: float, pump_ml_min: float, cfg: PourConfig) -> GraspState:
    """Advance by ``dt`` s at time ``t``: fill at ``pump_ml_min`` and resolve friction.

    ``normal_n``: total grip normal force (N) of all grasp fingers. Water only lands in the
    bottle while it is held; the state is mutated and returned.
    """
    held = normal_n > 0 and not s.fallen
    if not held:
        s.shear_n = 0.0
        s.stretch_mm = 0.0
        return s
    if pump_ml_min > 0 and math.isnan(s.times["pour_start"]):
        s.times["pour_start"] = t
    s.water_ml += pump_ml_min / 60.0 * dt
    W = s.weight_n(cfg)
    cap = cfg.friction_static * normal_n
    cap_k = cfg.kinetic_ratio * cap
    s.recoil *= math.exp(-dt / cfg.recoil_tau_s)
    # 2. partial slip: the contact edges give; stored strain and load are released
    if W >= cfg.partial_slip_ratio * cap and math.isnan(s.times["slip_onset"]):
        s.times["slip_onset"] = t
        s.recoil = 1.0
    # 3. rotation: torsional breakaway, then damped turning against kinetic torsion
    torque = W * cfg.com_offset_m * math.cos(s.rotation_rad)
    if not s.rotating and torque > cap * cfg.torsion_arm_m:
        s.rotating = True
        s.times["rotation"] = t
    if s.rotating:
        excess = torque - cap_k * cfg.torsion_arm_m
        if excess > 0:
            s.rotation_rad = min(s.rotation_rad + excess / cfg.rotation_damping_n_m_s * dt, cfg.max_rotation_rad)
    # 4. downward slide: linear breakaway, kinetic friction at the pads, viscous creep
    if not s.sliding and W > cap:
        s.sliding = True
        s.times["downward"] = t
    if s.sliding:
        s.shear_n = min(W, cap_k)
        s.slide_speed_mm_s = max(0.0, W - cap_k) / cfg.slide_damping_n_s_m * 1e3
        s.slide_mm += s.slide_speed_mm_s * dt
    else:
        s.shear_n = min(W, cap)
        s.slide_speed_mm_s = 0.0
    s.stretch_mm = min(cfg.stretch_mm_per_n * s.shear_n, cfg.max_stretch_mm) * (1.0 - cfg.slip_release * s.recoil)
    s.normal_scale = 1.0 - cfg.slip_normal_dip * s.recoil
    if s.slide_mm >= cfg.full_slip_mm:
        s.fallen = True
        s.times["full_slip"] = t
        s.shear_n = 0.0
        s.stretch_mm = 0.0
        s.slide_speed_mm_s = 0.0
    return s

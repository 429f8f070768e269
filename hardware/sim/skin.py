"""The skin under an object that moves against a still finger: stick, partial slip, slip, twist.

Pure functions on a small state (:class:`Skin`), sensor frame, mm and N. The mechanics are
those of a compliant elastic contact (Johnson, *Contact Mechanics*, 1985, §7.2–7.4), which
describe the fingertip's and the BioTac's silicone skin alike at the scale of a contact:

- the skin under the contact sticks to the object and moves with it (``stretch``, mm, in the
  sensor x–y plane; ``twist``, rad about the sensor's +z), loaded with Mindlin's initial
  stiffnesses of a contact of radius ``a``: tangential ``k_t = 8·G*·a`` (N/mm), torsional
  ``k_r = (16/3)·G*·a³`` (N·mm/rad);
- **partial slip** (Cattaneo–Mindlin): slip starts at the contact's edge and its stuck centre
  shrinks as the pull grows, so the traction grows ever more slowly with the stretch,
  ``Q(s) = μs·F·[1 − (1 − s/s*)^{3/2}]`` with ``s* = 3μs·F/(2k_t)`` (initial slope k_t), and
  the whole contact slips — gross slip, the ground truth's ``slip_onset`` — when the stretch
  reaches ``s*``. The same form is used for the twist, with the torque capacity of a Hertzian
  patch ``M* = (3π/16)·μs·F·a`` (Lubkin's torsion; Johnson §7.4) and ``θ* = 3M*/(2k_r)``: an
  approximation that keeps Lubkin's initial stiffness and capacity and its progressive slip
  from the edge. The finger pad behaves this way: incipient slip begins at the periphery and
  spreads inwards until the whole contact slides (Tada, Mochimaru & Kanade, EuroHaptics 2006;
  André et al., J. R. Soc. Interface 2011; Delhaye, Lefèvre & Thonnard, J. R. Soc. Interface
  11:20140698, 2014), and a tangential torque about the normal lowers the load at which it
  slips in proportion (Kinoshita et al., J. Neurophysiol. 78:1619, 1997);
- **a growing contact** (Mindlin & Deresiewicz, J. Appl. Mech. 20:327, 1953; Johnson §7.4):
  skin that comes into contact as the normal load grows joins it unstressed, so the traction
  (and the torque) the contact already carries stays what it was while its stiffness grows —
  the stretch it corresponds to shrinks by ``k_t(a_before)/k_t(a)`` (the twist by
  ``k_r(a_before)/k_r(a)``). Applied where the contact reaches a radius it never had before
  (``widest_mm``): a light press's tremor-sized stretch at touchdown (the holder's tremor,
  ``hardware.stage.tremor_mm``) is not carried, at full stiffness, into the press;
- after gross slip the traction falls to the kinetic level (``μk`` instead of ``μs``): the
  stretch relaxes to where ``Q = μk·F``; with ``stick_slip`` the skin sticks again at once
  and the next pull repeats the cycle (the stick-slip of a pulled object), else it rides at
  the kinetic level while the object keeps moving;
- what the electrodes see: the pressed skin (and its pressure) carried along by the stretch and
  turned by the twist (:func:`displaced`), plus the traction's loads: ahead of the stretched
  skin the skin bunches up and loads, behind it relaxes (:func:`hardware.sim.contact.shear_loads`;
  on the BioTac, tangential forces slide the skin over the core and change the impedance of the
  electrodes towards which it is pushed — SynTouch's force-sensing notes; Wettels et al., Adv.
  Robotics 22:829, 2008); for a twist every pressed point pushes along its own direction of
  motion, which for an elongated patch loads two opposite quadrants and unloads the other two
  (:func:`torsion_loads`): a small, antisymmetric change, the reason shear and torque are hard
  to tell apart on the BioTac (Lin et al., ICRA 2013).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

TORSION_CAPACITY = 3 * math.pi / 16      # torque capacity / (μ F a) of a Hertzian patch


@dataclass
class Skin:
    """State of the skin under one finger's contact (sensor frame)."""

    stretch: np.ndarray = field(default_factory=lambda: np.zeros(2))   # mm
    twist: float = 0.0                                                  # rad about +z
    traction_n: float = 0.0                                             # Q(|stretch|): partial-slip traction, N
    torque_n_mm: float = 0.0                                            # M(|twist|): partial-slip torque, N·mm
    slipping: bool = False                                              # slid in the last step
    twisting: bool = False                                              # turned against friction in the last step
    widest_mm: float = 0.0                                              # the contact's largest radius so far, mm

    def relax(self) -> None:
        """Out of contact: the skin springs back."""
        self.stretch = np.zeros(2)
        self.twist = self.traction_n = self.torque_n_mm = self.widest_mm = 0.0
        self.slipping = self.twisting = False


def stiffness(radius_mm: float, shear_modulus: float) -> tuple[float, float]:
    """Tangential (N/mm) and torsional (N·mm/rad) stiffness of a contact of radius ``radius_mm``."""
    a = max(radius_mm, 0.1)
    return 8.0 * shear_modulus * a, 16.0 / 3.0 * shear_modulus * a ** 3


def breakaway(capacity: float, stiffness_: float) -> float:
    """Stretch (or twist) at gross slip of a Cattaneo–Mindlin contact: ``3·capacity / (2·stiffness)``."""
    return 1.5 * capacity / stiffness_


def partial_slip_load(s: float, capacity: float, stiffness_: float) -> float:
    """Traction (or torque) of a contact stretched (twisted) by ``s`` ≥ 0 before gross slip:
    ``capacity·[1 − (1 − s/s*)^{3/2}]``, initial slope ``stiffness_``; ``capacity`` at and beyond s*."""
    x = min(abs(s) / breakaway(capacity, stiffness_), 1.0) if capacity > 0 else 1.0
    return capacity * (1.0 - (1.0 - x) ** 1.5)


def relaxed(capacity_static: float, capacity_kinetic: float, stiffness_: float) -> float:
    """The stretch (twist) at which the partial-slip traction equals ``capacity_kinetic``: where
    the skin settles after gross slip (on the loading curve of ``capacity_static``)."""
    ratio = min(max(capacity_kinetic / capacity_static, 0.0), 1.0) if capacity_static > 0 else 0.0
    return breakaway(capacity_static, stiffness_) * (1.0 - (1.0 - ratio) ** (2.0 / 3.0))


def step(skin: Skin, move_mm, turn_rad: float, force_n: float, radius_mm: float, mu_s: float, mu_k: float,
         shear_modulus: float, stick_slip: bool = True) -> bool:
    """Advance ``skin`` by the object's motion at the contact since the last step: ``move_mm``
    (2,) and ``turn_rad``. Returns whether the skin broke away (gross slip, sliding or turning)
    in this step (module docstring: partial slip up to it, the kinetic level after it)."""
    if force_n <= 0:
        skin.relax()
        return False
    kt, kr = stiffness(radius_mm, shear_modulus)
    grown(skin, radius_mm, shear_modulus)
    cap_s, cap_k = mu_s * force_n, mu_k * force_n
    move = np.asarray(move_mm, float)
    riding = not stick_slip and skin.slipping and float(np.hypot(*move)) > 0
    s = skin.stretch + move
    n = float(np.hypot(*s))
    skin.slipping = riding or n >= breakaway(cap_s, kt)
    if skin.slipping and n > 0:
        s = s / n * relaxed(cap_s, cap_k, kt)
    skin.stretch = s
    skin.traction_n = partial_slip_load(float(np.hypot(*s)), cap_s, kt)
    riding = not stick_slip and skin.twisting and turn_rad != 0
    w = skin.twist + turn_rad
    cap = TORSION_CAPACITY * force_n * radius_mm
    skin.twisting = riding or abs(w) >= breakaway(mu_s * cap, kr)
    if skin.twisting:
        w = math.copysign(relaxed(mu_s * cap, mu_k * cap, kr), w)
    skin.twist = w
    skin.torque_n_mm = partial_slip_load(w, mu_s * cap, kr)
    return skin.slipping or skin.twisting


def grown(skin: Skin, radius_mm: float, shear_modulus: float) -> None:
    """Where the contact reaches a radius it never had (``skin.widest_mm``), the skin that joins
    it is unstressed: the traction and the torque the contact carries are kept, so the stretch
    shrinks by ``k_t(before)/k_t(now)`` and the twist by ``k_r(before)/k_r(now)`` (in place;
    module docstring; exact at the initial stiffness, the traction of a stretch already part of the
    way to gross slip grows a little). A first contact (no radius yet) only records its radius."""
    if radius_mm <= skin.widest_mm:
        return
    if skin.widest_mm > 0:
        kt0, kr0 = stiffness(skin.widest_mm, shear_modulus)
        kt, kr = stiffness(radius_mm, shear_modulus)
        skin.stretch = skin.stretch * (kt0 / kt)
        skin.twist *= kr0 / kr
    skin.widest_mm = float(radius_mm)


def displaced(points, centre, skin: Skin) -> np.ndarray:
    """(n, 3) ``points`` (mm) of the pressed skin carried by the stretch and turned by the twist
    about ``centre`` (3,) in the sensor's x–y plane."""
    p = np.asarray(points, float).copy()
    c, s = math.cos(skin.twist), math.sin(skin.twist)
    dx, dy = p[:, 0] - centre[0], p[:, 1] - centre[1]
    p[:, 0] = centre[0] + c * dx - s * dy + skin.stretch[0]
    p[:, 1] = centre[1] + s * dx + c * dy + skin.stretch[1]
    return p


def footprint_loads(taxels, points, forces, sigma_mm: float) -> np.ndarray:
    """(24,) normal load (N) each taxel feels of the point ``forces`` (n,) at ``points`` (n, 3):
    the Gaussian footprint of :func:`hardware.sim.contact.build_fingertip`."""
    d2 = ((np.asarray(taxels)[:, None, :] - np.asarray(points)[None, :, :]) ** 2).sum(-1)
    return np.exp(-d2 / (2 * sigma_mm ** 2)) @ np.asarray(forces, float)


def torsion_loads(taxels, centre, points, forces, torque_n_mm: float, gain: float, length_mm: float,
                  unload_ratio: float = 0.3) -> np.ndarray:
    """(24,) taxel load (N-equivalent) of a torsional traction ``torque_n_mm`` (signed, about +z).

    Each pressed point carries a share of the torque as a tangential traction along its own
    direction of motion about ``centre``, ``t_q ∝ f_q·ẑ×(q − c)``; as for a translation
    (:func:`hardware.sim.contact.shear_loads`) the skin ahead of the point along ``t_q`` loads
    and behind it unloads (by ``unload_ratio``), fading over ``length_mm``.
    """
    q = np.asarray(points, float) - np.asarray(centre, float)
    f = np.asarray(forces, float)
    moment = float((f * (q[:, 0] ** 2 + q[:, 1] ** 2)).sum())
    if moment <= 0 or torque_n_mm == 0:
        return np.zeros(len(taxels))
    t = torque_n_mm / moment * f[:, None] * np.stack([-q[:, 1], q[:, 0]], -1)        # (n, 2) N
    off = np.asarray(taxels)[:, None, :2] - np.asarray(points)[None, :, :2]             # (24, n, 2)
    fade = np.exp(-(off ** 2).sum(-1) / (2 * length_mm ** 2))
    s = gain * ((off * t[None]).sum(-1) / length_mm * fade).sum(1)
    return np.where(s < 0, unload_ratio * s, s)

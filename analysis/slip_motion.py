"""How the contact pattern moved since the record's own first settled frames: pure functions.

A record that begins in contact has no tare, so its pattern's offset from the unloaded sensor
says *where* the touch sits, not whether anything moved: a still touch off the pad's middle
has the same offset as a slip. Motion is measured against the contact's own *reference
window*: its first ``reference_frames`` settled (and loaded) frames. Every quantity here is in
the sensor's x–y plane (mm) or about the pad normal (deg, + = counter-clockwise seen from
outside the pad, i.e. about the sensor's −z, as ``rotation_deg``), from the smoothed
activation ``A`` (T, n) kΩ of one finger and its taxel positions (n, 3) mm — n is whatever the
sensor model has, nothing assumes 24.

- the pattern ``p(t) = max(A, 0) / Σ max(A, 0)`` (its shape: a firmer press of the same shape
  is the same pattern), its centre of pressure ``c(t) = Σ p x`` and central second moments
  ``I(t) = Σ p (x − c)(x − c)ᵀ``;
- ``displacement (t) = c(t) − c̄_ref``: how far the pattern moved;
- ``turn (t)``: the rotation that carries the reference's second moments to the frame's, by
  least squares: a turn θ (about +z) changes a moment tensor by θ·K, ``K = J I − I J``, so
  ``θ = ⟨ΔI, K⟩ / ⟨K, K⟩`` (the antisymmetric part of the electrode change about the
  contact: a twisted skin loads two opposite quadrants of an elongated contact and unloads the
  others). It needs an elongated pattern: its ``weight`` is the elongation
  ``|K| / trace I`` of the reference (0 for a round one);
- ``change (t)``: the shape change, ``½ Σ |p(t) − p̄_ref|`` (0: the same shape, 1: nothing
  in common), with ``change_noise``, the same statistic between the halves of the reference
  window (what noise alone gives).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class PatternMotion:
    """The pattern's motion over frames [start, stop) of a contact (module docstring).

    Attributes:
        start: absolute frame of the first frame here (the reference window's first).
        reference_frames: frames in the reference window (the first ones here).
        displacement: (N, 2) centre of pressure − its reference mean, mm.
        turn_deg: (N,) rotation of the pattern's second moments since the reference, deg
            (+ = counter-clockwise seen from outside the pad).
        change: (N,) shape change since the reference, 0..1.
        load: (N,) total positive activation, kΩ.
        cop_noise_mm: frame-to-frame jitter of the centre of pressure at rest in the
            reference window (robust std of its differences / √2), mm.
        change_noise: shape change between the reference window's halves, 0..1.
        radius_mm: RMS radius of the reference pattern about its centre, mm.
        elongation: |K| / trace I of the reference pattern (0: round; the turn's weight).
    """

    start: int
    reference_frames: int
    displacement: np.ndarray
    turn_deg: np.ndarray
    change: np.ndarray
    load: np.ndarray
    cop_noise_mm: float
    change_noise: float
    radius_mm: float
    elongation: float


def pattern(activation) -> tuple[np.ndarray, np.ndarray]:
    """``(p, load)``: the normalised positive pattern (T, n) (NaN rows where nothing is pressed)
    and the total positive activation (T,) kΩ."""
    w = np.clip(np.asarray(activation, float), 0.0, None)
    load = w.sum(axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        p = np.where(load[..., None] > 0, w / load[..., None], np.nan)
    return p, load


def moments(p, xy) -> tuple[np.ndarray, np.ndarray]:
    """Centre (T, 2) mm and central second moments (T, 2, 2) mm² of patterns ``p`` (T, n) over
    taxel positions ``xy`` (n, 2)."""
    c = p @ xy
    d = xy[None, :, :] - c[:, None, :]
    return c, np.einsum("tn,tni,tnj->tij", p, d, d)


def _commutator(m) -> np.ndarray:
    """``K = J I − I J`` (…, 2, 2) for a rotation generator J = [[0, −1], [1, 0]]."""
    a, b, c = m[..., 0, 0], m[..., 0, 1], m[..., 1, 1]
    return np.stack([np.stack([-2 * b, a - c], -1), np.stack([a - c, 2 * b], -1)], -2)


def turn_deg(m, m_ref) -> tuple[np.ndarray, float]:
    """Rotation (deg, + = about the sensor's −z) carrying ``m_ref`` (2, 2) to each of ``m`` (T, 2, 2)
    by least squares, and the reference's elongation |K| / trace (0..1: the reading's weight)."""
    k = _commutator(m_ref)
    kk = float((k * k).sum())
    trace = float(np.trace(m_ref))
    if kk <= 0 or trace <= 0:
        return np.zeros(len(m)), 0.0
    theta = ((m - m_ref) * k).sum(axis=(-2, -1)) / kk          # about +z, rad
    return -np.degrees(theta), float(np.sqrt(kk / 2.0) / trace)


def pattern_motion(activation, taxels, start: int, stop: int, reference_frames: int) -> PatternMotion | None:
    """The motion of frames [start, stop) of ``activation`` (T, n) kΩ against its first
    ``reference_frames`` (module docstring); ``None`` if fewer than two reference frames are
    pressed or nothing is left after them."""
    xy = np.asarray(taxels, float)[:, :2]
    p, load = pattern(np.asarray(activation[start:stop], float))
    n_ref = int(min(reference_frames, len(p)))
    ok = np.all(np.isfinite(p), axis=1)
    if n_ref < 2 or ok[:n_ref].sum() < 2 or len(p) <= n_ref:
        return None
    p = _fill(p, ok)
    c, m = moments(p, xy)
    ref = slice(0, n_ref)
    p_ref = p[ref].mean(axis=0)
    c_ref = c[ref].mean(axis=0)
    _, m_ref = moments(p_ref[None], xy)
    turn, elongation = turn_deg(m, m_ref[0])
    jitter = np.diff(c[ref], axis=0)
    cop_noise = float(1.4826 * np.median(np.hypot(*(jitter - np.median(jitter, axis=0)).T)) / np.sqrt(2)) \
        if len(jitter) > 1 else 0.0
    half = n_ref // 2
    change_noise = float(0.5 * np.abs(p[:half].mean(axis=0) - p[half:n_ref].mean(axis=0)).sum()) if half else 0.0
    return PatternMotion(start=start, reference_frames=n_ref, displacement=c - c_ref, turn_deg=turn,
                         change=0.5 * np.abs(p - p_ref).sum(axis=1), load=load,
                         cop_noise_mm=cop_noise, change_noise=change_noise,
                         radius_mm=float(np.sqrt(max(np.trace(m_ref[0]), 0.0))), elongation=elongation)


def _fill(p, ok) -> np.ndarray:
    """Rows of ``p`` with nothing pressed take the last pressed row before them (or the first after)."""
    if ok.all():
        return p
    idx = np.where(ok, np.arange(len(p)), -1)
    idx = np.maximum.accumulate(idx)
    first = int(np.argmax(ok))
    idx[idx < 0] = first
    return p[idx]

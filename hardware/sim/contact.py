"""Fingertip contact and BioTac response: pure functions on arrays.

The fingertip is the ellipsoid fitted to the 24 taxel positions (``tactile.geometry``),
sampled on its contact half (θ ∈ [π/2, π]). Each sample point carries an area (mm²).
Against a height map, every point below the surface is indented by the vertical depth d
(mm) and pushes with local pressure ``k·d^n`` (N/mm², a Winkler foundation with a
Hertz-like exponent); summed over areas that is the normal force. Taxels see the
point forces through a Gaussian kernel of the distance in the sensor frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tactile import geometry


@dataclass(frozen=True)
class Fingertip:
    """Sampled contact half of the BioTac skin, sensor frame, mm.

    Attributes:
        points: (M, 3) points on the fitted ellipsoid (centre added), mm.
        area: (M,) area represented by each point, mm².
        taxels: (24, 3) taxel positions, mm.
        kernel: (24, M) taxel sensitivity to a unit force at each point (rows sum to 1).
        pole: (3,) lowest point of the pad (θ = π), mm.
    """

    points: np.ndarray
    area: np.ndarray
    taxels: np.ndarray
    kernel: np.ndarray
    pole: np.ndarray
    centre: np.ndarray
    axes: np.ndarray

    @property
    def points_m(self) -> np.ndarray:
        """(M, 3) the sample points in metres."""
        return self._points_m

    def __post_init__(self):
        object.__setattr__(self, "_points_m", self.points * 1e-3)


def build_fingertip(n_theta: int = 28, n_phi: int = 56, sigma_mm: float = 3.0) -> Fingertip:
    """Sample the contact half of the fitted BioTac ellipsoid on a (θ, φ) grid."""
    taxels = geometry.load_taxels()
    fit = geometry.fit_ellipsoid(taxels)
    a, b, c = fit.axes
    dth, dph = (np.pi / 2) / n_theta, 2 * np.pi / n_phi
    th = np.pi / 2 + (np.arange(n_theta) + 0.5) * dth
    ph = (np.arange(n_phi) + 0.5) * dph
    T, P = [g.ravel() for g in np.meshgrid(th, ph, indexing="ij")]
    pts = geometry.ellipsoid_points(fit.axes, T, P)
    # |∂r/∂θ × ∂r/∂φ| dθ dφ: the area element of the parametrisation
    d_th = np.stack([a * np.cos(T) * np.cos(P), b * np.cos(T) * np.sin(P), -c * np.sin(T)], -1)
    d_ph = np.stack([-a * np.sin(T) * np.sin(P), b * np.sin(T) * np.cos(P), np.zeros_like(T)], -1)
    area = np.linalg.norm(np.cross(d_th, d_ph), axis=-1) * dth * dph
    points = pts + fit.centre
    d2 = ((taxels[:, None, :] - points[None, :, :]) ** 2).sum(-1)
    kern = np.exp(-d2 / (2 * sigma_mm ** 2))
    kern /= kern.sum(1, keepdims=True)
    pole = fit.centre + np.array([0.0, 0.0, -c])
    return Fingertip(points, area, taxels, kern, pole, fit.centre, fit.axes)


def indentation(points_z, surface_z) -> np.ndarray:
    """Vertical indentation (same unit as the inputs) of points below the surface, ≥ 0."""
    return np.maximum(np.asarray(surface_z) - np.asarray(points_z), 0.0)


def point_forces(indent_mm, area_mm2, stiffness: float, exponent: float) -> np.ndarray:
    """Normal force (N) at each point: ``stiffness · d^exponent · area``."""
    return stiffness * np.power(indent_mm, exponent) * area_mm2


def shear_loads(taxels, centre, direction, shear_n: float, gain: float, length_mm: float,
                unload_ratio: float = 0.3) -> np.ndarray:
    """(24,) taxel load (N-equivalent) from a tangential traction ``shear_n`` along ``direction``.

    The skin is pushed towards the side the traction points to: taxels on the leading
    side (positive offset along ``direction`` from the contact ``centre``) load, those on
    the trailing side unload (by ``unload_ratio`` as much: the skin can relax only as far
    as its rest), fading with distance (``length_mm``).
    """
    off = taxels - centre
    along = off @ direction
    fade = np.exp(-(off ** 2).sum(-1) / (2 * length_mm ** 2))
    s = gain * shear_n * (along / length_mm) * fade
    return np.where(s < 0, unload_ratio * s, s)


def impedance_kohm(z0, load_n, total_n, impedance_per_n: float, far_rise_per_n: float) -> np.ndarray:
    """Electrode impedance (kΩ) under load.

    ``z0`` (..., 24) resting impedance; ``load_n`` (..., 24) taxel load (N-equivalent,
    may be negative where shear unloads); ``total_n`` (...,) total normal force. Pressed
    electrodes rise with their load; all electrodes fall a little with the total force (fluid
    displaced from the contact thickens over them, the real BioTac's far-field rise in
    counts). Floored at 5 % of rest.
    """
    far = 1.0 - far_rise_per_n * np.asarray(total_n)[..., None]
    return np.maximum(z0 * far + impedance_per_n * load_n, 0.05 * z0)


def counts_from_impedance(z_kohm) -> np.ndarray:
    """Inverse of ``tactile.signals.counts_to_impedance``: ``E = 4095 / (1 + Z/10kΩ)`` (float)."""
    return 4095.0 / (1.0 + np.asarray(z_kohm) / 10.0)


def impedance_from_counts(counts) -> np.ndarray:
    return (4095.0 / np.asarray(counts, float) - 1.0) * 10.0


def pdc_rise(total_n, counts_per_n: float, saturation_n: float) -> np.ndarray:
    """PDC increase (counts) with total normal force: linear, saturating smoothly."""
    f = np.asarray(total_n, float)
    return counts_per_n * saturation_n * np.tanh(f / saturation_n)


def quantise(x, lo: int = 0, hi: int = 4095) -> np.ndarray:
    """Round to integer counts and clip to the ADC range."""
    return np.clip(np.rint(x), lo, hi)

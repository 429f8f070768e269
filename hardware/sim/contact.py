"""Fingertip contact and BioTac response: pure functions on arrays.

The fingertip is the surface of the sensor model (:mod:`tactile.sensor`): for the BioTacs the
ellipsoid fitted to their taxels, sampled on its contact half (θ ∈ [π/2, π]); for a flat pad
its rectangle, on a grid. Each sample point carries an area (mm²).
Against a height map, every point below the surface is indented by the vertical depth d
(mm) and pushes with local pressure ``k·d^n`` (N/mm², a Winkler foundation with a
Hertz-like exponent); summed over areas that is the normal force. Each taxel feels the
point forces within its footprint: a Gaussian of the distance in the sensor frame, weight
1 at the taxel (so a taxel's load, N, does not depend on how finely the skin is sampled).
The footprint width and the electrode's response to its load are calibrated on real contact
frames (:mod:`hardware.sim.calibrate_contact`, ``docs/simulator.md``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tactile_flow.tactile import geometry


@dataclass(frozen=True)
class Fingertip:
    """Sampled contact side of the sensor's skin, sensor frame, mm.

    Attributes:
        points: (M, 3) points on the surface (centre added), mm.
        area: (M,) area represented by each point, mm².
        taxels: (N, 3) taxel positions, mm.
        kernel: (N, M) taxel footprint: the share of a force at each point the taxel feels
            (Gaussian of the distance, 1 at the taxel).
        pole: (3,) lowest point of the pad (θ = π; a flat pad's centre), mm.
        centre: (3,) the surface's centre, mm; ``reach_mm``: radius about it holding the surface.
    """

    points: np.ndarray
    area: np.ndarray
    taxels: np.ndarray
    kernel: np.ndarray
    pole: np.ndarray
    centre: np.ndarray
    axes: np.ndarray
    reach_mm: float = 0.0

    @property
    def n_taxels(self) -> int:
        return len(self.taxels)

    @property
    def points_m(self) -> np.ndarray:
        """(M, 3) the sample points in metres."""
        return self._points_m

    def __post_init__(self):
        object.__setattr__(self, "_points_m", self.points * 1e-3)


def build_fingertip(n_theta: int = 28, n_phi: int = 56, sigma_mm: float = 3.0, sensor=None) -> Fingertip:
    """Sample the contact half of the sensor's ellipsoid on a (θ, φ) grid (a flat pad: an
    ``n_theta`` × ``n_phi`` grid over its rectangle). ``sensor``: a
    :class:`tactile.sensor.SensorModel`, default the BioTac SP."""
    if sensor is None:
        from tactile_flow.tactile.sensor import builtin_sensor
        sensor = builtin_sensor()
    taxels = np.array(sensor.taxels)
    shape = sensor.shape
    if shape.kind == "plane":
        return _flat_fingertip(taxels, shape, n_theta, n_phi, sigma_mm)
    fit = geometry.EllipsoidFit(centre=shape.centre, axes=shape.extent, rms=shape.rms_mm)
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
    pole = fit.centre + np.array([0.0, 0.0, -c])
    return Fingertip(points, area, taxels, kern, pole, fit.centre, fit.axes, shape.reach_mm)


def _flat_fingertip(taxels, shape, nx: int, ny: int, sigma_mm: float) -> Fingertip:
    """A flat pad's rectangle sampled on an ``nx`` × ``ny`` grid of equal cells."""
    (sx, sy), centre = shape.extent, shape.centre
    x = (np.arange(nx) + 0.5) / nx * sx - sx / 2
    y = (np.arange(ny) + 0.5) / ny * sy - sy / 2
    gx, gy = (g.ravel() for g in np.meshgrid(x, y, indexing="ij"))
    points = np.stack([gx, gy, np.zeros_like(gx)], -1) + centre
    area = np.full(len(points), sx * sy / (nx * ny))
    d2 = ((taxels[:, None, :] - points[None, :, :]) ** 2).sum(-1)
    kern = np.exp(-d2 / (2 * sigma_mm ** 2))
    return Fingertip(points, area, taxels, kern, np.array(centre), np.array(centre), np.r_[sx / 2, sy / 2, 0.0],
                     shape.reach_mm)


def indentation(points_z, surface_z) -> np.ndarray:
    """Vertical indentation (same unit as the inputs) of points below the surface, ≥ 0."""
    return np.maximum(np.asarray(surface_z) - np.asarray(points_z), 0.0)


def point_forces(indent_mm, area_mm2, stiffness: float, exponent: float) -> np.ndarray:
    """Normal force (N) at each point: ``stiffness · d^exponent · area``."""
    return stiffness * np.power(indent_mm, exponent) * area_mm2


def shear_loads(taxels, centre, direction, shear_n: float, gain: float, length_mm: float,
                unload_ratio: float = 0.3) -> np.ndarray:
    """(N,) taxel load (N-equivalent) from a tangential traction ``shear_n`` along ``direction``.

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


def impedance_kohm(z0, load_n, shear_load, total_n, saturation_load_n: float, shear_kohm_per_n: float,
                   far_rise_per_n: float) -> np.ndarray:
    """Electrode impedance (kΩ) under load.

    ``z0`` (..., N) resting impedance; ``load_n`` (..., N) normal load in each taxel's
    footprint (N, ≥ 0); ``shear_load`` (..., N) tangential load (N-equivalent, negative
    where shear unloads); ``total_n`` (...,) total normal force.

    The skin pressed towards an electrode thins the conductive fluid over it and the
    impedance grows as 1 / thickness: ``z0 / (1 − load / saturation_load_n)`` (linear for light
    loads, the electrode bottoming out as the load nears ``saturation_load_n``; floored at
    0.2 % of the fluid, ~20 counts). Fluid displaced from the contact thickens over every
    electrode: a relative fall of ``far_rise_per_n`` per N of total force (the real sensor's
    far-field rise in counts). Skin stretch adds ``shear_kohm_per_n`` per N-equivalent of
    shear load. Floored at 5 % of rest.
    """
    far = 1.0 - far_rise_per_n * np.asarray(total_n)[..., None]
    thin = np.maximum(1.0 - np.asarray(load_n) / saturation_load_n, THINNEST)
    return np.maximum(z0 * far / thin + shear_kohm_per_n * np.asarray(shear_load), 0.05 * z0)


THINNEST = 0.002     # fluid left over a bottomed-out electrode (share of rest): ~20 counts


def contact_noise_kohm(z, z_unloaded, fraction: float) -> np.ndarray:
    """Standard deviation (kΩ) of the extra electrode noise in contact: ``fraction`` of the
    load's impedance change ``|z − z_unloaded|`` (micro-motion of the pressed skin)."""
    return fraction * np.abs(np.asarray(z) - np.asarray(z_unloaded))


def counts_from_impedance(z_kohm, counts_max: float = 4095.0, reference_kohm: float = 10.0) -> np.ndarray:
    """Inverse of ``tactile.signals.counts_to_impedance``: ``E = 4095 / (1 + Z/10kΩ)`` (float;
    ``counts_max``, ``reference_kohm``: the sensor model's electrodes)."""
    return counts_max / (1.0 + np.asarray(z_kohm) / reference_kohm)


def impedance_from_counts(counts, counts_max: float = 4095.0, reference_kohm: float = 10.0) -> np.ndarray:
    return (counts_max / np.asarray(counts, float) - 1.0) * reference_kohm


def pdc_rise(total_n, counts_per_n: float, saturation_n: float) -> np.ndarray:
    """PDC increase (counts) with total normal force: linear, saturating smoothly."""
    f = np.asarray(total_n, float)
    return counts_per_n * saturation_n * np.tanh(f / saturation_n)


def quantise(x, lo: int = 0, hi: int = 4095) -> np.ndarray:
    """Round to integer counts and clip to the ADC range."""
    return np.minimum(np.maximum(np.rint(x), lo), hi)

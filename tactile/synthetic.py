"""Synthetic activation patterns with known motion, for the demo, tests and benchmarks.

Patterns are defined on the taxels (N values per sample, kΩ: 24 for the BioTac SP), like real data, so the
whole method — interpolation, surface, frames, flow — is exercised on them.
"""

from __future__ import annotations

import numpy as np

from ._checks import finite_array, positive

__all__ = ["moving_bump", "rotating_pattern"]


def moving_bump(taxels, start, velocity, duration: float, rate_hz: float = 100.0,
                amplitude: float = 4.0, width: float = 3.0) -> np.ndarray:
    """A Gaussian bump of activation sliding across the sensor at constant velocity.

    Args:
        taxels: (N, 3) taxel positions, mm.
        start: (3,) bump centre at t = 0, mm (only x and y are used: the bump is a column
            of pressure along z, as an object pressed onto the pad).
        velocity: (3,) mm/s (x and y used).
        duration: s.  rate_hz: samples per second.
        amplitude: peak activation, kΩ.  width: standard deviation of the bump, mm.

    Returns:
        (T, N) activation, kΩ, T = round(duration × rate_hz).
    """
    taxels = finite_array("taxels", taxels, ndim=2, last=3)
    start = finite_array("start", start, ndim=1, last=3)
    velocity = finite_array("velocity", velocity, ndim=1, last=3)
    n = int(round(positive("duration", duration) * positive("rate_hz", rate_hz)))
    t = np.arange(n) / rate_hz
    centre = start[:2] + t[:, None] * velocity[:2]                      # (T, 2)
    d2 = ((taxels[None, :, :2] - centre[:, None, :]) ** 2).sum(-1)      # (T, N)
    return amplitude * np.exp(-d2 / (2 * positive("width", width) ** 2))


def rotating_pattern(taxels, omega: float, duration: float, rate_hz: float = 100.0,
                     amplitude: float = 4.0, width: float = 3.0, radius: float = 4.0,
                     centre=(0.0, 0.0)) -> np.ndarray:
    """Two bumps on opposite sides of ``centre`` turning about the pad normal (z).

    ``omega``: angular velocity about +z, rad/s (positive = counter-clockwise seen from +z).
    ``radius``: distance of each bump from ``centre`` (x, y), mm. Returns (T, N) kΩ.
    """
    taxels = finite_array("taxels", taxels, ndim=2, last=3)
    n = int(round(positive("duration", duration) * positive("rate_hz", rate_hz)))
    angle = omega * np.arange(n) / rate_hz
    out = np.zeros((n, len(taxels)))
    for offset in (0.0, np.pi):
        cx = centre[0] + radius * np.cos(angle + offset)
        cy = centre[1] + radius * np.sin(angle + offset)
        d2 = (taxels[None, :, 0] - cx[:, None]) ** 2 + (taxels[None, :, 1] - cy[:, None]) ** 2
        out += amplitude * np.exp(-d2 / (2 * positive("width", width) ** 2))
    return out

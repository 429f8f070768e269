"""Taxel positions of a sensor model (mm, sensor frame: x along the finger, y lateral, z normal
to the pad, contact side z < 0); the models themselves are data (:mod:`tactile.sensor`,
``conf/sensor/*.yaml``)."""

from __future__ import annotations

import numpy as np

__all__ = ["load_taxels"]


def load_taxels(sensor: str = "biotac_sp") -> np.ndarray:
    """Taxel positions (N, 3) mm of the built-in sensor model ``sensor`` (default the BioTac SP's
    24), rows in taxel order, a writable copy. Sources: the model's file (``conf/sensor/``)."""
    from .sensor import builtin_sensor
    return np.array(builtin_sensor(sensor).taxels)

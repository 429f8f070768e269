"""The BioTac SP's 24 taxel positions (mm, sensor frame: x along the finger, y lateral, z normal
to the pad, contact side z < 0)."""

from __future__ import annotations

import importlib.resources
import io

import numpy as np

__all__ = ["load_taxels"]

_TAXEL_FILE = "biotac_sp_taxels.csv"


def load_taxels() -> np.ndarray:
    """BioTac SP taxel positions, shape (24, 3), mm, sensor frame, rows in taxel order 1..24.

    Source: Garcia-Garcia et al. 2019, "TactileGCN: A Graph Convolutional Network for
    Predicting Grasp Stability with Tactile Sensors" (repository 3dperceptionlab/tactile-gcn,
    converted from inches and remapped to this frame; see ``tactile/data/README.md``).
    """
    text = importlib.resources.files("tactile_flow.tactile").joinpath("data", _TAXEL_FILE).read_text()
    table = np.genfromtxt(io.StringIO(text), delimiter=",", names=True, dtype=None,
                          encoding="utf-8")
    order = np.argsort(table["taxel"])
    if not np.array_equal(table["taxel"][order], np.arange(1, 25)):
        raise ValueError(f"{_TAXEL_FILE}: expected taxels 1..24, got {table['taxel']}")
    xyz = np.column_stack([table["x_mm"], table["y_mm"], table["z_mm"]]).astype(np.float64)
    return xyz[order]

"""Rigid transforms: UR rotation vectors (axis-angle, rad) ↔ rotation matrices, poses
``[x, y, z, rx, ry, rz]`` (m, rad) ↔ 4×4 homogeneous transforms.

One implementation for the simulator, the UR emulator and the planner, on
:class:`scipy.spatial.transform.Rotation` (exact near π, where hand-written Rodrigues
formulas need their own branches).

>>> import numpy as np
>>> R = rotvec_to_matrix([0, 0, np.pi / 2])
>>> np.round(R @ [1, 0, 0], 12).tolist()
[0.0, 1.0, 0.0]
>>> np.allclose(matrix_to_rotvec(R), [0, 0, np.pi / 2])
True
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

__all__ = ["rotvec_to_matrix", "matrix_to_rotvec", "pose_to_matrix", "matrix_to_pose"]


def rotvec_to_matrix(rv) -> np.ndarray:
    """(3,) rotation vector (rad) → (3, 3) rotation matrix."""
    return Rotation.from_rotvec(np.asarray(rv, float)).as_matrix()


def matrix_to_rotvec(R) -> np.ndarray:
    """(3, 3) rotation matrix → (3,) rotation vector (rad), angle in [0, π]."""
    return Rotation.from_matrix(np.asarray(R, float)).as_rotvec()


def pose_to_matrix(pose) -> np.ndarray:
    """(6,) ``[x, y, z, rx, ry, rz]`` (m, rad) → (4, 4) homogeneous transform."""
    pose = np.asarray(pose, float)
    T = np.eye(4)
    T[:3, :3] = rotvec_to_matrix(pose[3:6])
    T[:3, 3] = pose[:3]
    return T


def matrix_to_pose(T) -> np.ndarray:
    """(4, 4) homogeneous transform → (6,) ``[x, y, z, rx, ry, rz]`` (m, rad)."""
    T = np.asarray(T, float)
    return np.concatenate([T[:3, 3], matrix_to_rotvec(T[:3, :3])])

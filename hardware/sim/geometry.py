"""Rigid transforms: axis-angle (UR rotation vectors) ↔ matrices, pose composition."""

from __future__ import annotations

import numpy as np


def rotvec_to_matrix(rv) -> np.ndarray:
    """(3,) rotation vector (rad) → (3, 3) rotation matrix (Rodrigues)."""
    rv = np.asarray(rv, float)
    th = float(np.sqrt(rv @ rv))
    if th < 1e-12:
        return np.eye(3)
    k = rv / th
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(th) * K + (1 - np.cos(th)) * (K @ K)


def matrix_to_rotvec(R) -> np.ndarray:
    """(3, 3) rotation matrix → (3,) rotation vector (rad), angle in [0, π]."""
    R = np.asarray(R, float)
    c = np.clip((np.trace(R) - 1) / 2, -1.0, 1.0)
    th = float(np.arccos(c))
    if th < 1e-9:
        return np.zeros(3)
    if np.pi - th < 1e-6:
        # near π: axis from the largest diagonal entry of (R + I) / 2
        B = (R + np.eye(3)) / 2
        i = int(np.argmax(np.diag(B)))
        k = B[:, i] / np.sqrt(B[i, i])
        return k / np.linalg.norm(k) * th
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    return w / (2 * np.sin(th)) * th


def pose_to_matrix(pose) -> np.ndarray:
    """(6,) ``[x,y,z,rx,ry,rz]`` → (4, 4) homogeneous transform."""
    T = np.eye(4)
    T[:3, :3] = rotvec_to_matrix(pose[3:6])
    T[:3, 3] = pose[:3]
    return T


def matrix_to_pose(T) -> np.ndarray:
    return np.concatenate([T[:3, 3], matrix_to_rotvec(T[:3, :3])])

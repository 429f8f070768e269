"""Rigid transforms: UR rotation vectors (axis-angle, rad) ↔ rotation matrices and unit
quaternions, poses ``[x, y, z, rx, ry, rz]`` (m, rad) ↔ 4×4 homogeneous transforms.

One implementation for the simulator, the UR emulator, the planner, the analysis and the
viewer, with the arithmetic of SciPy's ``Rotation`` (which the program no longer imports:
``scipy.spatial`` cost ~0.25 s of every start on one core): a rotation vector becomes its unit quaternion
(a series for angles under 1e-3 rad) and the quaternion a matrix; a matrix becomes a quaternion
from the largest of its trace and diagonal (Shepperd's choice, as Markley), so it stays exact
near π, where hand-written Rodrigues formulas need their own branches; the rotation vector is
2·atan2(|v|, w) with w ≥ 0, angle in [0, π]. ``tests/test_small_math.py`` compares the results
with SciPy's (identical to the last bit on the development machine).

One rotation at a time is computed on Python floats (the simulator converts one per tick);
batches (..., 3) / (..., 3, 3) on arrays, with the same formulas.

>>> import numpy as np
>>> R = rotvec_to_matrix([0, 0, np.pi / 2])
>>> np.round(R @ [1, 0, 0], 12).tolist()
[0.0, 1.0, 0.0]
>>> np.allclose(matrix_to_rotvec(R), [0, 0, np.pi / 2])
True
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["rotvec_to_matrix", "matrix_to_rotvec", "rotvec_to_quaternion", "pose_to_matrix", "matrix_to_pose"]


def rotvec_to_quaternion(rv) -> np.ndarray:
    """(..., 3) rotation vectors (rad) → (..., 4) unit quaternions ``(x, y, z, w)``, w = cos(angle/2)."""
    (x, y, z), ops, lead = _components(rv, (3,))
    return _assemble(_quaternion(x, y, z, ops), lead, (4,))


def rotvec_to_matrix(rv) -> np.ndarray:
    """(..., 3) rotation vectors (rad) → (..., 3, 3) rotation matrices."""
    (x, y, z), ops, lead = _components(rv, (3,))
    return _assemble(_matrix(*_quaternion(x, y, z, ops)), lead, (3, 3))


def matrix_to_rotvec(R) -> np.ndarray:
    """(..., 3, 3) rotation matrices → (..., 3) rotation vectors (rad), angle in [0, π].

    A matrix further than 1e-12 from orthogonal is first replaced by the nearest rotation
    (``U Vᵀ`` of its SVD); one with a determinant ≤ 0 is refused (``ValueError``)."""
    R = np.asarray(R, float)
    m, ops, lead = _components(R, (3, 3))
    det, orthogonal = _validity(m)
    if not ops.all(det > 0):
        i = int(np.argmax(~np.atleast_1d(det > 0)))
        raise ValueError(f"not a rotation: matrix {i} has a non-positive determinant (a left-handed or "
                         f"degenerate frame): {R.reshape(-1, 3, 3)[i].tolist()}")
    if not ops.all(orthogonal):
        m = _components(_nearest_rotation(R, orthogonal), (3, 3))[0]
    q = _quaternion_of_matrix(m, ops)
    return _assemble(_rotvec(*q, ops), lead, (3,))


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


# ----------------------------------------------------------------------------- the formulas,
# written once for Python floats (one rotation) and for arrays (a batch, element-wise)

class _One:
    """Operations on Python floats."""
    sqrt, sin, cos, atan2 = math.sqrt, math.sin, math.cos, math.atan2

    @staticmethod
    def where(cond, a, b):
        return a if cond else b

    @staticmethod
    def choose(i, options):
        return options[i]

    @staticmethod
    def argmax(values):
        return values.index(max(values))

    all = staticmethod(bool)


class _Batch:
    """The same operations, element-wise on arrays."""
    sqrt, sin, cos, atan2, where = np.sqrt, np.sin, np.cos, np.arctan2, np.where

    @staticmethod
    def choose(i, options):
        return tuple(np.choose(i, column) for column in zip(*options))

    @staticmethod
    def argmax(values):
        return np.argmax(np.stack(values), axis=0)

    @staticmethod
    def all(a):
        return bool(np.all(a))


def _components(a, tail: tuple[int, ...]):
    """(the last axes' components, the operations for them, the leading shape or None)."""
    a = np.asarray(a, float)
    if a.shape[max(a.ndim - len(tail), 0):] != tail:
        raise ValueError(f"expected an array of shape (..., {', '.join(map(str, tail))}), got shape {a.shape}")
    if a.ndim == len(tail):
        return a.ravel().tolist(), _One, None
    flat = a.reshape(*a.shape[:-len(tail)], -1)
    return [flat[..., i] for i in range(flat.shape[-1])], _Batch, a.shape[:-len(tail)]


def _assemble(components, lead, tail) -> np.ndarray:
    if lead is None:
        return np.array(components).reshape(tail)
    return np.stack(components, axis=-1).reshape(*lead, *tail)


def _quaternion(x, y, z, ops):
    """Rotation vector → unit quaternion (x, y, z, w)."""
    angle = ops.sqrt(x * x + y * y + z * z)
    a2 = angle * angle
    small = angle <= 1e-3
    scale = ops.where(small, 0.5 - a2 / 48 + a2 * a2 / 3840, ops.sin(angle / 2) / (angle + small))
    return x * scale, y * scale, z * scale, ops.cos(angle / 2)


def _matrix(x, y, z, w):
    """Unit quaternion → the rotation matrix's 9 entries, row by row."""
    x2, y2, z2, w2 = x * x, y * y, z * z, w * w
    xy, zw, xz, yw, yz, xw = x * y, z * w, x * z, y * w, y * z, x * w
    return (x2 - y2 - z2 + w2, 2 * (xy - zw), 2 * (xz + yw),
            2 * (xy + zw), -x2 + y2 - z2 + w2, 2 * (yz - xw),
            2 * (xz - yw), 2 * (yz + xw), -x2 - y2 + z2 + w2)


def _quaternion_of_matrix(m, ops):
    """Rotation matrix (9 entries) → unit quaternion, from the largest of trace and diagonal."""
    m00, m01, m02, m10, m11, m12, m20, m21, m22 = m
    trace = m00 + m11 + m22
    q = ops.choose(ops.argmax([m00, m11, m22, trace]), (
        (1 - trace + 2 * m00, m10 + m01, m20 + m02, m21 - m12),
        (m10 + m01, 1 - trace + 2 * m11, m21 + m12, m02 - m20),
        (m20 + m02, m21 + m12, 1 - trace + 2 * m22, m10 - m01),
        (m21 - m12, m02 - m20, m10 - m01, 1 + trace)))
    norm = ops.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return tuple(c / norm for c in q)


def _rotvec(x, y, z, w, ops):
    """Unit quaternion → rotation vector, the quaternion taken with w ≥ 0 (then x ≥ 0, …)."""
    flip = (w < 0) | ((w == 0) & ((x < 0) | ((x == 0) & ((y < 0) | ((y == 0) & (z < 0))))))
    sign = ops.where(flip, -1.0, 1.0)
    x, y, z, w = x * sign, y * sign, z * sign, w * sign
    angle = 2 * ops.atan2(ops.sqrt(x * x + y * y + z * z), w)
    a2 = angle * angle
    small = angle <= 1e-3
    scale = ops.where(small, 2 + a2 / 12 + 7 * (a2 * a2) / 2880, angle / (ops.sin(angle / 2) + small))
    return scale * x, scale * y, scale * z


def _validity(m):
    """(determinant, whether R Rᵀ is within 1e-12 of I (1e-5 more on the diagonal, as SciPy's
    ``isclose`` test)) of a rotation matrix given as its 9 entries."""
    rows = (m[0:3], m[3:6], m[6:9])
    (m00, m01, m02), (m10, m11, m12), (m20, m21, m22) = rows
    det = m00 * (m11 * m22 - m12 * m21) - m01 * (m10 * m22 - m12 * m20) + m02 * (m10 * m21 - m11 * m20)
    orthogonal = True
    for a in range(3):
        for b in range(a, 3):
            g = rows[a][0] * rows[b][0] + rows[a][1] * rows[b][1] + rows[a][2] * rows[b][2]
            orthogonal = orthogonal & (abs(g - (a == b)) <= (1e-12 + 1e-5 if a == b else 1e-12))
    return det, orthogonal


def _nearest_rotation(R, orthogonal):
    """``R`` with the matrices that are not ``orthogonal`` replaced by U Vᵀ of their SVD."""
    R = R.copy()
    bad = ~np.asarray(orthogonal, bool)
    U, _, Vt = np.linalg.svd(R[bad], full_matrices=False)
    R[bad] = U @ Vt
    return R

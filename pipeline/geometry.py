"""SE(3) helpers on numpy arrays. Poses are 4x4 homogeneous matrices, metres and radians."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]


def inv_se3(T_a_b: F64) -> F64:
    """Inverse of one (4, 4) or a stack (N, 4, 4) of rigid transforms: T_b_a."""
    R = T_a_b[..., :3, :3]
    t = T_a_b[..., :3, 3]
    out = np.zeros_like(T_a_b)
    Rt = np.swapaxes(R, -1, -2)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, t)
    out[..., 3, 3] = 1.0
    return out


def quat_to_rot(q_xyzw: F64) -> F64:
    """Rotation matrices (..., 3, 3) from unit quaternions (..., 4) in x, y, z, w order."""
    q = np.asarray(q_xyzw, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    R = np.empty((*q.shape[:-1], 3, 3))
    R[..., 0, 0] = 1 - 2 * (y * y + z * z)
    R[..., 0, 1] = 2 * (x * y - z * w)
    R[..., 0, 2] = 2 * (x * z + y * w)
    R[..., 1, 0] = 2 * (x * y + z * w)
    R[..., 1, 1] = 1 - 2 * (x * x + z * z)
    R[..., 1, 2] = 2 * (y * z - x * w)
    R[..., 2, 0] = 2 * (x * z - y * w)
    R[..., 2, 1] = 2 * (y * z + x * w)
    R[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return R


def rot_to_quat(R: F64) -> F64:
    """Unit quaternions (..., 4) in x, y, z, w order (w >= 0) from rotations (..., 3, 3)."""
    R = np.asarray(R, dtype=np.float64)
    m00, m11, m22 = R[..., 0, 0], R[..., 1, 1], R[..., 2, 2]
    # Shepperd's method, vectorised: choose the largest of w, x, y, z for stability.
    t = np.stack([1 + m00 + m11 + m22, 1 + m00 - m11 - m22, 1 - m00 + m11 - m22,
                  1 - m00 - m11 + m22], axis=-1)
    k = np.argmax(t, axis=-1)
    s = np.sqrt(np.maximum(np.take_along_axis(t, k[..., None], -1)[..., 0], 1e-300)) * 2
    r21, r12 = R[..., 2, 1], R[..., 1, 2]
    r02, r20 = R[..., 0, 2], R[..., 2, 0]
    r10, r01 = R[..., 1, 0], R[..., 0, 1]
    cases = [
        ((r21 - r12) / s, (r02 - r20) / s, (r10 - r01) / s, s / 4),
        (s / 4, (r01 + r10) / s, (r02 + r20) / s, (r21 - r12) / s),
        ((r01 + r10) / s, s / 4, (r12 + r21) / s, (r02 - r20) / s),
        ((r02 + r20) / s, (r12 + r21) / s, s / 4, (r10 - r01) / s),
    ]
    q = np.zeros((*R.shape[:-2], 4))
    for i, case in enumerate(cases):
        sel = (k == i)[..., None]
        q = np.where(sel, np.stack(case, axis=-1), q)
    q *= np.where(q[..., 3:4] < 0, -1.0, 1.0)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def pose_from_xyz_quat(xyz: F64, q_xyzw: F64) -> F64:
    """(..., 4, 4) transforms from translations (..., 3) [m] and quaternions (..., 4)."""
    xyz = np.asarray(xyz, dtype=np.float64)
    T = np.zeros((*xyz.shape[:-1], 4, 4))
    T[..., :3, :3] = quat_to_rot(q_xyzw)
    T[..., :3, 3] = xyz
    T[..., 3, 3] = 1.0
    return T


def rot_z(yaw_rad: float) -> F64:
    """(3, 3) rotation about z by ``yaw_rad``."""
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rotation_angle(R: F64) -> F64:
    """Rotation angle(s) [rad] of (..., 3, 3) rotations, as the KITTI devkit computes it."""
    d = 0.5 * (R[..., 0, 0] + R[..., 1, 1] + R[..., 2, 2] - 1.0)
    return np.arccos(np.clip(d, -1.0, 1.0))


def path_distances(T_world_x: F64) -> F64:
    """Cumulative path length [m] along the translations of (N, 4, 4) poses; (N,) from 0."""
    t = T_world_x[:, :3, 3]
    step = np.linalg.norm(np.diff(t, axis=0), axis=1)
    return np.concatenate([[0.0], np.cumsum(step)])

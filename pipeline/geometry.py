"""SE(3) helpers on numpy arrays. Poses are 4x4 homogeneous matrices, metres and radians.

Quaternions, rotation matrices and slerp are scipy's (``scipy.spatial.transform``, imported in
the functions: it takes about a second to import).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import InputError

F64 = NDArray[np.float64]


MAX_POSITION_M = 1e8
"""A ground-truth position beyond 100 000 km from the origin is not a trajectory on Earth (ECEF
and UTM coordinates stay below 1e7 m)."""


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
    """Rotation matrices (..., 3, 3) from quaternions (..., 4) in x, y, z, w order (normalised).

    Raises ValueError for a zero quaternion (scipy's Rotation).
    """
    from scipy.spatial.transform import Rotation

    q = np.asarray(q_xyzw, dtype=np.float64)
    R = Rotation.from_quat(q.reshape(-1, 4)).as_matrix()
    return R.reshape(*q.shape[:-1], 3, 3)


def rot_to_quat(R: F64) -> F64:
    """Unit quaternions (..., 4) in x, y, z, w order (w >= 0) from rotations (..., 3, 3)."""
    from scipy.spatial.transform import Rotation

    R = np.asarray(R, dtype=np.float64)
    q = Rotation.from_matrix(R.reshape(-1, 3, 3)).as_quat(canonical=True)
    return q.reshape(*R.shape[:-2], 4)


def pose_from_xyz_quat(xyz: F64, q_xyzw: F64) -> F64:
    """(..., 4, 4) transforms from translations (..., 3) [m] and quaternions (..., 4)."""
    xyz = np.asarray(xyz, dtype=np.float64)
    T = np.zeros((*xyz.shape[:-1], 4, 4))
    T[..., :3, :3] = quat_to_rot(q_xyzw)
    T[..., :3, 3] = xyz
    T[..., 3, 3] = 1.0
    return T


def refuse_non_rotations(R: F64, what: str, lines: list[int] | None = None) -> None:
    """InputError naming the first (3, 3) block of ``R`` (M, 3, 3) that is not a rotation
    (R^T R = I and det R = +1 within 1e-3): a zero, scaled, sheared or reflected matrix."""
    bad = not_rotations(R)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        where = f"line {lines[k]}" if lines is not None else f"pose {k}"
        with np.errstate(all="ignore"):  # huge entries: det = inf, no warning
            det = np.linalg.det(R[k])
        raise InputError(f"{what} {where}: the rotation is not a rotation matrix (R^T R = I and "
                         f"det R = +1 within 1e-3; det = {det:.6g})")


def poses_from_quaternions(xyz: F64, q_xyzw: F64, what: str,
                           lines: list[int] | None = None) -> F64:
    """(M, 4, 4) poses of translations (M, 3) and quaternions (M, 4) x, y, z, w; InputError
    naming the first quaternion whose norm is not 1 within 1e-2 (zero and NaN included) or
    the first translation that is not finite."""
    with np.errstate(all="ignore"):  # a huge quaternion: refused below, no warning
        norm = np.linalg.norm(q_xyzw, axis=1)
    bad = ~(np.abs(norm - 1.0) <= 1e-2)  # NaN is bad too
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        where = f"line {lines[k]}" if lines is not None else f"pose {k}"
        raise InputError(f"{what} {where}: the quaternion has norm {norm[k]:.6g}, a rotation "
                         "needs a unit quaternion (norm 1 within 1e-2)")
    far = ~np.isfinite(xyz).all(axis=1)
    if far.any():
        k = int(np.flatnonzero(far)[0])
        where = f"line {lines[k]}" if lines is not None else f"pose {k}"
        raise InputError(f"{what} {where}: the translation is not finite ({xyz[k].tolist()})")
    return pose_from_xyz_quat(xyz, q_xyzw)


def rot_z(yaw_rad: float) -> F64:
    """(3, 3) rotation about z by ``yaw_rad``."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_euler("z", yaw_rad).as_matrix()


def not_rotations(R: F64, tol: float = 1e-3) -> NDArray[np.bool_]:
    """(...,) True where a (..., 3, 3) matrix is not a rotation: R^T R != I (beyond ``tol``,
    element-wise) or det(R) != +1 (zero, scaled, reflected or sheared matrices)."""
    R = np.asarray(R, dtype=np.float64)
    with np.errstate(all="ignore"):  # huge or NaN entries: not a rotation, no warning
        gram = np.swapaxes(R, -1, -2) @ R
        off = np.abs(gram - np.eye(3)).max(axis=(-1, -2))
        det = np.linalg.det(R)
    return ~((off <= tol) & (np.abs(det - 1.0) <= tol))


def interpolate_rotations(
    t_query: F64, t_key: F64, R_key: F64
) -> F64:
    """(Q, 3, 3) rotations at times ``t_query`` (Q,) by slerp between keys ``R_key`` (M, 3, 3)
    at increasing times ``t_key`` (M,); queries are clipped to the keys' span (scipy's Slerp)."""
    from scipy.spatial.transform import Rotation, Slerp

    if len(t_key) == 1:
        return np.repeat(np.asarray(R_key, np.float64)[:1], len(t_query), axis=0)
    slerp = Slerp(np.asarray(t_key, np.float64), Rotation.from_matrix(R_key))
    return slerp(np.clip(t_query, t_key[0], t_key[-1])).as_matrix()


def rotation_angle(R: F64) -> F64:
    """Rotation angle(s) [rad] of (..., 3, 3) rotations, as the KITTI devkit computes it."""
    d = 0.5 * (R[..., 0, 0] + R[..., 1, 1] + R[..., 2, 2] - 1.0)
    return np.arccos(np.clip(d, -1.0, 1.0))


def path_distances(T_world_x: F64) -> F64:
    """Cumulative path length [m] along the translations of (N, 4, 4) poses; (N,) from 0."""
    t = T_world_x[:, :3, 3]
    step = np.linalg.norm(np.diff(t, axis=0), axis=1)
    return np.concatenate([[0.0], np.cumsum(step)])

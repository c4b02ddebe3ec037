"""Small pieces shared by the in-process adapters: option models, SE(3) updates, voxel keys."""

from __future__ import annotations

from typing import Any, TypeVar

import numpy as np
from numpy.typing import NDArray

from pipeline.config import Section, validate_section

F64 = NDArray[np.float64]
OptionsT = TypeVar("OptionsT", bound=Section)

KEY_OFFSET = 1 << 20
"""Voxel coordinates are packed as 21-bit unsigned fields: |index| < 2**20 voxels per axis."""


def parse_options(model: type[OptionsT], adapter: str, options: dict[str, Any]) -> OptionsT:
    """Validated adapter ``options`` (CLI strings are converted); ConfigError naming them."""
    return validate_section(model, f"{adapter} option", options)


def voxel_indices(points: F64, voxel_m: float) -> NDArray[np.int64]:
    """(N, 3) int64 integer coordinates of the voxels of side ``voxel_m`` holding ``points``."""
    return np.floor(points * (1.0 / voxel_m)).astype(np.int64)


def pack_keys(ijk: NDArray[np.int64]) -> NDArray[np.int64]:
    """(N,) int64 keys of integer voxel coordinates (N, 3) (21 bits an axis, clipped)."""
    ijk = ijk + KEY_OFFSET
    np.clip(ijk, 0, (1 << 21) - 1, out=ijk)
    return (ijk[:, 0] << 42) | (ijk[:, 1] << 21) | ijk[:, 2]


def voxel_keys(points: F64, voxel_m: float) -> NDArray[np.int64]:
    """(N,) int64 keys of the voxels of side ``voxel_m`` holding ``points`` (N, 3) [m]."""
    return pack_keys(voxel_indices(points, voxel_m))


def voxel_downsample(points: NDArray[np.floating], voxel_m: float) -> F64:
    """Centroid of the points in every occupied voxel of side ``voxel_m``; (M, 3) float64,
    ordered by voxel key."""
    pts = np.asarray(points, dtype=np.float64)
    if voxel_m <= 0 or len(pts) == 0:
        return pts.copy()
    keys = voxel_keys(pts, voxel_m)
    order = np.argsort(keys)
    sorted_keys = keys[order]
    starts = np.flatnonzero(np.concatenate([[True], sorted_keys[1:] != sorted_keys[:-1]]))
    sums = np.add.reduceat(pts[order], starts, axis=0)
    counts = np.diff(np.append(starts, len(pts)))
    return sums / counts[:, None]


def hat(v: F64) -> F64:
    """Skew-symmetric matrices (..., 3, 3) of vectors (..., 3)."""
    out = np.zeros((*v.shape[:-1], 3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def so3_exp(w: F64) -> F64:
    """Rotation (3, 3) of the rotation vector ``w`` (3,) [rad] (Rodrigues)."""
    theta = float(np.linalg.norm(w))
    K = hat(w)
    if theta < 1e-10:
        return np.eye(3) + K
    return np.eye(3) + np.sin(theta) / theta * K + (1 - np.cos(theta)) / theta**2 * (K @ K)


def se3_exp(xi: F64) -> F64:
    """(4, 4) transform of the twist ``xi`` = (rotation vector [rad], translation [m]).

    The translation is applied as is (a first-order update, enough for small Newton steps).
    """
    T = np.eye(4)
    T[:3, :3] = so3_exp(xi[:3])
    T[:3, 3] = xi[3:]
    return T


def orthonormalize(T: F64) -> F64:
    """``T`` with its rotation block projected back onto SO(3) (SVD)."""
    U, _, Vt = np.linalg.svd(T[:3, :3])
    R = U @ Vt
    if np.linalg.det(R) < 0:
        U[:, -1] *= -1
        R = U @ Vt
    out = T.copy()
    out[:3, :3] = R
    return out


def constant_velocity_guess(poses: list[F64]) -> F64:
    """Prediction of the next T_world_lidar from the last two (identity motion at the start)."""
    if not poses:
        return np.eye(4)
    if len(poses) == 1:
        return poses[-1].copy()
    prev, last = poses[-2], poses[-1]
    delta = np.linalg.solve(prev, last)
    return last @ delta

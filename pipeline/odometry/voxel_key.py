"""The packed voxel key of the odometry adapters' voxel maps: a voxel's integer coordinates
(i, j, k) = floor(p / resolution), each shifted by ``KEY_OFFSET`` and clipped to
[0, ``KEY_MAX``], packed into 21-bit fields of one int64, so that a sort by key groups the
points of a voxel (``common.voxel_keys`` for arrays in numpy, ``packed_voxel_key`` for one point in
compiled code: the same keys)."""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

KEY_OFFSET = 1 << 20
"""Voxel coordinates are packed as 21-bit unsigned fields: |index| < 2**20 voxels per axis."""
KEY_MAX = (1 << 21) - 1
"""Largest field value of a packed voxel coordinate (indices are clipped to [0, KEY_MAX])."""


@numba.njit(cache=True, nogil=True)
def packed_voxel_key(x: float, y: float, z: float, inv_res: float, offsets: NDArray[np.int64],
               o: int) -> np.int64:  # pragma: no cover - compiled
    """Packed key of the voxel holding (x, y, z) [m], shifted by ``offsets[o]`` voxels
    (offsets (O, 3); ``common.voxel_keys`` for one point when the offset is zero)."""
    key = np.int64(0)
    for idx in (np.int64(np.floor(x * inv_res)) + offsets[o, 0],
                np.int64(np.floor(y * inv_res)) + offsets[o, 1],
                np.int64(np.floor(z * inv_res)) + offsets[o, 2]):
        idx = min(max(idx + KEY_OFFSET, np.int64(0)), np.int64(KEY_MAX))
        key = (key << np.int64(21)) | idx
    return key

"""The ``ndt`` odometry as it was before its registration was compiled as a whole (issue 16):
numpy around a per-point numba kernel (the Gauss-Newton loop, Rodrigues, the 6x6 solve and
the keyframe voxel map in numpy).

Kept here only as the same-run reference of bench_odometry.py (the frames/s the compiled
``pipeline/odometry/ndt_kernel.py`` is measured against, and the trajectories it must
match to ~1e-12 m). Not imported by the package.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import NDArray

from pipeline.odometry.base import ParameterSpace, Params
from pipeline.odometry.common import (
    F64,
    DownsampleCache,
    constant_velocity_guess,
    orthonormalize,
    se3_exp,
    vector_norm,
    voxel_keys,
)
from pipeline.odometry.ndt import SPACE, NdtOptions
from pipeline.odometry.voxel_key import KEY_MAX, KEY_OFFSET

log = logging.getLogger(__name__)

_DIAG = np.diag_indices(6)

# neighbours searched around a source point's own voxel
_OFFSETS = {
    1: np.zeros((1, 3), np.int64),
    7: np.array([[0, 0, 0], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]]),
}


@dataclass
class VoxelMap:
    """NDT voxels of one keyframe: sorted keys (K,), means (K, 3), inverse covariances (K, 3, 3)."""

    resolution: float
    keys: NDArray[np.int64]
    means: F64
    inv_covs: F64

    @classmethod
    def build(cls, points_world: F64, resolution: float, min_points: int) -> VoxelMap:
        """Voxel statistics of ``points_world`` (M, 3) [m] at ``resolution`` [m]."""
        keys, inv, counts = np.unique(voxel_keys(points_world, resolution),
                                      return_inverse=True, return_counts=True)
        # coordinates relative to a point of each voxel keep the second moments well conditioned
        first = np.zeros(len(keys), np.int64)
        first[inv[::-1]] = np.arange(len(inv))[::-1]
        local = points_world - points_world[first][inv]
        sums = np.stack([np.bincount(inv, local[:, k], len(keys)) for k in range(3)], axis=1)
        mean_local = sums / counts[:, None]
        second = np.empty((len(keys), 3, 3))
        for a in range(3):
            for b in range(a, 3):
                s = np.bincount(inv, local[:, a] * local[:, b], len(keys)) / counts
                second[:, a, b] = second[:, b, a] = s
        keep = counts >= min_points
        cov = (second - mean_local[:, :, None] * mean_local[:, None, :])[keep]
        cov *= (counts[keep] / (counts[keep] - 1.0))[:, None, None]
        evals, evecs = np.linalg.eigh(cov)
        floor = np.maximum(0.01 * evals[:, 2:3], 1e-6)
        evals = np.maximum(evals, floor)
        inv_covs = np.einsum("kij,kj,klj->kil", evecs, 1.0 / evals, evecs)
        means = mean_local[keep] + points_world[first[keep]]
        return cls(resolution, keys[keep], means, inv_covs)

    def __len__(self) -> int:
        return len(self.keys)


@numba.njit(cache=True, nogil=True)
def ndt_terms(source: F64, T: F64, keys: NDArray[np.int64], means: F64, inv_covs: F64,
              inv_res: float, offsets: NDArray[np.int64], d1: float,
              d2: float) -> tuple[float, F64, F64, int]:  # pragma: no cover - compiled
    """Score, Hessian (6, 6) and gradient (6,) of the NDT objective, and the pair count.

    source (N, 3) points [m] in the sensor frame; T (4, 4) the pose (R, t); keys (K,) the
    sorted packed voxel keys (``pack_keys``) of the map, means (K, 3), inv_covs (K, 3, 3);
    inv_res = 1 / resolution [1/m]; offsets (O, 3) voxel offsets searched around a point.
    Every point q = R p + t is paired with each map voxel of its own (and offset) voxel;
    a pair with e = q - mean, m = e^T C e contributes score -d1 exp(-d2 m / 2) and, with the
    weight w = -d1 d2 exp(-d2 m / 2) and J = dq/dxi = [-R [p]x | R] (right perturbation
    T exp(xi)), w J^T C J to the Hessian and w J^T C e to the gradient. Summation runs in
    point order, so the result is deterministic.
    """
    R = T[:3, :3]
    t = T[:3, 3]
    H = np.zeros((6, 6))
    g = np.zeros(6)
    score = 0.0
    pairs = 0
    J = np.empty((3, 6))
    CJ = np.empty((3, 6))
    q = np.empty(3)
    e = np.empty(3)
    Ce = np.empty(3)
    for a in range(3):
        for b in range(3):
            J[a, 3 + b] = R[a, b]
    n_keys = keys.shape[0]
    for i in range(source.shape[0]):
        px, py, pz = source[i, 0], source[i, 1], source[i, 2]
        for a in range(3):
            q[a] = R[a, 0] * px + R[a, 1] * py + R[a, 2] * pz + t[a]
        for o in range(offsets.shape[0]):
            key = np.int64(0)
            for a in range(3):
                idx = np.int64(np.floor(q[a] * inv_res)) + offsets[o, a] + KEY_OFFSET
                idx = min(max(idx, np.int64(0)), np.int64(KEY_MAX))
                key = (key << np.int64(21)) | idx
            v = np.searchsorted(keys, key)
            if v >= n_keys or keys[v] != key:
                continue
            pairs += 1
            m = 0.0
            for a in range(3):
                e[a] = q[a] - means[v, a]
            for a in range(3):
                Ce[a] = (inv_covs[v, a, 0] * e[0] + inv_covs[v, a, 1] * e[1]
                         + inv_covs[v, a, 2] * e[2])
                m += e[a] * Ce[a]
            ex = np.exp(-0.5 * d2 * m)
            score -= d1 * ex
            w = -d1 * d2 * ex
            for a in range(3):  # column j of -R [p]x is R (e_j x p)
                J[a, 0] = py * R[a, 2] - pz * R[a, 1]
                J[a, 1] = pz * R[a, 0] - px * R[a, 2]
                J[a, 2] = px * R[a, 1] - py * R[a, 0]
            for a in range(3):
                for c in range(6):
                    CJ[a, c] = (inv_covs[v, a, 0] * J[0, c] + inv_covs[v, a, 1] * J[1, c]
                                + inv_covs[v, a, 2] * J[2, c])
            for c in range(6):
                g[c] += w * (Ce[0] * J[0, c] + Ce[1] * J[1, c] + Ce[2] * J[2, c])
                for d in range(c, 6):
                    H[c, d] += w * (J[0, c] * CJ[0, d] + J[1, c] * CJ[1, d] + J[2, c] * CJ[2, d])
    for c in range(6):
        for d in range(c):
            H[c, d] = H[d, c]
    return score, H, g, pairs


def score_constants(resolution: float, outlier_ratio: float) -> tuple[float, float]:
    """Magnusson's (d1, d2) of the Gaussian-plus-uniform fit; d1 < 0 < d2."""
    c1 = 10.0 * (1.0 - outlier_ratio)
    c2 = outlier_ratio / resolution**3
    d3 = -math.log(c2)
    d1 = -math.log(c1 + c2) - d3
    d2 = -2.0 * math.log((-math.log(c1 * math.exp(-0.5) + c2) - d3) / d1)
    return d1, d2


class ReferenceNdtOdometry:
    """Streaming keyframe NDT: ``step`` one scan at a time, ``set_params`` between scans."""

    def __init__(self, params: Params, options: NdtOptions | None = None,
                 sources: DownsampleCache | None = None, space: ParameterSpace = SPACE) -> None:
        self.options = options or NdtOptions()
        self.space = space
        self.sources = sources if sources is not None else DownsampleCache()
        self.params = self.space.validate(params)
        self.poses: list[F64] = []
        self.keyframe_world: F64 | None = None
        self.voxels: VoxelMap | None = None
        self.travelled_m = 0.0
        self._offsets = _OFFSETS[self.options.neighbors]
        self._set_constants()

    def _set_constants(self) -> None:
        self.d1, self.d2 = score_constants(self.params["resolution"], self.options.outlier_ratio)

    def set_params(self, params: Params) -> None:
        """In place: a new resolution rebuilds the keyframe's voxel map; the rest is kept."""
        new = self.space.validate(params)
        rebuild = new["resolution"] != self.params["resolution"]
        self.params = new
        if rebuild:
            self._set_constants()
            if self.keyframe_world is not None:
                self._build_map()

    def _build_map(self) -> None:
        assert self.keyframe_world is not None
        self.voxels = VoxelMap.build(self.keyframe_world, self.params["resolution"],
                                     self.options.min_points)

    def step(self, points_lidar: NDArray[np.float32], stamp_ns: int) -> F64:
        """Register one scan ((N, 3) float32 [m]); T_world_lidar (4, 4), the first is identity."""
        if not self.poses:
            T = np.eye(4)
        else:
            guess = constant_velocity_guess(self.poses)
            source = self.sources.get(points_lidar[:, :3], self.options.source_voxel_m)
            T = self._align(source, guess)
            self.travelled_m += vector_norm(T[:3, 3] - self.poses[-1][:3, 3])
        self.poses.append(T)
        if self.keyframe_world is None or self.travelled_m >= self.params["keyframe_interval"]:
            # the scan in float64 only when it becomes the keyframe (~1 frame in 10: converting
            # every scan was 15 % of a trial)
            pts = np.asarray(points_lidar[:, :3], dtype=np.float64)
            self.keyframe_world = pts @ T[:3, :3].T + T[:3, 3]
            self.travelled_m = 0.0
            self._build_map()
        return T.copy()

    def _evaluate(self, source: F64, T: F64) -> tuple[float, F64, F64, int]:
        """NDT score of ``source`` at pose ``T``, Gauss-Newton Hessian (6, 6), gradient (6,)
        and the number of point-voxel pairs (``ndt_terms``)."""
        assert self.voxels is not None
        v = self.voxels
        return ndt_terms(source, T, v.keys, v.means, v.inv_covs, 1.0 / v.resolution,
                         self._offsets, self.d1, self.d2)

    def _align(self, source: F64, guess: F64) -> F64:
        """Levenberg-damped Gauss-Newton from ``guess``; the best pose found."""
        T = guess
        score, H, g, n = self._evaluate(source, T)
        if n < 6:
            log.debug("ndt: only %d correspondences, keeping the prediction", n)
            return T
        lam = 1e-4
        for _ in range(self.options.max_iterations):
            damped = H.copy()  # H + lam diag(max(diag(H), 1e-9)), without two 6x6 temporaries
            damped[_DIAG] += lam * np.maximum(H[_DIAG], 1e-9)
            try:
                xi = np.asarray(-np.linalg.solve(damped, g), np.float64)
            except np.linalg.LinAlgError:
                break
            cand = T @ se3_exp(xi)
            c_score, c_H, c_g, c_n = self._evaluate(source, cand)
            if c_score > score and c_n >= 6:
                T, score, H, g = cand, c_score, c_H, c_g
                lam = max(lam * 0.1, 1e-7)
                if vector_norm(xi) < self.options.convergence:
                    break
            else:
                lam *= 10.0
                if lam > 1e3:
                    break
        return orthonormalize(T)



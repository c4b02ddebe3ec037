"""``ndt``: keyframe NDT scan matching (point-to-distribution, Magnusson 2009). The voxel map
and the registration of a scan are compiled (``ndt_kernel``); this module holds the
odometry's state and its parameters.

Algorithm, per scan:
1. Source: the scan downsampled to the centroids of a voxel grid of ``source_voxel_m``
   (option, default 1.0 m; a fixed size so that ``resolution`` changes only the target).
2. Target: the keyframe (a full scan, stored in world coordinates) in a voxel grid of side
   ``resolution``; per voxel with >= ``min_points`` points the mean and the covariance,
   regularised by clamping its eigenvalues to >= 1 % of the largest (Magnusson's rule),
   and its inverse. Voxel keys are packed integer coordinates, kept sorted and in a hash
   table; a source point finds its voxel by hashing (and, with ``neighbors=7``, the 6 face
   neighbours).
3. Pose: Gauss-Newton on the NDT score sum_k -d1 exp(-d2/2 e_k^T S_k^-1 e_k) (the outlier
   ratio 0.55 gives d1, d2 as in Magnusson's thesis), i.e. iteratively reweighted least
   squares with weights -d1 d2/2 exp(...), Levenberg damping (a step is kept only when the
   score rises; else the damping grows tenfold), right-perturbation on SE(3), starting from a
   constant-velocity prediction; at most ``max_iterations`` steps, stop when a step is
   below ``convergence`` (1e-3: 1 mm / 0.06 deg).
4. Keyframe: replaced by the current scan (transformed with its estimated pose) when the path
   length travelled since the keyframe reaches ``keyframe_interval`` [m]; 0 = every frame.

Parameter changes (``set_params``) are applied in place: a new ``resolution`` rebuilds the
keyframe's voxel map from the stored keyframe points (and the score constants); a new
``keyframe_interval`` takes effect at the next keyframe decision. Pose, velocity and keyframe
are kept, so the trajectory stays continuous across a change.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from pydantic import Field

from pipeline.config import Section
from pipeline.odometry.base import (
    Adapter,
    ParameterSpace,
    Params,
    ParamSpec,
    Schedule,
)
from pipeline.odometry.common import (
    F64,
    DownsampleCache,
    StreamingAdapterBase,
    constant_velocity_guess,
    orthonormalize,
    vector_norm,
)
from pipeline.odometry.ndt_kernel import (
    build_voxels,
    key_table,
    ndt_align,
    ndt_terms,
    transform_points,
)
from pipeline.sequence import Scan

log = logging.getLogger(__name__)

SPACE = ParameterSpace((
    ParamSpec("resolution", 1.0, 10.0, 4.0, unit="m"),
    ParamSpec("keyframe_interval", 0.0, 10.0, 4.0, unit="m"),
))

# neighbours searched around a source point's own voxel
_OFFSETS = {
    1: np.zeros((1, 3), np.int64),
    7: np.array([[0, 0, 0], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]]),
}


class NdtOptions(Section):
    """Settings of ``ndt`` that are not tuned."""

    source_voxel_m: float = Field(default=1.0, gt=0, le=10)
    min_points: int = Field(default=5, ge=3)
    neighbors: int = Field(default=1, description="1 (own voxel) or 7 (and face neighbours)")
    max_iterations: int = Field(default=15, ge=1, le=100)
    convergence: float = Field(default=1e-3, gt=0, description="stop when |step| < this [rad, m]")
    outlier_ratio: float = Field(default=0.55, gt=0, lt=1)

    def model_post_init(self, __context: object) -> None:
        if self.neighbors not in _OFFSETS:
            raise ValueError(f"neighbors must be 1 or 7, got {self.neighbors}")


@dataclass
class VoxelMap:
    """NDT voxels of one keyframe: sorted keys (K,), means (K, 3), inverse covariances
    (K, 3, 3), and the hash table of the keys (``ndt_kernel.key_table``)."""

    resolution: float
    keys: NDArray[np.int64]
    means: F64
    inv_covs: F64
    slot_key: NDArray[np.int64]
    slot_index: NDArray[np.int64]

    @classmethod
    def build(cls, points_world: F64, resolution: float, min_points: int) -> VoxelMap:
        """Voxel statistics of ``points_world`` (M, 3) [m] at ``resolution`` [m]."""
        keys, means, inv_covs = build_voxels(np.ascontiguousarray(points_world, np.float64),
                                             float(resolution), int(min_points))
        return cls(resolution, keys, means, inv_covs, *key_table(keys))

    def __len__(self) -> int:
        return len(self.keys)


def score_constants(resolution: float, outlier_ratio: float) -> tuple[float, float]:
    """Magnusson's (d1, d2) of the Gaussian-plus-uniform fit; d1 < 0 < d2."""
    c1 = 10.0 * (1.0 - outlier_ratio)
    c2 = outlier_ratio / resolution**3
    d3 = -math.log(c2)
    d1 = -math.log(c1 + c2) - d3
    d2 = -2.0 * math.log((-math.log(c1 * math.exp(-0.5) + c2) - d3) / d1)
    return d1, d2


class NdtOdometry:
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
            self.keyframe_world = transform_points(points_lidar, T)
            self.travelled_m = 0.0
            self._build_map()
        return T.copy()

    def _evaluate(self, source: F64, T: F64) -> tuple[float, F64, F64, int]:
        """NDT score of ``source`` at pose ``T``, Gauss-Newton Hessian (6, 6), gradient (6,)
        and the number of point-voxel pairs (``ndt_terms``)."""
        assert self.voxels is not None
        v = self.voxels
        return ndt_terms(source, T, v.slot_key, v.slot_index, v.means, v.inv_covs,
                         1.0 / v.resolution, self._offsets, self.d1, self.d2)

    def _align(self, source: F64, guess: F64) -> F64:
        """Levenberg-damped Gauss-Newton from ``guess`` (``ndt_kernel.ndt_align``); the best
        pose found, its rotation re-orthonormalised (the prediction as is when fewer than 6
        point-voxel pairs were found)."""
        assert self.voxels is not None
        v = self.voxels
        T, optimised = ndt_align(source, guess, v.slot_key, v.slot_index, v.means, v.inv_covs,
                                 1.0 / v.resolution, self._offsets, self.d1, self.d2,
                                 self.options.max_iterations, self.options.convergence)
        if not optimised:
            log.debug("ndt: fewer than 6 correspondences, keeping the prediction")
            return T
        return orthonormalize(T)


class NdtAdapter(StreamingAdapterBase):
    """The ``ndt`` adapter: keyframe NDT, parameters ``resolution`` and ``keyframe_interval``."""

    name = "ndt"
    space = SPACE
    options_model = NdtOptions
    odometry_class = NdtOdometry
    options: NdtOptions

    def __init__(self, **options: object) -> None:
        super().__init__(**options)
        self.sources = DownsampleCache()
        """The source clouds of the scans this adapter was warmed with (``warm``)."""

    def start(self, params: Params) -> NdtOdometry:
        """A streaming odometry with ``params`` (validated; missing ones take defaults) and the
        source clouds of the warmed scans."""
        return NdtOdometry(params, self.options, self.sources, self.space)

    def warm(self, scans: list[Scan]) -> None:
        """Downsample the source cloud of every scan once (it depends on no tuned parameter);
        later runs of this adapter over these Scan objects take it from ``self.sources``. A
        two-frame run loads the compiled kernel into this process."""
        self.sources.fill([scan.xyz for scan in scans], self.options.source_voxel_m)
        if len(scans) >= 2:
            self.run(scans[:2], Schedule.constant(self.space.defaults(), 2))


_: type[Adapter] = NdtAdapter

"""``gicp``: keyframe GICP on small_gicp (the paper's KITTI algorithm).

Per scan: the scan is voxel-grid downsampled (``downsampling_resolution`` [m]), its point
covariances estimated from ``num_neighbors`` neighbours, and it is registered by small_gicp's
GICP against the current keyframe (its downsampled cloud, covariances and KdTree are cached),
with pairs farther than ``max_correspondence_distance`` [m] rejected, starting from a
constant-velocity prediction. The keyframe is replaced by the current scan when the path
length travelled since the keyframe reaches ``keyframe_interval`` [m]. One thread
(``num_threads`` option), so trials in parallel processes do not compete.

Parameter changes (``set_params``), applied in place: ``max_correspondence_distance`` and
``keyframe_interval`` take effect at the next scan; a new ``downsampling_resolution``
re-downsamples the stored raw keyframe points (covariances and KdTree rebuilt). Pose,
velocity and keyframe pose are kept, so the trajectory stays continuous across a change.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray
from pydantic import Field

from pipeline.config import Section
from pipeline.odometry.base import Adapter, ParameterSpace, Params, ParamSpec
from pipeline.odometry.common import F64, StreamingAdapterBase, constant_velocity_guess

SPACE = ParameterSpace((
    ParamSpec("max_correspondence_distance", 1.0, 10.0, 4.0, unit="m"),
    ParamSpec("keyframe_interval", 1.0, 30.0, 4.0, unit="m"),
    ParamSpec("downsampling_resolution", 0.1, 2.0, 0.25, log=True, unit="m"),
))


class GicpOptions(Section):
    """Settings of ``gicp`` that are not tuned."""

    num_threads: int = Field(default=1, ge=1, le=64)
    num_neighbors: int = Field(default=10, ge=5, le=50)
    max_iterations: int = Field(default=20, ge=1, le=200)


class GicpOdometry:
    """Streaming keyframe GICP: ``step`` one scan at a time, ``set_params`` between scans."""

    def __init__(self, params: Params, options: GicpOptions | None = None,
                 space: ParameterSpace = SPACE) -> None:
        self.options = options or GicpOptions()
        self.space = space
        self.params = self.space.validate(params)
        self.poses: list[F64] = []
        self.travelled_m = 0.0
        self.keyframe_raw: F64 | None = None  # (M, 3) keyframe points in its own frame
        self.T_world_keyframe = np.eye(4)
        self._keyframe: Any = None  # (small_gicp.PointCloud, small_gicp.KdTree)

    def set_params(self, params: Params) -> None:
        """In place; a new downsampling resolution rebuilds the keyframe cloud from raw points."""
        new = self.space.validate(params)
        redo = new["downsampling_resolution"] != self.params["downsampling_resolution"]
        self.params = new
        if redo and self.keyframe_raw is not None:
            self._keyframe = self._preprocess(self.keyframe_raw, with_tree=True)

    def _preprocess(self, points: F64, with_tree: bool) -> tuple[Any, Any]:
        """Downsampled small_gicp.PointCloud with covariances (and its KdTree)."""
        import small_gicp

        n_threads = self.options.num_threads
        cloud = small_gicp.voxelgrid_sampling(points, self.params["downsampling_resolution"],
                                              num_threads=n_threads)
        tree = small_gicp.KdTree(cloud, num_threads=n_threads)
        small_gicp.estimate_covariances(cloud, tree, num_neighbors=self.options.num_neighbors,
                                        num_threads=n_threads)
        return cloud, tree if with_tree else None

    def step(self, points_lidar: NDArray[np.float32], stamp_ns: int) -> F64:
        """Register one scan ((N, 3) float32 [m]); T_world_lidar (4, 4), the first is identity."""
        import small_gicp

        pts = np.ascontiguousarray(np.asarray(points_lidar, dtype=np.float64)[:, :3])
        source = self._preprocess(pts, with_tree=True)
        if not self.poses:
            T = np.eye(4)
        else:
            guess = constant_velocity_guess(self.poses)
            target, tree = self._keyframe
            result = small_gicp.align(
                target, source[0], tree,
                init_T_target_source=np.linalg.solve(self.T_world_keyframe, guess),
                registration_type="GICP",
                max_correspondence_distance=self.params["max_correspondence_distance"],
                num_threads=self.options.num_threads, max_iterations=self.options.max_iterations)
            T = self.T_world_keyframe @ result.T_target_source
            self.travelled_m += float(np.linalg.norm(T[:3, 3] - self.poses[-1][:3, 3]))
        self.poses.append(T)
        if self._keyframe is None or self.travelled_m >= self.params["keyframe_interval"]:
            self.keyframe_raw = pts
            self.T_world_keyframe = T
            self._keyframe = source
            self.travelled_m = 0.0
        return T.copy()


class GicpAdapter(StreamingAdapterBase):
    """The ``gicp`` adapter: keyframe GICP on small_gicp."""

    name = "gicp"
    space = SPACE
    options_model = GicpOptions
    odometry_class = GicpOdometry


_: type[Adapter] = GicpAdapter

"""``kiss_icp``: the KISS-ICP package (Vizzo et al., RA-L 2023) behind the black-box contract.

Parameters and baseline = KISS-ICP's own defaults (kiss_icp.config): ``max_range`` 100 m,
``min_range`` 0 m, ``voxel_size`` = max_range / 100 = 1.0 m (KISS-ICP derives it from
max_range when unset; we fix it at that value so the baseline is one point of the space),
``initial_threshold`` 2.0 m, ``min_motion_th`` 0.1 m, ``max_points_per_voxel`` 20.
Not tuned (options): ``deskew`` (True: KISS-ICP corrects each scan's motion distortion with
its per-point times, where the sequence MCAP has them: the PointCloud2 field ``time``, kept by
``ingest`` from the drivers' ``t`` / ``time`` / ``timestamp`` / ``offset_time``, or written by
``simulate`` for swept scans, its default; a scan without them, as KITTI's, is registered as it
is; False: never; KISS-ICP deskews a scan with its previous motion estimate, so the first
scan of a drive that starts moving enters the map smeared: docs/results/realism.md, "Why
KISS-ICP breaks on swept scans"),
``max_num_threads`` (1), ``max_num_iterations`` (500), ``convergence_criterion`` (1e-4).

Parameter changes (``set_params``) rebuild the KissICP object with the new configuration and
hand over: the last pose and the last relative motion (the constant-velocity prediction),
the local map's points (re-inserted into the new voxel map, so a new voxel size or points per
voxel re-voxelises them; a new max_range prunes them at the next update), and the adaptive
threshold's state, by replaying every past model deviation into the new estimator (so it is
the state the new min_motion_th / max_range would have reached). Nothing else is kept.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray
from pydantic import Field

from pipeline.config import Section
from pipeline.odometry.base import Adapter, ParameterSpace, Params, ParamSpec
from pipeline.odometry.common import F64, StreamingAdapterBase

SPACE = ParameterSpace((
    ParamSpec("voxel_size", 0.2, 3.0, 1.0, log=True, unit="m"),
    ParamSpec("max_range", 20.0, 200.0, 100.0, unit="m"),
    ParamSpec("min_range", 0.0, 10.0, 0.0, unit="m"),
    ParamSpec("initial_threshold", 0.1, 5.0, 2.0, log=True, unit="m"),
    ParamSpec("min_motion_th", 0.01, 1.0, 0.1, log=True, unit="m"),
    ParamSpec("max_points_per_voxel", 1.0, 50.0, 20.0, kind="int"),
))


class KissOptions(Section):
    """Settings of ``kiss_icp`` that are not tuned."""

    deskew: bool = True
    max_num_threads: int = Field(default=1, ge=0, le=64)
    max_num_iterations: int = Field(default=500, ge=1)
    convergence_criterion: float = Field(default=1e-4, gt=0)


def kiss_config(params: Params, options: KissOptions) -> Any:
    """A kiss_icp KISSConfig of ``params`` and ``options``."""
    from kiss_icp.config import KISSConfig
    from kiss_icp.config.config import (
        AdaptiveThresholdConfig,
        DataConfig,
        MappingConfig,
        RegistrationConfig,
    )

    return KISSConfig(
        data=DataConfig(max_range=params["max_range"], min_range=params["min_range"],
                        deskew=options.deskew),
        mapping=MappingConfig(voxel_size=params["voxel_size"],
                              max_points_per_voxel=int(params["max_points_per_voxel"])),
        registration=RegistrationConfig(max_num_iterations=options.max_num_iterations,
                                        convergence_criterion=options.convergence_criterion,
                                        max_num_threads=options.max_num_threads),
        adaptive_threshold=AdaptiveThresholdConfig(
            initial_threshold=params["initial_threshold"], min_motion_th=params["min_motion_th"]),
    )


class KissOdometry:
    """Streaming KISS-ICP: ``step`` one scan at a time, ``set_params`` between scans."""

    def __init__(self, params: Params, options: KissOptions | None = None,
                 space: ParameterSpace = SPACE) -> None:
        from kiss_icp.kiss_icp import KissICP

        self.options = options or KissOptions()
        self.space = space
        self.params = self.space.validate(params)
        self.kiss = KissICP(kiss_config(self.params, self.options))
        self.deviations: list[F64] = []  # model deviation of every frame, for the handover

    def set_params(self, params: Params) -> None:
        """Rebuild KissICP with the new parameters; pose, motion, map and threshold handed over."""
        from kiss_icp.kiss_icp import KissICP

        new = self.space.validate(params)
        if new == self.params:
            return
        old = self.kiss
        kiss = KissICP(kiss_config(new, self.options))
        kiss.last_pose = old.last_pose.copy()
        kiss.last_delta = old.last_delta.copy()
        map_points = old.local_map.point_cloud()
        if len(map_points):
            kiss.local_map.add_points(np.ascontiguousarray(map_points, dtype=np.float64))
        for dev in self.deviations:
            kiss.adaptive_threshold.update_model_deviation(dev)
        self.kiss, self.params = kiss, new

    deskews = True
    """``run_streaming`` hands this odometry each scan's per-point times (``time_s``)."""

    def step(self, points_lidar: NDArray[np.float32], stamp_ns: int,
             time_s: NDArray[np.float32] | None = None) -> F64:
        """Register one scan ((N, 3) float32 [m]; ``time_s`` (N,) per-point time [s], used
        when the ``deskew`` option is on); T_world_lidar (4, 4), the first is identity."""
        pts = np.ascontiguousarray(np.asarray(points_lidar, dtype=np.float64)[:, :3])
        guess = self.kiss.last_pose @ self.kiss.last_delta
        use_time = self.options.deskew and time_s is not None and len(time_s) == len(pts)
        times = np.asarray(time_s, np.float64) if use_time else np.zeros(0)
        self.kiss.register_frame(pts, times)
        T = np.array(self.kiss.last_pose, dtype=np.float64)
        self.deviations.append(np.linalg.solve(guess, T))
        return T


class KissIcpAdapter(StreamingAdapterBase):
    """The ``kiss_icp`` adapter."""

    name = "kiss_icp"
    space = SPACE
    options_model = KissOptions
    odometry_class = KissOdometry


_: type[Adapter] = KissIcpAdapter

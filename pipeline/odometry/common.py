"""Small pieces shared by the in-process adapters: their shell (``StreamingAdapterBase``),
option models, SE(3) updates, voxel keys."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, Any, ClassVar, TypeVar

import numpy as np
from numpy.typing import NDArray

from pipeline.config import Section, validate_section
from pipeline.odometry.base import Odometry, ParameterSpace, Params, Schedule, run_streaming
from pipeline.odometry.voxel_key import KEY_MAX, KEY_OFFSET
from pipeline.trajectory import Trajectory

if TYPE_CHECKING:
    from pipeline.sequence import Scan

F64 = NDArray[np.float64]
OptionsT = TypeVar("OptionsT", bound=Section)



def parse_options(model: type[OptionsT], adapter: str, options: dict[str, Any]) -> OptionsT:
    """Validated adapter ``options`` (CLI strings are converted); ConfigError naming them."""
    return validate_section(model, f"{adapter} option", options)


class StreamingAdapterBase:
    """The shell every in-process adapter shares: ``name``, its parameter ``space`` (the
    baseline = its defaults; ``with_space`` replaces it), its untuned options validated by
    ``options_model``, ``start(params)`` -> a streaming ``odometry_class(params, options,
    space)`` and ``run`` through ``run_streaming`` (one scan at a time, the schedule's
    parameters pushed between scans). A new adapter subclasses it and writes its odometry."""

    name: str
    space: ParameterSpace
    options_model: ClassVar[type[Section]]
    odometry_class: ClassVar[Callable[..., Odometry]]

    def __init__(self, **options: object) -> None:
        self.options = parse_options(self.options_model, self.name, dict(options))

    def start(self, params: Params) -> Odometry:
        """A streaming odometry with ``params`` (validated; missing ones take defaults)."""
        return self.odometry_class(params, self.options, self.space)

    def run(self, scans: Iterable[Scan], schedule: Schedule) -> Trajectory:
        """Run over ``scans`` with the per-frame ``schedule``."""
        return run_streaming(self.start, scans, schedule)


def voxel_indices(points: F64, voxel_m: float) -> NDArray[np.int64]:
    """(N, 3) int64 integer coordinates of the voxels of side ``voxel_m`` holding ``points``."""
    return np.floor(points * (1.0 / voxel_m)).astype(np.int64)


def pack_keys(ijk: NDArray[np.int64]) -> NDArray[np.int64]:
    """(N,) int64 keys of integer voxel coordinates (N, 3) (21 bits an axis, clipped)."""
    ijk = ijk + KEY_OFFSET
    np.clip(ijk, 0, KEY_MAX, out=ijk)
    return (ijk[:, 0] << 42) | (ijk[:, 1] << 21) | ijk[:, 2]


def voxel_keys(points: F64, voxel_m: float) -> NDArray[np.int64]:
    """(N,) int64 keys of the voxels of side ``voxel_m`` holding ``points`` (N, 3) [m]."""
    return pack_keys(voxel_indices(points, voxel_m))


def voxel_downsample(points: NDArray[np.floating], voxel_m: float) -> F64:
    """Centroid of the points (N, 3) [m] in every occupied voxel of side ``voxel_m``; (M, 3)
    float64, ordered by voxel key (compiled: ``pipeline.odometry.voxel_kernel``)."""
    from pipeline.odometry.voxel_kernel import sorted_centroids, voxel_keys_of

    if voxel_m <= 0 or len(points) == 0:
        return np.array(points, dtype=np.float64)
    keys = voxel_keys_of(points, 1.0 / voxel_m)  # strided views as they are: no copy
    return sorted_centroids(points, keys, np.argsort(keys))


class DownsampleCache:
    """Voxel-downsampled scans computed ahead of time (``fill``) and looked up by array.

    A tuning run gives the same scans to hundreds of trials; what depends only on a scan and
    untuned options (the ``ndt`` source cloud) is computed once per worker and study
    (``Adapter.warm``) and kept by the adapter instance the worker runs its trials with. Keys
    are the array object (its address, shape and strides) and the voxel size; the cache keeps
    a reference to every keyed array, so an address cannot be reused while its entry lives.
    Scans must not be modified (the adapter contract). A lookup that misses computes the
    result without storing it, so runs outside a tuning loop never grow the cache.
    """

    def __init__(self) -> None:
        self._entries: dict[tuple[int, tuple[int, ...], tuple[int, ...], float],
                            tuple[NDArray[Any], F64]] = {}

    @staticmethod
    def _key(points: NDArray[Any], voxel_m: float) -> tuple[int, tuple[int, ...],
                                                            tuple[int, ...], float]:
        return (points.__array_interface__["data"][0], points.shape, points.strides,
                float(voxel_m))

    def fill(self, clouds: list[NDArray[Any]], voxel_m: float) -> None:
        """Replace the cache by the downsampled ``clouds`` ((N, 3) arrays [m])."""
        self._entries = {self._key(c, voxel_m): (c, voxel_downsample(c, voxel_m))
                         for c in clouds}

    def get(self, points: NDArray[Any], voxel_m: float) -> F64:
        """``voxel_downsample(points, voxel_m)``, from the cache when it was filled with it."""
        hit = self._entries.get(self._key(points, voxel_m))
        return hit[1] if hit is not None else voxel_downsample(points, voxel_m)

    def __len__(self) -> int:
        return len(self._entries)


def vector_norm(v: F64) -> float:
    """Euclidean norm of a vector (n,): ``np.linalg.norm(v)`` to the last bit (it is
    ``sqrt(v.dot(v))`` too), without its per-call overhead (NDT calls it ~15 times a scan)."""
    return math.sqrt(float(v.dot(v)))


def hat(v: F64) -> F64:
    """Skew-symmetric matrices (..., 3, 3) of vectors (..., 3)."""
    out = np.zeros((*v.shape[:-1], 3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def so3_exp(w: F64) -> F64:
    """Rotation (3, 3) of the rotation vector ``w`` (3,) [rad] (Rodrigues)."""
    theta = vector_norm(w)
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

"""The NDT voxel classification histogram, the paper's environment descriptor (docs/design.md,
"Environment").

A scan is cut into cubic voxels; every voxel with at least ``min_points`` points gets the
eigenvalues l1 >= l2 >= l3 of its point covariance and is classified

- linear     if l2 / l1 < t_e                        (poles, trunks, edges, single scan rings),
- planar     if l3 / l2 < t_e (and not linear)       (ground, walls, roofs),
- spherical  otherwise                               (vegetation, clutter, rough rock),

and then into three sub-classes each. The counts per (class, sub-class) are accumulated in
``range_bins`` range bins of ``bin_m`` metres: 3 x 3 x 10 = 90 values.

Choices the paper (Koide et al., IROS 2021) leaves open, made here:

- Voxel grid: axis-aligned in the sensor frame, a corner at the sensor origin. Points farther
  than ``range_bins * bin_m`` (30 m) from the sensor are dropped before voxelising (the
  histogram has no bin for them).
- Range of a voxel: the 3-D distance of its point mean from the sensor origin.
- Covariance: the maximum-likelihood (1/n) covariance of the voxel's points.
- A voxel belongs to one range bin (by its mean), the crop is per point: a voxel cut by the
  30 m sphere keeps its inner points only.
- Sub-classes (angles in degrees; 30 / 60 split the quarter circle into thirds):
  linear: elevation of the principal axis v1 above the horizontal plane,
  asin(|v1_z|) in [0, 30) "horizontal", [30, 60) "oblique", [60, 90] "vertical";
  planar: tilt of the normal v3 from the vertical, acos(|v3_z|) in [0, 30) "horizontal plane"
  (ground, ceiling), [30, 60) "slope", [60, 90] "vertical plane" (wall);
  spherical: the ratio l2 / l1 in [t_e, 1], split into thirds of that interval: elongated blob,
  flat-ish blob, isotropic blob.
  Only |v_z| is used, so the histogram does not depend on the sign of an eigenvector.
- Layout of the 90 values: index = range_bin * 9 + class * 3 + sub_class with class 0 linear,
  1 planar, 2 spherical (sub-classes as listed above).
- Normalisation (``normalize=True``, the default): counts divided by the number of classified
  voxels, so the histogram sums to 1 (0 everywhere for a scan without a classified voxel).
  This makes the descriptor independent of the sensor's point count and voxel size, and keeps
  the shape of the environment; ``normalize=False`` returns the raw counts.
- Yaw invariance: classes, tilts, eigenvalue ratios and ranges do not change under a rotation
  about z; only the axis-aligned voxel boundaries move with the rotation, so a rotated scan
  gives a nearly (not bit-) equal histogram (tests/test_descriptor.py states the tolerance).

Speed: one pass of integer arithmetic and ``np.bincount`` (no sort): a dense voxel index over
the bounding box of the cropped scan, first moments and second moments per voxel by weighted
bincounts of coordinates relative to the voxel corner (well conditioned in float64), closed-
form eigenvalues of symmetric 3x3 matrices, eigenvectors by cross products. The voxel moments
have two implementations with the same result: a numba kernel (three passes over the points,
no per-point temporaries; used when numba is installed, compiled on first use) and the numpy
reference ``voxel_moments`` (used without numba, or for a bounding box of more than
``_DENSE_MAX_CELLS`` cells). The numpy path allocates a dozen (N,) temporaries per scan, and
their page faults make it 2-4 times slower and noisier on a virtual machine.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import ConfigError

if TYPE_CHECKING:
    from pipeline.descriptors.ndt_histogram_kernel import Moments

N_CLASSES = 3
N_SUB = 3
CLASS_NAMES = ("linear", "planar", "spherical")
SUB_NAMES = (
    ("horizontal", "oblique", "vertical"),
    ("horizontal_plane", "slope", "vertical_plane"),
    ("elongated", "flat", "isotropic"),
)
_DENSE_MAX_CELLS = 1_000_000  # above this the bounding box grid falls back to np.unique


@dataclass(frozen=True)
class NdtHistogram:
    """The NDT voxel classification histogram with its settings (module docstring); a
    ``pipeline.descriptors.Descriptor``, registered as ``ndt_histogram``.

    voxel_size_m: edge of a cubic voxel [m]; min_points: voxels with fewer points are skipped;
    t_e: eigenvalue ratio threshold; range_bins x bin_m: the range histogram [m];
    normalize: divide by the number of classified voxels. Width: range_bins * 9 values.
    """

    type: ClassVar[str] = "ndt_histogram"
    manifest_schema: ClassVar[dict[str, Any]] = {
        "required": ["voxel_size_m", "min_points", "t_e", "range_bins", "bin_m", "normalize"],
        "properties": {"voxel_size_m": {"type": "number", "exclusiveMinimum": 0},
                       "min_points": {"type": "integer", "minimum": 3},
                       "t_e": {"type": "number", "exclusiveMinimum": 0, "exclusiveMaximum": 1},
                       "range_bins": {"type": "integer", "minimum": 1},
                       "bin_m": {"type": "number", "exclusiveMinimum": 0},
                       "normalize": {"type": "boolean"}}}
    """The JSON Schema of ``to_json`` (the artifact's descriptor block)."""

    voxel_size_m: float = 1.0
    min_points: int = 5
    t_e: float = 0.1
    range_bins: int = 10
    bin_m: float = 3.0
    normalize: bool = True

    def __post_init__(self) -> None:
        for name, kind in (("voxel_size_m", float), ("min_points", int), ("t_e", float),
                           ("range_bins", int), ("bin_m", float), ("normalize", bool)):
            object.__setattr__(self, name, _typed(name, getattr(self, name), kind))
        if not self.voxel_size_m > 0:
            raise ConfigError(f"voxel_size_m must be > 0, got {self.voxel_size_m}")
        if self.min_points < 3:
            raise ConfigError(f"min_points must be >= 3, got {self.min_points}")
        if not 0 < self.t_e < 1:
            raise ConfigError(f"t_e must be in (0, 1), got {self.t_e}")
        if self.range_bins < 1 or not self.bin_m > 0:
            raise ConfigError(
                f"range_bins must be >= 1 and bin_m > 0, got ({self.range_bins}, {self.bin_m})"
            )

    @property
    def size(self) -> int:
        """Width of the descriptor: range_bins * 9 values."""
        return self.range_bins * N_CLASSES * N_SUB

    @property
    def max_range_m(self) -> float:
        return self.range_bins * self.bin_m

    def describe(self, points_lidar: NDArray[np.floating]) -> NDArray[np.float32]:
        """``describe(points_lidar, self)``: (size,) float32."""
        return describe(points_lidar, self)

    def value_names(self) -> list[str]:
        """``bin_names(self)``."""
        return bin_names(self)

    def to_json(self) -> dict[str, object]:
        """type, the settings, and the width ``size``."""
        return {"type": self.type, **asdict(self), "size": self.size}


def _typed(name: str, value: object, kind: type) -> object:
    """``value`` as ``kind`` (an int for an integral float, a float for an int); ConfigError
    when it is not a number of that kind (or not a bool for a bool)."""
    if kind is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{name} must be true or false, got {value!r}")
        return value
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ConfigError(f"{name} must be a number, got {value!r}")
    if kind is int:
        if value != int(value):
            raise ConfigError(f"{name} must be an integer, got {value!r}")
        return int(value)
    return float(value)


def describe(
    points_lidar: NDArray[np.floating], config: NdtHistogram = NdtHistogram()
) -> NDArray[np.float32]:
    """The descriptor of one scan: (config.size,) float32 (90 values by default).

    points_lidar: (N, 3) or (N, 4) points in the sensor frame [m] (a 4th column is ignored).
    """
    counts, mean, cov = _moments(points_lidar, config)
    hist = np.zeros((config.range_bins, N_CLASSES, N_SUB), np.float64)
    if len(counts):
        cls, sub = classify(cov, config.t_e)
        rbin = np.minimum(
            (np.linalg.norm(mean, axis=1) / config.bin_m).astype(np.int64), config.range_bins - 1
        )
        flat = (rbin * N_CLASSES + cls) * N_SUB + sub
        hist = np.bincount(flat, minlength=config.size).astype(np.float64)
        if config.normalize:
            hist /= len(counts)
    return np.asarray(hist, np.float32).reshape(-1)


def _moments(
    points_lidar: NDArray[np.floating], config: NdtHistogram
) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
    """``voxel_moments`` of the cropped scan, by the numba kernel where it is available."""
    kernel = _moments_kernel()
    if kernel is not None:
        pts = _check_points(points_lidar)
        ok, counts, mean, cov = kernel(
            np.ascontiguousarray(pts, np.float32),
            config.voxel_size_m,
            config.max_range_m,
            config.min_points,
            _DENSE_MAX_CELLS,
        )
        if ok:
            return counts, mean, cov
    xyz = _crop(points_lidar, config.max_range_m)
    return voxel_moments(xyz, config.voxel_size_m, config.min_points)


def _check_points(points_lidar: NDArray[np.floating]) -> NDArray[np.floating]:
    pts = np.asarray(points_lidar)
    if pts.ndim != 2 or pts.shape[1] < 3:
        raise ValueError(f"points must be (N, 3) or (N, 4), got {pts.shape}")
    return pts


def _crop(
    points_lidar: NDArray[np.floating], max_range_m: float
) -> tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.float32]]:
    """x, y, z (each (M,) float32) of the finite points within ``max_range_m`` of the sensor.

    The kept points are interleaved (stride ``_STRIDE``): neighbouring scan points fall into the
    same voxel, and ``np.bincount`` runs about twice as fast when consecutive points do not.
    """
    pts = _check_points(points_lidar)
    if pts.dtype != np.float32:
        pts = pts.astype(np.float32)
    x, y, z = pts[:, 0], pts[:, 1], pts[:, 2]
    r2 = x * x
    r2 += y * y
    r2 += z * z
    keep = np.flatnonzero(r2 < max_range_m * max_range_m)  # NaN compares False: dropped
    k = len(keep) // _STRIDE * _STRIDE
    if k:
        keep[:k] = keep[:k].reshape(_STRIDE, -1).T.reshape(-1)
    return x.take(keep), y.take(keep), z.take(keep)


_STRIDE = 16


def voxel_moments(
    xyz: tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.float32]],
    voxel_size_m: float,
    min_points: int,
) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
    """Per voxel with >= min_points points: counts (M,), mean (M, 3) [m], covariance (M, 3, 3).

    xyz: the point coordinates x, y, z [m], each (N,) float32 (as ``_crop`` returns them).
    Voxels are ordered by cell index (x slowest, z fastest).
    Sums of raw float64 coordinates: |p| < 30 m, so E[pp^T] - mu mu^T loses < 1e-12 m^2.
    """
    empty = (np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3, 3)))
    if len(xyz[0]) < min_points:
        return empty
    inv = np.float32(1.0 / voxel_size_m)
    cells = [np.floor(c * inv) for c in xyz]
    # raw coordinates in float64: |p| < 30 m, so E[pp^T] - mu mu^T loses < 1e-12 m^2
    x, y, z = (c.astype(np.float64) for c in xyz)
    lo = np.array([c.min() for c in cells], np.int64)
    dims = np.array([c.max() for c in cells], np.int64) - lo + 1
    n_cells = int(dims[0] * dims[1] * dims[2])
    if n_cells >= 2**24:  # float32 cell keys are exact below 2^24
        key = (
            (cells[0].astype(np.int64) - lo[0]) * dims[1] + (cells[1].astype(np.int64) - lo[1])
        ) * dims[2] + (cells[2].astype(np.int64) - lo[2])
    else:
        kf = cells[0] * np.float32(dims[1] * dims[2])
        kf += cells[1] * np.float32(dims[2])
        kf += cells[2]
        kf -= np.float32((lo[0] * dims[1] + lo[1]) * dims[2] + lo[2])
        key = kf.astype(np.intp)
    if n_cells <= _DENSE_MAX_CELLS:
        nb, uniq = n_cells, None  # bins = every cell of the bounding box
    else:
        uniq, key = np.unique(key, return_inverse=True)
        key = key.reshape(-1)
        nb = len(uniq)
    count = np.bincount(key, minlength=nb)
    occ = np.flatnonzero(count >= min_points)
    m = len(occ)
    if m == 0:
        return empty
    n = count[occ].astype(np.float64)
    inv_n = 1.0 / n
    buf = np.empty_like(x)
    s = [np.bincount(key, w, minlength=nb)[occ] * inv_n for w in (x, y, z)]
    e = []
    for a, b in ((x, x), (x, y), (x, z), (y, y), (y, z), (z, z)):
        np.multiply(a, b, out=buf)
        e.append(np.bincount(key, buf, minlength=nb)[occ] * inv_n)
    cov = np.empty((m, 3, 3))
    cov[:, 0, 0] = e[0] - s[0] * s[0]
    cov[:, 0, 1] = cov[:, 1, 0] = e[1] - s[0] * s[1]
    cov[:, 0, 2] = cov[:, 2, 0] = e[2] - s[0] * s[2]
    cov[:, 1, 1] = e[3] - s[1] * s[1]
    cov[:, 1, 2] = cov[:, 2, 1] = e[4] - s[1] * s[2]
    cov[:, 2, 2] = e[5] - s[2] * s[2]
    return n.astype(np.int64), np.stack(s, axis=1), cov


@functools.cache
def _moments_kernel() -> Callable[..., Moments] | None:
    """``pipeline.descriptors.ndt_histogram_kernel.voxel_moments_dense`` (numba), or None
    without numba.

    Imported on first use: numba takes a second to import, and ``adaptune --help`` must not.
    """
    try:
        from pipeline.descriptors.ndt_histogram_kernel import voxel_moments_dense
    except ImportError:  # pragma: no cover - numba is a dependency; the numpy path stays exact
        return None
    kernel: Callable[..., Moments] = voxel_moments_dense
    return kernel


def sym3_eigvals(cov: NDArray[np.float64]) -> NDArray[np.float64]:
    """Eigenvalues of symmetric 3x3 matrices, closed form (trigonometric): (M, 3), l1>=l2>=l3."""
    a00, a11, a22 = cov[:, 0, 0], cov[:, 1, 1], cov[:, 2, 2]
    a01, a02, a12 = cov[:, 0, 1], cov[:, 0, 2], cov[:, 1, 2]
    q = (a00 + a11 + a22) / 3.0
    p1 = a01 * a01 + a02 * a02 + a12 * a12
    b00, b11, b22 = a00 - q, a11 - q, a22 - q
    p2 = b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * p1
    p = np.sqrt(p2 / 6.0)
    safe = np.where(p > 0, p, 1.0)
    det = (
        b00 * (b11 * b22 - a12 * a12)
        - a01 * (a01 * b22 - a12 * a02)
        + a02 * (a01 * a12 - b11 * a02)
    )
    r = np.clip(det / (2.0 * safe**3), -1.0, 1.0)
    phi = np.arccos(r) / 3.0
    l1 = q + 2.0 * p * np.cos(phi)
    l3 = q + 2.0 * p * np.cos(phi + 2.0 * np.pi / 3.0)
    l2 = 3.0 * q - l1 - l3
    out = np.stack([l1, l2, l3], axis=1)
    return np.maximum(out, 0.0)  # covariances are PSD; clip round-off


def sym3_eigvec_z(cov: NDArray[np.float64], lam: NDArray[np.float64]) -> NDArray[np.float64]:
    """|z component| of the unit eigenvector of each ``cov`` (M, 3, 3) for eigenvalue ``lam`` (M,).

    The eigenvector spans the null space of (cov - lam I): the largest cross product of two of
    its rows. Only valid for a simple eigenvalue (which l1 of a linear and l3 of a planar
    voxel are, by the thresholds).
    """
    a00 = cov[:, 0, 0] - lam
    a11 = cov[:, 1, 1] - lam
    a22 = cov[:, 2, 2] - lam
    a01, a02, a12 = cov[:, 0, 1], cov[:, 0, 2], cov[:, 1, 2]
    # rows r0 = (a00, a01, a02), r1 = (a01, a11, a12), r2 = (a02, a12, a22); their cross products
    c01 = np.stack([a01 * a12 - a02 * a11, a02 * a01 - a00 * a12, a00 * a11 - a01 * a01])
    c02 = np.stack([a01 * a22 - a02 * a12, a02 * a02 - a00 * a22, a00 * a12 - a01 * a02])
    c12 = np.stack([a11 * a22 - a12 * a12, a12 * a02 - a01 * a22, a01 * a12 - a11 * a02])
    cands = np.stack([c01, c02, c12])  # (3 candidates, 3 components, M)
    norms = np.einsum("kjm,kjm->km", cands, cands)
    best = np.argmax(norms, axis=0)
    idx = np.arange(len(lam))
    vz = cands[best, 2, idx]
    nv = np.sqrt(norms[best, idx])
    return np.abs(vz) / np.where(nv > 0, nv, 1.0)


_SIN30, _SIN60 = 0.5, np.sqrt(3.0) / 2.0


def classify(cov: NDArray[np.float64], t_e: float) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Class (0 linear, 1 planar, 2 spherical) and sub-class (0..2) of each voxel: (M,) each."""
    lam = sym3_eigvals(cov)
    l1, l2, l3 = lam[:, 0], lam[:, 1], lam[:, 2]
    tiny = 1e-300
    r21 = l2 / np.maximum(l1, tiny)
    r32 = l3 / np.maximum(l2, tiny)
    linear = r21 < t_e
    planar = ~linear & (r32 < t_e)
    cls = np.full(len(cov), 2, np.int64)
    cls[linear] = 0
    cls[planar] = 1
    sub = np.zeros(len(cov), np.int64)
    if linear.any():
        # elevation of the line: sin(elev) = |v1_z|; bins at sin 30 and sin 60
        vz = sym3_eigvec_z(cov[linear], l1[linear])
        sub[linear] = (vz >= _SIN30).astype(np.int64) + (vz >= _SIN60)
    if planar.any():
        # tilt of the normal from vertical: cos(tilt) = |v3_z|; tilt < 30 -> 0, >= 60 -> 2
        nz = sym3_eigvec_z(cov[planar], l3[planar])
        sub[planar] = (nz <= _SIN60).astype(np.int64) + (nz <= _SIN30)
    sph = cls == 2
    if sph.any():
        u = (r21[sph] - t_e) / (1.0 - t_e)
        sub[sph] = np.clip((u * 3.0).astype(np.int64), 0, 2)
    return cls, sub


def bin_names(config: NdtHistogram = NdtHistogram()) -> list[str]:
    """Human-readable name of every descriptor value, e.g. ``r03_planar_vertical_plane``."""
    return [
        f"r{b:02d}_{CLASS_NAMES[c]}_{SUB_NAMES[c][s]}"
        for b in range(config.range_bins)
        for c in range(N_CLASSES)
        for s in range(N_SUB)
    ]

"""How wrong KITTI's ground truth is from one frame to the next, and that error added to the
simulated side (docs/simulator.md, "The ground truth's own error").

The real step error of an odometry is e = g + a: the ground truth's error g (OXTS RT3003 poses
through the calibration, and KITTI's motion compensation of the scans; the same for every
odometry) plus the odometry's own error a. Two parts of g are measured:
- systematic: two odometries that work differently (GICP, plane to plane; KISS-ICP, point to
  point) have different own errors, so the mean step error both show is the ground truth's
  bias on that stretch: per axis (translation [m], rotation vector [rad]) the smaller of the
  two means where they have the same sign, else 0 (what both agree on at least);
- random: white noise. Two bounds of its variance, each too large in its own way: the
  trajectory's (``white_sigma``: third differences of the relative motions, which a smooth
  drive keeps near zero; it also counts the car body's real quick motions) and the variance
  the two odometries share (mean((e1 - m)(e2 - m)); it also counts what both get wrong on the
  same hard frames). Per axis the smaller one is taken.
A slice's ground-truth error is modelled as g ~ N(m, diag(variance)) a step; the simulated
side, scored against its exact ground truth, gets such a g composed onto each step error, so
both sides carry the same ground-truth error.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class GroundTruthError:
    """A slice's ground-truth step error model: mean (6,) and per-axis variance (6,) of
    (translation [m], rotation vector [rad])."""

    mean: tuple[float, ...]
    variance: tuple[float, ...]

    @property
    def rms_t_cm(self) -> float:
        """RMS translational ground-truth error of a step [cm]."""
        m, v = np.asarray(self.mean[:3]), np.asarray(self.variance[:3])
        return float(100.0 * np.sqrt((m**2 + v).sum()))

    @property
    def rms_r_deg(self) -> float:
        """RMS rotational ground-truth error of a step [deg]."""
        m, v = np.asarray(self.mean[3:]), np.asarray(self.variance[3:])
        return float(np.rad2deg(np.sqrt((m**2 + v).sum())))

    def compose(self, E: F64, rng: np.random.Generator) -> F64:
        """Step errors E (N, 4, 4) with a drawn ground-truth error each: E exp(g)."""
        from scipy.spatial.transform import Rotation

        g = rng.normal(self.mean, np.sqrt(self.variance), (len(E), 6))
        G = np.tile(np.eye(4), (len(E), 1, 1))
        G[:, :3, :3] = Rotation.from_rotvec(g[:, 3:]).as_matrix()
        G[:, :3, 3] = g[:, :3]
        return E @ G


def twists(E: F64) -> F64:
    """(N, 6) rigid transforms E (N, 4, 4), e.g. step errors, as (translation [m], rotation
    vector [rad])."""
    from scipy.spatial.transform import Rotation

    return np.concatenate([E[:, :3, 3], Rotation.from_matrix(E[:, :3, :3]).as_rotvec()],
                          axis=1)


def shared_error(first: F64, second: F64, step_sigma: F64) -> GroundTruthError:
    """The ground-truth error model (module docstring) from two odometries' step errors
    (twists (N, 6) each, the same steps) and the trajectory's bound of a step's white noise
    (6,) per-axis sigma."""
    m1, m2 = first.mean(axis=0), second.mean(axis=0)
    m = np.where(np.sign(m1) == np.sign(m2), np.sign(m1) * np.minimum(abs(m1), abs(m2)), 0.0)
    shared = np.clip(((first - m1) * (second - m2)).mean(axis=0), 0.0, None)
    variance = np.minimum(shared, np.asarray(step_sigma) ** 2)
    return GroundTruthError(tuple(m.tolist()), tuple(variance.tolist()))


def white_sigma(T_world_lidar: F64) -> F64:
    """(6,) per-axis sigma of a step's error (translation [m], rotation vector [rad]) that
    white pose noise of the size the trajectory (N, 4, 4) shows gives: per axis the pose's
    sigma = robust std of the third difference of the relative motions / sqrt(70) (the
    binomial weights of the pose noise in it), a step's sqrt(2) times that."""
    from pipeline.geometry import inv_se3

    x = twists(inv_se3(T_world_lidar[:-1]) @ T_world_lidar[1:])
    d3 = x[3:] - 3 * x[2:-1] + 3 * x[1:-2] - x[:-3]
    sigma = 1.4826 * np.median(np.abs(d3 - np.median(d3, axis=0)), axis=0) / np.sqrt(70.0)
    return np.sqrt(2.0) * sigma


def white_noise(T_world_lidar: F64) -> tuple[float, float]:
    """(median translational [cm], rotational [deg]) step error of ``white_sigma``'s noise:
    the median norm of a 3-D Gaussian is 1.538 x its per-axis sigma (RMS over the axes)."""
    s = white_sigma(T_world_lidar).reshape(2, 3)
    step = 1.538 * np.sqrt((s**2).mean(axis=1))
    return float(100.0 * step[0]), float(np.rad2deg(step[1]))

"""The verdict's statistics for heavy-tailed, chaotic odometry errors (docs/results/verdict.md,
"Statistics"): everything a suite reports is computed here, nothing else computes them.

- Per world, a setting's RTE is the **median over its runs** (the nominal run and the
  replicas): one bimodal failure among three runs does not move it.
- Per suite, a ratio (adaptive / fixed, ...) is the **geometric mean of the per-world ratios**
  (the mean of their logarithms, exponentiated): a world 2x worse and one 2x better cancel.
  Its 95 % interval is scipy's BCa bootstrap of the mean log ratio, resampling worlds (the
  ratio of a world pairs two settings on that world), exponentiated back: in ratio units and
  not symmetric.
- The **win rate** (worlds whose ratio is below 1) with its Wilson score interval.
- The **pooled RTE** of a setting: the mean over every sub-trajectory of the suite (every
  start frame of every run of every world equally weighted), and the **failure rate**: the
  share of those sub-trajectories whose RTE exceeds the frozen threshold.
- The **closed gap** (ASlib's): log(SBS / adaptive) / log(SBS / oracle) over the suite's geometric
  means, with a paired bootstrap interval (worlds resampled with both logs).
- Within one recorded run, a ratio of two settings is the ratio of their mean RTE over the
  run's start frames (each frame: the median over the runs of a setting), with a **moving-block
  bootstrap** interval over the start frames (``block_ratio``): blocks of consecutive start
  frames, as long as the frames one sub-trajectory spans, so that the overlap of neighbouring
  sub-trajectories stays in every resample (scipy resamples independent observations only).
- The **power analysis**: from the spread (sample standard deviation) s of the per-world log
  ratios, the smallest effect n worlds detect and the worlds an effect needs (Student t,
  two-sided 95 % interval, 80 % power: |log effect| >= (t_0.975 + t_0.80) s / sqrt(n)).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

CONFIDENCE = 0.95
POWER = 0.80


@dataclass(frozen=True)
class Estimate:
    """A figure and its interval (``low``, ``high``; None where it is undefined: fewer than
    two worlds, or a degenerate resampling such as a closed gap over no headroom)."""

    value: float | None
    low: float | None
    high: float | None

    def to_json(self) -> dict[str, float | None]:
        return {"value": self.value, "low": self.low, "high": self.high}


def median_over_runs(runs: ArrayLike) -> float:
    """The median of a setting's finite run values on one world (NaN without any)."""
    v = np.asarray(runs, np.float64)
    v = v[np.isfinite(v)]
    return float(np.median(v)) if len(v) else math.nan


def geometric_mean(ratios: ArrayLike) -> float:
    """exp(mean(log ratios)) of positive finite ratios (NaN without any)."""
    r = _positive(ratios)
    return float(np.exp(np.mean(np.log(r)))) if len(r) else math.nan


def ratio_estimate(ratios: ArrayLike, confidence: float = CONFIDENCE, resamples: int = 9999,
                   seed: int = 0) -> Estimate:
    """The geometric mean of per-world ``ratios`` with the BCa bootstrap interval of the mean
    log ratio (worlds resampled, ``scipy.stats.bootstrap``), in ratio units."""
    logs = np.log(_positive(ratios))
    if len(logs) == 0:
        return Estimate(None, None, None)
    value = float(np.exp(logs.mean()))
    low, high = _bootstrap((logs,), _mean, confidence, resamples, seed)
    return Estimate(value, _exp(low), _exp(high))


def closed_gap(log_sbs_over_adaptive: ArrayLike, log_sbs_over_oracle: ArrayLike,
               confidence: float = CONFIDENCE, resamples: int = 9999, seed: int = 0) -> Estimate:
    """The share of the gap between the single best set (SBS) and the oracle that adaptive
    closes: mean(log(SBS / adaptive)) / mean(log(SBS / oracle)) over the worlds (1: as good as
    the oracle, 0: as good as SBS, < 0: worse than SBS), with the paired BCa bootstrap interval
    (worlds resampled with both of their logs). Worlds where either log is not finite are left
    out; the value is None when the oracle's mean gap is 0."""
    a = np.asarray(log_sbs_over_adaptive, np.float64)
    o = np.asarray(log_sbs_over_oracle, np.float64)
    ok = np.isfinite(a) & np.isfinite(o)
    a, o = a[ok], o[ok]
    if len(a) == 0 or o.mean() == 0.0:
        return Estimate(None, None, None)
    low, high = _bootstrap((a, o), _gap, confidence, resamples, seed, paired=True)
    return Estimate(float(a.mean() / o.mean()), low, high)


def wilson(successes: int, trials: int, confidence: float = CONFIDENCE) -> Estimate:
    """The share successes / trials with its Wilson score interval (scipy's ``binomtest``)."""
    from scipy.stats import binomtest

    if trials == 0:
        return Estimate(None, None, None)
    ci = binomtest(successes, trials).proportion_ci(confidence, method="wilson")
    return Estimate(successes / trials, float(ci.low), float(ci.high))


def pooled(t_err_pct: Sequence[ArrayLike], threshold_pct: float) -> dict[str, Any]:
    """The pooled RTE [%] (mean over every finite sub-trajectory of every array, each equally
    weighted) and the failure rate (the share above ``threshold_pct``), with their count."""
    v = np.concatenate([np.asarray(a, np.float64).ravel() for a in t_err_pct] or [np.empty(0)])
    v = v[np.isfinite(v)]
    if len(v) == 0:
        return {"rte_pct": None, "failure_rate": None, "sub_trajectories": 0}
    return {"rte_pct": float(v.mean()), "failure_rate": float((v > threshold_pct).mean()),
            "sub_trajectories": len(v)}


def log_spread(ratios: ArrayLike) -> float:
    """The sample standard deviation (ddof 1) of the logs of positive finite ratios (NaN below
    two)."""
    logs = np.log(_positive(ratios))
    return float(logs.std(ddof=1)) if len(logs) >= 2 else math.nan


def detectable_ratio(spread: float, worlds: int, confidence: float = CONFIDENCE,
                     power: float = POWER) -> float:
    """The smallest effect ``worlds`` worlds detect: the geometric-mean ratio r < 1 whose 95 %
    interval excludes 1 with probability ``power`` when the per-world log ratios spread by
    ``spread`` (r = exp(-(t_c + t_p) spread / sqrt(n)), Student t with n - 1 degrees of
    freedom). The same factor separates a true ratio from any bound: a suite shows
    ``ratio <= bound`` (the interval's upper end below it) with that power when the true
    ratio is at most ``bound * r``."""
    from scipy.stats import t

    if worlds < 2 or not spread >= 0:
        return math.nan
    df = worlds - 1
    factor = t.ppf(0.5 + confidence / 2, df) + t.ppf(power, df)
    return float(np.exp(-factor * spread / np.sqrt(worlds)))


def worlds_needed(spread: float, true_ratio: float, bound: float = 1.0,
                  confidence: float = CONFIDENCE, power: float = POWER,
                  most: int = 10_000) -> int | None:
    """The fewest worlds whose interval shows ``true_ratio`` below ``bound`` with ``power``
    (``detectable_ratio``); None when ``true_ratio >= bound`` or more than ``most`` are
    needed."""
    if not true_ratio < bound or not spread >= 0:
        return None
    for n in range(2, most + 1):
        if true_ratio <= bound * detectable_ratio(spread, n, confidence, power):
            return n
    return None


def block_ratio(num: ArrayLike, den: ArrayLike, block: int, resamples: int = 10000,
                confidence: float = CONFIDENCE, seed: int = 0) -> Estimate:
    """mean(num) / mean(den) over start frames (``num``, ``den`` (N,) paired per frame: two
    settings' RTE [%] of the same sub-trajectories) with its moving-block bootstrap interval:
    each resample draws ceil(N / block) blocks of ``block`` consecutive frames, every one of
    the N - block + 1 starts equally likely, joins them and keeps the first N frames; the
    interval is the percentile one of ``resamples`` resamples (seeded). No interval (None
    ends) below two frames; a block longer than the run is the run."""
    a, b = np.asarray(num, np.float64), np.asarray(den, np.float64)
    if a.shape != b.shape or a.ndim != 1:
        raise ValueError(f"num and den must be (N,) alike, got {a.shape} and {b.shape}")
    n = len(a)
    if n == 0 or b.sum() <= 0:
        return Estimate(None, None, None)
    value = float(a.mean() / b.mean())
    if n < 2:
        return Estimate(value, None, None)
    block = max(1, min(int(block), n))
    starts = np.random.default_rng(seed).integers(0, n - block + 1,
                                                  (resamples, -(-n // block)))
    idx = (starts[:, :, None] + np.arange(block)).reshape(resamples, -1)[:, :n]
    with np.errstate(divide="ignore", invalid="ignore"):
        stats = a[idx].mean(axis=1) / b[idx].mean(axis=1)
    stats = stats[np.isfinite(stats)]
    if not len(stats):
        return Estimate(value, None, None)
    low, high = np.quantile(stats, [(1 - confidence) / 2, (1 + confidence) / 2])
    return Estimate(value, float(low), float(high))


def _positive(values: ArrayLike) -> NDArray[np.float64]:
    v = np.asarray(values, np.float64).ravel()
    return v[np.isfinite(v) & (v > 0)]


def _mean(x: NDArray[np.float64], axis: int = -1) -> NDArray[np.float64]:
    return np.mean(x, axis=axis)  # type: ignore[no-any-return]


def _gap(a: NDArray[np.float64], o: NDArray[np.float64], axis: int = -1) -> NDArray[np.float64]:
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.mean(a, axis=axis) / np.mean(o, axis=axis)  # type: ignore[no-any-return]


def _bootstrap(data: tuple[NDArray[np.float64], ...], statistic: Any, confidence: float,
               resamples: int, seed: int, paired: bool = False) -> tuple[float | None,
                                                                         float | None]:
    """scipy's BCa interval of ``statistic`` over ``data`` (worlds resampled), None for each
    end that is undefined (one world, or every resample alike)."""
    from scipy.stats import bootstrap

    if len(data[0]) < 2:
        return None, None
    if all(np.all(d == d[0]) for d in data):  # every resample alike: no spread to resample
        v = float(statistic(*data))
        return v, v
    with warnings.catch_warnings():  # a degenerate BCa (NaN ends) is reported as None
        warnings.simplefilter("ignore")
        res = bootstrap(data, statistic, n_resamples=resamples, confidence_level=confidence,
                        paired=paired, vectorized=True, method="BCa",
                        rng=np.random.default_rng(seed))
    low, high = float(res.confidence_interval.low), float(res.confidence_interval.high)
    return (low if math.isfinite(low) else None), (high if math.isfinite(high) else None)


def _exp(v: float | None) -> float | None:
    return None if v is None else float(np.exp(v))

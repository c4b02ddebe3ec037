"""Synthetic inputs for the evaluation tests and bench: ground-truth paths, drifting estimates,
and whole SMBO outputs in the trials layout (pipeline.tuning.layout), written with the real
writers."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from pipeline.geometry import rot_z
from pipeline.io_utils import atomic_path
from pipeline.odometry.base import ParameterSpace, ParamSpec
from pipeline.sequence import EnvLabel, SequenceInfo, SequenceWriter
from pipeline.trajectory import Trajectory, write_trajectory
from pipeline.tuning.layout import trajectory_path, trials_table_path
from pipeline.tuning.table import STUDY_KEY
from schemas.arrow import trials_schema


def gt_path(n: int, step_m: float = 1.0, stop: tuple[int, int] | None = (10, 14),
            seed: int = 0) -> np.ndarray:
    """(n, 4, 4) ground truth: a winding, slightly hilly path.

    Frames stop[0] + 1 .. stop[1] stand still (same pose as frame stop[0]).
    """
    rng = np.random.default_rng(seed)
    T = np.tile(np.eye(4), (n, 1, 1))
    yaw, pos = 0.0, np.zeros(3)
    for i in range(1, n):
        moving = stop is None or not (stop[0] < i <= stop[1])
        if moving:
            yaw += 0.03 * np.sin(i / 7.0) + rng.normal(0, 0.005)
            pos = pos + step_m * np.array([np.cos(yaw), np.sin(yaw), 0.02 * np.sin(i / 5.0)])
        T[i, :3, :3] = rot_z(yaw)
        T[i, :3, 3] = pos
    return T


def drifting(gt: np.ndarray, seed: int, trans_sigma: float = 0.01,
             rot_sigma: float = 0.002, scale: float = 1.0) -> np.ndarray:
    """(n, 4, 4) estimate: ground-truth increments with noise and scale, composed from frame 0."""
    rng = np.random.default_rng(seed)
    rel = np.linalg.inv(gt[:-1]) @ gt[1:]
    est = [gt[0].copy()]
    for r in rel:
        noise = np.eye(4)
        noise[:3, :3] = rot_z(rng.normal(0, rot_sigma)) @ _rot_x(rng.normal(0, rot_sigma))
        noise[:3, 3] = rng.normal(0, trans_sigma, 3)
        step = r.copy()
        step[:3, 3] *= scale
        est.append(est[-1] @ step @ noise)
    return np.array(est)


def _rot_x(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def write_sequence(path: Path, gt: np.ndarray, labels: list[EnvLabel] | None = None) -> np.ndarray:
    """A sequence MCAP with tiny scans and ground truth ``gt``; returns the stamps [ns]."""
    stamps = 1_000_000_000 + np.arange(len(gt), dtype=np.int64) * 100_000_000
    pts = np.array([[1, 0, 0, 0.5], [0, 1, 0, 0.5], [0, 0, 1, 0.5]], np.float32)
    info = SequenceInfo(name=path.stem, sensor="synthetic", source="test", labels=labels or [])
    with SequenceWriter(path, info) as w:
        for s, T in zip(stamps, gt, strict=True):
            w.add(int(s), pts, T)
    return stamps


def write_trials_table(out_dir: Path, algorithm: str, sequence: str,
                       rows: list[dict], param_names: list[str]) -> Path:
    """One trials.parquet following schemas.arrow.trials_schema, with a study fingerprint that
    holds the parameter space searched (every parameter a float in [0, 100], default 1:
    ``pipeline.tuning.table.read_space`` reads it)."""
    space = ParameterSpace(tuple(ParamSpec(n, 0.0, 100.0, 1.0) for n in param_names))
    schema = trials_schema(param_names)
    schema = schema.with_metadata({**schema.metadata,
                                   STUDY_KEY: json.dumps({"space": space.to_json()}).encode()})
    cols = {f.name: [r[f.name] for r in rows] for f in schema}
    table = pa.Table.from_pydict(cols, schema=schema)
    path = trials_table_path(out_dir, algorithm, sequence)
    with atomic_path(path) as tmp:
        pq.write_table(table, tmp)
    return path


def write_study(out_dir: Path, algorithm: str, gts: dict[str, tuple[np.ndarray, np.ndarray]],
                trials: int, param_names: list[str], seed: int = 0,
                joint: bool = False) -> dict[tuple[str, int], np.ndarray]:
    """An SMBO output: a drifting trajectory per (sequence, trial) and the trials tables.

    gts: sequence -> (stamps_ns, gt poses). Trial 1 of every table is 'failed' (no trajectory).
    Returns (sequence, trial) -> estimate.
    """
    estimates: dict[tuple[str, int], np.ndarray] = {}
    for k, (sequence, (stamps, gt)) in enumerate(sorted(gts.items())):
        rows = []
        for trial in range(trials):
            params = {p: float(trial + i) for i, p in enumerate(param_names)}
            failed = trial == 1
            if not failed:
                est = drifting(gt, seed=seed + 1000 * k + trial, trans_sigma=0.002 * (trial + 1))
                estimates[(sequence, trial)] = est
                write_trajectory(trajectory_path(out_dir, algorithm, sequence, trial),
                                 Trajectory(np.arange(len(gt)), stamps, est))
            rows.append({"trial": trial, "status": "failed" if failed else "ok",
                         "error": "diverged" if failed else "",
                         "objective": 100.0 if failed else 1.0,
                         "seed": seed + trial,
                         "params_json": json.dumps(params),
                         **{f"p_{p}": v for p, v in params.items()}})
        if not joint:
            write_trials_table(out_dir, algorithm, sequence, rows, param_names)
    if joint:
        write_trials_table(out_dir, algorithm, "__joint__", rows, param_names)
    return estimates


def cli_fails(args: list[str], *needles: str) -> str:
    """Run ``adaptune ARGS``: exit code 1 and one line ``adaptune: error: ...`` holding every
    needle; returns that line."""
    from click.testing import CliRunner

    from stages.cli import main

    result = CliRunner().invoke(main, args)
    assert result.exit_code == 1, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("adaptune: error:"), result.output
    for needle in needles:
        assert needle in lines[0], lines[0]
    return lines[0]

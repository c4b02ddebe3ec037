"""A small results database built by the real ``rte`` command: two labelled sequences (cave_0
for training, street_0 for validation), a per-sequence study of GICP (4 trials) and NDT (2, on
cave_0), a joint study (3) and a portfolio (3 members), each with trial 1 failed
(helpers.evaluation_data.write_study), and descriptors of every frame."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from helpers.evaluation_data import gt_path, write_sequence, write_study
from pipeline.sequence import EnvLabel, SequenceReader

LENGTH_M = 10.0
KITTI_LENGTHS = (15.0, 30.0)


@dataclass
class World:
    root: Path
    params: Path
    gts: dict[str, np.ndarray]
    estimates: dict[str, dict[tuple[str, int], np.ndarray]]  # study -> (sequence, trial) -> poses

    @property
    def db(self) -> Path:
        """The database ``build_database`` writes."""
        return self.root / "adaptune.duckdb"

    def args(self, db: Path, *extra: str) -> list[str]:
        return ["rte", "--params", str(self.params), "--sequences", str(self.root / "seq"),
                "--trials", str(self.root / "trials"), "--fixed", str(self.root / "fixed"),
                "--portfolio", str(self.root / "portfolio"), "--db", str(db), *extra]


def make_world(root: Path) -> World:
    """The sequences (``root``/seq, with index.json) and the studies (``root``/trials, fixed,
    portfolio), no database yet."""
    gts, stamped = {}, {}
    for name, n in (("cave_0", 60), ("street_0", 45)):
        gt = gt_path(n, seed=n)
        labels = [EnvLabel(0, 19, "cave"), EnvLabel(20, n - 1, "open")]
        stamps = write_sequence(root / "seq" / f"{name}.mcap", gt, labels)
        # what the store sees: the ground truth after the MCAP round trip
        gts[name] = SequenceReader(root / "seq" / f"{name}.mcap").ground_truth()
        stamped[name] = (stamps, gt)
    (root / "seq" / "index.json").write_text(json.dumps({"train": ["cave_0"],
                                                         "validation": ["street_0"]}))
    estimates = {
        "trials": write_study(root / "trials", "gicp", stamped, 4, ["max_corr_m", "kf_m"]),
        "fixed": write_study(root / "fixed", "gicp", stamped, 3, ["max_corr_m", "kf_m"],
                             seed=7, joint=True),
        "portfolio": write_study(root / "portfolio", "gicp", stamped, 3,
                                 ["max_corr_m", "kf_m"], seed=11),
    }
    write_study(root / "trials", "ndt", {"cave_0": stamped["cave_0"]}, 2, ["resolution_m"], seed=3)
    params = root / "params.yaml"
    params.write_text(f"base:\n  length_m: {LENGTH_M}\n"
                      f"devkit:\n  lengths_m: {list(KITTI_LENGTHS)}\n")
    return World(root, params, gts, estimates)


def write_environment(path: Path, gts: dict[str, np.ndarray]) -> None:
    """Descriptors of every frame: e0..e9 = 0..9."""
    rows = [(s, f) for s, gt in gts.items() for f in range(len(gt))]
    cols = {"sequence": pa.array([r[0] for r in rows]),
            "frame": pa.array([r[1] for r in rows], pa.int32())}
    cols.update({f"e{i}": pa.array(np.full(len(rows), i, np.float32)) for i in range(10)})
    pq.write_table(pa.table(cols), path)


def build_database(world: World) -> World:
    """``world``'s descriptors (its root/environment.parquet) and the database the ``rte``
    command builds from them and its studies (``World.db``)."""
    from click.testing import CliRunner

    from stages.cli import main

    write_environment(world.root / "environment.parquet", world.gts)
    result = CliRunner().invoke(main, world.args(world.db, "--environment",
                                                 str(world.root / "environment.parquet")))
    assert result.exit_code == 0, result.output
    return world

"""`adaptune live`: online selection pushed into a running odometry; the output MCAP."""

from __future__ import annotations

import json
from itertools import pairwise
from pathlib import Path

import numpy as np
from click.testing import CliRunner
from test_surrogate import build_model, write_tiny_sequence

from pipeline.odometry.registry import get_adapter
from pipeline.runtime import PARAMS_TOPIC, POSE_TOPIC
from pipeline.sequence import SequenceReader
from stages.cli import main


def test_live_writes_poses_and_params(tmp_path: Path, kitti_root: Path) -> None:
    model_dir = build_model(
        tmp_path / "model",
        kitti_root,
        selection={
            "period_s": 0.2,
            "hysteresis": 0.0,
            "min_scan_points": 1000,
            "subset_rows": 256,
            "refine_iters": 2,
        },
    )
    seq = tmp_path / "s.mcap"
    write_tiny_sequence(seq, kitti_root, "04", n=5, step=4)
    out = tmp_path / "live.mcap"
    res = CliRunner().invoke(main, ["live", str(model_dir), str(seq), "--out", str(out),
                                    "--json"])
    assert res.exit_code == 0, res.output
    live = json.loads(res.stdout)
    res = CliRunner().invoke(main, ["select", str(model_dir), str(seq), "--out",
                                    str(tmp_path / "schedule.parquet"), "--json"])
    assert res.exit_code == 0, res.output
    select = json.loads(res.stdout)
    space = get_adapter("ndt").space
    with SequenceReader(out) as r, SequenceReader(seq) as src:
        assert len(r) == 5 and r.ground_truth() is not None
        np.testing.assert_array_equal(r[2].points_lidar, src[2].points_lidar)
        poses = list(r.iter_topic_poses(POSE_TOPIC))
        params = list(r.iter_topic_json(PARAMS_TOPIC))
    assert [t for t, _ in poses] == [int(s) for s in src.stamps_ns]
    assert all(np.isfinite(T).all() for _, T in poses)
    assert len(params) == 5
    assert [m["selected"] for _, m in params] == [True, False, True, False, True]
    for _, m in params:
        space.validate({n: m[n] for n in space.names})
        assert m["predicted_rte_pct"] is None or m["predicted_rte_pct"] > 0
    # one count of parameter changes: frames whose parameters differ from the previous frame's
    values = [tuple(m[n] for n in space.names) for _, m in params]
    changes = sum(a != b for a, b in pairwise(values))
    for summary in (live, select):
        assert {k: summary[k] for k in ("algorithm", "frames", "selections", "changes")} == {
            "algorithm": "ndt", "frames": 5, "selections": 3, "changes": changes}

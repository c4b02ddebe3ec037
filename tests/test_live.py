"""`adaptune live`: online selection pushed into a running odometry; the output MCAP, read back
with the ROS 2 decoders of mcap_ros2 only (what ROS 2 tools and Foxglove see)."""

from __future__ import annotations

import json
from itertools import pairwise
from pathlib import Path

import numpy as np
from click.testing import CliRunner
from helpers.models import build_model, write_tiny_sequence
from helpers.ros2_messages import pose_matrix, ros2_messages

from pipeline.odometry.registry import get_adapter
from pipeline.sequence import SequenceReader
from stages.cli import main


def test_live_writes_poses_and_params(tmp_path: Path, kitti_root: Path) -> None:
    model_dir = build_model(tmp_path / "model", kitti_root)
    params = tmp_path / "params.yaml"  # the selector's runtime settings
    params.write_text("select: {period_s: 0.2, hysteresis: 0.0, subset_rows: 256, "
                      "refine_iters: 2, window: 1}\n")
    seq = tmp_path / "s.mcap"
    write_tiny_sequence(seq, kitti_root, "04", n=5, step=4)
    out = tmp_path / "live.mcap"
    res = CliRunner().invoke(main, ["live", "--params", str(params), str(model_dir), str(seq),
                                    "--out", str(out), "--scans", "--json"])
    assert res.exit_code == 0, res.output
    live = json.loads(res.stdout)
    res = CliRunner().invoke(main, ["select", "--params", str(params), str(model_dir), str(seq),
                                    "--out", str(tmp_path / "schedule.parquet"), "--json"])
    assert res.exit_code == 0, res.output
    select = json.loads(res.stdout)
    space = get_adapter("ndt").space
    with SequenceReader(seq) as src:
        stamps = [int(t) for t in src.stamps_ns]
        gt = src.ground_truth()
        scan2 = src[2].points_lidar
    with SequenceReader(out) as r:  # the adaptune reader still reads it as a sequence
        assert len(r) == 5 and r.ground_truth() is not None
        np.testing.assert_array_equal(r[2].points_lidar, scan2)
    by_topic = ros2_messages(out)
    # every channel is a ROS 2 type: the ROS 2 decoder reads them all
    assert set(by_topic) == {"/lidar/points", "/ground_truth/pose", "/tf", "/odometry/pose",
                             "/adaptune/params"}
    poses = [pose_matrix(m.pose) for _, m in by_topic["/odometry/pose"]]
    assert [t for t, _ in by_topic["/odometry/pose"]] == stamps
    assert all(np.isfinite(T).all() for T in poses)
    np.testing.assert_allclose(poses[0], gt[0], atol=1e-6)  # the estimate starts at the GT
    # /tf: world -> lidar (ground truth), world -> odom (the anchor), odom -> lidar_odometry
    tf: dict[tuple[str, str], list[np.ndarray]] = {}
    for _, msg in by_topic["/tf"]:
        for t in msg.transforms:
            tf.setdefault((t.header.frame_id, t.child_frame_id), []).append(
                pose_matrix(t.transform))
    assert set(tf) == {("world", "lidar"), ("world", "odom"), ("odom", "lidar_odometry")}
    np.testing.assert_allclose(tf[("world", "lidar")], gt, atol=1e-6)
    np.testing.assert_allclose(tf[("world", "odom")][0] @ tf[("odom", "lidar_odometry")][0],
                               poses[0], atol=1e-6)
    np.testing.assert_allclose(tf[("odom", "lidar_odometry")][0], np.eye(4), atol=1e-6)
    # /adaptune/params: rcl_interfaces/msg/ParameterEvent, one a frame
    events = [m for _, m in by_topic["/adaptune/params"]]
    assert len(events) == 5 and {e.node for e in events} == {"/adaptune/ndt"}
    assert [len(e.new_parameters) > 0 for e in events] == [True, False, False, False, False]
    params = [{p.name: p.value for p in (*e.new_parameters, *e.changed_parameters)}
              for e in events]
    assert [m["adaptune.selected"].bool_value for m in params] == [True, False, True, False, True]
    assert [m["adaptune.frame"].integer_value for m in params] == list(range(5))
    for m in params:
        space.validate({n: m[n].double_value for n in space.names})
        pred = m["adaptune.predicted_rte_pct"].double_value
        if m["adaptune.selected"].bool_value:
            assert np.isnan(pred) or pred > 0
        else:
            assert np.isnan(pred)
    # one count of parameter changes: frames whose parameters differ from the previous frame's
    values = [tuple(m[n].double_value for n in space.names) for m in params]
    changes = sum(a != b for a, b in pairwise(values))
    for summary in (live, select):
        assert {k: summary[k] for k in ("algorithm", "frames", "selections", "changes")} == {
            "algorithm": "ndt", "frames": 5, "selections": 3, "changes": changes}

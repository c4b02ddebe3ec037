"""`adaptune live --serve`: the run shown by a real Foxglove WebSocket server (foxglove-sdk) while
it runs, seen by a WebSocket client that speaks the protocol (tests/helpers/foxglove_client.py)
and decodes with the schemas the server advertises; the output MCAP without the scans."""

from __future__ import annotations

import json
import queue
import re
import subprocess
import sys
import threading
from pathlib import Path
from typing import Any

import numpy as np
from helpers.foxglove_client import TIMEOUT_S, FoxgloveClient
from helpers.models import build_model, write_tiny_sequence
from helpers.ros2_messages import pose_matrix, ros2_decoder, ros2_messages

from pipeline.sequence import SequenceReader

ADAPTUNE = str(Path(sys.executable).parent / "adaptune")
FRAMES = 5
TOPICS = {"/lidar/points": "sensor_msgs/msg/PointCloud2",
          "/ground_truth/pose": "geometry_msgs/msg/PoseStamped",
          "/odometry/pose": "geometry_msgs/msg/PoseStamped", "/tf": "tf2_msgs/msg/TFMessage",
          "/adaptune/params": "rcl_interfaces/msg/ParameterEvent",
          "/ground_truth/path": "nav_msgs/msg/Path", "/odometry/path": "nav_msgs/msg/Path"}


def test_live_serve_shows_the_run(tmp_path: Path, kitti_root: Path) -> None:
    model_dir = build_model(tmp_path / "model", kitti_root)
    params = tmp_path / "params.yaml"
    params.write_text("select: {period_s: 0.2, hysteresis: 0.0, subset_rows: 256, "
                      "refine_iters: 2, window: 1}\n")
    seq = tmp_path / "s.mcap"
    write_tiny_sequence(seq, kitti_root, "04", n=FRAMES, step=4)
    out = tmp_path / "live.mcap"
    proc = subprocess.Popen([ADAPTUNE, "live", "--params", str(params), str(model_dir), str(seq),
                             "--out", str(out), "--serve", "--port", "0", "--json"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        lines = StderrLines(proc)
        url = next(m.group(1) for line in lines if (m := re.search(r"(ws://[\d.:]+)", line)))
        got = receive_run(url)
        stdout, _ = proc.communicate(timeout=TIMEOUT_S)  # the client left: the command ends
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    stderr = "".join(lines.seen)
    assert proc.returncode == 0, stderr
    summary = json.loads(stdout)
    assert summary["frames"] == FRAMES and summary["url"] == url
    # progress lines, as every long loop shows them without a terminal
    assert "live s: 5 frames" in stderr and "live s finished: 5 frames" in stderr

    with SequenceReader(seq) as src:
        stamps = [int(t) for t in src.stamps_ns]
        last_scan = src[FRAMES - 1].points_lidar
        gt = src.ground_truth()
    mcap = ros2_messages(out)
    assert "/lidar/points" not in mcap  # the scans only with --scans
    estimate = [pose_matrix(m.pose) for _, m in mcap["/odometry/pose"]]
    # every channel was advertised with its ROS 2 type and sent messages stamped by frame
    assert {topic: schema for topic, (schema, _) in got.items()} == TOPICS
    for _, messages in got.values():
        assert messages and all(t in stamps for t, _ in messages)
        assert messages[-1][0] == stamps[-1]  # each channel's last message is the last frame's
    # the trajectories so far, whole in the last path messages: the MCAP's estimate, the GT
    for topic, poses in (("/odometry/path", estimate), ("/ground_truth/path", list(gt))):
        path = got[topic][1][-1][1]
        assert [stamp_ns(p.header.stamp) for p in path.poses] == stamps
        np.testing.assert_allclose([pose_matrix(p.pose) for p in path.poses], poses, atol=1e-9)
    np.testing.assert_allclose(pose_matrix(got["/odometry/pose"][1][-1][1].pose), estimate[-1],
                               atol=1e-9)
    cloud = got["/lidar/points"][1][-1][1]
    points = np.frombuffer(bytes(cloud.data), "<f4").reshape(-1, cloud.point_step // 4)[:, :4]
    np.testing.assert_array_equal(points, last_scan)
    # the parameters in force, as the MCAP has them
    assert parameters(got["/adaptune/params"][1][-1][1]) == \
        parameters(mcap["/adaptune/params"][-1][1])
    frames = {(tf.header.frame_id, tf.child_frame_id)
              for _, msg in got["/tf"][1] for tf in msg.transforms}
    assert frames == {("world", "lidar"), ("world", "odom"), ("odom", "lidar_odometry")}


class StderrLines:
    """The lines a process writes on stderr, read by a thread; iterating waits for the next."""

    def __init__(self, proc: subprocess.Popen[str]) -> None:
        self.seen: list[str] = []
        self._lines: queue.Queue[str | None] = queue.Queue()
        threading.Thread(target=self._read, args=(proc,), daemon=True).start()

    def _read(self, proc: subprocess.Popen[str]) -> None:
        assert proc.stderr is not None
        for line in proc.stderr:
            self.seen.append(line)
            self._lines.put(line)
        self._lines.put(None)

    def __iter__(self) -> Any:
        while (line := self._lines.get(timeout=TIMEOUT_S)) is not None:
            yield line


def receive_run(url: str) -> dict[str, tuple[str, list[tuple[int, Any]]]]:
    """topic -> (schema name, [(log time, decoded message)]) of a whole run: subscribed to every
    channel, until the ground-truth path (the last message of a frame) reaches the last
    frame."""
    got: dict[str, tuple[str, list[tuple[int, Any]]]] = {}
    with FoxgloveClient(url) as client:
        channels = client.channels()
        decoders = {}
        for cid, ch in channels.items():
            assert ch["encoding"] == "cdr" and ch["schemaEncoding"] == "ros2msg"
            decoders[cid] = ros2_decoder(ch["schemaName"], ch["schema"])
            got[ch["topic"]] = (ch["schemaName"], [])
        client.subscribe(list(channels))
        for ch, log_time, data in client.messages():
            msg = decoders[int(ch["id"])](data)
            got[ch["topic"]][1].append((log_time, msg))
            if ch["topic"] == "/ground_truth/path" and len(msg.poses) == FRAMES:
                return got
    raise AssertionError("the server closed before the last frame")


def stamp_ns(stamp: Any) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def parameters(event: Any) -> dict[str, Any]:
    """name -> value of a decoded ParameterEvent's parameters (doubles, integers, bools)."""
    out = {}
    for p in (*event.new_parameters, *event.changed_parameters):
        v = p.value
        out[p.name] = (v.type, v.bool_value, v.integer_value, v.string_value,
                       None if np.isnan(v.double_value) else v.double_value)
    return out

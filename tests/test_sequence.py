"""Sequence MCAP: round trip, random access, ROS 2 compatibility, bad input."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from helpers.mcap_chunks import chunk_compressions

from pipeline.errors import ConfigError, InputError
from pipeline.geometry import pose_from_xyz_quat
from pipeline.ros2_cdr import POINTCLOUD2, POSE_STAMPED, TF_MESSAGE
from pipeline.sequence import (
    GT_TOPIC,
    POINTS_TOPIC,
    TF_TOPIC,
    EnvLabel,
    SequenceInfo,
    SequenceReader,
    SequenceWriter,
)


def _write(path: Path, rng: np.random.Generator, n: int = 5, gt: bool = True,
           compression: str = "zstd") -> list[np.ndarray]:
    clouds = []
    info = SequenceInfo(
        name="t", sensor="hdl32", source="test", labels=[EnvLabel(0, n - 1, "cave")]
    )
    with SequenceWriter(path, info, compression=compression) as w:  # type: ignore[arg-type]
        for i in range(n):
            pts = rng.normal(size=(100 + i, 4)).astype(np.float32)
            T = pose_from_xyz_quat(
                np.array([i, 0.5 * i, 0.0]), np.array([0, 0, np.sin(i / 10), np.cos(i / 10)])
            )
            w.add(1_000_000_000 + i * 100_000_000, pts, T if gt else None)
            clouds.append(pts)
    return clouds


def test_round_trip_random_access_and_iteration(tmp_path: Path, rng: np.random.Generator) -> None:
    clouds = _write(tmp_path / "s.mcap", rng)
    with SequenceReader(tmp_path / "s.mcap") as r:
        assert len(r) == 5 and r.info.frame_count == 5 and r.info.label_of(3) == "cave"
        np.testing.assert_array_equal(r[3].points_lidar, clouds[3])
        assert r[3].stamp_ns == 1_300_000_000
        scans = list(r)
        assert [s.frame for s in scans] == list(range(5))
        np.testing.assert_allclose(scans[2].T_world_lidar[:3, 3], [2, 1, 0], atol=1e-12)
        np.testing.assert_array_equal(scans[4].points_lidar, clouds[4])


def test_uncompressed_chunks_read_back_the_same(tmp_path: Path) -> None:
    """``compression="none"`` writes chunks without zstd (larger) that read back exactly what
    the zstd file holds; another compression is refused naming the choices."""
    zstd, none = tmp_path / "z.mcap", tmp_path / "n.mcap"
    clouds = _write(zstd, np.random.default_rng(3))
    _write(none, np.random.default_rng(3), compression="none")
    assert chunk_compressions(zstd) == {"zstd"} and chunk_compressions(none) == {""}
    assert none.stat().st_size > zstd.stat().st_size
    with SequenceReader(zstd) as a, SequenceReader(none) as b:
        assert a.info == b.info and np.array_equal(a.stamps_ns, b.stamps_ns)
        for sa, sb, cloud in zip(a, b, clouds, strict=True):
            np.testing.assert_array_equal(sb.points_lidar, cloud)
            np.testing.assert_array_equal(sb.points_lidar, sa.points_lidar)
            np.testing.assert_array_equal(sb.T_world_lidar, sa.T_world_lidar)
    with pytest.raises(ConfigError, match="compression must be one of zstd, none, got 'lz4'"):
        SequenceWriter(tmp_path / "x.mcap", SequenceInfo(name="x"), compression="lz4")  # type: ignore[arg-type]
    assert not list(tmp_path.glob("x*"))


def test_without_ground_truth(tmp_path: Path, rng: np.random.Generator) -> None:
    _write(tmp_path / "s.mcap", rng, gt=False)
    with SequenceReader(tmp_path / "s.mcap") as r:
        assert not r.has_ground_truth and r.ground_truth() is None and r[0].T_world_lidar is None


def test_messages_decode_with_mcap_ros2(tmp_path: Path, rng: np.random.Generator) -> None:
    """What adaptune writes is read back with ROS 2 decoders only (mcap_ros2's DecoderFactory):
    the scans, the ground truth and /tf (world -> lidar, the ground-truth pose)."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    clouds = _write(tmp_path / "s.mcap", rng)
    with open(tmp_path / "s.mcap", "rb") as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        schemas = {s.name: s.encoding for s in reader.get_summary().schemas.values()}
        msgs = list(reader.iter_decoded_messages(topics=[POINTS_TOPIC, GT_TOPIC, TF_TOPIC]))
    assert schemas == {t: "ros2msg" for t in (POINTCLOUD2, POSE_STAMPED, TF_MESSAGE)}
    pcs = [m for _, ch, _, m in msgs if ch.topic == POINTS_TOPIC]
    poses = [m for _, ch, _, m in msgs if ch.topic == GT_TOPIC]
    tfs = [(msg.log_time, m) for _, ch, msg, m in msgs if ch.topic == TF_TOPIC]
    assert len(pcs) == 5 and len(poses) == 5 and len(tfs) == 5
    assert [f.name for f in pcs[1].fields] == ["x", "y", "z", "intensity"]
    assert pcs[1].header.frame_id == "lidar"
    got = np.frombuffer(bytes(pcs[1].data), np.float32).reshape(-1, 4)
    np.testing.assert_array_equal(got, clouds[1])
    assert poses[3].pose.position.x == pytest.approx(3.0)
    log_ns, tf = tfs[3]
    (t,) = tf.transforms
    assert (t.header.frame_id, t.child_frame_id) == ("world", "lidar")
    assert t.header.stamp.sec * 10**9 + t.header.stamp.nanosec == log_ns == 1_300_000_000
    xyz = [t.transform.translation.x, t.transform.translation.y, t.transform.translation.z]
    q = [t.transform.rotation.x, t.transform.rotation.y, t.transform.rotation.z,
         t.transform.rotation.w]
    np.testing.assert_allclose(xyz, [3.0, 1.5, 0.0], atol=1e-12)
    np.testing.assert_allclose(q, [0, 0, np.sin(0.3), np.cos(0.3)], atol=1e-12)


def test_no_tf_without_ground_truth_and_extra_transforms(tmp_path: Path) -> None:
    """/tf carries world -> lidar only where the ground truth is known; ``add_tf`` adds others
    (e.g. an estimate's frame), in time order, decodable by ROS 2 tools."""
    from pipeline.ros2_cdr import decode_tf

    with SequenceWriter(tmp_path / "a.mcap", SequenceInfo(name="a")) as w:
        w.add(10, np.ones((3, 3), np.float32))
    with SequenceReader(tmp_path / "a.mcap") as r:
        assert TF_TOPIC not in r.topics
    T = np.eye(4)
    T[:3, 3] = [1, 2, 3]
    with SequenceWriter(tmp_path / "b.mcap", SequenceInfo(name="b")) as w:
        w.add(10, np.ones((3, 3), np.float32))
        w.add_tf(20, "world", "odom_estimate", T)
        w.add_tf(10, "world", "odom_estimate", np.eye(4))
    from mcap.reader import make_reader

    with open(tmp_path / "b.mcap", "rb") as fh:
        got = [decode_tf(m.data) for _, _, m in make_reader(fh).iter_messages(topics=[TF_TOPIC])]
    assert [g[0][:3] for g in got] == [(10, "world", "odom_estimate"),
                                      (20, "world", "odom_estimate")]
    np.testing.assert_allclose(got[1][0][3], T)


def test_nan_points_dropped_and_empty_scan_refused(tmp_path: Path) -> None:
    pts = np.ones((10, 4), np.float32)
    pts[2, 0] = np.nan
    pts[5, 1] = np.inf
    with SequenceWriter(tmp_path / "a.mcap", SequenceInfo(name="a")) as w:
        w.add(1, pts)
        assert w.dropped_points == 2
    with SequenceReader(tmp_path / "a.mcap") as r:
        assert r[0].points_lidar.shape == (8, 4)
    bad = np.full((4, 4), np.nan, np.float32)
    with (
        pytest.raises(InputError, match="empty scan"),
        SequenceWriter(tmp_path / "b.mcap", SequenceInfo(name="b")) as w,
    ):
        w.add(1, bad)
    assert not (tmp_path / "b.mcap").exists()
    assert not list(tmp_path.glob(".b.mcap*"))


def test_stamps_must_increase(tmp_path: Path) -> None:
    with (
        pytest.raises(InputError, match="not after"),
        SequenceWriter(tmp_path / "c.mcap", SequenceInfo(name="c")) as w,
    ):
        w.add(5, np.ones((3, 3), np.float32))
        w.add(5, np.ones((3, 3), np.float32))
    assert not (tmp_path / "c.mcap").exists()


@pytest.mark.parametrize("cut", [0.5, 0.9])
def test_truncated_mcap_is_one_clear_error(
    tmp_path: Path, rng: np.random.Generator, cut: float
) -> None:
    _write(tmp_path / "s.mcap", rng)
    data = (tmp_path / "s.mcap").read_bytes()
    (tmp_path / "t.mcap").write_bytes(data[: int(len(data) * cut)])
    with (
        pytest.raises(InputError, match="corrupt or truncated MCAP"),
        SequenceReader(tmp_path / "t.mcap") as r,
    ):
        list(r)


def test_corrupt_chunk_is_one_clear_error(tmp_path: Path, rng: np.random.Generator) -> None:
    _write(tmp_path / "s.mcap", rng)
    data = bytearray((tmp_path / "s.mcap").read_bytes())
    for i in range(200, 600):
        data[i] ^= 0xFF
    (tmp_path / "t.mcap").write_bytes(bytes(data))
    with (
        pytest.raises(InputError, match="corrupt or truncated MCAP"),
        SequenceReader(tmp_path / "t.mcap") as r,
    ):
        list(r)


def test_not_an_mcap(tmp_path: Path) -> None:
    (tmp_path / "x.mcap").write_text("hello")
    with pytest.raises(InputError, match=r"x.mcap"):
        SequenceReader(tmp_path / "x.mcap")


def test_packed_float32_fast_path_equals_the_general_decoder(rng: np.random.Generator) -> None:
    """The packed x, y, z, intensity float32 layout (what adaptune writes) is read in one copy;
    the same points with a padded point (general path) or a float64 intensity decode equal."""
    from pipeline.ros2_cdr import PointField, pointcloud2_to_xyzi

    pts = rng.normal(0, 10, (300, 4)).astype(np.float32)
    fields = [PointField(n, 4 * k, 7) for k, n in enumerate(("x", "y", "z", "intensity"))]
    packed = pointcloud2_to_xyzi(1, 300, fields, False, 16, 16 * 300, pts.tobytes(), "packed")
    assert packed.flags.writeable and packed.flags.c_contiguous
    np.testing.assert_array_equal(packed, pts)
    padded = np.zeros((300, 20), np.uint8)
    padded[:, :16] = pts.view(np.uint8).reshape(300, 16)
    general = pointcloud2_to_xyzi(1, 300, fields, False, 20, 20 * 300, padded.tobytes(), "pad")
    np.testing.assert_array_equal(general, pts)
    wide = np.zeros((300, 20), np.uint8)
    wide[:, :12] = pts[:, :3].copy().view(np.uint8).reshape(300, 12)
    wide[:, 12:] = pts[:, 3].astype(np.float64).view(np.uint8).reshape(300, 8)
    f64 = [*fields[:3], PointField("intensity", 12, 8)]
    np.testing.assert_array_equal(
        pointcloud2_to_xyzi(1, 300, f64, False, 20, 20 * 300, wide.tobytes(), "f64"), pts)


def test_prefetch_yields_in_order_and_hands_over_errors() -> None:
    import threading

    from pipeline.io_utils import prefetch

    assert list(prefetch(range(100), depth=1)) == list(range(100))
    producer = threading.current_thread()

    def failing():
        yield threading.current_thread() is not producer  # produced in another thread
        raise InputError("frame 1: broken")

    it = prefetch(failing(), depth=1)
    assert next(it) is True
    with pytest.raises(InputError, match="frame 1: broken"):
        next(it)
    before = threading.active_count()
    early = prefetch(iter(range(10**9)), depth=1)  # the consumer stops: the producer stops too
    assert next(early) == 0
    early.close()
    assert threading.active_count() == before

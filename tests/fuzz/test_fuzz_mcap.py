"""Fuzz the MCAP readers: sequence MCAPs (SequenceReader) and any MCAP with PointCloud2
(``ingest mcap``), through fuzzed metadata, fuzzed message fields and damaged bytes
(fuzz_contract: refuse in one line or give valid output; never change the input, never leave
an output or a temporary file behind on a refusal)."""

from __future__ import annotations

from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
from helpers.fuzz_contract import (
    NUMBER_TOKENS,
    RARELY,
    TOKENS,
    fuzz,
    holds,
    is_pose,
    mutate,
    scratch,
    valid_stamps,
)
from hypothesis import given
from hypothesis import strategies as st

from pipeline.sequence import (
    GT_TOPIC,
    META_FRAMES,
    META_SEQUENCE,
    POINTS_TOPIC,
    SequenceInfo,
    SequenceReader,
    SequenceWriter,
)
from pipeline.sources.base import write_sequence
from pipeline.sources.mcap_file import McapSource
from schemas import read_text

CLOUD = "sensor_msgs/msg/PointCloud2"
POSE = "geometry_msgs/msg/PoseStamped"


@cache
def store() -> Any:
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_HUMBLE)


def cloud_cdr(stamp_ns: int, layout: dict[str, Any]) -> bytes:
    """CDR bytes (rosbags' serialiser) of a PointCloud2 with the fields of ``layout``."""
    T = store().types
    stamp = T["builtin_interfaces/msg/Time"](sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9)
    fields = [T["sensor_msgs/msg/PointField"](name=n, offset=o, datatype=d, count=c)
              for n, o, d, c in layout["fields"]]
    msg = T[CLOUD](header=T["std_msgs/msg/Header"](stamp=stamp, frame_id="lidar"),
                   height=layout["height"], width=layout["width"], fields=fields,
                   is_bigendian=layout["big"], point_step=layout["point_step"],
                   row_step=layout["row_step"],
                   data=np.frombuffer(layout["data"], np.uint8), is_dense=False)
    return bytes(store().serialize_cdr(msg, CLOUD))


def pose_cdr(stamp_ns: int, xyz: list[float], q_xyzw: list[float]) -> bytes:
    T = store().types
    stamp = T["builtin_interfaces/msg/Time"](sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9)
    pose = T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](*xyz),
                                       orientation=T["geometry_msgs/msg/Quaternion"](*q_xyzw))
    msg = T[POSE](header=T["std_msgs/msg/Header"](stamp=stamp, frame_id="world"), pose=pose)
    return bytes(store().serialize_cdr(msg, POSE))


U32 = st.integers(0, 2**32 - 1)
SMALL = st.integers(0, 24) | U32


@st.composite
def cloud_layouts(draw: st.DrawFn) -> dict[str, Any]:
    """A PointCloud2 layout: float32 x, y, z, intensity packed (often), or fields of other
    names, datatypes, offsets, counts; sizes that fit the data, or not."""
    if draw(st.booleans()):
        fields = [("x", 0, 7, 1), ("y", 4, 7, 1), ("z", 8, 7, 1), ("intensity", 12, 7, 1)]
    else:
        names = st.sampled_from(["x", "y", "z", "intensity", "i", "t", "time", "offset_time",
                                 "ring", ""])
        fields = draw(st.lists(st.tuples(names, SMALL, st.integers(0, 9) | U32.map(
            lambda v: v % 256), st.integers(0, 3)), max_size=6))
    height, width = draw(st.integers(0, 3)), draw(st.integers(0, 6))
    consistent = draw(st.booleans())  # sizes that fit, or any
    step = 16 if consistent or not draw(RARELY) else draw(SMALL)
    row_step = step * width % 2**32 if consistent or not draw(RARELY) else draw(SMALL)
    need = row_step * max(height - 1, 0) + width * step if height * width else 0
    size = min(need, 4096) if consistent else draw(st.integers(0, 200))
    if draw(st.booleans()):  # coordinates of a scan in metres
        data = np.array(draw(st.lists(st.floats(-100, 100, width=32), min_size=size // 4,
                                      max_size=size // 4)), "<f4").tobytes()
        data += bytes(size - len(data))
    else:
        data = draw(st.binary(min_size=size, max_size=size))
    return {"fields": fields, "height": height, "width": width, "point_step": step,
            "row_step": row_step, "big": draw(st.booleans()), "data": data}


def write_mcap(path: Path, metadata: dict[str, dict[str, str]],
               messages: list[tuple[str, str, int, bytes]]) -> None:
    """An MCAP of ``messages`` (topic, msgtype, log_time, data) and metadata records, written
    with mcap's own writer (not adaptune's)."""
    from mcap.writer import Writer

    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start(profile="ros2", library="fuzz")
        schemas: dict[str, int] = {}
        channels: dict[str, int] = {}
        for topic, msgtype, log_time, data in messages:
            if msgtype not in schemas:
                pkg, _, name = msgtype.split("/")
                text = read_text(f"ros2/{pkg}__{name}.msg").encode()
                schemas[msgtype] = w.register_schema(msgtype, "ros2msg", text)
            if topic not in channels:
                channels[topic] = w.register_channel(topic, "cdr", schemas[msgtype])
            w.add_message(channels[topic], log_time=log_time, data=data, publish_time=log_time)
        for name, record in metadata.items():
            w.add_metadata(name, record)
        w.finish()


STAMPS = st.lists(st.integers(0, 5 * 10**9), min_size=1, max_size=3, unique=True).map(sorted)


@st.composite
def sequence_files(draw: st.DrawFn) -> tuple[dict[str, dict[str, str]], list]:
    """(metadata, messages) of a sequence MCAP: right records and messages, then a few
    values replaced, keys dropped, stamps moved, point clouds or poses of other shapes."""
    stamps = draw(STAMPS)
    info = SequenceInfo(name="fuzz", frame_count=len(stamps)).to_record()
    frames = {"stamps_ns": " ".join(map(str, stamps))}
    for record in (info, frames):
        for key in draw(st.sets(st.sampled_from(sorted(record)), max_size=2)):
            if draw(st.booleans()):
                del record[key]
            else:
                record[key] = draw(NUMBER_TOKENS | TOKENS | st.just("[[0, 1, 2]]"))
    messages = []
    for k, s in enumerate(stamps):
        log_time = draw(st.just(s) | st.integers(0, 2**63 - 1)) if k == 0 else s
        layout = draw(st.just(None) | cloud_layouts()) if k == 0 else None
        if layout is None:  # a right cloud of 3 points
            pts = np.arange(12, dtype="<f4").tobytes()
            layout = {"fields": [("x", 0, 7, 1), ("y", 4, 7, 1), ("z", 8, 7, 1),
                                 ("intensity", 12, 7, 1)], "height": 1, "width": 3,
                      "point_step": 16, "row_step": 48, "big": False, "data": pts * 3}
        messages.append((POINTS_TOPIC, CLOUD, log_time, cloud_cdr(s, layout)))
    if draw(st.booleans()):
        for s in stamps[: draw(st.integers(0, len(stamps)))]:
            q = draw(st.just([0.0, 0.0, 0.0, 1.0]) | st.lists(st.floats(), min_size=4,
                                                             max_size=4))
            messages.append((GT_TOPIC, POSE, s, pose_cdr(s, [1.0, 2.0, 3.0], q)))
    metadata = {META_SEQUENCE: info, META_FRAMES: frames}
    if draw(RARELY):
        metadata.pop(draw(st.sampled_from(sorted(metadata))))
    return metadata, messages


def read_all(path: Path) -> tuple[list[Any], Any]:
    """Everything a stage reads of a sequence: the scans in order, one by index, the ground
    truth."""
    with SequenceReader(path) as r:
        scans = list(r)
        if len(r):
            assert r[len(r) - 1].frame == len(r) - 1
        return scans, r.ground_truth()


@fuzz(80)
@given(file=sequence_files())
def test_sequence_reader(tmp_path: Path, file: tuple[dict, list]) -> None:
    with scratch(tmp_path) as d:
        path = d / "seq.mcap"
        write_mcap(path, *file)
        got = holds(lambda: read_all(path), [path])
        if got is not None:
            scans, gt = got
            assert valid_stamps(np.array([s.stamp_ns for s in scans], np.int64))
            for s in scans:
                assert s.points_lidar.dtype == np.float32 and s.points_lidar.shape[1] == 4
            assert gt is None or (gt.shape == (len(scans), 4, 4) and is_pose(gt))


@cache
def good_sequence(base: Path) -> bytes:
    """A small sequence MCAP written by adaptune's writer (3 frames with ground truth)."""
    path = base / "good.mcap"
    with SequenceWriter(path, SequenceInfo(name="good")) as w:
        for k in range(3):
            w.add(k * 10**8, np.random.default_rng(k).normal(size=(50, 4)).astype(np.float32),
                  np.eye(4))
    return path.read_bytes()


@fuzz(60)
@given(data=st.data())
def test_damaged_sequence_bytes(tmp_path_factory: Any, tmp_path: Path, data: st.DataObject
                                ) -> None:
    good = good_sequence(tmp_path_factory.getbasetemp())
    with scratch(tmp_path) as d:
        path = d / "seq.mcap"
        path.write_bytes(data.draw(mutate(good)))
        got = holds(lambda: read_all(path), [path])
        if got is not None:
            assert len(got[0]) == 3 and got[1] is not None and is_pose(got[1])


@st.composite
def pointcloud_mcaps(draw: st.DrawFn) -> list[tuple[str, str, int, bytes]]:
    """Messages of a recording: 1-3 PointCloud2 of fuzzed layouts, sometimes a pose topic."""
    stamps = draw(STAMPS)
    layout = draw(cloud_layouts())
    messages = [(POINTS_TOPIC, CLOUD, s,
                 cloud_cdr(draw(st.just(s) | st.integers(0, 2**40)),
                           draw(st.just(layout) | cloud_layouts())))
                for s in stamps]
    if draw(RARELY):
        messages.append(("/cloud2", CLOUD, 0, messages[0][3]))
    return messages


@fuzz(100)
@given(messages=pointcloud_mcaps())
def test_ingest_mcap(tmp_path: Path, messages: list) -> None:
    with scratch(tmp_path) as d:
        path, out = d / "rec.mcap", d / "out" / "seq.mcap"
        write_mcap(path, {}, messages)
        report = holds(lambda: write_sequence(McapSource(path), out), [path])
        leftovers = [p for p in (d / "out").glob("*") if p != out] if out.parent.exists() else []
        assert not leftovers, leftovers
        if report is None:
            assert not out.exists()
        else:
            scans, gt = read_all(out)
            assert len(scans) == report.frames and gt is None

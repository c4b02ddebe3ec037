"""The hand-written CDR codec pipeline/ros2_cdr.py had before mcap_ros2 (issue 18, item 6).

Kept here only as the same-run reference of bench_cdr.py: the figures that decided for the
library must stay reproducible. Not imported by the package.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

_HEADER = b"\x00\x01\x00\x00"  # CDR_LE encapsulation

@dataclass(frozen=True)
class PointField:
    """One field of a PointCloud2: byte ``offset`` in a point, ``datatype`` 1-8, ``count``."""

    name: str
    offset: int
    datatype: int
    count: int = 1


@dataclass(frozen=True)
class PointCloud2:
    """A decoded PointCloud2: raw bytes plus the layout to interpret them."""

    stamp_ns: int
    frame_id: str
    height: int
    width: int
    fields: tuple[PointField, ...]
    is_bigendian: bool
    point_step: int
    row_step: int
    data: bytes
    is_dense: bool


class _Writer:
    def __init__(self) -> None:
        self.parts: list[bytes] = []
        self.pos = 0

    def align(self, n: int) -> None:
        pad = (-self.pos) % n
        if pad:
            self.raw(b"\x00" * pad)

    def raw(self, b: bytes) -> None:
        self.parts.append(b)
        self.pos += len(b)

    def pack(self, fmt: str, *values: object, align: int) -> None:
        self.align(align)
        self.raw(struct.pack("<" + fmt, *values))

    def string(self, s: str) -> None:
        b = s.encode() + b"\x00"
        self.pack("I", len(b), align=4)
        self.raw(b)

    def header(self, stamp_ns: int, frame_id: str) -> None:
        sec, nsec = divmod(int(stamp_ns), 1_000_000_000)
        self.pack("iI", sec, nsec, align=4)
        self.string(frame_id)

    def bytes(self) -> bytes:
        return _HEADER + b"".join(self.parts)


class _Reader:
    def __init__(self, buf: bytes | memoryview, what: str) -> None:
        self.buf = memoryview(buf)
        self.what = what
        if len(buf) < 4 or bytes(self.buf[:2]) not in (b"\x00\x01", b"\x00\x00"):
            raise ValueError(f"{what}: not a little-endian CDR message")
        self.little = bytes(self.buf[:2]) == b"\x00\x01"
        self.pos = 0
        self.body = self.buf[4:]

    def align(self, n: int) -> None:
        self.pos += (-self.pos) % n

    def unpack(self, fmt: str, align: int) -> tuple:
        self.align(align)
        size = struct.calcsize("<" + fmt)
        if self.pos + size > len(self.body):
            raise ValueError(f"{self.what}: message truncated")
        vals = struct.unpack_from(("<" if self.little else ">") + fmt, self.body, self.pos)
        self.pos += size
        return vals

    def string(self) -> str:
        (n,) = self.unpack("I", 4)
        raw = self.take(n)
        return bytes(raw[:-1] if n and raw[-1] == 0 else raw).decode(errors="replace")

    def take(self, n: int) -> memoryview:
        if self.pos + n > len(self.body):
            raise ValueError(f"{self.what}: message truncated")
        out = self.body[self.pos : self.pos + n]
        self.pos += n
        return out

    def header(self) -> tuple[int, str]:
        sec, nsec = self.unpack("iI", 4)
        return sec * 1_000_000_000 + nsec, self.string()


XYZI_FIELDS = (
    PointField("x", 0, 7), PointField("y", 4, 7), PointField("z", 8, 7),
    PointField("intensity", 12, 7),
)


def encode_pointcloud2(
    stamp_ns: int, points_xyzi: NDArray[np.float32], frame_id: str = "lidar"
) -> bytes:
    """CDR bytes of an unorganised PointCloud2 with float32 x, y, z, intensity.

    ``points_xyzi``: (N, 4) float32 in the sensor frame [m] and intensity (any unit).
    """
    pts = np.ascontiguousarray(points_xyzi, dtype="<f4")
    if pts.ndim != 2 or pts.shape[1] != 4:
        raise ValueError(f"points must be (N, 4) x, y, z, intensity, got shape {pts.shape}")
    w = _Writer()
    w.header(stamp_ns, frame_id)
    w.pack("II", 1, len(pts), align=4)
    w.pack("I", len(XYZI_FIELDS), align=4)
    for f in XYZI_FIELDS:
        w.string(f.name)
        w.pack("I", f.offset, align=4)
        w.pack("B", f.datatype, align=1)
        w.pack("I", f.count, align=4)
    w.pack("?", False, align=1)
    w.pack("II", 16, 16 * len(pts), align=4)
    w.pack("I", pts.nbytes, align=4)
    w.raw(pts.tobytes())
    w.pack("?", True, align=1)
    return w.bytes()


def decode_pointcloud2(buf: bytes | memoryview, what: str = "PointCloud2") -> PointCloud2:
    """Decode CDR bytes of a sensor_msgs/msg/PointCloud2 (any layout)."""
    r = _Reader(buf, what)
    stamp_ns, frame_id = r.header()
    height, width = r.unpack("II", 4)
    (nfields,) = r.unpack("I", 4)
    fields = []
    for _ in range(nfields):
        name = r.string()
        (offset,) = r.unpack("I", 4)
        (datatype,) = r.unpack("B", 1)
        (count,) = r.unpack("I", 4)
        fields.append(PointField(name, offset, datatype, count))
    (bigendian,) = r.unpack("?", 1)
    point_step, row_step = r.unpack("II", 4)
    (n,) = r.unpack("I", 4)
    data = bytes(r.take(n))
    (dense,) = r.unpack("?", 1) if r.pos < len(r.body) else (False,)
    return PointCloud2(stamp_ns, frame_id, height, width, tuple(fields), bool(bigendian),
                       point_step, row_step, data, bool(dense))



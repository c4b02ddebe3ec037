"""ROS 2 messages as the tools outside adaptune decode them: mcap_ros2's own decoders, from an
MCAP's schemas or from the schemas a Foxglove server advertises; never adaptune's codecs."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np


def ros2_messages(path: Path) -> dict[str, list[tuple[int, Any]]]:
    """topic -> [(log time, message)] of an MCAP, decoded by mcap_ros2's decoder only."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    out: dict[str, list[tuple[int, Any]]] = {}
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            assert schema.encoding == "ros2msg" and channel.message_encoding == "cdr"
            out.setdefault(channel.topic, []).append((message.log_time, decoded))
    return out


def ros2_decoder(schema_name: str, schema_text: str) -> Any:
    """mcap_ros2's decoder of ``schema_name`` messages from their ros2msg ``schema_text``."""
    from mcap_ros2._dynamic import generate_dynamic

    return generate_dynamic(schema_name, schema_text)[schema_name]


def pose_matrix(pose: Any) -> np.ndarray:
    """(4, 4) of a decoded geometry_msgs Pose or Transform."""
    from scipy.spatial.transform import Rotation

    t = getattr(pose, "position", None) or pose.translation
    q = getattr(pose, "orientation", None) or pose.rotation
    T = np.eye(4)
    T[:3, :3] = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
    T[:3, 3] = [t.x, t.y, t.z]
    return T

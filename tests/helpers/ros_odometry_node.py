"""A small odometry node for the live node's test: a real rospy node that runs adaptune's NDT
odometry (scan by scan, ``StreamingAdapter.start`` / ``step`` / ``set_params``) on a PointCloud2
topic and applies the parameters it is sent, through a real dynamic_reconfigure server built
from the adapter's parameter space (``--via dynamic_reconfigure``), or from
dynamic_reconfigure/Config messages on a topic (``--via topic``), as a node without a server
would. It also listens to the schedule topic.

Everything it sees goes to a JSON-lines log, one event a line, written as it happens:
``{"event": "config", "params": {...}, "initial": bool}`` (the parameters applied; the server's
first configuration is its defaults, ``initial``), ``{"event": "schedule", "stamp_ns": ...,
"params": {...}}`` and ``{"event": "scan", "stamp_ns": ..., "params": {...}, "pose": [16]}``
(the parameters in force when the scan was registered, and the pose it gave).

    python ros_odometry_node.py --via dynamic_reconfigure|topic --log FILE [--name NAME]
        [--cloud TOPIC] [--param-topic TOPIC] [--schedule-topic TOPIC]
"""

from __future__ import annotations

import argparse
import json
import threading
from pathlib import Path
from types import SimpleNamespace
from typing import Any

ALGORITHM = "ndt"


def config_type(space: Any) -> SimpleNamespace:
    """What dynamic_reconfigure's generated ``<Name>Config`` module holds (the description,
    min, max, defaults, level and type of every parameter), built from a ParameterSpace."""
    params = [{"name": s.name, "type": "int" if s.kind == "int" else "double",
               "default": _typed(s, s.default), "level": 1, "description": s.unit or s.name,
               "min": _typed(s, s.low), "max": _typed(s, s.high), "edit_method": ""}
              for s in (space[n] for n in space.names)]
    description = {"name": "Default", "type": "", "state": True, "cstate": "true", "id": 0,
                   "parent": 0, "parameters": params, "groups": []}
    return SimpleNamespace(
        config_description=description, all_level=1,
        **{key: {p["name"]: p[field] for p in params}
           for key, field in (("min", "min"), ("max", "max"), ("defaults", "default"),
                              ("level", "level"), ("type", "type"))})


def _typed(spec: Any, value: float) -> float | int:
    return int(value) if spec.kind == "int" else float(value)


class OdometryNode:
    """The node's state: the odometry, the parameters in force, the log."""

    def __init__(self, log: Path) -> None:
        from pipeline.odometry.registry import build_adapter, get_adapter

        self.space = get_adapter(ALGORITHM).space
        self.adapter = build_adapter(ALGORITHM)
        self.params = self.space.defaults()
        self.odometry: Any = None
        self.lock = threading.Lock()
        self.log = log.open("a", buffering=1)

    def write(self, event: str, **fields: Any) -> None:
        self.log.write(json.dumps({"event": event, **fields}) + "\n")

    def apply(self, config: dict[str, Any], initial: bool = False) -> None:
        """Apply the space's parameters of ``config`` (dynamic_reconfigure's dict)."""
        with self.lock:
            self.params = self.space.validate({n: float(config[n]) for n in self.space.names})
            if self.odometry is not None:
                self.odometry.set_params(self.params)
            self.write("config", params=self.params, initial=initial)

    def on_cloud(self, msg: Any) -> None:
        from pipeline.ros2_cdr import cloud_to_xyzi

        stamp_ns = int(msg.header.stamp.to_nsec())
        xyz = cloud_to_xyzi(msg, "cloud")[:, :3]
        with self.lock:
            if self.odometry is None:
                self.odometry = self.adapter.start(self.params)
            pose = self.odometry.step(xyz, stamp_ns)
            self.write("scan", stamp_ns=stamp_ns, params=self.params,
                       pose=[float(v) for v in pose.ravel()])

    def on_schedule(self, msg: Any) -> None:
        self.write("schedule", stamp_ns=int(msg.header.stamp.to_nsec()),
                   params=dict(zip(msg.name, msg.position, strict=True)))


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--via", choices=("dynamic_reconfigure", "topic"), required=True)
    parser.add_argument("--log", type=Path, required=True)
    parser.add_argument("--name", default="odometry")
    parser.add_argument("--cloud", default="/points")
    parser.add_argument("--param-topic", default="/adaptune/parameters")
    parser.add_argument("--schedule-topic", default="/adaptune/schedule")
    args = parser.parse_args()

    import rospy
    from dynamic_reconfigure.encoding import decode_config
    from dynamic_reconfigure.msg import Config
    from dynamic_reconfigure.server import Server
    from sensor_msgs.msg import JointState, PointCloud2

    node = OdometryNode(args.log)
    rospy.init_node(args.name)
    if args.via == "dynamic_reconfigure":
        def reconfigure(config: Any, level: int) -> Any:
            node.apply(config, initial=level == -1)  # the server's first call: level ~0
            return config

        Server(config_type(node.space), reconfigure)
    else:
        rospy.Subscriber(args.param_topic, Config, lambda m: node.apply(decode_config(m)),
                         queue_size=None)
    rospy.Subscriber(args.schedule_topic, JointState, node.on_schedule, queue_size=None)
    rospy.Subscriber(args.cloud, PointCloud2, node.on_cloud, queue_size=None, buff_size=1 << 27)
    rospy.spin()


if __name__ == "__main__":
    main()

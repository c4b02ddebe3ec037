"""The live ROS 1 node, ``adaptune node``: rospy around ``pipeline.node`` (docs/design.md,
"The live ROS node").

It subscribes to a sensor_msgs/PointCloud2 topic, selects with the model artifact every
``select.period_s`` (of the clouds' header stamps) and
- sends the odometry node the parameters when they change (``pipeline.node``), through its
  dynamic_reconfigure server (``via="dynamic_reconfigure"``: the ``set_parameters`` service of
  ``target``, as ``rosrun dynamic_reconfigure dynparam set`` does), or as a latched
  dynamic_reconfigure/Config message on ``param_topic`` for a node without a server
  (``via="topic"``: the message type a server publishes on ``~parameter_updates``, which
  ``dynamic_reconfigure.encoding.decode_config`` reads back as a dict);
- publishes every selection on ``schedule_topic`` as a sensor_msgs/JointState (a standard
  stamped list of named doubles, which rostopic, rosbag, rqt_plot and Foxglove read without
  any adaptune message): ``header.stamp`` the stamp of the cloud it was selected from,
  ``name`` the model's parameter names, ``position`` their values.

rospy and the ROS messages are imported inside the functions: they come from Debian's ROS
packages (docs/usage.md, "A live ROS node"), which the rest of adaptune never needs.
Signals stay adaptune's (``init_node(disable_signals=True)``): Ctrl-C and SIGTERM unwind
through ``run_node``, which shuts the node down, as they do every other command.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import Any

from pipeline.errors import ConfigError, InputError
from pipeline.node import NodeSelection, Selection
from pipeline.runtime import Model, Selector
from pipeline.selection import SelectionSettings

VIA = ("dynamic_reconfigure", "topic")
"""How the odometry node is sent its parameters."""
CLOUD_BUFFER_BYTES = 1 << 27
"""rospy's receive buffer for the cloud topic: larger than a cloud (a 128-beam scan is ~10 MB),
or rospy delivers stale clouds with a short queue (its known default of 64 KB)."""
SPIN_S = 0.2
"""How often the main thread looks whether the node was shut down [s]."""

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class NodeOptions:
    """The node's ROS side: topics, the odometry node and how it is sent parameters.

    cloud_topic: the PointCloud2 topic; target: the odometry node's dynamic_reconfigure
    namespace (its node name, e.g. ``/lio``), for ``via="dynamic_reconfigure"``; param_topic:
    the Config topic for ``via="topic"``; queue_size: clouds kept waiting while a selection runs
    (1: the newest only; 0: every cloud); wait_s: how long to wait for the target's server [s].
    """

    cloud_topic: str = "/velodyne_points"
    target: str | None = None
    via: str = "dynamic_reconfigure"
    param_topic: str = "/adaptune/parameters"
    schedule_topic: str = "/adaptune/schedule"
    name: str = "adaptune"
    queue_size: int = 1
    wait_s: float = 30.0

    def __post_init__(self) -> None:
        if self.via not in VIA:
            raise ConfigError(f"via must be one of {', '.join(VIA)}, got {self.via!r}")
        if self.via == "dynamic_reconfigure" and not self.target:
            raise ConfigError("--target NODE is needed with --via dynamic_reconfigure (the "
                              "odometry node whose dynamic_reconfigure server gets the "
                              "parameters); a node without one: --via topic")
        if self.queue_size < 0:
            raise ConfigError(f"queue_size must be >= 0, got {self.queue_size}")
        if not self.wait_s > 0:
            raise ConfigError(f"wait_s must be > 0, got {self.wait_s}")


def import_rospy() -> Any:
    """rospy, or ConfigError saying how this interpreter gets it."""
    import sys

    try:
        import rospy
    except ImportError as exc:
        raise ConfigError(
            f"adaptune node needs rospy, which {sys.executable} cannot import ({exc}): install "
            "Debian 12's ROS 1 packages and run `make setup` (docs/usage.md, \"A live ROS "
            "node\")") from None
    return rospy


def run_node(model: Model, settings: SelectionSettings, options: NodeOptions,
             rename: Mapping[str, str] | None = None) -> dict[str, int]:
    """Run the node until ROS shuts it down (``rosnode kill``, the master's shutdown) or Ctrl-C
    / SIGTERM (which propagate once the node is down). Returns the scans received, selections
    made and parameter sets sent (``NodeSelection.summary``)."""
    logic = NodeSelection(Selector(model, settings), rename)
    with _adaptune_logging():
        rospy = import_rospy()
        rospy.init_node(options.name, anonymous=False, disable_signals=True)
    from sensor_msgs.msg import PointCloud2

    try:
        send = _target(rospy, options, logic)
        publish = _schedule_publisher(rospy, options.schedule_topic, model.names)

        def on_cloud(msg: Any) -> None:
            _on_cloud(rospy, logic, msg, options.cloud_topic, send, publish)

        rospy.Subscriber(options.cloud_topic, PointCloud2, on_cloud,
                         queue_size=options.queue_size or None, buff_size=CLOUD_BUFFER_BYTES)
        rospy.loginfo("adaptune node: %s model, clouds from %s, schedule on %s, parameters via "
                      "%s", model.algorithm, options.cloud_topic, options.schedule_topic,
                      options.target if options.via == "dynamic_reconfigure"
                      else options.param_topic)
        while not rospy.is_shutdown():
            rospy.rostime.wallsleep(SPIN_S)
    finally:
        rospy.signal_shutdown("adaptune node ends")
        log.info("adaptune node: %s", logic.summary())
    return logic.summary()


@contextlib.contextmanager
def _adaptune_logging() -> Iterator[None]:
    """Keep adaptune's logging through importing rospy and ``rospy.init_node``: ROS's logging
    configuration replaces the root logger's handlers (a file under ROS_HOME/log only);
    adaptune's come back, at adaptune's level, minus the records ROS prints or files itself
    (its loggers ``rospy*`` and ``rosout``)."""
    root = logging.getLogger()
    handlers, level = list(root.handlers), root.level
    for handler in handlers:
        handler.addFilter(_not_ros)
    try:
        yield
    finally:
        for handler in handlers:
            if handler not in root.handlers:
                root.addHandler(handler)
        root.setLevel(level)


def _not_ros(record: logging.LogRecord) -> bool:
    """False for a record of ROS's own loggers (ROS prints them itself)."""
    return not record.name.startswith(("rospy", "rosout"))


def _on_cloud(rospy: Any, logic: NodeSelection, msg: Any, topic: str,
              send: Any, publish: Any) -> None:
    """One cloud: select when due, publish the schedule entry, send changed parameters."""
    from pipeline.ros2_cdr import cloud_to_xyzi

    stamp_ns = int(msg.header.stamp.to_nsec())
    try:
        points = cloud_to_xyzi(msg, f"{topic} at {stamp_ns} ns")
    except InputError as exc:
        rospy.logwarn_throttle(10.0, f"adaptune node: cloud skipped: {exc}")
        return
    selection = logic.on_scan(points, stamp_ns)
    if selection is None:
        return
    publish(selection)
    if selection.changed:
        send(selection)


def _schedule_publisher(rospy: Any, topic: str, names: list[str]) -> Any:
    """A function publishing a Selection as sensor_msgs/JointState on ``topic``."""
    from sensor_msgs.msg import JointState

    pub = rospy.Publisher(topic, JointState, queue_size=100)

    def publish(selection: Selection) -> None:
        msg = JointState()
        msg.header.stamp = rospy.Time(selection.stamp_ns // 1_000_000_000,
                                      selection.stamp_ns % 1_000_000_000)
        msg.name = list(names)
        msg.position = [float(selection.params[n]) for n in names]
        pub.publish(msg)

    return publish


def _target(rospy: Any, options: NodeOptions, logic: NodeSelection) -> Any:
    """A function sending a Selection's parameters to the odometry node (``options.via``)."""
    if options.via == "topic":
        from dynamic_reconfigure.encoding import encode_config
        from dynamic_reconfigure.msg import Config

        pub = rospy.Publisher(options.param_topic, Config, queue_size=10, latch=True)

        def publish(selection: Selection) -> None:
            pub.publish(encode_config(logic.for_target(selection.params)))
            _log_sent(rospy, selection, options.param_topic)

        return publish
    client = _reconfigure_client(rospy, str(options.target), options.wait_s, logic)

    def reconfigure(selection: Selection) -> None:
        from dynamic_reconfigure import DynamicReconfigureCallbackException

        try:
            client.update_configuration(logic.for_target(selection.params))
        except (DynamicReconfigureCallbackException, rospy.ServiceException) as exc:
            rospy.logerr(f"adaptune node: {options.target} refused the parameters ({exc})")
            return
        _log_sent(rospy, selection, str(options.target))

    return reconfigure


def _reconfigure_client(rospy: Any, target: str, wait_s: float, logic: NodeSelection) -> Any:
    """A dynamic_reconfigure client of ``target``; ConfigError when no server answers within
    ``wait_s`` or the server lacks one of the (renamed) parameters."""
    from dynamic_reconfigure.client import Client

    try:
        client = Client(target, timeout=wait_s)
        descriptions = client.get_parameter_descriptions(timeout=wait_s)
    except rospy.ROSException as exc:
        raise ConfigError(f"{target}: no dynamic_reconfigure server answered within "
                          f"{wait_s:g} s ({exc}); is the odometry node running under that "
                          "name?") from None
    if descriptions is None:
        raise ConfigError(f"{target}: its dynamic_reconfigure server published no parameter "
                          f"descriptions within {wait_s:g} s")
    have = {str(d["name"]) for d in descriptions}
    missing = [n for n in logic.target_names.values() if n not in have]
    if missing:
        raise ConfigError(f"{target}: its dynamic_reconfigure server has no parameter "
                          f"{', '.join(missing)} (its parameters: {', '.join(sorted(have))}); "
                          "map a model parameter to its name with --rename MODEL=NODE")
    return client


def _log_sent(rospy: Any, selection: Selection, where: str) -> None:
    values = ", ".join(f"{n}={v:.6g}" for n, v in selection.params.items())
    rospy.loginfo(f"adaptune node: {values} -> {where} (from the cloud at "
                  f"{selection.stamp_ns / 1e9:.3f} s)")

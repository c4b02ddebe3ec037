"""The live view of ``adaptune live --serve``: a Foxglove WebSocket server (foxglove-sdk) that
shows the run while it runs; Foxglove opens it with "Open connection", ``ws://HOST:PORT``.

Channels: ROS 2 messages in CDR with the schemas of ``schemas/ros2/`` (what the output MCAP
holds, ``pipeline.live``), so Foxglove decodes them as it decodes the MCAP:
- ``/lidar/points`` (the scan, frame ``lidar``), ``/ground_truth/pose``, ``/odometry/pose``,
  ``/tf`` (world -> lidar, world -> odom, odom -> lidar_odometry) and ``/adaptune/params`` (the
  parameters in force and the selection's state), one message each a frame;
- ``/ground_truth/path`` and ``/odometry/path``: nav_msgs/msg/Path of both trajectories so far
  (frame ``world``), so that a client that connects late sees them whole. A path keeps at most
  ``PATH_POSES`` poses: past that, every other one is dropped (the newest is always kept), so a
  frame's message stays under ~40 KB and ~10 ms to encode, however long the sequence.

The session: the run starts once a client has subscribed to a channel (Foxglove subscribes as it
connects), so the view shows it from its first frame; after the last frame the server keeps
serving until every client has left, so the end state can be looked at (Ctrl-C ends that wait
like a client leaving: the outputs are complete by then). foxglove is imported here only, inside
the functions: the rest of adaptune never needs it.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Mapping
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pipeline.live import PARAMS_TOPIC, POSE_TOPIC, LiveFrame
from pipeline.progress import PROGRESS
from pipeline.runtime import Model, Selector

GT_PATH_TOPIC = "/ground_truth/path"
ESTIMATE_PATH_TOPIC = "/odometry/path"
PATH_POSES = 500
"""The most poses a path message holds (module docstring)."""
WAIT_S = 0.5
"""How often a wait for clients looks again (Ctrl-C is seen within this) [s]."""

log = logging.getLogger(__name__)


class Trail:
    """A trajectory shown as a path: stamps (n,) [ns] and poses (n, 4, 4), thinned to at most
    ``limit`` (every other one dropped when it grows past, the newest kept)."""

    def __init__(self, limit: int = PATH_POSES) -> None:
        self.limit = limit
        self.stamps_ns: list[int] = []
        self.poses: list[NDArray[np.float64]] = []

    def add(self, stamp_ns: int, T_world_x: NDArray[np.float64]) -> None:
        self.stamps_ns.append(int(stamp_ns))
        self.poses.append(np.asarray(T_world_x, np.float64))
        if len(self.poses) > self.limit:
            keep = [*range(0, len(self.poses) - 1, 2), len(self.poses) - 1]
            self.stamps_ns = [self.stamps_ns[i] for i in keep]
            self.poses = [self.poses[i] for i in keep]

    def encode(self) -> bytes:
        from pipeline.ros2_cdr import encode_path

        return encode_path(np.array(self.stamps_ns, np.int64), np.stack(self.poses))


class LiveView:
    """The Foxglove WebSocket server of a live run (module docstring): a context manager that
    starts it on ``host``:``port`` (0: a free port) and stops it; ``show`` each frame."""

    def __init__(self, host: str = "127.0.0.1", port: int = 8765) -> None:
        self.host, self.port = host, port
        self.gt_path, self.estimate_path = Trail(), Trail()
        self._subscribed: set[tuple[int, int]] = set()  # (client id, channel id)
        self._changed = threading.Condition()
        self._channels: dict[str, Any] = {}

    @property
    def url(self) -> str:
        return f"ws://{self.host}:{self.port}"

    def __enter__(self) -> LiveView:
        import foxglove

        from pipeline.ros2_cdr import PARAMETER_EVENT, PATH, POINTCLOUD2, POSE_STAMPED, TF_MESSAGE
        from pipeline.sequence import GT_TOPIC, POINTS_TOPIC, TF_TOPIC

        self._context = context = foxglove.Context()  # the channels' and the server's
        topics = {POINTS_TOPIC: POINTCLOUD2, GT_TOPIC: POSE_STAMPED, POSE_TOPIC: POSE_STAMPED,
                  TF_TOPIC: TF_MESSAGE, PARAMS_TOPIC: PARAMETER_EVENT, GT_PATH_TOPIC: PATH,
                  ESTIMATE_PATH_TOPIC: PATH}
        self._channels = {topic: _channel(foxglove, context, topic, msgtype)
                          for topic, msgtype in topics.items()}
        self._server = foxglove.start_server(name="adaptune", host=self.host, port=self.port,
                                             context=context, server_listener=_listener(self))
        self.port = int(self._server.port)
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self._server.stop()

    def _subscription(self, client: int, channel: int, subscribed: bool) -> None:
        """The server's listener: a client subscribed to (or left) a channel."""
        with self._changed:
            if subscribed:
                self._subscribed.add((client, channel))
            else:
                self._subscribed.discard((client, channel))
            self._changed.notify_all()

    @property
    def clients(self) -> int:
        """How many clients are subscribed to a channel."""
        with self._changed:
            return len({client for client, _ in self._subscribed})

    def wait_for_client(self) -> None:
        """Block until a client has subscribed to a channel."""
        PROGRESS.info("live view: %s, waiting for a client (Foxglove: Open connection)", self.url)
        with self._changed:
            while not self._subscribed:
                self._changed.wait(WAIT_S)

    def hold(self) -> None:
        """Block until every client has left (Ctrl-C or SIGTERM end the wait too)."""
        if self.clients:
            PROGRESS.info("live view: the run has ended; serving %s until its clients leave "
                          "(Ctrl-C ends)", self.url)
        try:
            with self._changed:
                while self._subscribed:
                    self._changed.wait(WAIT_S)
        except KeyboardInterrupt:
            log.info("live view: ended by an interrupt")

    def show(self, frame: LiveFrame) -> None:
        """Log one frame on every channel (``pipeline.live.FrameSink``)."""
        from pipeline.live import ESTIMATE_FRAME, ODOM_FRAME
        from pipeline.ros2_cdr import encode_pointcloud2, encode_pose_stamped, encode_tf
        from pipeline.sequence import GT_TOPIC, LIDAR_FRAME, POINTS_TOPIC, TF_TOPIC, WORLD_FRAME

        t = frame.stamp_ns
        T_world_estimate = frame.T_world_odom @ frame.T_odom_lidar
        self.estimate_path.add(t, T_world_estimate)
        out = [(POINTS_TOPIC, encode_pointcloud2(t, frame.points_lidar)),
               (POSE_TOPIC, encode_pose_stamped(t, T_world_estimate)),
               (TF_TOPIC, encode_tf(t, WORLD_FRAME, ODOM_FRAME, frame.T_world_odom)),
               (TF_TOPIC, encode_tf(t, ODOM_FRAME, ESTIMATE_FRAME, frame.T_odom_lidar)),
               (PARAMS_TOPIC, frame.event),
               (ESTIMATE_PATH_TOPIC, self.estimate_path.encode())]
        if frame.T_world_lidar is not None:
            self.gt_path.add(t, frame.T_world_lidar)
            out += [(GT_TOPIC, encode_pose_stamped(t, frame.T_world_lidar)),
                    (TF_TOPIC, encode_tf(t, WORLD_FRAME, LIDAR_FRAME, frame.T_world_lidar)),
                    (GT_PATH_TOPIC, self.gt_path.encode())]
        for topic, data in out:
            self._channels[topic].log(data, log_time=t)


def _listener(view: LiveView) -> Any:
    """foxglove's ServerListener telling ``view`` of subscriptions (a client that disconnects
    is unsubscribed from every channel)."""
    from foxglove.websocket import ServerListener

    class Listener(ServerListener):
        def on_subscribe(self, client: Any, channel: Any) -> None:
            view._subscription(int(client.id), int(channel.id), True)

        def on_unsubscribe(self, client: Any, channel: Any) -> None:
            view._subscription(int(client.id), int(channel.id), False)

    return Listener()


def _channel(foxglove: Any, context: Any, topic: str, msgtype: str) -> Any:
    """A foxglove channel of ROS 2 ``msgtype`` messages in CDR on ``topic``."""
    from pipeline.ros2_cdr import schema_text

    schema = foxglove.Schema(name=msgtype, encoding="ros2msg",
                             data=schema_text(msgtype).encode())
    return foxglove.Channel(topic, schema=schema, message_encoding="cdr", context=context)


def serve_live(model: Model, sequence: str | Path, out: str | Path, selector: Selector,
               adapter_options: Mapping[str, Any] | None = None, *, scans: bool = False,
               host: str = "127.0.0.1", port: int = 8765) -> dict[str, Any]:
    """``pipeline.live.run_live`` shown by a LiveView on ``host``:``port`` (module docstring:
    it waits for a client, runs, then serves until the clients leave). Returns run_live's
    summary and the server's ``url``."""
    from pipeline.live import run_live

    with LiveView(host, port) as view:
        view.wait_for_client()
        summary = run_live(model, sequence, out, selector, adapter_options, scans=scans,
                           sink=view)
        view.hold()
    return {**summary, "url": view.url}

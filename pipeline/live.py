"""Live selection: scans streamed one by one through the model's odometry, parameters chosen
online every period and pushed into it (``adapter.start`` / ``set_params``), written as an MCAP
that ROS 2 tools and Foxglove read, and shown while it runs by a ``FrameSink`` such as the
Foxglove server of ``pipeline.live_view`` (``adaptune live --serve``). The frames show progress
(``pipeline.progress``).

The output holds the sequence's ground truth (``/ground_truth/pose``, ``/tf`` world -> lidar),
its scans (``/lidar/points``) only when asked (``scans``: 1.4 MB a KITTI frame compressed;
without them the MCAP is a record of the run, 1.2 KB a frame), and:
- ``/odometry/pose`` (geometry_msgs/msg/PoseStamped, frame ``world``): the estimate, anchored at
  the first frame's ground-truth pose, so ground truth and estimate start at the same place;
- ``/tf``: ``world`` -> ``odom`` (that anchor, ``T_world_odom``) and ``odom`` ->
  ``lidar_odometry`` (the odometry's own pose, starting at the identity): the estimated lidar
  has a frame of its own beside the ground truth's ``lidar``;
- ``/adaptune/params`` (rcl_interfaces/msg/ParameterEvent, node ``/adaptune/<algorithm>``): one
  event a frame that restates every odometry parameter in force (doubles; ``new_parameters`` on
  the first frame, ``changed_parameters`` after), and the selection's state as parameters of
  their own: ``adaptune.frame`` (integer), ``adaptune.selected`` (bool),
  ``adaptune.predicted_rte_pct`` (double, NaN between selections) and ``adaptune.kept``
  (string). In Foxglove: ``/adaptune/params.changed_parameters[:]{name=="resolution"}
  .value.double_value``.

Kept apart from ``pipeline.runtime`` (the deployable part, numpy and scipy only): this module
needs the odometry adapters and the MCAP writer.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import ConfigError
from pipeline.runtime import Model, Params, Selector

PARAMS_TOPIC = "/adaptune/params"
POSE_TOPIC = "/odometry/pose"
ODOM_FRAME = "odom"
ESTIMATE_FRAME = "lidar_odometry"

# rcl_interfaces/msg/ParameterType
_BOOL, _INTEGER, _DOUBLE, _STRING = 1, 2, 3, 4


@dataclass(frozen=True)
class LiveFrame:
    """One frame of a live run, as a ``FrameSink`` shows it.

    points_lidar: (N, 4) float32 x, y, z, intensity in the sensor frame [m]; T_world_lidar:
    its ground-truth pose (4, 4), or None; T_world_odom: the estimate's anchor (4, 4);
    T_odom_lidar: the odometry's pose (4, 4); params: the parameters in force; event: the CDR
    bytes of the frame's ``PARAMS_TOPIC`` ParameterEvent."""

    frame: int
    stamp_ns: int
    points_lidar: NDArray[np.float32]
    T_world_lidar: NDArray[np.float64] | None
    T_world_odom: NDArray[np.float64]
    T_odom_lidar: NDArray[np.float64]
    params: Params
    event: bytes


class FrameSink(Protocol):
    """What shows a live run while it runs (``pipeline.live_view.LiveView``)."""

    def show(self, frame: LiveFrame) -> None: ...


def run_live(
    model: Model, sequence: str | Path, out: str | Path, selector: Selector | None = None,
    adapter_options: Mapping[str, Any] | None = None, *, scans: bool = False,
    sink: FrameSink | None = None,
) -> dict[str, int]:
    """Stream ``sequence`` through the model's odometry, selecting parameters online; write
    ``out`` (module docstring), with the scans when ``scans``; ``sink`` is shown every frame.
    Returns frames, selections and parameter changes (the ``set_params`` calls, counted as
    ``Schedule.n_changes`` counts them).

    ``adapter_options``: the adapter's untuned settings, as in the trials (params
    ``trials.adapter_options``). ConfigError for an adapter that cannot stream (``command``).
    """
    from pipeline.odometry.base import StreamingAdapter
    from pipeline.odometry.registry import build_adapter
    from pipeline.progress import progress
    from pipeline.ros2_cdr import PARAMETER_EVENT, encode
    from pipeline.sequence import WORLD_FRAME, SequenceReader, SequenceWriter

    selector = selector or Selector(model)
    adapter = build_adapter(model.algorithm, adapter_options, model.space)
    if not isinstance(adapter, StreamingAdapter):
        raise ConfigError(f"{model.algorithm}: adaptune live needs an adapter that streams "
                          "scan by scan (start); this one runs whole sequences (use adaptive)")
    node = f"/adaptune/{model.algorithm}"
    odom = None
    selections = changes = 0
    with SequenceReader(sequence) as reader:
        gt = reader.ground_truth()
        T_world_odom = np.eye(4) if gt is None else gt[0]
        info = reader.info
        info.extra = {**info.extra, "adaptune.model": str(model.path),
                      "adaptune.algorithm": model.algorithm}
        with SequenceWriter(out, info, points=scans) as writer:
            for scan in progress(reader, len(reader), f"live {info.name}"):
                selected = selector.due(scan.stamp_ns)
                before = selector.current
                params = selector.update(scan.points_lidar, scan.stamp_ns)
                selections += selected
                if odom is None:
                    odom = adapter.start(params)
                elif params != before:
                    odom.set_params(params)
                    changes += 1
                T_odom_lidar = odom.step(scan.xyz, scan.stamp_ns)
                writer.add(scan.stamp_ns, scan.points_lidar, scan.T_world_lidar)
                writer.add_pose(POSE_TOPIC, scan.stamp_ns, T_world_odom @ T_odom_lidar)
                writer.add_tf(scan.stamp_ns, WORLD_FRAME, ODOM_FRAME, T_world_odom)
                writer.add_tf(scan.stamp_ns, ODOM_FRAME, ESTIMATE_FRAME, T_odom_lidar)
                event = encode(PARAMETER_EVENT, parameter_event(
                    node, scan.stamp_ns, params, selection_state(
                        model, selector, scan.frame, selected), first=scan.frame == 0))
                writer.add_ros2(PARAMS_TOPIC, PARAMETER_EVENT, scan.stamp_ns, event)
                if sink is not None:
                    sink.show(LiveFrame(scan.frame, scan.stamp_ns, scan.points_lidar,
                                        scan.T_world_lidar, T_world_odom, T_odom_lidar,
                                        params, event))
    return {"frames": len(reader), "selections": selections, "changes": changes}


def selection_state(model: Model, selector: Selector, frame: int,
                    selected: bool) -> dict[str, Any]:
    """The selection's state of one frame (values typed as their ROS 2 parameter types):
    ``adaptune.frame``, ``.selected``, ``.predicted_rte_pct`` (NaN unless selected) and
    ``.kept`` (why the parameters in force were kept: ``hysteresis``, ``anchor``, ``novel``,
    ``too_few_points``; empty unless selected)."""
    t = selector.last.get("predicted_t") if selected else None
    pred = math.nan if t is None else float(np.expm1(t) if model.target == "log" else t)
    return {"adaptune.frame": int(frame), "adaptune.selected": bool(selected),
            "adaptune.predicted_rte_pct": pred,
            "adaptune.kept": str(selector.last.get("kept", "")) if selected else ""}


def parameter_event(node: str, stamp_ns: int, params: dict[str, float],
                    state: dict[str, Any], first: bool) -> dict[str, Any]:
    """An rcl_interfaces/msg/ParameterEvent (as nested dicts) of the odometry ``params``
    (doubles) and the selection ``state`` (bool, int, float or str values)."""
    entries = [_parameter(name, float(value)) for name, value in params.items()]
    entries += [_parameter(name, value) for name, value in state.items()]
    return {"stamp": {"sec": stamp_ns // 1_000_000_000, "nanosec": stamp_ns % 1_000_000_000},
            "node": node, "new_parameters": entries if first else [],
            "changed_parameters": [] if first else entries, "deleted_parameters": []}


def _parameter(name: str, value: bool | int | float | str) -> dict[str, Any]:
    """rcl_interfaces/msg/Parameter of a Python value (bool before int: bool is an int)."""
    if isinstance(value, bool):
        return {"name": name, "value": {"type": _BOOL, "bool_value": value}}
    if isinstance(value, int):
        return {"name": name, "value": {"type": _INTEGER, "integer_value": value}}
    if isinstance(value, float):
        return {"name": name, "value": {"type": _DOUBLE, "double_value": value}}
    return {"name": name, "value": {"type": _STRING, "string_value": value}}

"""What the live ROS node decides, without ROS: when a scan triggers a selection, which
parameters go to the odometry node and what the schedule says (docs/design.md, "The live ROS
node"). ``pipeline.ros_node`` wires it to rospy; this module imports neither rospy nor any
ROS message, so it is tested without a ROS installation.

- A scan is selected from when a selection is due at its header stamp (``Selector.due``: the
  first scan, then every ``select.period_s``), as ``adaptune live`` and ``adaptive`` do, so a
  live run selects what ``select`` selects on the same scans. A stamp earlier than the last
  selection's (a bag played again, ``rosbag play -l``) starts the period over.
- Every selection is one schedule entry (its stamp and every parameter), whether the parameters
  changed or not; the odometry node is sent the first selection and every one that changed
  the parameters (what ``adaptune live`` pushes with ``set_params``).
- What the odometry node is sent: the model's parameters renamed as the node calls them
  (``rename``, model name -> node name), integers as ``int`` (a parameter of kind ``int``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import ConfigError
from pipeline.live import selection_state
from pipeline.runtime import Params, Selector


@dataclass(frozen=True)
class Selection:
    """One schedule entry: the selection made from the scan stamped ``stamp_ns`` [ns].

    params: every model parameter in force from this scan on (model names); changed: True
    when the odometry node is to be sent them (the first selection, or they differ from the
    last sent); state: the selection's state (``pipeline.live.selection_state``)."""

    stamp_ns: int
    params: Params
    changed: bool
    state: dict[str, Any] = field(default_factory=dict)


class NodeSelection:
    """The node's selection state over a stream of scans (module docstring).

    ``rename``: model parameter name -> the odometry node's name for it (the rest keep their
    names); ConfigError for a name the model does not have, or two parameters given one name.
    """

    def __init__(self, selector: Selector, rename: Mapping[str, str] | None = None) -> None:
        model = selector.model
        rename = dict(rename or {})
        unknown = sorted(set(rename) - set(model.names))
        if unknown:
            raise ConfigError(f"--rename {unknown[0]}: the model has no parameter of that name "
                              f"(its parameters: {', '.join(model.names)})")
        self.target_names = {n: rename.get(n, n) for n in model.names}
        if len(set(self.target_names.values())) != len(self.target_names):
            raise ConfigError(f"--rename gives two parameters one name: {self.target_names}")
        self.integers = {str(s["name"]) for s in model.space if s.get("kind") == "int"}
        self.selector = selector
        self.sent: Params | None = None
        self.scans = self.selections = self.sets_sent = 0

    def on_scan(self, points_lidar: NDArray[np.floating], stamp_ns: int) -> Selection | None:
        """The selection this scan triggers ((N, 3|4) points in the sensor frame [m], its
        header stamp [ns]), or None when none is due."""
        self.scans += 1
        selector = self.selector
        if selector.last_stamp_ns is not None and stamp_ns < selector.last_stamp_ns:
            selector.last_stamp_ns = None  # time went back: the period starts over
        if not selector.due(stamp_ns):
            return None
        params = selector.select(points_lidar, stamp_ns)
        self.selections += 1
        changed = params != self.sent
        if changed:
            self.sent = params
            self.sets_sent += 1
        state = selection_state(selector.model, selector, self.scans - 1, selected=True)
        return Selection(int(stamp_ns), params, changed, state)

    def for_target(self, params: Params) -> dict[str, float | int]:
        """``params`` as the odometry node is sent them: its names, integers as int."""
        return {self.target_names[n]: (round(v) if n in self.integers else float(v))
                for n, v in params.items()}

    def summary(self) -> dict[str, int]:
        """Scans received, selections made, parameter sets sent to the odometry node."""
        return {"scans": self.scans, "selections": self.selections, "sent": self.sets_sent}

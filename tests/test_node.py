"""`adaptune node`, the live ROS 1 node.

Without ROS: its decisions (``pipeline.node``) against the offline selector. With ROS (Debian
12's packages, which `make setup` installs; with CI=true these tests fail rather than skip
without them): the venv imports rospy & co. without losing its own numpy, and a real graph
runs the node: a real ``roscore`` on a port of its own, ``rosbag play`` of a ROS 1 bag made
here from real KITTI scans, and a small odometry node (tests/helpers/ros_odometry_node.py:
adaptune's NDT odometry behind a real dynamic_reconfigure server, or a parameter topic) that
applies what it is sent. Every process ends with the test (tests/helpers/ros_graph.py).
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from helpers.models import build_model, write_tiny_sequence
from helpers.ros_graph import RosGraph, require_ros
from helpers.source_inputs import BAG_T0_NS, load_kitti, write_bag

from pipeline.errors import ConfigError
from pipeline.node import NodeSelection
from pipeline.ros_node import NodeOptions
from pipeline.runtime import Selector, load_model
from pipeline.selection import SelectionSettings
from pipeline.sequence import SequenceReader

HELPERS = Path(__file__).resolve().parent / "helpers"
ADAPTUNE = str(Path(sys.executable).parent / "adaptune")
SETTINGS = SelectionSettings(period_s=0.2, hysteresis=0.0, subset_rows=256, refine_iters=2,
                             window=1)
PARAMS_YAML = ("select: {period_s: 0.2, hysteresis: 0.0, subset_rows: 256, refine_iters: 2, "
               "window: 1}\n")
SCANS, STRIDE = 10, 4


@pytest.fixture(scope="module")
def model_dir(tmp_path_factory: pytest.TempPathFactory, kitti_root: Path) -> Path:
    return build_model(tmp_path_factory.mktemp("node") / "model", kitti_root)


# ------------------------------------------------------------------ without ROS


def test_node_selects_what_the_offline_selector_selects(tmp_path: Path, kitti_root: Path,
                                                        model_dir: Path) -> None:
    seq = tmp_path / "s.mcap"
    write_tiny_sequence(seq, kitti_root, "04", n=6, step=4)
    model = load_model(model_dir)
    with SequenceReader(seq) as reader:
        scans = list(reader)
        schedule = Selector(model, SETTINGS).schedule(reader)
    logic = NodeSelection(Selector(model, SETTINGS))
    selections = [logic.on_scan(s.points_lidar, s.stamp_ns) for s in scans]
    picked = [i for i, sel in enumerate(selections) if sel is not None]
    assert picked == [0, 2, 4]  # every period_s (0.2 s) of the 0.1 s scans, from the first
    for i, sel in enumerate(selections):  # the parameters in force are the schedule's
        if sel is not None:
            assert sel.stamp_ns == scans[i].stamp_ns and sel.params == schedule.at(i)
            assert sel.state["adaptune.selected"] is True
    # sent to the odometry: the first selection, then every one that changed the parameters
    sent = [i for i in picked if selections[i].changed]  # type: ignore[union-attr]
    assert sent == [0] + [i for j, i in enumerate(picked[1:])
                          if schedule.at(i) != schedule.at(picked[j])]
    assert logic.summary() == {"scans": 6, "selections": 3, "sent": len(sent)}
    # a stamp before the last selection (a bag played again) starts the period over
    again = logic.on_scan(scans[1].points_lidar, scans[1].stamp_ns)
    assert again is not None and again.stamp_ns == scans[1].stamp_ns


def test_node_sends_the_odometry_its_names_and_types(model_dir: Path) -> None:
    model = load_model(model_dir)
    int_space = [{**s, "kind": "int", "low": 1.0, "high": 10.0, "default": 4.0}
                 if s["name"] == "resolution" else s for s in model.space]
    logic = NodeSelection(Selector(replace(model, space=int_space), SETTINGS),
                          {"resolution": "ndt_resolution"})
    sent = logic.for_target({"resolution": 3.0, "keyframe_interval": 2.5})
    assert sent == {"ndt_resolution": 3, "keyframe_interval": 2.5}
    assert isinstance(sent["ndt_resolution"], int)
    with pytest.raises(ConfigError, match="--rename size: the model has no parameter"):
        NodeSelection(Selector(model, SETTINGS), {"size": "x"})
    with pytest.raises(ConfigError, match="two parameters one name"):
        NodeSelection(Selector(model, SETTINGS), {"resolution": "keyframe_interval"})
    with pytest.raises(ConfigError, match="--target NODE is needed"):
        NodeOptions(via="dynamic_reconfigure")
    with pytest.raises(ConfigError, match="via must be one of"):
        NodeOptions(via="service", target="/odom")


# ------------------------------------------------------------------ with ROS


def test_venv_imports_debian_ros_and_keeps_its_own_modules() -> None:
    """What .ci/ros-python sets up: rospy & co. from Debian's dist-packages, after the venv's
    site-packages, so every module both have stays the venv's."""
    require_ros()
    code = """
import importlib.util, json, pathlib, sys, sysconfig
import rospy, rosgraph, sensor_msgs.msg, dynamic_reconfigure.client, dynamic_reconfigure.server
site = sysconfig.get_paths()["purelib"]
debian = next(p for p in sys.path if p.endswith("dist-packages"))
both = sorted({p.name.split(".")[0] for p in pathlib.Path(debian).iterdir()
               if (pathlib.Path(site) / p.name).exists() and p.name.split(".")[0].isidentifier()
               and not p.name.endswith("-info") and p.name != "__pycache__"})
origins = {n: importlib.util.find_spec(n).origin for n in both + ["numpy"]}
print(json.dumps({"site": site, "debian": debian, "rospy": rospy.__file__, "origins": origins,
                  "order": [sys.path.index(site), sys.path.index(debian)]}))
"""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    got = json.loads(done.stdout)
    assert got["rospy"].startswith(got["debian"])
    assert got["order"][0] < got["order"][1]  # the venv first
    assert "numpy" in got["origins"] and "yaml" in got["origins"]  # Debian has PyYAML too
    for name, origin in got["origins"].items():
        assert origin.startswith(got["site"]), (name, origin)


@pytest.mark.parametrize("via", ["dynamic_reconfigure", "topic"])
def test_node_sets_parameters_of_a_running_odometry(tmp_path: Path, kitti_root: Path,
                                                    model_dir: Path, via: str) -> None:
    require_ros()
    params = tmp_path / "params.yaml"
    params.write_text(PARAMS_YAML)
    kf = load_kitti(kitti_root, "04", SCANS)
    kf = replace(kf, points=[p[::STRIDE].copy() for p in kf.points])
    bag = write_bag(tmp_path / "scans.bag", kf, ros=1, gt=None, cloud_topic="/points")
    stamps = [int(t) for t in BAG_T0_NS + kf.stamps_ns]
    log = tmp_path / "odometry.jsonl"
    with RosGraph(tmp_path) as graph:
        odometry = graph.start("odometry", [sys.executable, str(HELPERS / "ros_odometry_node.py"),
                                            "--via", via, "--log", str(log)])
        graph.wait_until(lambda: "/odometry" in graph.subscribers("/points"),
                         "the odometry node subscribes")
        node = graph.start("adaptune", [ADAPTUNE, "-v", "node", "--params", str(params),
                                        str(model_dir), "--cloud", "/points", "--target",
                                        "/odometry", "--via", via, "--queue-size", "0"])
        topics = ["/adaptune/schedule"] + (["/adaptune/parameters"] if via == "topic" else [])
        graph.wait_until(lambda: graph.subscribers("/points") == {"/odometry", "/adaptune"}
                         and all(graph.connected("/odometry", t) for t in topics),
                         "both nodes listen and the node's topics reach the odometry node")
        play = graph.start("rosbag", ["rosbag", "play", "--quiet", "-d", "1", str(bag)])
        assert play.status() == 0, play.text()
        # the node selects from the first cloud it got, then every 0.2 s of the stamps
        graph.wait_until(lambda: events(log, "schedule"), "a selection")
        expected = offline_schedule(model_dir, kf.points, stamps,
                                    events(log, "schedule")[0]["stamp_ns"])
        n_sent = sum(changed for _, _, changed in expected)
        counts = (len(expected), n_sent + (via == "dynamic_reconfigure"), stamps[-1])
        graph.wait_until(lambda: progress(log) == counts, "every selection and every scan")
        if via == "topic":  # SIGTERM ends the node as it ends every command: exit code 130
            assert node.interrupt(signal.SIGTERM) == 130
        else:  # ROS shuts it down (`rosnode kill`): it ends by itself with its summary
            graph.shutdown("/adaptune")
            assert node.status() == 0
        assert odometry.guard.poll() is None  # still running until the graph ends
    text = node.text()
    assert f"'selections': {len(expected)}, 'sent': {n_sent}" in text, text
    if via == "topic":
        assert "adaptune: interrupted (SIGTERM)" in text
    else:
        assert f"ndt: {SCANS} clouds, {len(expected)} selections, {n_sent} parameter sets " \
            "sent" in text or f"{len(expected)} selections, {n_sent} parameter sets sent" in text
    # the schedule: every selection, stamped with its cloud, what the offline selector chose
    schedule = events(log, "schedule")
    assert [(e["stamp_ns"], e["params"]) for e in schedule] == \
        [(t, p) for t, p, _ in expected]
    # the odometry node was sent the first selection and every change, and applied them
    configs = [e for e in events(log, "config") if not e["initial"]]
    assert [c["params"] for c in configs] == [p for _, p, changed in expected if changed]
    applied = [{"resolution": 4.0, "keyframe_interval": 4.0}] + [c["params"] for c in configs]
    scans = events(log, "scan")
    assert [s["stamp_ns"] for s in scans] == stamps[-len(scans):]  # played in order
    assert all(s["params"] in applied for s in scans)
    assert all(np.isfinite(s["pose"]).all() for s in scans)


def test_node_refuses_an_odometry_it_cannot_set(tmp_path: Path, model_dir: Path) -> None:
    """One line and exit code 1: no dynamic_reconfigure server under the target's name, or a
    server without one of the model's parameters (as renamed)."""
    require_ros()
    log = tmp_path / "odometry.jsonl"
    with RosGraph(tmp_path) as graph:
        graph.start("odometry", [sys.executable, str(HELPERS / "ros_odometry_node.py"),
                                 "--via", "dynamic_reconfigure", "--log", str(log)])
        graph.wait_until(lambda: "/odometry/set_parameters" in graph.services(),
                         "the odometry node's server runs")
        absent = graph.start("absent", [ADAPTUNE, "node", str(model_dir), "--target", "/lio",
                                        "--wait", "1"])
        renamed = graph.start("renamed", [ADAPTUNE, "node", str(model_dir), "--target",
                                          "/odometry", "--rename", "resolution=ndt_resolution",
                                          "--name", "adaptune_renamed"])
        assert absent.status() == 1 and renamed.status() == 1
    assert "adaptune: error: /lio: no dynamic_reconfigure server answered within 1 s" in \
        absent.text()
    assert ("adaptune: error: /odometry: its dynamic_reconfigure server has no parameter "
            "ndt_resolution (its parameters: keyframe_interval, resolution)") in renamed.text()


def events(log: Path, kind: str) -> list[dict[str, Any]]:
    """The odometry node's events of one kind, in order (a line still being written is not
    read)."""
    if not log.exists():
        return []
    lines = log.read_text().split("\n")[:-1]  # whole lines only
    return [e for e in map(json.loads, lines) if e["event"] == kind]


def progress(log: Path) -> tuple[int, int, int | None]:
    """The odometry node's schedule entries and configurations so far, its last scan's stamp."""
    scans = events(log, "scan")
    return (len(events(log, "schedule")), len(events(log, "config")),
            scans[-1]["stamp_ns"] if scans else None)


def offline_schedule(model_dir: Path, points: list[np.ndarray], stamps: list[int],
                     first_ns: int) -> list[tuple[int, dict[str, float], bool]]:
    """(stamp, parameters, sent to the odometry?) of every selection the offline selector
    makes on the clouds from the one stamped ``first_ns`` on (the first the node received)."""
    selector = Selector(load_model(model_dir), SETTINGS)
    out: list[tuple[int, dict[str, float], bool]] = []
    last = None
    for pts, t in zip(points, stamps, strict=True):
        if t < first_ns or not selector.due(t):
            continue
        params = selector.select(pts, t)
        out.append((t, params, params != last))
        last = params
    return out

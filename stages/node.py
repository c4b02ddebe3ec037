"""`adaptune node MODEL --cloud TOPIC --target NODE`: the live ROS 1 node. It selects parameters
from a PointCloud2 topic every ``select.period_s`` and sets them on the odometry node, through
its dynamic_reconfigure server or a parameter topic, and publishes the schedule
(``pipeline.ros_node``; docs/usage.md, "A live ROS node", says how the interpreter gets rospy).
It runs until ROS shuts it down or Ctrl-C."""

from __future__ import annotations

from pathlib import Path

import click

from stages.common import algorithm_option, json_option, model_argument, params_option


def _rename(ctx: click.Context, param: click.Parameter, values: tuple[str, ...]
            ) -> dict[str, str]:
    """``--rename MODEL=NODE`` pairs as a mapping."""
    out = {}
    for value in values:
        ours, sep, theirs = value.partition("=")
        if not sep or not ours or not theirs:
            raise click.BadParameter(f"{value!r}: expected MODEL_NAME=NODE_NAME")
        out[ours] = theirs
    return out


@click.command()
@params_option
@model_argument
@algorithm_option("Refuse a model made for another algorithm.")
@click.option("--cloud", "cloud_topic", default="/velodyne_points", show_default=True,
              help="The sensor_msgs/PointCloud2 topic to select from.")
@click.option("--target", default=None,
              help="The odometry node (its dynamic_reconfigure namespace, e.g. /lio).")
@click.option("--via", type=click.Choice(["dynamic_reconfigure", "topic"]),
              default="dynamic_reconfigure", show_default=True,
              help="How the odometry node gets the parameters: its dynamic_reconfigure server "
              "(--target), or dynamic_reconfigure/Config messages on --param-topic.")
@click.option("--param-topic", default="/adaptune/parameters", show_default=True,
              help="With --via topic: the latched dynamic_reconfigure/Config topic.")
@click.option("--schedule-topic", default="/adaptune/schedule", show_default=True,
              help="Every selection as a sensor_msgs/JointState (stamp, names, values).")
@click.option("--rename", multiple=True, callback=_rename, metavar="MODEL=NODE",
              help="A model parameter's name on the odometry node (repeatable).")
@click.option("--name", default="adaptune", show_default=True, help="The ROS node's name.")
@click.option("--queue-size", type=click.IntRange(0), default=1, show_default=True,
              help="Clouds kept waiting while a selection runs (1: the newest only; 0: all).")
@click.option("--wait", "wait_s", type=click.FloatRange(0, min_open=True), default=30.0,
              show_default=True,
              help="How long to wait for the odometry node's dynamic_reconfigure server [s].")
@json_option
def node(params_path: Path | None, model_dir: Path, algorithm: str | None, cloud_topic: str,
         target: str | None, via: str, param_topic: str, schedule_topic: str,
         rename: dict[str, str], name: str, queue_size: int, wait_s: float,
         as_json: bool) -> None:
    """Run the live ROS 1 node: select parameters from a cloud topic and set them on the
    odometry node (the selector's settings: params ``select``)."""
    from pipeline.config import SelectSection, load_section
    from pipeline.ros_node import NodeOptions, run_node
    from pipeline.runtime import load_model
    from stages.common import report

    selection = load_section(params_path, "select", SelectSection).settings()
    options = NodeOptions(cloud_topic=cloud_topic, target=target, via=via,
                          param_topic=param_topic, schedule_topic=schedule_topic, name=name,
                          queue_size=queue_size, wait_s=wait_s)
    model = load_model(model_dir, expected_algorithm=algorithm)
    summary = run_node(model, selection, options, rename)
    report({"algorithm": model.algorithm, **summary},
           f"{model.algorithm}: {summary['scans']} clouds, {summary['selections']} selections, "
           f"{summary['sent']} parameter sets sent", as_json)

"""The ``adaptune`` command: a click group whose sub-commands load lazily (``stages.groups``:
the one place an AdaptuneError becomes one line on stderr and exit code 1, an interrupt one line
and exit code 130).

Sub-commands live in ``stages/<module>.py``: ``COMMANDS`` are what ``adaptune --help`` lists
(what a user of the method runs), ``STAGES`` the commands of the dvc stages, run but not
listed, and ``study`` the group of the project's studies (``stages.study``), whose commands
also run under their old top-level names. ``adaptune --help`` never imports numpy-heavy code.
"""

from __future__ import annotations

import logging
import sys

import click

from stages.groups import LazyGroup, Registry

COMMANDS: Registry = {
    # what a user of the method runs: the only commands ``adaptune --help`` lists (<= 15)
    "init": ("stages.init:init",
             "Start a project: params.yaml and dvc.yaml for a list of recordings."),
    "ingest": (
        "stages.ingest:ingest",
        "Convert KITTI, ROS bags, MCAP or scan folders into a sequence MCAP.",
    ),
    "simulate": ("stages.simulate:simulate", "Ray-cast a simulated world into a sequence MCAP."),
    "info": ("stages.info:info", "Summarise a sequence MCAP."),
    "params": ("stages.params:params", "The parameters an algorithm tunes: ranges, defaults."),
    "run": ("stages.run:run", "Run an odometry algorithm once (fixed params or a schedule)."),
    "trials": ("stages.trials:trials", "SMBO (hyperopt TPE) trials of an odometry algorithm."),
    "surrogate": (
        "stages.surrogate:surrogate",
        "Fit the kNN surrogate and write the model artifact.",
    ),
    "select": ("stages.select:select", "Parameter schedule of a recorded sequence from a model."),
    "live": (
        "stages.live:live",
        "Stream a sequence through odometry with online parameter selection.",
    ),
    "node": (
        "stages.node:node",
        "Live ROS 1 node: select from a PointCloud2 topic, set the odometry's parameters.",
    ),
    "metric": ("stages.metric:metric",
               "Trajectory error metrics (KITTI devkit; RTE, APE, RPE of any length)."),
    "query": ("stages.query:query", "Run SQL against the results database."),
    "export": ("stages.export:export",
               "Export a trajectory (KITTI, TUM) or trials (an Optuna storage)."),
    "study": ("stages.study:study", "The project's own studies of the method (make verdict, "
              "make kitti, make docs)."),
}
STAGES: Registry = {
    # the commands of the stages of dvc.yaml (and of `adaptune init`'s): run, not listed
    "ingest-set": (
        "stages.ingest:ingest_set",
        "Ingest the recordings of params.yaml's data section (dvc stage).",
    ),
    "simulate-set": (
        "stages.simulate:simulate_set",
        "Simulate the toy data set of params.yaml (dvc stage).",
    ),
    "simulate-kitti-set": (
        "stages.simulate:simulate_kitti_set",
        "Simulate KITTI along its ground-truth trajectories (dvc stage).",
    ),
    "descriptors": ("stages.descriptors:descriptors", "Environment descriptors of every frame."),
    "rte": ("stages.rte:rte", "Score trials into the DuckDB results database."),
    "portfolio": ("stages.portfolio:portfolio",
                  "Run a portfolio of parameter sets on every training sequence."),
    "adaptive": (
        "stages.adaptive:adaptive",
        "Adaptive runs on the evaluated sequences (dvc stage).",
    ),
    "evaluate": (
        "stages.evaluate:evaluate",
        "Baseline vs fixed vs adaptive: metrics, plots, report.",
    ),
    "plot-world": (
        "stages.simulate:plot_world",
        "Top-down PNG of a world, its trajectory and one scan.",
    ),
}
HIDDEN: Registry = {
    "exec": ("stages.exec_command:exec_command",
             "Run a command with adaptune's pinned CPU dispatch (make test, make bench)."),
}
"""Commands that run but are not listed by ``adaptune --help``."""


def _study_aliases() -> Registry:
    """The study commands under their old top-level names (``adaptune verdict`` is
    ``adaptune study verdict``): the dvc.yaml files keep their commands."""
    from stages.study import STUDY_COMMANDS

    return dict(STUDY_COMMANDS)


def every_command() -> Registry:
    """Every name ``adaptune NAME`` runs, listed or not."""
    return {**COMMANDS, **STAGES, **HIDDEN, **_study_aliases()}


@click.group(cls=LazyGroup, listed=COMMANDS,
             unlisted=lambda: {**STAGES, **HIDDEN, **_study_aliases()},
             epilog="The stages of dvc.yaml run commands of their own: "
             + ", ".join(STAGES) + " (adaptune NAME --help).")
@click.option("-v", "--verbose", count=True, help="More log output (-v info, -vv debug).")
@click.version_option(package_name="adaptune")
def main(verbose: int) -> None:
    """adaptune: adaptive hyperparameter tuning for black-box LiDAR odometry."""
    from pipeline.lifetime import exit_on_termination

    exit_on_termination()  # SIGTERM ends children and temporary files, as Ctrl-C does
    level = logging.WARNING - 10 * min(verbose, 2)  # warnings only, unless -v / -vv
    logging.basicConfig(
        level=level, format="%(levelname)s %(name)s: %(message)s", stream=sys.stderr
    )
    # progress lines of long stages (when stderr is no terminal) show at any verbosity
    logging.getLogger("pipeline.progress").setLevel(logging.INFO)


def entry() -> None:
    """The ``adaptune`` executable: re-executes itself once in the pinned CPU dispatch
    environment (``pipeline.dispatch``: the same numbers on every machine), then runs ``main``.
    Tests that invoke ``main`` in-process (click's runner) do not re-execute."""
    import os

    from pipeline.dispatch import pinned_environment

    try:
        env = pinned_environment(os.environ)
    except Exception as exc:  # an AdaptuneError: the one line, as main would print it
        click.echo(f"adaptune: error: {exc}", err=True)
        sys.exit(1)
    if env is not None:
        os.execve(sys.executable, [sys.executable, *sys.orig_argv[1:]], env)
    main()


if __name__ == "__main__":
    entry()

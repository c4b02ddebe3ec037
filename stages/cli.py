"""The ``adaptune`` command: a click group whose sub-commands load lazily.

Only this module turns an AdaptuneError into one line on stderr and exit code 1, and an
interrupt (Ctrl-C, SIGTERM, SIGHUP) into one line and exit code 130.
Sub-commands live in ``stages/<module>.py``; ``COMMANDS`` maps names to them so that
``adaptune --help`` never imports numpy-heavy code.
"""

from __future__ import annotations

import importlib
import logging
import sys
from typing import Any

import click

INTERRUPTED = 130
"""The exit code of a command ended by Ctrl-C, SIGTERM or SIGHUP (128 + SIGINT, as a shell
reports Ctrl-C); every error is exit code 1."""

Registry = dict[str, tuple[str, str]]
"""Command name -> (``module:attribute`` of its click command, short help)."""

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


class LazyGroup(click.Group):
    """A group that imports a sub-command only when it is run or asked for help:
    ``listed`` commands show in ``--help``, ``unlisted`` ones (a callable giving a registry)
    run too."""

    def __init__(self, *args: Any, listed: Registry | None = None,
                 unlisted: Any = None, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.listed = listed if listed is not None else COMMANDS
        self.unlisted = unlisted or (lambda: {**STAGES, **HIDDEN, **_study_aliases()})

    def list_commands(self, ctx: click.Context) -> list[str]:
        return [n for n, (target, _) in self.listed.items() if _module_exists(target)]

    def get_command(self, ctx: click.Context, name: str) -> click.Command | None:
        known = self.listed if name in self.listed else self.unlisted()
        if name not in known or not _module_exists(known[name][0]):
            return None
        target, short = known[name]
        module, attr = target.split(":")
        cmd = getattr(importlib.import_module(module), attr)
        cmd.short_help = cmd.short_help or short
        return cmd

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        rows = [(n, self.listed[n][1]) for n in self.list_commands(ctx)]
        if rows:
            with formatter.section("Commands"):
                formatter.write_dl(rows)

    def invoke(self, ctx: click.Context) -> Any:
        from pipeline.errors import AdaptuneError

        try:
            return super().invoke(ctx)
        except AdaptuneError as exc:
            click.echo(f"adaptune: error: {exc}", err=True)
            ctx.exit(1)
        except KeyboardInterrupt as exc:  # Ctrl-C, or SIGTERM / SIGHUP (lifetime.Terminated)
            import signal

            name = signal.Signals(getattr(exc, "signum", signal.SIGINT)).name
            click.echo(f"adaptune: interrupted ({name})", err=True)
            ctx.exit(INTERRUPTED)


def _module_exists(target: str) -> bool:
    import importlib.util

    return importlib.util.find_spec(target.split(":")[0]) is not None


@click.group(cls=LazyGroup, epilog="The stages of dvc.yaml run commands of their own: "
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

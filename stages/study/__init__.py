"""``adaptune study ...``: the project's own studies of the method, apart from the product.

Each runs a study of the ``studies`` package (docs/design.md, "Layout"): the toy's
generalization suite, the coverage model's verdict, the paper's KITTI protocol, the sim-to-real
comparison, the docs pages that quote the committed metrics. The old top-level names
(``adaptune verdict``, ``adaptune generalize``, ...) run the same commands, unlisted, so that no
dvc.yaml's command changes.
"""

from __future__ import annotations

import click

from stages.groups import LazyGroup

STUDY_COMMANDS: dict[str, tuple[str, str]] = {
    "generalize": (
        "stages.study.generalize:generalize",
        "Baseline vs fixed vs adaptive on unseen worlds (the toy's dvc stage).",
    ),
    "verdict": (
        "stages.study.verdict:verdict",
        "The coverage model on a suite of unseen worlds (verdict/dvc.yaml stage).",
    ),
    "oracles": (
        "stages.study.verdict:oracles",
        "Run the oracles on the in-distribution suite's worlds (verdict/dvc.yaml stage).",
    ),
    "headroom": (
        "stages.study.verdict:headroom",
        "Oracles against SBS and the closed gap of the in-distribution suite (verdict/dvc.yaml "
        "stage).",
    ),
    "tuning-suite": (
        "stages.study.verdict:tuning_suite",
        "Simulate the coverage model's tuning suite, indexed per sensor (verdict/dvc.yaml "
        "stage).",
    ),
    "kitti-preset": (
        "stages.study.kitti:kitti_preset",
        "The `dvc exp run` arguments of the paper's KITTI protocol.",
    ),
    "kitti-table": (
        "stages.study.kitti:kitti_table",
        "The paper's Table II from the evaluate metrics of each algorithm.",
    ),
    "realism": (
        "stages.study.realism:realism",
        "Real KITTI slices against simulated KITTI: scan statistics, odometry errors.",
    ),
    "real-units": (
        "stages.study.real.units:real_units",
        "Cut the real runs into their halves by distance (real/dvc.yaml stage).",
    ),
    "real-studies": (
        "stages.study.real.studies:real_studies",
        "Every real unit's own study of an algorithm (real/dvc.yaml stage).",
    ),
    "real-folds": (
        "stages.study.real.folds:real_folds",
        "Every fold of the real-data study for an algorithm (real/dvc.yaml stage).",
    ),
    "real-models": (
        "stages.study.real.models:real_models",
        "The real-data deploy models, one per sensor (real/dvc.yaml stage).",
    ),
    "real-report": (
        "stages.study.real.report:real_report",
        "The real-data study's figures and the reference's floor (real/dvc.yaml stage).",
    ),
    "docs": ("stages.study.docs:docs", "Render the docs pages that quote the committed metrics."),
}


@click.group(cls=LazyGroup, listed=STUDY_COMMANDS)
def study() -> None:
    """The project's own studies of the method (docs/results/)."""

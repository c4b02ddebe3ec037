"""``adaptune study real-*``: the real-data study's stages (real/dvc.yaml; docs/results/real.md),
a module each, so that each stage's dvc.yaml deps are the code it runs.

``real-units`` cuts the ingested runs into their halves; ``real-studies`` runs every unit's own
study of one algorithm; ``real-folds`` every fold of it (the joint study, the model, the
in-sample best, the suite); ``real-models`` the deploy models, one per sensor; ``real-report``
the figures of every algorithm and fold (``studies.real`` documents each).
"""

from __future__ import annotations

import click

algorithm_option = click.option("--algorithm", required=True,
                                 help="The odometry algorithm (one of real.algorithms).")

"""``adaptune trials``: SMBO (hyperopt TPE) trials of an odometry algorithm (dvc stages
``trials`` and, with ``--joint``, ``fixed``).

Sequences are given as MCAP paths, or (DVC form) as ``--sequences DIR`` with the split of
``DIR/index.json`` (``--split``, default params ``trials.split``). Options override the params
section ``trials`` (with ``--joint``, the section ``fixed`` overrides it first); the seed
defaults to ``base.seed``.
"""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import click

from stages.common import (
    FILE,
    algorithm_option,
    dir_option,
    echo_output,
    file_option,
    json_option,
    params_option,
)


@click.command()
@click.argument("sequence_paths", nargs=-1, type=FILE)
@dir_option("--out", "out_dir",
            help="Output folder (results/trials, or results/fixed with --joint).")
@dir_option("--sequences", "sequence_dir", required=False,
            help="Sequence folder with index.json (instead of SEQ.mcap paths).")
@click.option("--split", default=None, help="Split of index.json to use [trials.split].")
@algorithm_option("Adapter name [trials.algorithm].")
@click.option("--iterations", type=int, default=None, help="Trials per study [trials.iterations].")
@click.option("--seed", type=int, default=None, help="Base seed [base.seed].")
@click.option("--workers", type=int, default=None, help="Trials in flight [trials.workers].")
@click.option("--dask", "dask", default=None, help="'local' or a scheduler address [trials.dask].")
@click.option("--length-m", type=float, default=None, help="RTE segment length [base.length_m].")
@click.option(
    "--time-limit-s", type=float, default=None, help="Per sequence run [trials.time_limit_s]."
)
@click.option(
    "--joint", is_flag=True, help="One study over all sequences (the 'fixed' parameters)."
)
@dir_option("--warm-start", "warm_start_dir", required=False,
            help="With --joint and fixed.warm_start: the per-sequence trials output to start "
                 "from (the parameters it predicts best for all sequences first).")
@file_option("--record", "record_path", required=False,
             help="Write the studies' counts and wall times here (records/<stage>.json: the "
                  "trials tables keep no time).")
@params_option
@json_option
def trials(
    sequence_paths: tuple[Path, ...],
    out_dir: Path,
    sequence_dir: Path | None,
    split: str | None,
    algorithm: str | None,
    iterations: int | None,
    seed: int | None,
    workers: int | None,
    dask: str | None,
    length_m: float | None,
    time_limit_s: float | None,
    joint: bool,
    warm_start_dir: Path | None,
    record_path: Path | None,
    params_path: Path | None,
    as_json: bool,
) -> None:
    """SMBO trials: per sequence, or one joint study (--joint) into OUT."""
    from pipeline.config import BaseSection, load_section, validate_section
    from pipeline.errors import ConfigError
    from pipeline.sequence_index import read_index
    from pipeline.tuning.smbo import FixedSection, TrialsSection, run_trials, study_adapter
    from pipeline.tuning.warm_start import warm_start_params

    section = load_section(params_path, "trials", TrialsSection)
    warm = 0
    if joint:  # the `fixed` section overrides `trials` for the joint study
        fixed = load_section(params_path, "fixed", FixedSection)
        warm = fixed.warm_start
        section = validate_section(TrialsSection, "trials", {
            **section.model_dump(), **fixed.model_dump(exclude_none=True,
                                                       exclude={"warm_start"})})
    elif warm_start_dir is not None:
        raise ConfigError("--warm-start goes with --joint (a joint study starts from the "
                          "per-sequence ones)")
    overrides = dict(
        algorithm=algorithm,
        iterations=iterations,
        workers=workers,
        dask=dask,
        length_m=length_m,
        time_limit_s=time_limit_s,
        split=split,
    )
    settings = validate_section(
        TrialsSection,
        "trials",
        {**section.model_dump(), **{k: v for k, v in overrides.items() if v is not None}},
    )
    base = load_section(params_path, "base", BaseSection)
    if seed is not None:  # --seed follows base.seed's rule
        base = validate_section(BaseSection, "base", {**base.model_dump(), "seed": seed})
    seed = base.seed
    if bool(sequence_paths) == (sequence_dir is not None):
        raise ConfigError("give either SEQ.mcap paths or --sequences DIR, not both or neither")
    paths = (
        read_index(sequence_dir).paths(settings.split)
        if sequence_dir is not None
        else list(sequence_paths)
    )
    first: list[dict[str, float]] = []
    if warm:
        if warm_start_dir is None:
            raise ConfigError("fixed.warm_start needs --warm-start DIR (the trials output)")
        adapter = study_adapter(settings)
        first = warm_start_params(warm_start_dir, adapter.name, adapter.space, warm)
    studies = []
    for s in run_trials(paths, out_dir, settings, seed, joint=joint, warm_start=first):
        studies.append(s)
        if not as_json:
            click.echo(f"{s.algorithm} {s.sequence}: {s.trials} trials ({s.ran} run now), "
                       f"{s.failed} failed, {s.pruned} pruned, "
                       f"best objective {s.best_objective:.4g} % (trial {s.best_trial})",
                       err=True)
    if record_path is not None:
        from pipeline.report.outputs import write_json

        write_json(record_path, {"studies": [s.record() for s in studies]})
    if as_json:
        echo_output(json.dumps([asdict(s) for s in studies], indent=1, default=str))

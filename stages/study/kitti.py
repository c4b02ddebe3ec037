"""``adaptune kitti-preset`` and ``kitti-table``: the paper's KITTI protocol (Table II).

``kitti-preset`` prints, one a line, the ``--set-param`` arguments of ``dvc exp run`` that turn
params.yaml into the protocol (``studies.kitti.preset``); ``make kitti`` runs them. ``kitti-table``
lays the ``evaluate`` metrics of one or more algorithms out as the paper's Table II.
"""

from __future__ import annotations

from pathlib import Path

import click

from stages.common import DIR, FILE, algorithm_option, dir_option, echo_output, params_option


def _names(text: str | None) -> list[str] | None:
    return None if text is None else [s.strip() for s in text.split(",") if s.strip()]


def _window(text: str) -> tuple[str, tuple[int, int]]:
    """``NN=START:END`` -> (NN, (START, END)); ConfigError otherwise."""
    from pipeline.errors import ConfigError

    name, _, frames = text.partition("=")
    start, _, end = frames.partition(":")
    if not (name and start.isdigit() and end.isdigit()):
        raise ConfigError(f"--window must be NN=START:END, got {text!r}")
    return name, (int(start), int(end))


@click.command("kitti-preset")
@click.option("--root", type=DIR, default=None,
              help="KITTI odometry root (ROOT/sequences/NN/velodyne, ROOT/poses/NN.txt).")
@click.option("--simulated", type=DIR, default=None,
              help="Simulated KITTI instead: folder of the ground-truth files NN.txt.")
@click.option("--train", default=None, help="Training sequences, comma-separated [00-05].")
@click.option("--test", default=None, help="Test sequences, comma-separated [06-10].")
@click.option("--stride", type=int, default=1, show_default=True,
              help="Every stride-th sequence of the training and of the test list.")
@click.option("--start", type=int, default=None, help="First frame of every sequence [0].")
@click.option("--end", type=int, default=None,
              help="Last frame of every sequence, INCLUSIVE [the last].")
@click.option("--window", "windows", multiple=True,
              help="NN=START:END, the frames of one sequence (simulated KITTI), repeatable.")
@click.option("--change-windows", type=int, default=None,
              help="Windows of N frames around each sequence's first change of environment "
              "(simulated KITTI).")
@algorithm_option("Odometry to tune [params.yaml's trials.algorithm].")
@click.option("--iterations", type=int, default=None,
              help="SMBO iterations per training sequence [params.yaml's].")
@click.option("--joint-iterations", type=int, default=None,
              help="SMBO iterations of the joint study [as --iterations].")
@click.option("--time-limit-s", type=float, default=None,
              help="A trial's time limit per sequence run [s]: a slower parameter set fails "
              "with the penalty [params.yaml's trials.time_limit_s].")
@click.option("--length-m", type=float, default=100.0, show_default=True,
              help="L, the RTE length of the SMBO objective [m].")
@click.option("--kitti-lengths-m", default=None,
              help="Devkit segment lengths [m], comma-separated [100,...,800].")
@click.option("--replicas", type=int, default=None,
              help="Extra runs of every setting with its parameters moved by at most 0.5 % "
              "(the table gives their spread) [params.yaml's evaluate.replicas].")
@click.option("--fidelity", type=click.Choice(["whole", "halving"]), default=None,
              help="whole: every trial runs every frame (the paper); halving: successive "
              "halving over rungs, per-sequence and joint studies [params.yaml's].")
@params_option
def kitti_preset(root: Path | None, simulated: Path | None, train: str | None,
                 test: str | None, stride: int, start: int | None, end: int | None,
                 windows: tuple[str, ...], change_windows: int | None, algorithm: str | None,
                 iterations: int | None, joint_iterations: int | None,
                 time_limit_s: float | None, length_m: float, kitti_lengths_m: str | None,
                 replicas: int | None, fidelity: str | None, params_path: Path) -> None:
    """Print the `dvc exp run` arguments of the KITTI protocol, one a line.

    \b
    make kitti KITTI_ROOT=... (or KITTI_SIMULATED=...) runs them; by hand:
      adaptune kitti-preset --root /data/kitti/dataset > kitti.args
      xargs -a kitti.args -d '\\n' dvc exp run evaluate generalize
    """
    from pipeline.config import read_params, validate_section
    from pipeline.errors import ConfigError
    from studies.kitti.preset import KittiProtocol, kitti_protocol, set_params

    if (root is None) == (simulated is None):
        raise ConfigError("give either --root (real KITTI) or --simulated (simulated KITTI)")
    raw = {"source": "real" if root else "simulated", "root": str(root or simulated),
           "train": _names(train), "test": _names(test), "stride": stride, "start": start,
           "end": end, "windows": dict(_window(w) for w in windows),
           "change_windows": change_windows, "algorithm": algorithm,
           "iterations": iterations,
           "joint_iterations": joint_iterations, "time_limit_s": time_limit_s,
           "length_m": length_m,
           "kitti_lengths_m": _names(kitti_lengths_m), "replicas": replicas,
           "fidelity": fidelity}
    protocol = validate_section(KittiProtocol, "kitti-preset",
                                {k: v for k, v in raw.items() if v is not None})
    for arg in set_params(kitti_protocol(protocol, read_params(params_path))):
        echo_output(arg)


@click.command("kitti-table")
@click.argument("metrics", nargs=-1, required=True, type=FILE)
@dir_option("--out", help="Folder for table.md and table.json.")
def kitti_table(metrics: tuple[Path, ...], out: Path) -> None:
    """Lay the evaluate metrics of every algorithm out as the paper's Table II.

    Each METRICS file DIR/metrics/NAME.json goes with its record DIR/records/NAME.json (as the
    evaluate stage writes them: metrics/evaluation.json, records/evaluation.json).
    """
    from pipeline.report.table2 import KITTI_SPLIT_TITLES, write_table2

    table = write_table2(list(metrics), out, KITTI_SPLIT_TITLES)
    click.echo(f"{out / 'table.md'}: {', '.join(table['algorithms'])}", err=True)

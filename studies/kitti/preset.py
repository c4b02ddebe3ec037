"""Presets: the params.yaml values of a named protocol, as ``dvc exp run --set-param``s.

``kitti_protocol`` is the paper's KITTI experiment (Koide et al. 2021, Table II): per-sequence
SMBO on the training sequences 00-05, the joint SMBO over them, the surrogate from them, and
baseline / fixed / adaptive scored with the KITTI devkit metric on the training AND the test
sequences 06-10 (``evaluate.splits = [validation, train]``: the test set is the index's
``validation`` split and the headline), L = 100 m. Its data are the real KITTI odometry scans
of a KITTI root (the ``ingest`` stage) or simulated KITTI: HDL-64E scans along the ground-truth
trajectories (the ``simulate_kitti`` stage, pipeline/sim/kitti_world.py). Real KITTI is two
``kitti`` sources of the ``data`` section (train, and test as the ``validation`` split), its
root stored absolute. Options size the run
to a machine: a frame window of every sequence (or of single sequences, simulated KITTI), a
stride over the sequences, the SMBO budget. The protocol has no generalization suite
(``generalize.worlds = 0``: that stage writes outputs that say so), so its experiment carries
no figure of the toy's suite.

A preset never edits params.yaml itself: ``set_params`` lists ``section.key=value`` pairs
for ``dvc exp run --set-param`` (values in its override grammar, Hydra's), which keeps
params.yaml's comments and records the run as a DVC experiment.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Literal

from pydantic import Field, model_validator

from pipeline.config import SEQUENCE_FOLDERS, IterationCount, Section, check_params
from pipeline.errors import ConfigError

KITTI_TRAIN = ("00", "01", "02", "03", "04", "05")
KITTI_TEST = ("06", "07", "08", "09", "10")
KITTI_LENGTH_M = 100.0


class KittiProtocol(Section):
    """The options of the KITTI protocol preset (module docstring).

    source: ``real`` (``root`` = a KITTI odometry root, ROOT/sequences/NN/velodyne and
    ROOT/poses/NN.txt) or ``simulated`` (``root`` = a folder of ground-truth files NN.txt);
    train / test: sequence names; stride: every stride-th sequence of each list;
    start / end: frame window of every sequence (KITTI frame numbers, end inclusive);
    windows: {NN: (start, end)} of single sequences (simulated KITTI only);
    change_windows: a window of this many frames around the first change of environment of
    every sequence (simulated KITTI only; ``pipeline.sim.kitti_world.change_window``);
    iterations / joint_iterations: SMBO budget per training sequence / of the joint study
    (null keeps params.yaml's); time_limit_s: a trial's time limit per sequence run [s] (a
    slower parameter set fails with the penalty; null keeps params.yaml's); length_m: L [m];
    kitti_lengths_m: devkit lengths (null keeps params.yaml's, 100..800 m); replicas: extra
    runs of every setting with its parameters moved by at most 0.5 % (``evaluate.replicas``:
    how far one run is from the next; null keeps params.yaml's); fidelity: ``whole`` (the
    paper's whole trials) or ``halving`` (successive halving) for the per-sequence and the joint
    studies (``trials.fidelity``, ``fixed.fidelity``; null keeps params.yaml's).
    """

    source: Literal["real", "simulated"] = "real"
    root: str
    train: list[str] = Field(default_factory=lambda: list(KITTI_TRAIN), min_length=1)
    test: list[str] = Field(default_factory=lambda: list(KITTI_TEST), min_length=1)
    stride: int = Field(1, ge=1)
    start: int | None = Field(None, ge=0)
    end: int | None = Field(None, ge=0)
    windows: dict[str, tuple[int, int]] = Field(default_factory=dict)
    change_windows: int | None = Field(None, ge=2)
    algorithm: str | None = None
    iterations: IterationCount | None = None
    joint_iterations: IterationCount | None = None
    time_limit_s: float | None = Field(None, gt=0)
    length_m: float = Field(KITTI_LENGTH_M, gt=0)
    kitti_lengths_m: list[float] | None = Field(None, min_length=1)
    replicas: int | None = Field(None, ge=0)
    fidelity: Literal["whole", "halving"] | None = None

    @model_validator(mode="after")
    def _consistent(self) -> KittiProtocol:
        both = sorted(set(self.train) & set(self.test))
        if both:
            raise ValueError(f"sequence {both[0]!r} is in both train and test, got "
                             f"(train={self.train}, test={self.test})")
        if self.start is not None and self.end is not None and self.end < self.start:
            raise ValueError(f"end must be >= start, got (start={self.start}, end={self.end})")
        if (self.windows or self.change_windows) and self.source == "real":
            raise ValueError(f"windows of single sequences need the simulated source, got "
                             f"(source={self.source!r}, windows={self.windows}, "
                             f"change_windows={self.change_windows})")
        return self


def kitti_protocol(protocol: KittiProtocol, params: Mapping[str, Any]) -> dict[str, Any]:
    """The values ("section.key" -> value) that turn ``params`` (a params.yaml) into the KITTI
    protocol. ConfigError when the result breaks a section's rules."""
    train, test = protocol.train[:: protocol.stride], protocol.test[:: protocol.stride]
    _check_root(protocol, [*train, *test])
    if protocol.source == "real":
        window = {k: v for k, v in (("start", protocol.start), ("end", protocol.end))
                  if v is not None}
        data: dict[str, Any] = {
            "base.sequences": SEQUENCE_FOLDERS["ingest"], "data.sources": [
                {"kind": "kitti", "path": str(Path(protocol.root).resolve()),
                 "sequences": names, "split": split, **window}
                for names, split in ((train, "train"), (test, "validation"))]}
    else:
        data = {"base.sequences": SEQUENCE_FOLDERS["simulate_kitti"],
                "simulate_kitti.trajectories": protocol.root,
                "simulate_kitti.train": train, "simulate_kitti.validation": test,
                "simulate_kitti.start": protocol.start, "simulate_kitti.end": protocol.end,
                "simulate_kitti.windows": _windows(protocol, [*train, *test])}
    data |= {"base.length_m": protocol.length_m, "evaluate.splits": ["validation", "train"],
             "generalize.worlds": 0}
    if protocol.algorithm is not None:
        data["trials.algorithm"] = protocol.algorithm
    if protocol.iterations is not None:
        data["trials.iterations"] = protocol.iterations
        # hyperopt's 20 random start-up trials would be the whole of a small budget
        startup = int(params.get("trials", {}).get("startup_trials", 20))
        data["trials.startup_trials"] = min(startup, max(2, protocol.iterations // 4))
    if protocol.joint_iterations is not None:
        data["fixed.iterations"] = protocol.joint_iterations
    if protocol.time_limit_s is not None:
        data["trials.time_limit_s"] = protocol.time_limit_s
    if protocol.kitti_lengths_m is not None:
        data["devkit.lengths_m"] = protocol.kitti_lengths_m
    if protocol.replicas is not None:
        data["evaluate.replicas"] = protocol.replicas
    if protocol.fidelity is not None:
        data["trials.fidelity"] = protocol.fidelity
        data["fixed.fidelity"] = protocol.fidelity
    check_params(apply(params, data), "the preset's params")
    return data


def _windows(protocol: KittiProtocol, names: list[str]) -> list[list[Any]]:
    """The per-sequence windows of simulated KITTI: ``change_windows`` for every sequence
    (from its ground-truth file's length), then the explicit ``windows``."""
    from pipeline.sim.kitti_world import change_window

    out: dict[str, list[int]] = {}
    if protocol.change_windows is not None:
        for name in names:
            frames = _line_count(Path(protocol.root) / f"{name}.txt")
            out[name] = list(change_window(name, frames, protocol.change_windows))
    out |= {n: list(w) for n, w in protocol.windows.items() if n in names}
    return [[name, *window] for name, window in out.items()]


def _line_count(path: Path) -> int:
    from pipeline.io_utils import read_input

    return sum(1 for line in read_input(path, "KITTI pose file", error=ConfigError).splitlines()
               if line.strip())


def _check_root(protocol: KittiProtocol, names: list[str]) -> None:
    """ConfigError unless ``protocol.root`` holds every sequence of ``names``."""
    root = Path(protocol.root)
    where = {n: root / "sequences" / n if protocol.source == "real" else root / f"{n}.txt"
             for n in names}
    missing = [n for n, path in where.items() if not path.exists()]
    if missing:
        raise ConfigError(f"root: {where[missing[0]]} does not exist (sequences "
                          f"{', '.join(missing)} missing)")


def apply(params: Mapping[str, Any], values: Mapping[str, Any]) -> dict[str, Any]:
    """A copy of ``params`` with ``values`` ("section.key" -> value) set."""
    out = json.loads(json.dumps(dict(params)))
    for dotted, value in values.items():
        section, key = dotted.split(".", 1)
        out.setdefault(section, {})[key] = value
    return out


def set_params(values: Mapping[str, Any]) -> list[str]:
    """``--set-param=section.key=<value>`` arguments of ``dvc exp run`` for ``values``, in the
    override grammar DVC parses them with (Hydra's: JSON, but dictionary keys unquoted)."""
    return [f"--set-param={k}={override_value(v)}" for k, v in values.items()]


def override_value(value: Any) -> str:
    """``value`` (JSON data) in Hydra's override grammar: ``{00:[368,447]}``, ``["00"]``, "x",
    null. ConfigError for a dictionary key that grammar cannot write unquoted."""
    if isinstance(value, Mapping):
        bad = [k for k in value if not (isinstance(k, str) and k.replace("_", "a").isalnum())]
        if bad:
            raise ConfigError(f"dictionary key {bad[0]!r} cannot be a --set-param key (letters, "
                              "digits and _ only)")
        return "{" + ",".join(f"{k}:{override_value(v)}" for k, v in value.items()) + "}"
    if isinstance(value, list | tuple):
        return "[" + ",".join(override_value(v) for v in value) + "]"
    return json.dumps(value)


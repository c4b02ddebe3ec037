"""The simulate stage's data set: the same files whatever the number of worker processes."""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from pydantic import ValidationError

from pipeline.errors import InputError
from pipeline.sim.dataset import SimulateSection, simulate_all, simulate_set
from pipeline.sim.simulate import SimSpec, SimSummary, simulate_sequence


def test_workers_write_the_same_bytes_as_one_process(tmp_path: Path) -> None:
    settings = dict(sensor="vlp16", train={"cave": 1, "street": 1}, train_frames=10,
                    validation_frames=30)
    runs = {}
    for workers in (1, 2):
        out = tmp_path / f"w{workers}"
        done = simulate_set(SimulateSection(workers=workers, **settings), 5, out)
        assert [s.name for s in done] == ["cave_0", "street_0", "composite_0"]
        runs[workers] = {p.name: p.read_bytes() for p in sorted(out.iterdir())}
    assert sorted(runs[1]) == ["cave_0.mcap", "composite_0.mcap", "index.json",
                               "street_0.mcap"]
    assert runs[2] == runs[1]  # index.json, then every MCAP byte for byte
    assert len(set(runs[1].values())) == 4  # three different sequences


def test_workers_must_be_at_least_one() -> None:
    with pytest.raises(ValidationError, match="workers"):
        SimulateSection(workers=0)


def _simulate_or_fail(spec: SimSpec, out: Path, wait_for: Path | None) -> SimSummary:
    """In a worker: simulate, or (``wait_for``) fail once the other worker is writing
    ``wait_for`` (its temporary exists)."""
    if wait_for is None:
        return simulate_sequence(spec, out)
    for _ in range(600):
        if list(wait_for.parent.glob(f".{wait_for.name}.*.tmp")):
            break
        time.sleep(0.05)
    raise InputError("this job fails")


def test_a_failing_job_leaves_no_temporary_of_the_others(tmp_path: Path) -> None:
    long, bad = tmp_path / "long.mcap", tmp_path / "bad.mcap"
    jobs = [(SimSpec("cave", 1, 500, "vlp16"), long, None), (SimSpec("cave", 2, 10), bad, long)]
    with pytest.raises(InputError, match="this job fails"):
        simulate_all(_simulate_or_fail, jobs, [long, bad], 2, log_lines=False)
    assert list(tmp_path.iterdir()) == []  # the long job was killed mid-write, cleaned up


def test_train_sensors_cycle_over_each_worlds_training_sequences(tmp_path: Path) -> None:
    """``train_sensors``: cave_i and street_i use train_sensors[i % n], recorded in their
    MCAP; the validation sequence keeps ``sensor``."""
    from pipeline.sequence import SequenceReader
    from pipeline.sim.dataset import dataset_specs
    from pipeline.sim.sensors import SENSOR_TITLES

    section = SimulateSection(sensor="hdl32", train={"cave": 3, "street": 1}, train_frames=10,
                              validation_frames=30, train_sensors=["vlp16", "hdl64"], workers=1)
    specs = {name: spec.sensor for name, (_, spec) in dataset_specs(section, 5).items()}
    assert specs == {"cave_0": "vlp16", "cave_1": "hdl64", "cave_2": "vlp16",
                     "street_0": "vlp16", "composite_0": "hdl32"}
    simulate_set(section.model_copy(update={"train": {"cave": 2}}), 5, tmp_path)
    for name, sensor in (("cave_0", "vlp16"), ("cave_1", "hdl64"), ("composite_0", "hdl32")):
        with SequenceReader(tmp_path / f"{name}.mcap") as reader:
            assert reader.info.sensor == SENSOR_TITLES[sensor]
    with pytest.raises(ValidationError, match="train_sensors"):
        SimulateSection(train_sensors=["hdl128"])


def test_the_typed_sensor_names_are_the_simulated_sensors() -> None:
    """``SensorName`` (the params sections' type) names exactly the sensors of SENSORS."""
    from typing import get_args

    from pipeline.sim.sensors import SENSORS, SensorName

    assert sorted(get_args(SensorName)) == sorted(SENSORS)


def test_worlds_start_costliest_first() -> None:
    """By rays (frames x beams x azimuths: HDL-32E 32 x 1800, HDL-64E 64 x 2170, VLP-16
    16 x 1800), ties in list order: the HDL-64E's 500 frames (69.4 M rays) before the
    HDL-32E's 1000 (57.6 M) and the VLP-16's 2000 (57.6 M); by frames it would start last
    but one."""
    from pipeline.executor import costliest_first

    specs = [SimSpec("street", 1, 1000, sensor="hdl32"), SimSpec("street", 1, 500, sensor="hdl64"),
             SimSpec("street", 1, 2000, sensor="vlp16"), SimSpec("street", 1, 400, sensor="hdl32")]
    assert [s.rays() for s in specs] == [57_600_000, 69_440_000, 57_600_000, 23_040_000]
    assert costliest_first([s.rays() for s in specs]) == [1, 0, 2, 3]

"""The simulate stage's data set: the same files whatever the number of worker processes."""

from __future__ import annotations

from pathlib import Path

import pytest
from pydantic import ValidationError

from pipeline.sim.dataset import SimulateSection, simulate_set


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

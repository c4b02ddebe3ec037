"""experiments/headroom_controls.py on a hand-made oracles output: four worlds written as the
oracles stage writes them (studies.suites.runner.write_runs and candidates.json), three
candidates, two labels and two sensors whose per-label best candidates are swapped, so that
every control's ratio to SBS is known by hand."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from helpers.scripts import load_script
from helpers.verdict_data import world

from studies.suites.runner import write_runs

SCRIPT = Path(__file__).resolve().parents[2] / "experiments" / "headroom_controls.py"
CANDIDATES = [{"resolution": 2.0, "keyframe_interval": 4.0},  # the fixed set: SBS
              {"resolution": 1.0, "keyframe_interval": 4.0},
              {"resolution": 3.0, "keyframe_interval": 4.0}]


def _headroom(folder: Path) -> None:
    """hdl32 worlds: candidate 1 is best in caves, 2 on streets (RTE 1 against 2 for SBS and
    3 for the other); hdl64 worlds the other way round; 10 scored frames of each label."""
    labels = ["cave"] * 10 + ["street"] * 10
    for name, sensor in (("a0", "hdl32"), ("a1", "hdl32"), ("b0", "hdl64"), ("b1", "hdl64")):
        best = {"cave": 1, "street": 2} if sensor == "hdl32" else {"cave": 2, "street": 1}
        label_rte = {lab: [2.0, 1.0 if b == 1 else 3.0, 1.0 if b == 2 else 3.0]
                     for lab, b in best.items()}
        write_runs(folder / name, world(name, {"oracle": [[1.0] * 20]}, labels, sensor=sensor))
        (folder / name / "candidates.json").write_text(json.dumps(
            {"candidates": CANDIDATES, "selection_replica_rte_pct": label_rte, "choice": {}}))


def test_the_controls_on_hand_made_worlds(tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    _headroom(tmp_path / "headroom")
    (tmp_path / "headroom.json").write_text(json.dumps({"fixed": CANDIDATES[0]}))
    load_script(SCRIPT).main(["--headroom", str(tmp_path / "headroom"),
                              "--metrics", str(tmp_path / "headroom.json")])
    lines = capsys.readouterr().out.splitlines()
    assert "4 worlds, 3 candidates (SBS = candidate 0)" in lines[0]
    got = {m[1]: (float(m[2]), int(m[3])) for line in lines[1:]
           if (m := re.fullmatch(r"  (\S+ / \S+): (\S+) \(.*\), (\d)/4 worlds better", line))}
    # one set for the whole world: every candidate averages 2 over the two labels (= SBS);
    # per label from the three other worlds: two of them have the other sensor, whose best
    # (3 here) wins the vote; per label and sensor: the right one, 1; in sample: 1
    assert got == {"constant / sbs": (1.0, 0), "class / sbs": (1.5, 0),
                   "class_sensor / sbs": (0.5, 4), "label_oracle / sbs": (0.5, 4),
                   "class / constant": (1.5, 0), "class_sensor / class": (0.333, 4)}


def test_a_folder_without_candidates_is_refused_by_name(tmp_path: Path) -> None:
    (tmp_path / "headroom").mkdir()
    with pytest.raises(SystemExit, match=r"headroom: no world with candidates.json"):
        load_script(SCRIPT).main(["--headroom", str(tmp_path / "headroom"),
                                  "--metrics", str(tmp_path / "headroom.json")])

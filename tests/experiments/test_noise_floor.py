"""experiments/noise_floor.py, small: one dev world cut to 10 frames, NDT's defaults and the fixed
set of an evaluate record, each run once as it is and once moved by the replicas' factors; and
the fixed set read from the committed record, or a clear error."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from helpers.scripts import load_script

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "experiments" / "noise_floor.py"


def _record(path: Path, fixed: dict[str, float], algorithm: str = "ndt") -> Path:
    path.write_text(json.dumps({"algorithm": algorithm,
                                "params": {"baseline": {}, "fixed": fixed}}))
    return path


def test_the_fixed_set_is_the_committed_evaluate_records() -> None:
    record = json.loads((ROOT / "records" / "evaluation.json").read_text())
    fixed = load_script(SCRIPT).toy_fixed(ROOT / "records" / "evaluation.json")
    assert fixed == {record["algorithm"]: record["params"]["fixed"]}
    assert set(fixed["ndt"]) == {"resolution", "keyframe_interval"}


def test_a_record_without_the_fixed_set_is_refused_by_name(tmp_path: Path) -> None:
    module = load_script(SCRIPT)
    with pytest.raises(SystemExit, match=r"missing\.json: no such file"):
        module.main(["--record", str(tmp_path / "missing.json")])
    bare = tmp_path / "bare.json"
    bare.write_text(json.dumps({"algorithm": "ndt", "params": {"baseline": {}}}))
    with pytest.raises(SystemExit, match=r"bare\.json: no 'algorithm' and 'params.fixed'"):
        module.main(["--record", str(bare)])


def test_a_small_run_gives_the_spread_of_both_settings(tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    record = _record(tmp_path / "evaluation.json", {"resolution": 2.0, "keyframe_interval": 4.0})
    params = tmp_path / "params.yaml"
    params.write_text("generalize:\n  targets:\n    worst: 1.2\n")
    load_script(SCRIPT).main(["--worlds", "0", "--replicas", "1", "--algorithms", "ndt",
                              "--frames", "10", "--length-m", "2", "--record", str(record),
                              "--params", str(params)])
    (line,) = capsys.readouterr().out.strip().splitlines()
    # the defaults and the record's fixed set on the one world, each run twice; the target
    # the pairs are counted against: the params' generalize.targets.worst
    got = re.fullmatch(r"ndt: .* \(dev_00; 1 replicas\): median CV over 2 worlds x settings "
                       r"(\S+) \(range (\S+)-(\S+)\); .* exceeds 1.2: (\S+) %", line)
    assert got is not None, line
    cv, low, high, above = (float(v) for v in got.groups())
    assert 0.0 <= low <= cv <= high and 0.0 <= above <= 100.0

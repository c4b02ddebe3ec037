"""A stopped headroom study resumes from its journal (studies/suites/journal.py): the worlds a pass
finished are not run again, the output is the uninterrupted run's byte for byte, and a journal
of other inputs or code is never mixed in."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from helpers.verdict_data import world

import studies.verdict.headroom as headroom
from studies.suites.journal import Journal, code_digest, fingerprint, journal_dir
from studies.suites.runner import SuiteInputs

BUILD_INPUTS = """
from pipeline.odometry.ndt import SPACE
from pipeline.sim.dataset import SimulateSection
from studies.suites.runner import SuiteInputs
from studies.verdict.section import SuiteDraw
from studies.verdict.worlds import sensor_template, world_of

draw = SuiteDraw(seed_roots={"dev": 1, "test": 2}, worlds=2, sensors=("vlp16",),
                 segments=(2, 2), frames=(60, 60))
template = sensor_template(SimulateSection(), 42)
worlds = [world_of(draw, "id", "dev", i, template) for i in range(2)]
inputs = SuiteInputs("ndt", SPACE, SPACE.defaults(), {"resolution": 2.0, "keyframe_interval": 1.0},
                     {}, 4.0, 1, 0.005, 100.0)
"""


def tiny_study() -> tuple[list, SuiteInputs, list[dict[str, float]]]:
    """Two 60-frame VLP-16 worlds, one replica, three candidates."""
    namespace: dict = {}
    exec(BUILD_INPUTS, namespace)
    worlds, inputs = namespace["worlds"], namespace["inputs"]
    candidates = [inputs.baseline, inputs.fixed, {"resolution": 3.0, "keyframe_interval": 2.0}]
    return worlds, inputs, candidates


def files(folder: Path) -> dict[str, bytes]:
    return {p.relative_to(folder).as_posix(): p.read_bytes()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def test_a_stopped_headroom_resumes_where_it_stopped(tmp_path: Path,
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    """Stopped in the class oracle's pass on its second world: the rerun runs that world's
    class oracle alone, writes what an uninterrupted run writes and deletes the journal."""
    worlds, inputs, candidates = tiny_study()
    whole = tmp_path / "whole"
    headroom.run_headroom(worlds, inputs, candidates, 1.0, whole, 1)
    assert not journal_dir(whole).exists()

    calls: list[tuple[str, str]] = []
    first, second = headroom.first_pass, headroom.second_pass

    def counted_first(w, *args):  # type: ignore[no-untyped-def]
        calls.append(("first", w.name))
        return first(w, *args)

    def stopping_second(w, *args):  # type: ignore[no-untyped-def]
        calls.append(("second", w.name))
        if len([c for c in calls if c[0] == "second"]) == 2:
            raise KeyboardInterrupt
        return second(w, *args)

    monkeypatch.setattr(headroom, "first_pass", counted_first)
    monkeypatch.setattr(headroom, "second_pass", stopping_second)
    out = tmp_path / "resumed"
    with pytest.raises(KeyboardInterrupt):
        headroom.run_headroom(worlds, inputs, candidates, 1.0, out, 1)
    assert not out.exists()
    journal = journal_dir(out)
    assert sorted(p.parent.parent.name for p in journal.glob("*/*/world.json")) == [
        "class", "cross_fitted", "cross_fitted"]
    stopped_at = calls[-1][1]

    calls.clear()

    def counted_second(w, *args):  # type: ignore[no-untyped-def]
        calls.append(("second", w.name))
        return second(w, *args)

    monkeypatch.setattr(headroom, "second_pass", counted_second)
    headroom.run_headroom(worlds, inputs, candidates, 1.0, out, 1)
    assert calls == [("second", stopped_at)]
    assert files(out) == files(whole)
    assert not journal.exists()


def test_a_journal_of_another_study_is_discarded(tmp_path: Path) -> None:
    """A world recorded under one fingerprint is found under it, and gone under another."""
    out = tmp_path / "oracles"
    journal = Journal.open(out, "a")
    journal.record("pass", world("w0", {"oracle": [[1.0, 2.0]]}, ["cave", "street"]),
                   {"choice": {"cave": 1}})
    found = Journal.open(out, "a").finished("pass")
    assert list(found) == ["w0"] and found["w0"][1] == {"choice": {"cave": 1}}
    assert found["w0"][0].t_err_pct["oracle"].tolist() == [[1.0, 2.0]]
    assert Journal.open(out, "b").finished("pass") == {}
    assert json.loads((journal_dir(out) / "fingerprint.json").read_text()) == {
        "fingerprint": "b"}


def test_the_fingerprint_follows_the_inputs_and_the_code(tmp_path: Path,
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    """Equal inputs give one fingerprint in any process (no address or hash order in it); a
    changed input or source file another."""
    worlds, inputs, candidates = tiny_study()
    here = fingerprint((worlds, inputs, candidates, 1.0))
    code = BUILD_INPUTS + (
        "from studies.suites.journal import fingerprint\n"
        "candidates = [inputs.baseline, inputs.fixed, "
        "{'resolution': 3.0, 'keyframe_interval': 2.0}]\n"
        "print(fingerprint((worlds, inputs, candidates, 1.0)))\n")
    for hash_seed in ("1", "2"):
        done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                              check=True, env={**os.environ, "PYTHONHASHSEED": hash_seed})
        assert done.stdout.strip() == here
    assert fingerprint((worlds, inputs, candidates, 2.0)) != here
    assert fingerprint((worlds[:1], inputs, candidates, 1.0)) != here

    package = tmp_path / "somepkg"
    package.mkdir()
    (package / "__init__.py").write_text("X = 1\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    before = code_digest(["somepkg"])
    (package / "__init__.py").write_text("X = 2\n")
    assert code_digest(["somepkg"]) != before


"""The real-data study's folds (studies.real.folds): what each trains on and tests on."""

from __future__ import annotations

import pytest

from studies.real.folds import IN_DISTRIBUTION, OUT_OF_ENVIRONMENT, Unit, fold_named, folds
from studies.real.section import RealSection

SECTION = RealSection.model_validate({"runs": [
    {"name": "a", "sensor": "s", "odometry": "a.txt"},
    {"name": "b", "sensor": "s", "odometry": "b.txt"},
    {"name": "c", "sensor": "s", "odometry": "c.txt"},
    {"name": "drive", "sensor": "t", "out_of_environment": False, "odometry": "d.txt"}]})
UNITS = [Unit("a_h1", "a", "h1"), Unit("a_h2", "a", "h2"), Unit("b_h1", "b", "h1"),
         Unit("b_h2", "b", "h2"), Unit("c_h1", "c", "h1"), Unit("c_h2", "c", "h2"),
         Unit("drive_p0_h1", "drive", "h1"), Unit("drive_p1_h1", "drive", "h1"),
         Unit("drive_p1_h2", "drive", "h2")]


def test_the_in_distribution_folds_swap_the_halves_of_every_run() -> None:
    in_a, in_b = (fold_named(UNITS, SECTION, n) for n in ("in_a", "in_b"))
    assert in_a.family == in_b.family == IN_DISTRIBUTION
    assert in_a.train == ("a_h1", "b_h1", "c_h1", "drive_p0_h1", "drive_p1_h1")
    assert dict(in_a.test) == {"a": ("a_h2",), "b": ("b_h2",), "c": ("c_h2",),
                               "drive": ("drive_p1_h2",)}
    assert set(in_b.train) == set(in_a.test_units)
    assert set(in_b.test_units) == set(in_a.train)


def test_out_of_environment_leaves_each_hand_held_run_out_and_never_the_drive() -> None:
    out = [f for f in folds(UNITS, SECTION) if f.family == OUT_OF_ENVIRONMENT]
    assert [f.name for f in out] == ["out_a", "out_b", "out_c"]
    for f in out:
        left = f.name.removeprefix("out_")
        assert dict(f.test) == {left: (f"{left}_h1", f"{left}_h2")}
        assert not any(u.startswith((left, "drive")) for u in f.train)
        assert len(f.train) == 4


def test_no_fold_tests_on_what_it_trains_on() -> None:
    for f in folds(UNITS, SECTION):
        assert not set(f.train) & set(f.test_units), f.name


def test_an_unknown_fold_is_refused_by_name() -> None:
    with pytest.raises(ValueError, match=r"no fold 'in_c' .*in_a, in_b, out_a"):
        fold_named(UNITS, SECTION, "in_c")

"""The portfolio study (pipeline.portfolio): its members, and every member run whole on
every sequence, in the trials stage's layout."""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers.tuning_adapters import SPACE
from helpers.tuning_settings import settings

from pipeline.errors import ConfigError
from pipeline.portfolio import PortfolioSection, portfolio_members, run_portfolio
from pipeline.tuning.table import read_trials, trials_path


def section(grid: dict[str, list[float]], fixed: bool = False) -> PortfolioSection:
    return PortfolioSection(grid=grid, fixed=fixed)


def test_members_are_the_grid_product_then_the_fixed_set_without_repeats() -> None:
    members = portfolio_members(SPACE, section({"bias": [-0.5, 0.5, 0.0], "window": [2, 3]},
                                               fixed=True), {"bias": 0.0, "window": 2})
    # bias slowest; (0.5, 3) is the baseline (trial 0), the fixed set repeats (0.0, 2)
    assert [(m["bias"], m["window"]) for m in members] == [
        (-0.5, 2), (-0.5, 3), (0.5, 2), (0.0, 2), (0.0, 3)]
    assert all(m["gain"] == SPACE.defaults()["gain"] for m in members)
    assert portfolio_members(SPACE, section({}), None) == []
    fixed_only = portfolio_members(SPACE, section({}, fixed=True), {"gain": 2.0})
    assert fixed_only == [{**SPACE.defaults(), "gain": 2.0}]


@pytest.mark.parametrize(("grid", "fixed", "message"), [
    ({"nope": [1.0]}, False, "portfolio.grid: unknown parameter 'nope' (known: bias, gain"),
    ({"bias": []}, False, "portfolio.grid.bias must list at least one value, got []"),
    ({"bias": [2.0]}, False, "portfolio.grid: bias must be in [-1.0, 1.0], got 2.0"),
    ({}, True, "portfolio.fixed needs the joint study's output"),
])
def test_bad_members_name_the_setting(grid: dict[str, list[float]], fixed: bool,
                                      message: str) -> None:
    with pytest.raises(ConfigError, match=None) as err:
        portfolio_members(SPACE, section(grid, fixed), None)
    assert message in str(err.value)


def test_every_member_runs_whole_on_every_sequence(sequences: list[Path],
                                                   tmp_path: Path) -> None:
    """Trial 0 the baseline, trial i member i, each study unpruned even where trials.pruning
    would prune; the layout the rte stage reads as a study."""
    grid = {"bias": [-1.0, 1.0], "gain": [0.25]}
    pruning = {"percentile": 1.0, "checkpoints": 2, "warmup": 0.1, "min_trials": 1}
    summaries = run_portfolio(sequences, tmp_path, settings(pruning=pruning), section(grid),
                              seed=3)
    members = portfolio_members(SPACE, section(grid), None)
    assert len(members) == 2 and [s.sequence for s in summaries] == ["seq_a", "seq_b"]
    for s in summaries:
        trials = sorted(read_trials(trials_path(tmp_path, "drift", s.sequence), SPACE),
                        key=lambda r: r.trial)
        assert [r.params for r in trials] == [SPACE.defaults(), *members]
        assert [r.status for r in trials] == ["ok"] * 3


@pytest.mark.parametrize(("portfolio", "message"), [
    ("{grid: {nope: [1.0]}, fixed: false}",
     "portfolio.grid: unknown parameter 'nope' (known: resolution, keyframe_interval)"),
    ("{grid: {resolution: []}, fixed: false}",
     "portfolio.grid.resolution must list at least one value, got []"),
    ("{grid: {resolution: [0.5]}, fixed: false}",
     "portfolio.grid: resolution must be in [1.0, 10.0], got 0.5"),
    ("{grid: {resolution: [2.0]}, fixed: true}", "portfolio.fixed needs the joint study's"),
])
def test_the_cli_turns_a_bad_portfolio_into_one_line(tmp_path: Path, portfolio: str,
                                                     message: str) -> None:
    """``adaptune portfolio`` (NDT, the default algorithm): the bad setting is one line and
    exit code 1 before any sequence is read (the one listed is not even MCAP), and nothing is
    written."""
    from helpers.evaluation_data import cli_fails

    from pipeline.sequence_index import write_index

    params = tmp_path / "params.yaml"
    params.write_text(f"portfolio: {portfolio}\n")
    write_index(tmp_path / "seqs", {"train": ["a"]})
    (tmp_path / "seqs" / "a.mcap").write_bytes(b"not an mcap file")
    out = tmp_path / "portfolio"
    cli_fails(["portfolio", "--params", str(params), "--sequences", str(tmp_path / "seqs"),
               "--out", str(out)], message)
    assert not out.exists()


@pytest.mark.parametrize(("split", "message"), [
    ("hdl64", "no sequences in split 'hdl64' (splits: hdl32, train, validation)"),
    ("hdl32", "split 'hdl32' lists b.mcap"),
])
def test_split_picks_the_index_split_the_portfolio_runs_on(tmp_path: Path, split: str,
                                                           message: str) -> None:
    """``--split`` (the tuning suite's per-sensor splits) replaces trials.split: the split's
    sequences are the ones read, one line and exit code 1 when it is missing or names a file
    that is not there."""
    from helpers.evaluation_data import cli_fails

    from pipeline.sequence_index import write_index

    params = tmp_path / "params.yaml"
    params.write_text("portfolio: {grid: {resolution: [2.0]}, fixed: false}\n")
    write_index(tmp_path / "seqs", {"train": ["a"], "validation": [], "hdl32": ["b"]})
    (tmp_path / "seqs" / "a.mcap").write_bytes(b"")
    out = tmp_path / "portfolio"
    cli_fails(["portfolio", "--params", str(params), "--sequences", str(tmp_path / "seqs"),
               "--out", str(out), "--split", split], message)
    assert not out.exists()

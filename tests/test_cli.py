"""The `adaptune` command group: instant help, lazy sub-commands, one-line errors."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from click.testing import CliRunner

from stages.cli import COMMANDS, every_command, main
from stages.study import STUDY_COMMANDS

HEAVY = ("numpy", "open3d", "duckdb", "sklearn", "hyperopt", "dask", "pyarrow", "small_gicp", "dvc")


def test_help_imports_nothing_heavy_and_lists_every_command() -> None:
    code = ("import sys; from stages.cli import main\n"
            "try:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
            "print('MODULES', ' '.join(sorted(m for m in sys.modules if '.' not in m)))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    help_text, _, modules = out.stdout.rpartition("MODULES ")
    loaded = set(modules.split())
    assert "click" in loaded
    assert not loaded & set(HEAVY), loaded & set(HEAVY)
    section = help_text.split("Commands:")[1].split("\n\n")[0]  # up to the epilog
    listed = {line.split()[0] for line in section.splitlines()
              if line.startswith("  ") and not line.startswith("    ")}
    assert listed == set(COMMANDS)


OLD_NAMES = ("ingest", "info", "init", "simulate", "metric", "query", "export", "run", "trials",
             "portfolio", "params", "rte", "descriptors", "surrogate", "select", "live",
             "adaptive", "evaluate", "generalize", "verdict", "oracles", "headroom",
             "tuning-suite", "ingest-set", "simulate-set", "kitti-preset", "kitti-table",
             "simulate-kitti-set", "docs", "realism", "plot-world")
"""The 31 commands `adaptune --help` listed at 8fd4b99: each still runs (dvc.yaml files, the
projects `adaptune init` wrote, users' scripts)."""


def test_help_lists_at_most_15_commands_and_every_old_name_still_runs() -> None:
    runner = CliRunner()
    assert len(main.list_commands(None)) <= 15  # type: ignore[arg-type]
    assert set(OLD_NAMES) <= set(every_command())
    for name in OLD_NAMES:
        sub = runner.invoke(main, [name, "--help"])
        assert sub.exit_code == 0, (name, sub.output)
    for name in STUDY_COMMANDS:  # a study command under `study` and its old name: the same
        assert main.get_command(None, "study").get_command(None, name) is (  # type: ignore
            main.get_command(None, name))  # type: ignore[arg-type]


def test_every_listed_command_resolves() -> None:
    runner = CliRunner()
    result = runner.invoke(main, ["--help"])
    assert result.exit_code == 0
    for name in main.list_commands(None):  # type: ignore[arg-type]
        sub = runner.invoke(main, [name, "--help"])
        assert sub.exit_code == 0, (name, sub.output)


def test_adaptune_error_becomes_one_line_exit_1(tmp_path: Path) -> None:
    missing = tmp_path / "missing.mcap"
    result = subprocess.run([sys.executable, "-m", "stages.cli", "info", str(missing)],
                            capture_output=True, text=True)
    assert result.returncode == 1
    assert result.stdout == ""
    assert result.stderr.splitlines() == [f"adaptune: error: {missing}: no such sequence file"]


def test_no_info_lines_without_verbose(tmp_path: Path) -> None:
    """Warnings only by default: the summary line alone on stderr; -v adds the INFO lines."""
    params = tmp_path / "params.yaml"
    params.write_text("data: {}\n")
    args = [sys.executable, "-m", "stages.cli", "ingest-set", "--params", str(params),
            "--out", str(tmp_path / "k")]
    quiet = subprocess.run(args, capture_output=True, text=True, check=True)
    summary = f"{tmp_path / 'k' / 'index.json'}: 0 train, 0 validation sequences"
    assert (quiet.stdout, quiet.stderr.splitlines()) == ("", [summary])
    verbose = subprocess.run([*args[:3], "-v", *args[3:]], capture_output=True, text=True,
                             check=True)
    assert verbose.stderr.splitlines() == [
        "INFO pipeline.sources.dataset: ingest: no data sources configured, writing an empty "
        "data set", summary]


def test_default_simulation_fits_the_default_length() -> None:
    """`adaptune simulate` with its default frame count drives farther than the default L, in
    every world, so that a first `adaptune trials` on it can score RTE."""
    import numpy as np

    from pipeline.config import BaseSection
    from pipeline.sim.simulate import SimSpec, make_world
    from pipeline.sim.worlds import WORLDS  # the toy worlds (kitti drives a given trajectory)
    from stages.simulate import simulate

    frames = next(p.default for p in simulate.params if p.name == "frames")
    for world in WORLDS:
        for seed in (0, 1) if world == "cave" else (0,):  # cave: the slowest
            poses = make_world(SimSpec(world, seed, frames)).poses.T_world_lidar
            length = np.linalg.norm(np.diff(poses[:, :3, 3], axis=0), axis=1).sum()
            assert length > 1.2 * BaseSection().length_m, (world, seed, length)

"""The `adaptune` command group: instant help, lazy sub-commands, one-line errors."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from click.testing import CliRunner

from stages.cli import COMMANDS, main

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
    listed = {line.split()[0] for line in help_text.split("Commands:")[1].splitlines()
              if line.startswith("  ") and not line.startswith("    ")}
    assert listed == set(COMMANDS)


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

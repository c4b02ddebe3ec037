"""The `adaptune` command group: instant help, lazy sub-commands, one-line errors."""

from __future__ import annotations

import subprocess
import sys

from click.testing import CliRunner

from stages.cli import COMMANDS, main

HEAVY = ("numpy", "open3d", "duckdb", "sklearn", "hyperopt", "dask", "pyarrow", "small_gicp", "dvc")


def test_help_imports_nothing_heavy() -> None:
    code = ("import sys; from stages.cli import main\n"
            "try:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
            "print(' '.join(sorted(m for m in sys.modules if '.' not in m)))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    loaded = set(out.stdout.split())
    assert not loaded & set(HEAVY), loaded & set(HEAVY)
    for name in ("ingest", "info"):
        assert name in out.stdout or name in COMMANDS


def test_every_listed_command_resolves() -> None:
    runner = CliRunner()
    result = runner.invoke(main, ["--help"])
    assert result.exit_code == 0
    for name in main.list_commands(None):  # type: ignore[arg-type]
        sub = runner.invoke(main, [name, "--help"])
        assert sub.exit_code == 0, (name, sub.output)


def test_adaptune_error_becomes_one_line_exit_1(tmp_path) -> None:
    if "info" not in main.list_commands(None):  # type: ignore[arg-type]
        import pytest

        pytest.skip("info command not built yet")
    result = CliRunner().invoke(main, ["info", str(tmp_path / "missing.mcap")])
    assert result.exit_code in (1, 2)
    assert "Traceback" not in result.output

"""Every script in experiments/ has a test here that runs it small (tests/experiments/
test_<script>.py), and reaches the library as the installed package: no ``sys.path`` edit, no
import of a file of bench/ or experiments/ as a bare module (bench/common.py as ``common``)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPTS = sorted((ROOT / "experiments").glob("*.py"))
LOOSE = {p.stem for folder in ("bench", "experiments") for p in (ROOT / folder).glob("*.py")}
"""Modules that only a sys.path edit would make importable."""


def imported_modules(path: Path) -> set[str]:
    """The top-level names of every module ``path`` imports, at any depth of its code."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names |= {alias.name.split(".")[0] for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split(".")[0])
    return names


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: p.stem)
def test_each_script_has_its_test(script: Path) -> None:
    test = Path(__file__).with_name(f"test_{script.stem}.py")
    assert test.is_file(), f"{script.name}: no {test.relative_to(ROOT)} runs it"
    assert f'"{script.name}"' in test.read_text(), f"{test.name} does not name {script.name}"


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: p.stem)
def test_each_script_imports_the_installed_package(script: Path) -> None:
    assert "sys.path" not in script.read_text(), f"{script.name} edits sys.path"
    assert not imported_modules(script) & LOOSE, f"{script.name} imports a loose script"


def test_the_check_sees_a_bare_import_of_bench_common(tmp_path: Path) -> None:
    script = tmp_path / "probe.py"
    script.write_text("def main():\n    from common import data_root\n")
    assert imported_modules(script) & LOOSE == {"common"}

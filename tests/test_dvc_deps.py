"""dvc.yaml deps that cannot go stale: every project file a stage's command runs is one of its
dependencies (docs/design.md, "Stages").

The command of a stage is ``adaptune <name> ...``; ``stages.cli.COMMANDS`` names the module of
that sub-command. From there the static import graph is followed through the project packages
(pipeline, stages, schemas), lazy imports inside functions included, ``if TYPE_CHECKING:``
blocks left out; a package's ``__init__.py`` counts for each module imported from it, and a
schema file a module names (``"tables.sql"``, or a folder of them: ``f"ros2/{name}.msg"``)
counts too. Each of those files must be covered by
a deps entry of the stage: the file itself or a folder holding it.
"""

from __future__ import annotations

import ast
from functools import cache
from pathlib import Path

import pytest
import yaml

from stages.cli import COMMANDS

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("pipeline", "stages", "schemas")
SCHEMA_FILES = {p.relative_to(REPO / "schemas").as_posix(): p
                for p in (REPO / "schemas").rglob("*") if p.is_file() and p.suffix != ".py"}


def module_file(name: str) -> Path | None:
    """The source file of a project module (None outside the project packages)."""
    if name.split(".")[0] not in PACKAGES:
        return None
    base = REPO.joinpath(*name.split("."))
    if (base / "__init__.py").is_file():
        return base / "__init__.py"
    return base.with_suffix(".py") if base.with_suffix(".py").is_file() else None


def _is_type_checking(node: ast.AST) -> bool:
    test = node.test if isinstance(node, ast.If) else None
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _nodes(tree: ast.AST) -> list[ast.AST]:
    """Every node of ``tree`` outside ``if TYPE_CHECKING:`` blocks."""
    out, stack = [], [tree]
    while stack:
        node = stack.pop()
        out.append(node)
        for child in ast.iter_child_nodes(node):
            if _is_type_checking(child):
                stack.extend(child.orelse)  # type: ignore[attr-defined]
            else:
                stack.append(child)
    return out


@cache
def imports_of(name: str) -> tuple[frozenset[str], frozenset[str]]:
    """(project modules imported by module ``name``, schema files it names)."""
    path = module_file(name)
    assert path is not None, name
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    modules, schema_files = set(), set()
    for node in _nodes(ast.parse(path.read_text(encoding="utf-8"))):
        targets: list[str] = []
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*parent, base] if base else parent)
            targets = [base] + [f"{base}.{a.name}" for a in node.names]
        elif isinstance(node, ast.Constant) and isinstance(node.value, str):
            # a schema file by name, or a folder of them (the constant part of an f-string)
            schema_files.update(f for f in SCHEMA_FILES if f == node.value or (
                node.value.endswith("/") and f.startswith(node.value)))
        for target in targets:
            parts = target.split(".")
            for i in range(1, len(parts) + 1):  # a package's __init__ runs for its modules
                if module_file(".".join(parts[:i])) is not None:
                    modules.add(".".join(parts[:i]))
    return frozenset(modules), frozenset(schema_files)


def files_of_command(command_module: str) -> set[Path]:
    """Every project file the command module imports, transitively, and the schema files."""
    seen: set[str] = set()
    files: set[Path] = set()
    todo = [command_module]
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        files.add(module_file(name))  # type: ignore[arg-type]
        modules, schemas = imports_of(name)
        files.update(SCHEMA_FILES[s] for s in schemas)
        todo.extend(modules - seen)
    return files


def stage_commands() -> dict[str, tuple[str, list[str]]]:
    """stage -> (command module, deps) from dvc.yaml."""
    stages = yaml.safe_load((REPO / "dvc.yaml").read_text())["stages"]
    out = {}
    for stage, spec in stages.items():
        words = " ".join(spec["cmd"].split()).split()
        assert words[0] == "adaptune", f"{stage}: the command must be an adaptune sub-command"
        module = COMMANDS[words[1]][0].split(":")[0]
        out[stage] = (module, [str(d) for d in spec.get("deps", [])])
    return out


@pytest.mark.parametrize("stage", list(stage_commands()))
def test_every_module_a_stage_runs_is_a_dependency(stage: str) -> None:
    module, deps = stage_commands()[stage]
    covered = [REPO / d for d in deps if "${" not in d]
    missing = sorted(
        str(f.relative_to(REPO)) for f in files_of_command(module)
        if not any(f == d or d in f.parents for d in covered)
    )
    assert not missing, f"dvc.yaml stage {stage!r} runs {missing} but does not depend on them"


def test_the_import_graph_sees_lazy_imports() -> None:
    """The walk follows an import inside a function: the surrogate stage reaches the forest
    through the registry, and the adaptive stage the artifact loader."""
    surrogate = {f.relative_to(REPO).as_posix() for f in files_of_command("stages.surrogate")}
    assert {"pipeline/surrogates/forest.py", "pipeline/surrogates/fit.py",
            "schemas/artifact.schema.json", "pipeline/__init__.py"} <= surrogate
    adaptive = {f.relative_to(REPO).as_posix() for f in files_of_command("stages.adaptive")}
    assert "pipeline/artifact.py" in adaptive and "pipeline/surrogates/fit.py" not in adaptive

"""dvc.yaml's code dependencies, generated from the import graph (docs/design.md, "Stages").

The command of a stage is ``adaptune <name> ...``; ``stages.cli.COMMANDS`` names the module of
that sub-command. From there the static import graph is followed through the project packages
(pipeline, stages, schemas), lazy imports inside functions included, ``if TYPE_CHECKING:``
blocks left out; a package's ``__init__.py`` counts for each module imported from it, and a
schema file a module names (``"tables.sql"``, or a folder of them: ``f"ros2/{name}.msg"``)
counts too. A folder whose every file is needed is listed as the folder.

A ``foreach`` stage has its command and deps in its ``do:`` block (``stage_spec``).
``python tests/helpers/dvc_deps.py`` rewrites the ``deps:`` of every stage in dvc.yaml,
verdict/dvc.yaml and real/dvc.yaml (``DVC_FILES``; its data dependencies first, as written,
then the code); ``--check`` exits 1 when one differs (``make deps`` / ``make lint``;
tests/test_dvc_deps.py checks it in the suite).
"""

from __future__ import annotations

import ast
import re
import sys
from functools import cache
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
PACKAGES = ("pipeline", "studies", "stages", "schemas")
CODE_ROOTS = tuple(f"{p}/" for p in PACKAGES)
SCHEMA_FILES = {p.relative_to(REPO / "schemas").as_posix(): p
                for p in (REPO / "schemas").rglob("*")
                if p.is_file() and p.suffix != ".py" and "__pycache__" not in p.parts}
WIDTH = 100


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


def imported_names(path: Path, package: str, *, type_checking: bool = False) -> set[str]:
    """Absolute names of everything module ``path`` (of ``package``) imports; with
    ``type_checking`` the ``if TYPE_CHECKING:`` blocks count too."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    names: set[str] = set()
    for node in (ast.walk(tree) if type_checking else _nodes(tree)):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*parent, base] if base else parent)
            names.add(base)
            names.update(f"{base}.{a.name}" for a in node.names)
    return names


def project_modules(names: set[str]) -> set[str]:
    """The project modules ``names`` load: each one and the packages above it."""
    out = set()
    for target in names:
        parts = target.split(".")
        for i in range(1, len(parts) + 1):  # a package's __init__ runs for its modules
            if module_file(".".join(parts[:i])) is not None:
                out.add(".".join(parts[:i]))
    return out


@cache
def imports_of(name: str) -> tuple[frozenset[str], frozenset[str]]:
    """(project modules imported by module ``name``, schema files it names)."""
    path = module_file(name)
    assert path is not None, name
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    schema_files = set()
    for node in _nodes(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Constant) and isinstance(node.value, str):
            # a schema file by name, or a folder of them (the constant part of an f-string)
            schema_files.update(f for f in SCHEMA_FILES if f == node.value or (
                node.value.endswith("/") and f.startswith(node.value)))
    return frozenset(project_modules(imported_names(path, package))), frozenset(schema_files)


ENTRY_MODULES = ("pipeline.dispatch",)
"""What every command's process runs under besides its own module: ``stages.cli.entry`` pins
the CPU dispatch with it (its pins change the numbers), not the rest of the CLI (a new
command re-runs no stage)."""


def files_of_command(command_module: str) -> set[Path]:
    """Every project file the command module imports, transitively, the modules the
    ``adaptune`` executable runs every command under (``ENTRY_MODULES``) and the schema files."""
    seen: set[str] = set()
    files: set[Path] = set()
    todo = [command_module, *ENTRY_MODULES]
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


def _tracked(folder: Path) -> set[Path]:
    """The files of ``folder`` a stage could depend on (no caches)."""
    return {p for p in folder.rglob("*") if p.is_file() and "__pycache__" not in p.parts}


def cover(files: set[Path]) -> list[str]:
    """The shortest list of files and folders (relative to the repo) that is exactly ``files``:
    a folder stands for its files when every one of them is in ``files``."""
    out: list[str] = []
    todo = set(files)
    folders = sorted({p for f in files for p in f.parents if REPO in p.parents},
                     key=lambda p: len(p.parts))
    for folder in folders:
        inside = _tracked(folder)
        if inside and inside <= todo and not any(Path(REPO / o) in folder.parents for o in out):
            out.append(folder.relative_to(REPO).as_posix())
            todo -= inside
    out += [f.relative_to(REPO).as_posix() for f in todo]
    return sorted(out, key=lambda s: (s.split("/")[0] != "stages", s))


def stage_spec(spec: dict) -> dict:
    """The stage's own fields: its ``do:`` block for a ``foreach`` stage (one stage per item,
    the same command and deps with ``${item}`` in them), else the stage."""
    return spec["do"] if "foreach" in spec else spec


def stage_commands(dvc_yaml: str) -> dict[str, str]:
    """stage -> the module of its ``adaptune`` sub-command."""
    import yaml

    sys.path.insert(0, str(REPO))
    from stages.cli import every_command
    from stages.study import STUDY_COMMANDS

    out = {}
    for stage, spec in yaml.safe_load(dvc_yaml)["stages"].items():
        words = " ".join(stage_spec(spec)["cmd"].split()).split()
        assert words[0] == "adaptune", f"{stage}: the command must be an adaptune sub-command"
        registry, name = ((STUDY_COMMANDS, words[2]) if words[1] == "study"
                          else (every_command(), words[1]))
        out[stage] = registry[name][0].split(":")[0]
    return out


def _flow(items: list[str], indent: int) -> str:
    """``[a, b, ...]`` wrapped at WIDTH, continuation lines under the first item (``indent``
    columns in: the first line's ``    deps: [`` prefix)."""
    words = [(f'"{item}"' if "$" in item else item) for item in items]
    lines: list[str] = []
    line = ""
    for i, word in enumerate(words):
        word += "]" if i == len(words) - 1 else ","
        if line and indent + len(line) + 1 + len(word) > WIDTH:
            lines.append(line)
            line = word
        else:
            line = f"{line} {word}" if line else word
    lines.append(line)
    return "[" + ("\n" + " " * indent).join(lines)


def generated(dvc_yaml: str, prefix: str = "") -> str:
    """``dvc_yaml`` with every stage's deps: its data deps as written, then its code (paths
    relative to the repository, with ``prefix`` in front: ``../`` for a dvc.yaml one folder
    down, whose stages run there)."""
    import yaml

    specs = yaml.safe_load(dvc_yaml)["stages"]
    commands = stage_commands(dvc_yaml)
    roots = tuple(prefix + root for root in CODE_ROOTS)
    for stage, module in commands.items():
        data = [str(d) for d in stage_spec(specs[stage]).get("deps", [])
                if not f"{str(d).rstrip('/')}/".startswith(roots)]  # a package whole, too
        deps = data + [prefix + path for path in cover(files_of_command(module))]
        indent = "      " if "foreach" in specs[stage] else "    "  # a do: block is indented
        block = re.compile(rf"(\n  {re.escape(stage)}:[^\n]*\n(?:    [^\n]*\n)*?{indent}deps: )"
                           r"\[[^\]]*\]")
        if not block.search(dvc_yaml):
            raise SystemExit(f"dvc.yaml: stage {stage!r} has no one-list deps: [...] to rewrite")
        listed = _flow(deps, len(indent) + 7)
        dvc_yaml = block.sub(lambda m, listed=listed: m.group(1) + listed, dvc_yaml, count=1)
    return dvc_yaml


DVC_FILES = {"dvc.yaml": "", "verdict/dvc.yaml": "../", "real/dvc.yaml": "../"}
"""Every pipeline of the repository: its dvc.yaml -> the prefix of a repository path seen from
its stages' folder."""


def main(argv: list[str]) -> int:
    stale = []
    for name, prefix in DVC_FILES.items():
        path = REPO / name
        text = path.read_text(encoding="utf-8")
        new = generated(text, prefix)
        if new != text:
            stale.append(name)
            if "--check" not in argv:
                path.write_text(new, encoding="utf-8")
    if stale and "--check" in argv:
        print(f"{', '.join(stale)}: code deps are stale; run `make deps`", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))

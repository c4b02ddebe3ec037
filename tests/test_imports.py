"""The code's import graph has no circle and no import that runs back up (docs/design.md,
"Layout"), counting the imports inside functions (``if TYPE_CHECKING:`` blocks left out: they
never run).

The layers, bottom up: ``schemas``; ``pipeline`` (the product's library); ``studies`` (the
project's own studies of the method); ``stages`` (the command line). A module imports from its
own layer and the ones below. Within a layer, neither the modules nor the units (a package's
subpackage or top-level module: ``pipeline.sim``, ``pipeline.io_utils``) import each other in
a circle.
"""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

from helpers.dvc_deps import PACKAGES, imports_of, module_file

REPO = Path(__file__).resolve().parents[1]
LAYERS = ("schemas", "pipeline", "studies", "stages")
"""Bottom up: a module may import its own layer and the ones before it."""


def modules() -> list[str]:
    """Every module of the project's packages, by name."""
    out = []
    for package in PACKAGES:
        for path in sorted((REPO / package).rglob("*.py")):
            parts = path.relative_to(REPO).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            if module_file(name) is not None:
                out.append(name)
    return out


def edges() -> dict[str, set[str]]:
    """module -> the project modules it imports (packages' ``__init__`` modules only for the
    package they belong to, which every import of one of its modules runs)."""
    graph = {}
    for name in modules():
        imported, _ = imports_of(name)
        graph[name] = {m for m in imported if m != name and not name.startswith(m + ".")}
    return graph


def unit(name: str) -> str:
    """``pipeline.sim.raycast`` -> ``pipeline.sim``; ``pipeline.io_utils`` -> itself."""
    return ".".join(name.split(".")[:2])


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of ``graph`` with more than one node (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_no_module_imports_a_layer_above_its_own() -> None:
    up = sorted((m, t) for m, targets in edges().items() for t in targets
                if LAYERS.index(t.split(".")[0]) > LAYERS.index(m.split(".")[0]))
    assert up == []


def test_no_circle_of_modules() -> None:
    assert cycles(edges()) == []


def test_no_circle_of_packages() -> None:
    graph: dict[str, set[str]] = defaultdict(set)
    for m, targets in edges().items():
        graph[unit(m)] |= {unit(t) for t in targets if unit(t) != unit(m)}
    assert cycles(dict(graph)) == []


def test_the_graph_sees_imports_inside_functions() -> None:
    """A check of the checker: an import inside a function counts (pipeline.adaptive imports
    pipeline.runtime only inside its functions)."""
    assert "pipeline.runtime" in edges()["pipeline.adaptive"]


SUITE_NAMES = ("run_suite", "score_world", "SuiteInputs", "suite_metrics", "ratio_summary",
               "plot_rows", "suite_worlds", "world_of", "_logged", "suite_figure", "load_world",
               "write_world", "read_results", "WorldResult", "costliest_first")
"""The names the toy's generalization suite and the verdict once both defined (two runners of
"settings over a suite of worlds"): one suite runner now, ``studies.suites``."""


def test_no_two_modules_define_the_same_suite_function() -> None:
    import ast

    where: dict[str, list[str]] = defaultdict(list)
    for package in ("pipeline", "studies"):
        for path in sorted((REPO / package).rglob("*.py")):
            for node in ast.parse(path.read_text(encoding="utf-8")).body:
                if isinstance(node, ast.FunctionDef | ast.ClassDef) and node.name in SUITE_NAMES:
                    where[node.name].append(str(path.relative_to(REPO)))
    assert {name: files for name, files in where.items() if len(files) > 1} == {}

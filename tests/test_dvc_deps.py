"""dvc.yaml deps that cannot go stale: every project file a stage's command runs is one of its
dependencies (docs/design.md, "Stages"). The deps are generated from the import graph
(tests/helpers/dvc_deps.py, ``make deps``); this checks that dvc.yaml is what it generates and
that the walk sees what it must."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml
from helpers.dvc_deps import (
    DVC_FILES,
    REPO,
    files_of_command,
    generated,
    stage_commands,
    stage_spec,
)

TEXTS = {name: (REPO / name).read_text(encoding="utf-8") for name in DVC_FILES}


@pytest.mark.parametrize("name", list(DVC_FILES))
def test_dvc_yaml_deps_are_the_generated_ones(name: str) -> None:
    text = TEXTS[name]
    assert generated(text, DVC_FILES[name]) == text, \
        f"{name}'s code deps are stale: run `make deps`"


@pytest.mark.parametrize(("name", "stage"), [(name, stage) for name in DVC_FILES
                                             for stage in stage_commands(TEXTS[name])])
def test_every_module_a_stage_runs_is_a_dependency(name: str, stage: str) -> None:
    module = stage_commands(TEXTS[name])[stage]
    deps = stage_spec(yaml.safe_load(TEXTS[name])["stages"][stage]).get("deps", [])
    stage_dir = (REPO / name).parent
    covered = [(stage_dir / d).resolve() for d in deps if "${" not in d]
    missing = sorted(
        str(f.relative_to(REPO)) for f in files_of_command(module)
        if not any(f == d or d in f.parents for d in covered)
    )
    assert not missing, f"{name} stage {stage!r} runs {missing} but does not depend on them"


def test_the_import_graph_sees_lazy_imports() -> None:
    """The walk follows an import inside a function: the surrogate stage reaches the forest
    through the registry, and the adaptive stage the artifact loader."""
    def rel(files: set[Path]) -> set[str]:
        return {f.relative_to(REPO).as_posix() for f in files}

    surrogate = rel(files_of_command("stages.surrogate"))
    assert {"pipeline/surrogates/forest.py", "pipeline/surrogates/fit.py",
            "schemas/artifact.schema.json", "pipeline/__init__.py"} <= surrogate
    adaptive = rel(files_of_command("stages.adaptive"))
    assert "pipeline/artifact.py" in adaptive and "pipeline/surrogates/fit.py" not in adaptive


def test_a_foreach_stage_gets_the_deps_of_its_command() -> None:
    """A ``foreach`` stage (one stage per item: the coverage model's per-sensor stages) has its
    command and deps in ``do:``; they are generated there, indented, its data deps kept."""
    text = ("stages:\n"
            "  portfolio:\n"
            "    foreach: [hdl32, hdl64]\n"
            "    do:\n"
            "      cmd: adaptune portfolio --sequences data/tune --split ${item} --out x/${item}\n"
            "      deps: [data/tune, ../pipeline/stale.py]\n"
            "      outs: [\"x/${item}\"]\n")
    assert stage_commands(text) == {"portfolio": "stages.portfolio"}
    out = generated(text, "../")
    deps = yaml.safe_load(out)["stages"]["portfolio"]["do"]["deps"]
    assert deps[0] == "data/tune" and "../pipeline/stale.py" not in deps
    assert {"../stages/portfolio.py", "../pipeline/portfolio.py"} <= set(deps)
    assert "\n      deps: [data/tune, ../stages/__init__.py," in out  # under do:, wrapped at 100
    assert generated(out, "../") == out

"""Every SQL query of docs/usage.md ("SQL") runs, and gives rows, on the results database of
every registered adapter (issue 57.7: two of three failed on a KISS-ICP project, they named
NDT's parameters)."""

from __future__ import annotations

import json
import shlex
from pathlib import Path

import pytest
from click.testing import CliRunner
from helpers.evaluation_data import gt_path, write_sequence, write_study

from pipeline.odometry.registry import adapter_names, get_adapter
from pipeline.sequence import EnvLabel
from stages.cli import main

USAGE = Path(__file__).resolve().parents[2] / "docs" / "usage.md"
COMMAND_PARAMS = ["voxel_m", "max_corr_m"]
"""The parameters of the command adapter's database (its space is the user's)."""


def documented_queries() -> list[str]:
    """The SQL of every `adaptune query` line of the block after ``<!-- sql examples -->``."""
    block = USAGE.read_text().split("<!-- sql examples -->\n```sh\n", 1)[1].split("```", 1)[0]
    words = shlex.split(block, comments=True)
    starts = [i for i, w in enumerate(words) if w == "adaptune"]
    assert starts and all(words[i + 1] == "query" for i in starts)
    return [words[i + 2] for i in starts]


def param_names(algorithm: str) -> list[str]:
    return COMMAND_PARAMS if algorithm == "command" else get_adapter(algorithm).space.names


@pytest.fixture(scope="module", params=adapter_names())
def database(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
             ) -> tuple[str, Path]:
    """(algorithm, the results database of a per-sequence and a joint study of it)."""
    algorithm = request.param
    root = tmp_path_factory.mktemp(algorithm)
    stamped = {}
    for name, n in (("cave_0", 40), ("street_0", 30)):
        gt = gt_path(n, seed=n)
        labels = [EnvLabel(0, 14, "cave"), EnvLabel(15, n - 1, "open")]
        stamped[name] = (write_sequence(root / "seq" / f"{name}.mcap", gt, labels), gt)
    (root / "seq" / "index.json").write_text(json.dumps({"train": ["cave_0", "street_0"],
                                                         "validation": []}))
    write_study(root / "trials", algorithm, stamped, 6, param_names(algorithm))
    write_study(root / "fixed", algorithm, stamped, 3, param_names(algorithm), seed=7,
                joint=True)
    (root / "params.yaml").write_text("base:\n  length_m: 5.0\ndevkit:\n  lengths_m: [5.0]\n")
    db = root / "adaptune.duckdb"
    result = CliRunner().invoke(main, ["rte", "--params", str(root / "params.yaml"),
                                       "--sequences", str(root / "seq"), "--trials",
                                       str(root / "trials"), "--fixed", str(root / "fixed"),
                                       "--db", str(db)])
    assert result.exit_code == 0, result.output
    return algorithm, db


@pytest.mark.parametrize("k", range(len(documented_queries())))
def test_every_documented_query_runs_on_every_algorithm(database: tuple[str, Path],
                                                         k: int) -> None:
    algorithm, db = database
    sql = documented_queries()[k]
    result = CliRunner().invoke(main, ["query", "--db", str(db), sql, "--format", "json"])
    assert result.exit_code == 0, (algorithm, sql, result.output)
    rows = json.loads(result.stdout)
    assert rows, (algorithm, sql)
    if "param" in rows[0]:  # every parameter of the algorithm, none of another
        assert {r["param"] for r in rows} == {f"p_{n}" for n in param_names(algorithm)}


def test_the_queries_are_found() -> None:
    queries = documented_queries()
    assert len(queries) == 3 and all(q.lstrip().startswith(("SELECT", "WITH")) for q in queries)

"""The documentation: generated pages equal what the committed metrics give, every link of
README.md and docs/ resolves, and the README stays a front door (issue 31): at most 250 lines,
the quick start within the first 100, every command of it valid for the current CLI."""

from __future__ import annotations

import hashlib
import json
import re
import shlex
import shutil
from pathlib import Path

import click
import pytest
import yaml

from pipeline.errors import InputError
from stages.cli import main
from studies.docs.pages import (
    BEGIN,
    END,
    EVALUATION,
    GENERALIZATION,
    RUNS,
    SUMMARIES,
    SURROGATE,
    TOY_PAGE,
    render_docs,
    stale_files,
)
from studies.docs.verdict_history import HISTORY

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"
QUICK_START = "## Your data, your odometry, in five minutes"
PAGES = [README, *sorted((REPO / "docs").rglob("*.md"))]


def test_the_generated_pages_are_what_the_committed_metrics_give() -> None:
    assert stale_files(REPO) == [], "run `make docs`"
    readme = README.read_text()
    block = readme[readme.index(BEGIN):readme.index(END)]
    evaluation = json.loads((REPO / EVALUATION).read_text())
    assert f"**{evaluation['rte_pct']['adaptive']:.3f}**" in block


def _copy(tmp: Path) -> Path:
    """What the generator reads, in a scratch repository ``tmp``: the toy's run and, once one
    is recorded, the verdict's with the history of its test suites."""
    verdict = (yaml.safe_load((REPO / RUNS).read_text()) or {}).get("verdict")
    verdict_files = ["verdict/dvc.lock", *verdict["outputs"], str(HISTORY)] if verdict else []
    for name in ("README.md", "dvc.lock", str(RUNS), EVALUATION, SURROGATE, GENERALIZATION,
                 *SUMMARIES.values(), *verdict_files):
        (tmp / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(REPO / name, tmp / name)
    return tmp


def test_a_new_run_renders_only_once_its_commit_is_recorded(tmp_path: Path) -> None:
    """Changed metrics are refused until dvc.lock and docs/results/runs.yaml both record their
    md5 (the run and its commit), and then the pages quote the new figures."""
    repo = _copy(tmp_path)
    path = repo / EVALUATION
    metrics = json.loads(path.read_text())
    metrics["rte_pct"]["adaptive"] = 0.123456
    path.write_text(json.dumps(metrics, indent=2) + "\n")
    md5 = hashlib.md5(path.read_bytes()).hexdigest()
    with pytest.raises(InputError, match=r"dvc\.lock"):
        render_docs(repo)
    lock = repo / "dvc.lock"
    old = hashlib.md5((REPO / EVALUATION).read_bytes()).hexdigest()
    lock.write_text(lock.read_text().replace(old, md5))
    with pytest.raises(InputError, match=r"runs\.yaml"):
        render_docs(repo)
    runs = yaml.safe_load((repo / RUNS).read_text())
    runs["toy"]["outputs"][EVALUATION] = md5
    runs["toy"]["commit"] = "abcdef1"
    (repo / RUNS).write_text(yaml.safe_dump(runs))
    pages = render_docs(repo)
    assert "**0.123**" in pages[Path("README.md")] and "main@abcdef1" in pages[TOY_PAGE]
    assert "| 0.123 |" in pages[TOY_PAGE]


def test_the_records_are_checked_too(tmp_path: Path) -> None:
    """A record (the bookkeeping beside the metrics) changed after the run is refused as a
    metrics file is: the page quotes it (the algorithm, the trial counts)."""
    repo = _copy(tmp_path)
    path = repo / SUMMARIES[EVALUATION]
    record = json.loads(path.read_text())
    record["algorithm"] = "gicp"
    path.write_text(json.dumps(record))
    with pytest.raises(InputError, match=r"records/evaluation\.json: md5 .* dvc\.lock"):
        render_docs(repo)


# ---------------------------------------------------------------- links


def _slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"[`*_]|\[([^]]*)\]\([^)]*\)", r"\1", heading.strip()).lower()
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def _unfenced(text: str) -> str:
    """``text`` without its fenced code blocks."""
    return re.sub(r"^```.*?^```", "", text, flags=re.S | re.M)


def _prose(text: str) -> str:
    """``text`` without code, fenced or inline (no links live there)."""
    return re.sub(r"`[^`\n]*`", "", _unfenced(text))


def _anchors(page: Path) -> set[str]:
    seen: dict[str, int] = {}
    out = set()
    for line in _unfenced(page.read_text()).splitlines():
        if line.startswith("#"):
            slug = _slug(line.lstrip("#"))
            out.add(f"{slug}-{seen[slug]}" if slug in seen else slug)
            seen[slug] = seen.get(slug, 0) + 1
    return out


def _links(page: Path) -> list[str]:
    return re.findall(r"\]\(([^)\s]+)\)", _prose(page.read_text()))


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(REPO)))
def test_every_link_resolves(page: Path) -> None:
    links = [u for u in _links(page) if not re.match(r"[a-z]+:", u)]
    for link in links:
        target, _, anchor = link.partition("#")
        path = (page.parent / target).resolve() if target else page
        assert path.exists(), f"{page.name}: {link}: no such file"
        if anchor:
            assert anchor in _anchors(path), f"{page.name}: {link}: no such heading"


def test_the_link_check_sees_a_broken_link_and_anchor(tmp_path: Path) -> None:
    page = tmp_path / "page.md"
    page.write_text("# A `page` (the first)\n\n[ok](#a-page-the-first) [bad](#nope) "
                    "[gone](missing.md)\n\n```sh\nnot [a](link.md)\n```\n")
    assert _links(page) == ["#a-page-the-first", "#nope", "missing.md"]
    assert _anchors(page) == {"a-page-the-first"}


# ---------------------------------------------------------------- the README as front door


def test_the_readme_is_a_front_door() -> None:
    lines = README.read_text().splitlines()
    assert len(lines) <= 250
    assert QUICK_START in lines[:100]


def _quick_start() -> str:
    text = README.read_text()
    return text.split(QUICK_START, 1)[1].split("\n## ", 1)[0]


def _blocks(section: str, language: str) -> list[str]:
    return [b.split("```", 1)[0] for b in section.split(f"```{language}\n")[1:]]


def _parse(args: list[str]) -> None:
    """Parse ``adaptune ARGS`` as the CLI would, without running it (click errors raise)."""
    cmd: click.Command = main
    name = "adaptune"
    while isinstance(cmd, click.Group):
        name, args = args[0], args[1:]
        sub = cmd.get_command(click.Context(cmd), name)
        assert sub is not None, f"no command {name!r}"
        cmd = sub
    cmd.make_context(name, args).close()


def test_every_quick_start_command_is_valid() -> None:
    """Every `adaptune` line of the quick start names a command and options the CLI has; it
    starts with `adaptune init` on several recordings; its params block is a valid trials
    section for the command adapter."""
    from pipeline.config import validate_section
    from pipeline.odometry.command import CommandOptions
    from pipeline.tuning.section import TrialsSection

    lines = [ln for b in _blocks(_quick_start(), "sh")
             for ln in b.replace("\\\n", " ").splitlines()]
    commands = [shlex.split(ln, comments=True)[1:] for ln in lines if ln.startswith("adaptune ")]
    assert commands[0][0] == "init" and commands[0].count("--recording") >= 2
    assert "dvc repro" in "\n".join(lines) and len(commands) >= 5
    for args in commands:
        _parse(args)
    with pytest.raises(click.UsageError):
        _parse(["trials", "--no-such-option"])
    (params,) = [yaml.safe_load(b) for b in _blocks(_quick_start(), "yaml")]
    trials = validate_section(TrialsSection, "trials", params["trials"])
    validate_section(CommandOptions, "command option", trials.adapter_options)


# ---------------------------------------------------------------- the metric's figure

USAGE = REPO / "docs" / "usage.md"
METRIC_FIGURE = REPO / "docs" / "figures" / "metric-rte.png"


def _marked_commands(page: Path, marker: str) -> list[list[str]]:
    """The `adaptune` command lines of the sh block after ``<!-- marker -->`` in ``page``."""
    block = page.read_text().split(f"<!-- {marker} -->\n```sh\n", 1)[1].split("```", 1)[0]
    return [shlex.split(ln)[1:] for ln in block.replace("\\\n", " ").splitlines()
            if ln.startswith("adaptune ")]


def test_the_metric_figure_is_made_by_the_documented_commands(
        kitti_root: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """docs/usage.md's `metric rte --plot` lines run as written on the real KITTI 04 scans
    (the KITTI root is the test data's): they give a table of the two estimates and a PNG of
    the committed figure's size."""
    from click.testing import CliRunner
    from PIL import Image

    commands = _marked_commands(USAGE, "metric plot")
    assert [c[0] for c in commands] == ["ingest", "run", "run", "metric"]
    monkeypatch.chdir(tmp_path)
    for args in commands:
        args = [str(kitti_root) if a == "/data/kitti/dataset" else a for a in args]
        result = CliRunner().invoke(main, args)
        assert result.exit_code == 0, (args, result.output)
    rows = result.stdout.splitlines()[3:]
    assert [r.split()[0] for r in rows] == ["gicp.parquet", "kiss_icp.parquet"]
    with Image.open(tmp_path / "metric-rte.png") as made, Image.open(METRIC_FIGURE) as committed:
        assert made.size == committed.size

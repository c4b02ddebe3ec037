"""``adaptune docs``: write the pages of docs/ that quote the committed metrics (``make docs``).

The pages and the README's result block are rendered from metrics/*.json, dvc.lock and
docs/results/runs.yaml (``studies.docs.pages``); ``--check`` writes nothing and fails when a
committed page is not what the metrics give.
"""

from __future__ import annotations

from pathlib import Path

import click

from stages.common import DIR


@click.command("docs")
@click.option("--repo", type=DIR, default=Path("."), show_default=True,
              help="The repository whose docs to render.")
@click.option("--check", is_flag=True,
              help="Write nothing; exit 1 naming every generated file that is out of date.")
def docs(repo: Path, check: bool) -> None:
    """Render docs/results/toy.md and the README's result from the committed metrics."""
    from pipeline.errors import InputError
    from pipeline.io_utils import atomic_write_text
    from studies.docs.pages import render_docs, stale_files

    if check:
        stale = stale_files(repo)
        if stale:
            raise InputError(f"{', '.join(map(str, stale))}: not what the committed metrics "
                             "give; run `make docs`")
        click.echo("docs: every generated page is up to date", err=True)
        return
    for path, text in render_docs(repo).items():
        atomic_write_text(repo / path, text)
        click.echo(f"{path}: written", err=True)

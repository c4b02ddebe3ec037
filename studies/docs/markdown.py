"""Markdown for the generated docs pages (``studies.docs.pages``,
``studies.docs.verdict_page``, ``studies.docs.real_page``): numbers, tables, prose wrapped at
96 columns, the params a page's run used."""

from __future__ import annotations

import math
import textwrap
from collections.abc import Mapping, Sequence
from typing import Any


def number(v: float | None, digits: int = 3) -> str:
    """``v`` with ``digits`` decimals; ``-`` for None or a non-finite value."""
    return "-" if v is None or not math.isfinite(v) else f"{v:.{digits}f}"


def percent(v: float | None) -> str:
    """A share as a whole percentage (``-`` for None)."""
    return "-" if v is None else f"{100 * v:.0f} %"


def values(p: Mapping[str, float]) -> str:
    """Parameters as ``name value, ...`` (3 significant digits)."""
    return ", ".join(f"{k} {v:.3g}" for k, v in p.items())


def wrap(text: str, prefix: str = "", indent: str | None = None) -> str:
    """``text`` as lines of at most 96 characters, the first starting with ``prefix``, the
    others with ``indent`` (``prefix`` if None)."""
    return textwrap.fill(text, 96, initial_indent=prefix,
                         subsequent_indent=prefix if indent is None else indent,
                         break_long_words=False, break_on_hyphens=False)


def bullet(text: str) -> str:
    """``text`` as a list item of lines of at most 96 characters, continued under its text."""
    return wrap(text, "- ", "  ")


def fill(text: str) -> str:
    """``text`` with its prose lines wrapped by ``wrap``: tables, headings, quotes, HTML and
    fenced code as they are."""
    out, fenced = [], False
    for line in text.split("\n"):
        if line.startswith("```"):
            fenced = not fenced
        keep = fenced or line.startswith(("```", "|", "#", ">", "<")) or len(line) <= 96
        out.append(line if keep else wrap(line))
    return "\n".join(out)


def row(cells: Sequence[object]) -> str:
    """One table row."""
    return "| " + " | ".join(str(c) for c in cells) + " |"


def table(head: Sequence[str], rows: Sequence[Sequence[object]]) -> list[str]:
    """A table's lines: the head, the rule, the rows."""
    return [row(head), "|" + "---|" * len(head), *(row(r) for r in rows)]


def params_section(params: Mapping[str, Any], params_file: str) -> list[str]:
    """A page's closing section: the values of ``params_file`` every stage behind its figures
    ran with (``params``, as dvc.lock records them), as YAML in a folded block."""
    import yaml

    return ["## Params", "", f"<details><summary>{params_file} values of every stage behind "
            "these figures</summary>", "", "```yaml",
            yaml.safe_dump(dict(params), sort_keys=False, default_flow_style=None,
                           width=80).rstrip(), "```", "", "</details>"]

"""The one loader of JSON and YAML text that adaptune reads from users' files and options:
``parse_json`` and ``parse_yaml``, nesting bounded by ``MAX_NESTING``.

A parser of nested text recurses: 100,000 nested ``[`` were a RecursionError traceback of
``json.loads`` (``run --values @nested.json``), and libyaml's composer recurses in C. The
nesting is measured first, without recursion (JSON: the brackets outside strings; YAML: the
parser's start and end events), and text nested deeper than ``MAX_NESTING`` is refused in one
line naming the limit. docs/design.md, "Inputs".
"""

from __future__ import annotations

import json
import re
from typing import Any

from pipeline.errors import AdaptuneError, InputError

MAX_NESTING = 100
"""The deepest nesting of lists and mappings a JSON or YAML input may have (adaptune's own
files nest 5 deep at most: params.yaml, the artifact's manifest)."""

_JSON_STRING = re.compile(r'"(?:[^"\\]|\\.)*"', re.DOTALL)
_JSON_BRACKET = re.compile(r"[\[\]{}]")


def check_json_nesting(text: str, what: str, *, error: type[AdaptuneError] = InputError
                       ) -> None:
    """``error`` naming ``what`` and ``MAX_NESTING`` when ``text`` opens more brackets (``[``
    or ``{`` outside strings) at once; linear, without recursion, stops at the first level
    past the limit."""
    depth = 0
    for m in _JSON_BRACKET.finditer(_JSON_STRING.sub("", text)):
        depth += 1 if m.group() in "[{" else -1
        if depth > MAX_NESTING:
            raise error(_too_deep(what))


def parse_json(text: str | bytes, what: str, *, error: type[AdaptuneError] = InputError
               ) -> Any:
    """``text`` parsed as JSON; ``error`` naming ``what`` (a file, an option) when it is not
    JSON or nests deeper than ``MAX_NESTING``."""
    if isinstance(text, bytes):
        try:
            text = text.decode("utf-8-sig")
        except UnicodeDecodeError as exc:
            raise error(f"{what}: not UTF-8 text (byte {exc.start})") from None
    check_json_nesting(text, what, error=error)
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise error(f"{what}: not valid JSON ({exc})") from None


def parse_yaml(text: str, what: str, *, error: type[AdaptuneError] = InputError) -> Any:
    """``text`` parsed as YAML (safe: plain data only, libyaml when installed); ``error``
    naming ``what`` when it is not YAML or nests deeper than ``MAX_NESTING``."""
    import yaml

    loader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)  # libyaml: 10x faster
    try:
        depth = 0
        for event in yaml.parse(text, Loader=loader):
            if isinstance(event, yaml.SequenceStartEvent | yaml.MappingStartEvent):
                depth += 1
                if depth > MAX_NESTING:
                    raise error(_too_deep(what))
            elif isinstance(event, yaml.SequenceEndEvent | yaml.MappingEndEvent):
                depth -= 1
        return yaml.load(text, Loader=loader)
    except yaml.YAMLError as exc:
        raise error(f"{what}: not valid YAML ({exc})") from None


def _too_deep(what: str) -> str:
    return (f"{what}: lists and mappings nested more than {MAX_NESTING} deep (MAX_NESTING); "
            "adaptune reads no deeper input")

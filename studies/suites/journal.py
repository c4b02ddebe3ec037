"""A stopped study's finished worlds, kept so that a rerun resumes it (docs/design.md, "The
suite runner").

A study that runs its subjects one by one for hours (the headroom's oracles: two passes over
40 worlds, about 2 h on two cores) records each world's result as it finishes in a *journal*,
``<output>.resume/`` beside its output (``journal_dir``): DVC deletes a stage's output before
running it again, not a folder beside it. A rerun takes every world a pass already finished
from the journal and runs the others; the output, written at the end, is the one an
uninterrupted run writes, and the journal is then deleted.

The journal's ``fingerprint.json`` is a digest of everything its results depend on: the
study's inputs (``fingerprint``'s argument: plain data or dataclasses, by their ``repr``) and
the source of the ``pipeline`` and ``studies`` packages. A journal with another fingerprint is
of another study (its inputs or code changed since) and is discarded whole, never mixed in.

Layout: ``<output>.resume/fingerprint.json`` and ``<output>.resume/<step>/<world>/``, the
world's ``rte.parquet`` and ``world.json`` (``studies.suites.runner.write_runs``; ``world.json``
is written last, so a world counts only once it is whole) and, when the step keeps more,
``extra.json`` (written first).
"""

from __future__ import annotations

import hashlib
import importlib
import json
import logging
import shutil
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

from studies.suites.runner import WorldResult, read_results, write_runs

log = logging.getLogger(__name__)

PROGRESS = logging.getLogger("pipeline.progress")
R = TypeVar("R")
Record = tuple[WorldResult, dict[str, Any] | None]

SUFFIX = ".resume"
CODE_PACKAGES = ("pipeline", "studies")
"""The packages whose source a journal's results depend on."""


def journal_dir(output: Path) -> Path:
    """The journal of the study writing ``output``: ``<output>.resume`` beside it."""
    return output.with_name(output.name + SUFFIX)


def code_digest(packages: Sequence[str] = CODE_PACKAGES) -> str:
    """SHA-256 of the ``.py`` sources of ``packages`` (path and bytes of each, sorted)."""
    digest = hashlib.sha256()
    for name in packages:
        root = Path(importlib.import_module(name).__file__ or "").parent
        for path in sorted(root.rglob("*.py")):
            digest.update(path.relative_to(root.parent).as_posix().encode() + b"\0")
            digest.update(path.read_bytes() + b"\0")
    return digest.hexdigest()


def fingerprint(inputs: Any, packages: Sequence[str] = CODE_PACKAGES) -> str:
    """The digest of a study: ``repr(inputs)`` (dataclasses, dicts, lists and floats have an
    exact, stable ``repr``) and the source of ``packages``."""
    digest = hashlib.sha256(repr(inputs).encode())
    digest.update(code_digest(packages).encode())
    return digest.hexdigest()


@dataclass(frozen=True)
class Journal:
    """The journal of one study (module docstring): its folder and fingerprint."""

    folder: Path
    fingerprint: str

    @classmethod
    def open(cls, output: Path, digest: str) -> Journal:
        """The journal beside ``output`` for the study of fingerprint ``digest``; one of
        another study there is deleted first."""
        from pipeline.io_utils import atomic_write_text

        folder = journal_dir(output)
        stored = folder / "fingerprint.json"
        if folder.exists():
            found = json.loads(stored.read_text()).get("fingerprint") if stored.is_file() else None
            if found != digest:
                log.info("%s: another study's journal (its inputs or code changed): discarded",
                         folder)
                shutil.rmtree(folder)
        if not stored.is_file():
            folder.mkdir(parents=True, exist_ok=True)
            atomic_write_text(stored, json.dumps({"fingerprint": digest}) + "\n")
        return cls(folder, digest)

    def finished(self, step: str) -> dict[str, tuple[WorldResult, dict[str, Any]]]:
        """Every world ``step`` finished, by name: its result and its ``extra``."""
        folder = self.folder / step
        if not folder.is_dir():
            return {}
        out = {}
        for result in read_results(folder):
            extra_path = folder / result.name / "extra.json"
            extra = json.loads(extra_path.read_text()) if extra_path.is_file() else {}
            out[result.name] = (result, extra)
        return out

    def record(self, step: str, result: WorldResult,
               extra: Mapping[str, Any] | None = None) -> None:
        """Keep ``result`` (and ``extra``: plain JSON data) as finished by ``step``."""
        from pipeline.io_utils import atomic_write_text

        folder = self.folder / step / result.name
        folder.mkdir(parents=True, exist_ok=True)
        if extra is not None:
            atomic_write_text(folder / "extra.json", json.dumps(extra) + "\n")
        write_runs(folder, result)

    def run(self, step: str, fn: Callable[..., R], jobs: Sequence[tuple[Any, ...]],
            names: Sequence[str], workers: int, *, keep: Callable[[R], Record],
            restore: Callable[[WorldResult, dict[str, Any]], R],
            costs: Sequence[float] | None = None,
            on_done: Callable[[R, int], object] | None = None) -> list[R]:
        """``[fn(*job) for job in jobs]`` (job i runs world ``names[i]``), ``workers`` at a
        time, the costliest first (``costs``), except for the worlds ``step`` finished before:
        those are restored from the journal. Each new result is recorded as it finishes
        (``keep``: its world result and extra), then ``on_done(result, finished)`` runs
        (``finished``: how many of the step's worlds are done, restored ones included)."""
        from pipeline.executor import costliest_first, map_in_processes

        done = self.finished(step)
        todo = [i for i, name in enumerate(names) if name not in done]
        if len(todo) < len(names):
            PROGRESS.info("%s: %d of %d worlds resumed from %s", step, len(names) - len(todo),
                          len(names), self.folder)
        count = len(names) - len(todo)

        def finished(_: int, result: R) -> None:
            nonlocal count
            self.record(step, *keep(result))
            count += 1
            if on_done is not None:
                on_done(result, count)

        order = costliest_first([costs[i] for i in todo]) if costs is not None else None
        new = dict(zip(todo, map_in_processes(fn, [jobs[i] for i in todo], workers,
                                              on_done=finished, order=order), strict=True))
        return [new[i] if i in new else restore(*done[name]) for i, name in enumerate(names)]

    def close(self) -> None:
        """Delete the journal (its study's output is written)."""
        shutil.rmtree(self.folder, ignore_errors=True)

"""A new project from a list of recordings: ``adaptune init DIR`` (docs/usage.md, "Your own
data set").

``init_project`` writes ``DIR/params.yaml`` and ``DIR/dvc.yaml``, as ``dvc init`` and
``kiss_icp_pipeline`` start a user off:

- a KITTI root stands for its sequences that have ground truth, each a recording
  (``pipeline.sources.detect.recordings_of``);
- every recording is described by ``pipeline.sources.detect.recording_entry`` (its kind,
  point-cloud topic and ground truth, found where unambiguous, checked by opening it; its
  ground truth must run longer than ``length_m``, written as base.length_m) and becomes a
  source of the ``data`` section, its path relative to DIR when it lies inside DIR, else
  absolute; the sequences of one KITTI root in one split are one source;
- splits: a recording's own ``split`` option, else ``validation`` / ``test`` (the recordings
  named there), else, when no recording is in the validation split and there are two or more,
  the last one is validation; the rest train. Recordings in the test split are evaluated too
  (``evaluate.splits``: validation, test); with no validation recording, the evaluation runs
  on the training recordings;
- params.yaml: every section the new dvc.yaml reads at the code's defaults
  (``pipeline.config.section_defaults``), ``base.sequences`` the ingest stage's folder;
- dvc.yaml: the stages of adaptune's own dvc.yaml (``DVC_YAML``, read from the source tree)
  from the recordings to the evaluation, the generators of simulated data and the
  generalization suite left out (``LEFT_OUT``), the ingest stage depending on the recordings.
  The code is adaptune's installation, not the project's: stages do not list it as deps
  (``dvc repro -f`` after an upgrade).

A recording is a path plus options (the keys of a ``data`` source): ``Recording``;
``read_recording_list`` reads them from a text file, one a line: ``PATH [key=value ...]``.
"""

from __future__ import annotations

import shlex
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from pipeline.config import SEQUENCE_FOLDERS, check_params, section_defaults
from pipeline.errors import ConfigError

DVC_YAML = Path(__file__).resolve().parents[1] / "dvc.yaml"
"""adaptune's own dvc.yaml, the one home of the stages' commands, outputs and params."""
LEFT_OUT = ("simulate", "simulate_kitti", "generalize")
"""Stages of DVC_YAML a project of recordings has no use for."""
CODE_PACKAGES = ("pipeline", "stages", "schemas")
"""Dependencies of DVC_YAML's stages in these folders are adaptune's code."""
PARAMS_KEYS: dict[str, tuple[str, ...]] = {
    "base": ("seed", "length_m", "sequences"), "data": ("sources",), "descriptors": (),
    "trials": ("algorithm", "iterations", "workers"), "fixed": ("iterations",),
    "devkit": ("lengths_m",), "surrogate": ("k",), "select": ("period_s",),
    "evaluate": ("splits", "workers")}
"""The sections the new project's stages read, and the keys its params.yaml spells out: the
ones a first run edits. Every other key takes the code's default, so that `dvc exp show` has a
column for these (DVC shows every key of params.yaml) and not for 60 more; `dvc exp run -S
++section.key=value` adds one (docs/usage.md, "DVC experiments on a project")."""
PATH_OPTIONS = ("poses", "times", "extrinsic")
"""Options of a recording that are paths (relative: to the list file that gives them)."""


@dataclass(frozen=True)
class Recording:
    """A recording to start a project from: ``path`` and its ``options`` (``data`` source
    keys: split, kind, topic, gt_topic, poses, ...)."""

    path: Path
    options: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Project:
    """What ``init_project`` wrote: the files, and every source by split."""

    params: Path
    dvc_yaml: Path
    sources: list[dict[str, Any]]
    evaluate_splits: list[str]

    def recordings(self) -> list[dict[str, Any]]:
        """One source a recording (a KITTI source: one a sequence, its path
        ``ROOT/sequences/NN``), in order."""
        out = []
        for s in self.sources:
            if s["kind"] != "kitti":
                out.append(s)
                continue
            out += [{**s, "path": f"{s['path']}/sequences/{seq}", "sequences": [seq],
                     "poses": f"{s['path']}/poses/{seq}.txt"} for seq in s["sequences"]]
        return out

    def splits(self) -> dict[str, list[str]]:
        """Split -> the paths of its recordings (``recordings``)."""
        out: dict[str, list[str]] = {}
        for s in self.recordings():
            out.setdefault(s["split"], []).append(s["path"])
        return out


def read_recording_list(path: str | Path) -> list[Recording]:
    """Recordings from a text file: ``PATH [key=value ...]`` a line (shell quoting), ``#``
    comments; relative paths (the recording's, poses, times, an extrinsic file) are relative
    to the list file's folder."""
    from pipeline.sources.poses import is_numbers, resolve_path

    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read the recording list ({exc.strerror})") from None
    base = path.parent.resolve()
    out = []
    for k, line in enumerate(text.splitlines(), 1):
        words = shlex.split(line, comments=True)
        if not words:
            continue
        options: dict[str, Any] = {}
        for word in words[1:]:
            key, sep, value = word.partition("=")
            if not sep or not key:
                raise ConfigError(f"{path} line {k}: options are key=value, got {word!r}")
            keep = key == "extrinsic" and is_numbers(value)
            options[key] = value if key not in PATH_OPTIONS or keep else resolve_path(value, base)
        out.append(Recording(Path(resolve_path(words[0], base) or words[0]), options))
    if not out:
        raise ConfigError(f"{path}: no recordings listed")
    return out


def init_project(directory: str | Path, recordings: Sequence[Recording],
                 validation: Sequence[str | Path] = (), test: Sequence[str | Path] = (),
                 force: bool = False, length_m: float | None = None) -> Project:
    """Write ``directory``/params.yaml and dvc.yaml for ``recordings`` (module docstring).

    ``validation`` / ``test``: paths of recordings for those splits (a KITTI root's: its
    sequence folders). ``length_m``: base.length_m (None: the code's default). ConfigError
    when a file exists (unless ``force``), when a recording is ambiguous or has no ground
    truth, or when a split names a path that is not a recording; InputError naming a
    recording whose ground truth runs no longer than ``length_m``."""
    from pipeline.sources.detect import recording_entry, recordings_of

    directory = Path(directory).resolve()
    params_path, dvc_path = directory / "params.yaml", directory / "dvc.yaml"
    existing = [p for p in (params_path, dvc_path) if p.exists()]
    if existing and not force:
        raise ConfigError(f"{existing[0]}: exists; give --force to overwrite it")
    if not recordings:
        raise ConfigError("no recordings: give at least one (--recording PATH or --list FILE)")
    recordings = [Recording(path, rec.options) for rec in recordings
                  for path in recordings_of(rec.path.resolve())]
    length = float(section_defaults("base")["length_m"]) if length_m is None else length_m
    splits = assign_splits(recordings, validation, test)
    sources: list[dict[str, Any]] = []
    for rec, split in zip(recordings, splits, strict=True):
        entry = _relative(recording_entry(rec.path, {**rec.options, "split": split}, length),
                          directory)
        if sources and _same_kitti_root(sources[-1], entry):
            sources[-1]["sequences"] = [*sources[-1]["sequences"], *entry["sequences"]]
        else:
            sources.append(entry)
    evaluate_splits: list[str] = [s for s in ("validation", "test") if s in splits] or ["train"]
    params = project_params(sources, evaluate_splits, length)
    deps = list(dict.fromkeys(d for s in sources for d in _deps(s)))
    stages, plots = project_stages(deps)
    directory.mkdir(parents=True, exist_ok=True)
    _write(params_path, PARAMS_HEADER, params)
    _write(dvc_path, DVC_HEADER, {"stages": stages, "plots": plots})
    ignore_outputs(directory, stages)
    return Project(params_path, dvc_path, sources, evaluate_splits)


def cached_outputs(stages: Mapping[str, Any]) -> list[str]:
    """The outputs of ``stages`` that DVC caches (and git must not track): every ``outs`` entry
    but those with ``cache: false`` (metrics, records, plot data: committed to git)."""
    out = []
    for stage in stages.values():
        for item in stage.get("outs", []):
            path = _path_of(item)
            options = item[path] if isinstance(item, Mapping) else None
            if not (isinstance(options, Mapping) and options.get("cache") is False):
                out.append(path)
    return out


def ignore_outputs(directory: Path, stages: Mapping[str, Any]) -> list[Path]:
    """Write the ``.gitignore`` entries DVC writes for the cached outputs when their stage runs
    (``/name`` in the ``.gitignore`` of the output's folder), before any stage runs: a first
    ``dvc repro`` that fails leaves no output for ``git add -A`` to commit. Entries already
    there are kept; returns the files written."""
    from pipeline.io_utils import atomic_write_text

    wanted: dict[Path, list[str]] = {}
    for out in cached_outputs(stages):
        path = Path(out)
        wanted.setdefault(directory / path.parent / ".gitignore", []).append(f"/{path.name}")
    written = []
    for gitignore, entries in wanted.items():
        text = gitignore.read_text(encoding="utf-8") if gitignore.is_file() else ""
        missing = [e for e in dict.fromkeys(entries) if e not in text.splitlines()]
        if missing:
            body = text if not text or text.endswith("\n") else text + "\n"
            gitignore.parent.mkdir(parents=True, exist_ok=True)
            atomic_write_text(gitignore, body + "".join(f"{e}\n" for e in missing))
            written.append(gitignore)
    return written


def assign_splits(recordings: Sequence[Recording], validation: Sequence[str | Path],
                  test: Sequence[str | Path]) -> list[str]:
    """The split of every recording (module docstring)."""
    named = {Path(p).resolve(): "validation" for p in validation}
    named |= {Path(p).resolve(): "test" for p in test}
    paths = [r.path.resolve() for r in recordings]
    unknown = [p for p in named if p not in paths]
    if unknown:
        raise ConfigError(f"{unknown[0]}: named for the {named[unknown[0]]} split but not a "
                          "recording (give it with --recording too)")
    splits = [str(r.options.get("split") or named.get(p, "train"))
              for r, p in zip(recordings, paths, strict=True)]
    if "validation" not in splits and len(recordings) > 1 and not named and not any(
            "split" in r.options for r in recordings):
        splits[-1] = "validation"
    return splits


def _same_kitti_root(a: Mapping[str, Any], b: Mapping[str, Any]) -> bool:
    """Whether the KITTI sources ``a`` and ``b`` differ in their sequences only."""
    return a["kind"] == b["kind"] == "kitti" and all(
        a.get(k) == b.get(k) for k in {*a, *b} - {"sequences"})


def project_params(sources: list[dict[str, Any]], evaluate_splits: list[str],
                   length_m: float | None = None) -> dict[str, Any]:
    """The new project's params: the keys of PARAMS_KEYS at their defaults (base.length_m
    ``length_m`` when given), the data and where it goes, checked against every section's
    rules."""
    params = {name: {k: v for k, v in section_defaults(name).items() if k in keys}
              for name, keys in PARAMS_KEYS.items()}
    params["base"]["sequences"] = SEQUENCE_FOLDERS["ingest"]
    if length_m is not None:
        params["base"]["length_m"] = length_m
    params["data"] = {"sources": sources}
    params["evaluate"]["splits"] = evaluate_splits
    check_params(params, "the new params.yaml")
    return params


def project_stages(recordings: list[str]) -> tuple[dict[str, Any], list[Any]]:
    """(stages, plots) of the new dvc.yaml: DVC_YAML's without LEFT_OUT and the code deps,
    the ingest stage depending on ``recordings`` (paths as dvc.yaml gives them)."""
    try:
        ours = yaml.safe_load(DVC_YAML.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ConfigError(f"{DVC_YAML}: not found: adaptune init copies the stages of "
                          "adaptune's dvc.yaml, so it runs from a clone of the repository "
                          "(make setup installs it there)") from None
    stages = {}
    left_out: set[str] = set()
    for name, stage in ours["stages"].items():
        if name in LEFT_OUT:
            left_out |= {_path_of(o) for o in stage.get("outs", []) + stage.get("metrics", [])}
            continue
        deps = [d for d in stage.get("deps", []) if str(d).split("/")[0] not in CODE_PACKAGES]
        if name == "ingest":
            deps = recordings
        stages[name] = {**stage, "deps": deps} if deps else {
            k: v for k, v in stage.items() if k != "deps"}
    plots = [p for p in ours.get("plots", []) if not _plot_files(p) & left_out]
    return stages, plots


def _path_of(out: Any) -> str:
    return next(iter(out)) if isinstance(out, Mapping) else str(out)


def _plot_files(plot: Any) -> set[str]:
    """The files a dvc.yaml plot entry draws (its key, or the keys of its ``y``)."""
    if not isinstance(plot, Mapping):
        return {str(plot)}
    key, body = next(iter(plot.items()))
    y = body.get("y") if isinstance(body, Mapping) else None
    return set(y) if isinstance(y, Mapping) else {key}


def _relative(entry: dict[str, Any], directory: Path) -> dict[str, Any]:
    """``entry`` with the paths inside ``directory`` relative to it (as params.yaml reads)."""
    from pipeline.sources.poses import is_numbers

    out = dict(entry)
    for key in ("path", *PATH_OPTIONS):
        value = out.get(key)
        if value is None or (key == "extrinsic" and is_numbers(value)):
            continue
        path = Path(value)
        if path.is_relative_to(directory):
            out[key] = path.relative_to(directory).as_posix() or "."
    return out


def _deps(entry: Mapping[str, Any]) -> list[str]:
    """What the ingest stage reads of a source (paths as params.yaml gives them): the
    recording and its pose, times and extrinsic files outside it; of a KITTI root, the
    sequences' folders and its poses folder (one dependency, one `dvc exp show` column, for
    every sequence's ground truth)."""
    from pipeline.sources.poses import is_numbers

    root = str(entry["path"])
    if entry["kind"] == "kitti":
        return [*(f"{root}/sequences/{seq}" for seq in entry["sequences"]), f"{root}/poses"]
    files = [str(entry[k]) for k in PATH_OPTIONS
             if entry.get(k) is not None and not (k == "extrinsic" and is_numbers(entry[k]))]
    return [root, *(f for f in files if not Path(f).is_relative_to(root))]


PARAMS_HEADER = """\
# adaptune params.yaml, written by `adaptune init` from a list of recordings: one section per
# stage (docs/design.md, "Stages") with the keys a first run edits; every other key takes the
# code's default (adaptune's own params.yaml lists them all): add one here or with
# `dvc exp run -S ++section.key=value`. data.sources are your recordings (paths relative to
# this file): edit their options or splits here (docs/usage.md, "Your own data set"). A first
# run: fewer trials.iterations, then `dvc repro`.
"""
DVC_HEADER = """\
# adaptune dvc.yaml, written by `adaptune init`: adaptune's own stages from your recordings
# (params.yaml's data section) to the model artifact (model/) and the evaluation
# (metrics/evaluation.json, report/). Stages depend on their data and params; adaptune's code
# is its installation: after upgrading it, `dvc repro -f`.
"""


def _write(path: Path, header: str, data: Mapping[str, Any]) -> None:
    from pipeline.io_utils import atomic_write_text

    body = "\n".join(yaml.safe_dump({k: v}, sort_keys=False, width=96,
                                    default_flow_style=None if k not in ("data", "stages")
                                    else False)
                     for k, v in data.items())
    atomic_write_text(path, header + body)

"""The index of a sequences folder: ``<folder>/index.json``, split name -> sequence names.

``{"train": ["cave_0", ...], "validation": ["composite_0"]}``: every name is the file stem of
``<folder>/<name>.mcap``. Written by the ``simulate`` and ``ingest`` stages (``write_index``),
read by every later stage through ``read_index`` (docs/design.md, "Formats").
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

from pipeline.errors import InputError

INDEX_NAME = "index.json"


def check_split(source_key: str, source: object, train: list[str],
                validation: list[str]) -> None:
    """ValueError unless the split of a data-set section (``ingest``, ``simulate_kitti``) is
    consistent: ``train`` names sequences when the section's source ``source_key`` is set and
    no split names any when it is not (there would be no file behind the index), every name is
    a plain file name (it becomes ``<name>.mcap`` in the output folder and an index entry), and
    no sequence is in both ``train`` and ``validation``."""
    from pipeline.io_utils import check_plain_name

    if source is not None and not train:
        raise ValueError(f"train must name KITTI sequences when {source_key} is set, got "
                         f"({source_key}={source!r}, train={train})")
    if source is None and (train or validation):
        raise ValueError(f"train and validation name no sequences while {source_key} is not "
                         f"set (no file would be behind the index), got ({source_key}=None, "
                         f"train={train}, validation={validation})")
    for split, names in (("train", train), ("validation", validation)):
        for name in names:
            check_plain_name(name, f"{split} entry", ValueError)
    both = sorted(set(train) & set(validation))
    if both:
        raise ValueError(f"sequence {both[0]!r} is in both train and validation, got "
                         f"(train={train}, validation={validation})")


@dataclass(frozen=True)
class SequenceIndex:
    """The splits of one sequences folder (names in file order, every split a list)."""

    folder: Path
    splits: dict[str, list[str]] = field(default_factory=dict)

    @property
    def path(self) -> Path:
        return self.folder / INDEX_NAME

    def names(self, split: str) -> list[str]:
        """The sequence names of ``split``; InputError when it is missing or empty."""
        names = self.splits.get(split)
        if not names:
            known = ", ".join(sorted(self.splits)) or "none"
            raise InputError(f"{self.path}: no sequences in split {split!r} (splits: {known})")
        return list(names)

    def paths(self, split: str) -> list[Path]:
        """The MCAP paths of ``split``; InputError when one does not exist."""
        paths = [self.folder / f"{name}.mcap" for name in self.names(split)]
        missing = [p for p in paths if not p.is_file()]
        if missing:
            raise InputError(f"{self.path}: split {split!r} lists {missing[0].name}, "
                             "which does not exist")
        return paths

    def split_paths(self, splits: list[str]) -> dict[Path, str]:
        """MCAP path -> split of every sequence of ``splits``, in order; a sequence listed by
        two of them belongs to the first. InputError as ``paths``."""
        out: dict[Path, str] = {}
        for split in splits:
            for path in self.paths(split):
                out.setdefault(path, split)
        return out

    def all_names(self) -> list[str]:
        """Every listed sequence once, in split order."""
        return list(dict.fromkeys(n for names in self.splits.values() for n in names))

    def split_of(self) -> dict[str, str]:
        """Sequence name -> split (the first split that lists it)."""
        out: dict[str, str] = {}
        for split, names in self.splits.items():
            for name in names:
                out.setdefault(name, split)
        return out


def read_index(folder: str | Path, missing_ok: bool = False) -> SequenceIndex:
    """``folder``/index.json, validated as {split: [name, ...]}.

    InputError when it is missing (unless ``missing_ok``: then no splits), not JSON, or not a
    mapping of lists of names.
    """
    folder = Path(folder)
    path = folder / INDEX_NAME
    from pipeline.io_utils import check_plain_name, read_input_text

    if missing_ok and not os.path.lexists(path):
        return SequenceIndex(folder)
    text = read_input_text(path, "sequence index", strict=True,
                           hint=" (written by the simulate or ingest stage)")
    from pipeline.json_yaml import parse_json

    data = parse_json(text, str(path))
    if not isinstance(data, dict) or not all(
        isinstance(names, list) and all(isinstance(n, str) and n for n in names)
        for names in data.values()
    ):
        raise InputError(f"{path}: expected {{split: [sequence name, ...]}}")
    for split, names in data.items():
        for name in names:  # <folder>/<name>.mcap must be in the folder
            check_plain_name(name, f"{path}: split {split!r} entry", InputError)
    return SequenceIndex(folder, {str(k): list(v) for k, v in data.items()})


def write_index(folder: str | Path, splits: dict[str, list[str]]) -> None:
    """Write ``folder``/index.json atomically."""
    from pipeline.io_utils import atomic_write_text

    atomic_write_text(Path(folder) / INDEX_NAME, json.dumps(splits, indent=2) + "\n")

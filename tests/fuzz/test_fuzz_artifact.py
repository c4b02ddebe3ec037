"""Fuzz the model artifact loader: manifest values, arrays and the folder's files changed,
with the checksums re-signed (so only the loader's own checks stand between the change and
the runtime) or not (fuzz_contract: refuse in one line, or load a model that selects
parameters in range)."""

from __future__ import annotations

import hashlib
import json
import math
import os
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from helpers.fuzz_contract import fuzz, holds, mutate, scratch
from hypothesis import given
from hypothesis import strategies as st

from pipeline.artifact import canonical_manifest_hash
from pipeline.runtime import Selector, load_model


@pytest.fixture(scope="module")
def good(tmp_path_factory: pytest.TempPathFactory, kitti_root: Path) -> Path:
    from helpers.models import build_model

    return build_model(tmp_path_factory.mktemp("fuzz_model") / "model", kitti_root, trials=8)


def sign(folder: Path, manifest: dict[str, Any]) -> None:
    """Write ``manifest`` with every listed regular file's sha256 (and shape) and its own hash
    fresh."""
    from test_artifact_loader import declare

    for name in list(manifest.get("files", {})):
        path = folder / name
        if path.is_file() and not path.is_symlink():
            manifest["files"][name] = hashlib.sha256(path.read_bytes()).hexdigest()
            declare(manifest, name, path)
    manifest["manifest_sha256"] = canonical_manifest_hash(manifest)
    (folder / "manifest.json").write_text(json.dumps(manifest))


def leaves(node: Any, prefix: tuple = ()) -> list[tuple]:
    """Paths of every value in a JSON document (dicts and lists walked)."""
    out = [prefix]
    items = node.items() if isinstance(node, dict) else enumerate(node) \
        if isinstance(node, list) else ()
    for key, value in items:
        out += leaves(value, (*prefix, key))
    return out


def set_at(doc: Any, path: tuple, value: Any) -> Any:
    if not path:
        return value
    node = doc
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    return doc


VALUES = st.one_of(
    st.none(), st.booleans(), st.integers(-(2**64), 2**64), st.floats(),
    st.sampled_from([0, -1, 1, 0.0, 1e308, math.nan, math.inf, "", "ndt", "knn", "forest",
                     [], {}, [1.0, 2.0], {"resolution": 1.0}]),
    st.text(max_size=4),
)


@st.composite
def arrays(draw: st.DrawFn, like: np.ndarray) -> np.ndarray:
    """An array shaped and typed like ``like`` mostly: values replaced (NaN, huge, negative),
    another shape, dtype or rank."""
    kind = draw(st.sampled_from(["values", "shape", "dtype", "scalar"]))
    if kind == "scalar":
        return np.array(draw(st.floats()))
    if kind == "dtype":
        return like.astype(draw(st.sampled_from(["<f4", "<i4", "<u1", "<c16", "|b1"])))
    if kind == "shape":
        shape = draw(st.lists(st.integers(0, 5), min_size=1, max_size=3))
        return np.resize(like, shape) if like.size else np.zeros(shape, like.dtype)
    out = like.copy()
    if out.size:
        flat = out.reshape(-1)
        for _ in range(draw(st.integers(1, 3))):
            kind = out.dtype.kind
            bad = [np.nan, np.inf, -1.0, 0.0, 1e30] if kind == "f" else [0, 1] if kind == "b" \
                else [0, 1, int(np.iinfo(out.dtype).max), int(np.iinfo(out.dtype).min)]
            flat[draw(st.integers(0, out.size - 1))] = draw(st.sampled_from(bad))
    return out


@st.composite
def damages(draw: st.DrawFn, good: Path) -> tuple[str, Any]:
    manifest = json.loads((good / "manifest.json").read_text())
    names = sorted(manifest["files"])
    kind = draw(st.sampled_from(["value", "value", "array", "bytes", "file", "manifest_bytes"]))
    if kind == "value":
        path = draw(st.sampled_from([p for p in leaves(manifest) if p and p[0] != "files"]))
        return kind, (path, draw(VALUES))
    if kind == "array":
        name = draw(st.sampled_from(names))
        return kind, (name, draw(arrays(np.load(good / name, allow_pickle=False))))
    if kind == "bytes":
        name = draw(st.sampled_from(names))
        return kind, (name, draw(mutate((good / name).read_bytes())), draw(st.booleans()))
    if kind == "manifest_bytes":
        return kind, draw(mutate((good / "manifest.json").read_bytes()))
    return kind, (draw(st.sampled_from([*names, "manifest.json"])),
                  draw(st.sampled_from(["remove", "dir", "fifo", "symlink", "extra"])))


def apply(folder: Path, damage: tuple[str, Any]) -> None:
    kind, what = damage
    manifest = json.loads((folder / "manifest.json").read_text())
    if kind == "value":
        sign(folder, set_at(manifest, *what))
    elif kind == "array":
        np.save(folder / what[0], what[1], allow_pickle=False)
        sign(folder, manifest)
    elif kind == "bytes":
        (folder / what[0]).write_bytes(what[1])
        if what[2]:
            sign(folder, manifest)
    elif kind == "manifest_bytes":
        (folder / "manifest.json").write_bytes(what)
    else:
        name, how = what
        target = folder / name
        if how == "extra":
            (folder / "extra.npy").write_bytes(b"x")
            return
        outside = folder.parent / f"outside-{name}"
        shutil.copy(target, outside)
        target.unlink()
        if how == "dir":
            target.mkdir()
        elif how == "fifo":
            os.mkfifo(target)
        elif how == "symlink":
            target.symlink_to(outside)


def loaded_and_selects(folder: Path) -> dict[str, float]:
    model = load_model(folder)
    return Selector(model).select_environment(model.env[0])


@fuzz(40)
@given(data=st.data())
def test_artifact_loader(good: Path, tmp_path: Path, data: st.DataObject) -> None:
    damage = data.draw(damages(good))
    with scratch(tmp_path) as d:
        folder = d / "model"
        shutil.copytree(good, folder)
        apply(folder, damage)
        inputs = [p for p in folder.iterdir() if p.is_file() and not p.is_symlink()
                  and not p.is_fifo()] if folder.is_dir() else []
        params = holds(lambda: loaded_and_selects(folder), inputs)
        if params is not None:
            space = {p["name"]: p for p in json.loads(
                (folder / "manifest.json").read_text())["parameter_space"]}
            for name, value in params.items():
                assert math.isfinite(value)
                assert space[name]["low"] <= value <= space[name]["high"], (name, value)

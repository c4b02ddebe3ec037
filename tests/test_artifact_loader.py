"""The artifact loader trusts neither the filesystem nor the numbers (issue 13, item 6).

Every case is a model folder whose checksums all match (the manifest re-signed after the
change), so only the loader's own checks stand between it and the runtime: each must end in
one ArtifactError line naming the file or the field, never a hang, a traceback or a model.
"""

from __future__ import annotations

import io
import json
import os
import shutil
import tokenize
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner
from helpers.models import build_model, write_tiny_sequence

from pipeline.artifact import canonical_manifest_hash
from pipeline.errors import ArtifactError
from pipeline.runtime import load_model
from stages.cli import main


@pytest.fixture(scope="module")
def good(tmp_path_factory: pytest.TempPathFactory, kitti_root: Path) -> Path:
    return build_model(tmp_path_factory.mktemp("good") / "model", kitti_root)


def copy(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst)
    return dst


def sign(folder: Path, change: Callable[[dict[str, Any]], None] | None = None) -> None:
    """Apply ``change`` to the manifest, refresh every file's sha256 and the manifest's own."""
    import hashlib

    manifest = json.loads((folder / "manifest.json").read_text())
    if change is not None:
        change(manifest)
    for name in manifest["files"]:
        path = folder / name
        if path.is_file() and not path.is_symlink():
            manifest["files"][name] = hashlib.sha256(path.read_bytes()).hexdigest()
            declare(manifest, name, path)
    manifest["manifest_sha256"] = canonical_manifest_hash(manifest)
    (folder / "manifest.json").write_text(json.dumps(manifest))


def declare(manifest: dict[str, Any], name: str, path: Path) -> None:
    """Declare in the manifest the shape and dtype the .npy header of ``path`` gives (nothing
    when it has none)."""
    fmt = np.lib.format
    if not isinstance(manifest.get("arrays"), dict):
        return
    with open(path, "rb") as fh:
        try:
            version = fmt.read_magic(fh)
            read = fmt.read_array_header_1_0 if version == (1, 0) else \
                fmt.read_array_header_2_0
            shape, _, dtype = read(fh)
        except (ValueError, SyntaxError, TypeError, tokenize.TokenError):
            return
    manifest["arrays"][name] = {"shape": list(shape), "dtype": dtype.str}


def refused(folder: Path, *words: str) -> str:
    with pytest.raises(ArtifactError) as exc:
        load_model(folder)
    msg = str(exc.value)
    assert "\n" not in msg, msg
    for word in words:
        assert word in msg, msg
    return msg


def test_a_symlink_out_of_the_folder_is_refused(good: Path, tmp_path: Path) -> None:
    outside = tmp_path / "elsewhere.npy"
    shutil.copy(good / "rows_t.npy", outside)  # the same bytes: its sha256 matches
    bad = copy(good, tmp_path / "m")
    (bad / "rows_t.npy").unlink()
    (bad / "rows_t.npy").symlink_to(outside)
    refused(bad, "rows_t.npy", "regular file")


@pytest.mark.timeout(30, method="signal")
def test_a_fifo_is_refused_without_blocking(good: Path, tmp_path: Path) -> None:
    bad = copy(good, tmp_path / "m")
    (bad / "env.npy").unlink()
    os.mkfifo(bad / "env.npy")
    refused(bad, "env.npy", "regular file")


def test_a_huge_npy_shape_is_refused_before_reading(good: Path, tmp_path: Path) -> None:
    bad = copy(good, tmp_path / "m")
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        header, {"descr": "<f8", "fortran_order": False, "shape": (10**12,)})
    (bad / "rows_t.npy").write_bytes(header.getvalue() + np.zeros(8).tobytes())
    sign(bad)
    refused(bad, "rows_t.npy")
    seq = tmp_path / "s.mcap"
    res = CliRunner().invoke(main, ["select", str(bad), str(seq), "--out",
                                    str(tmp_path / "o.parquet")])
    assert res.exit_code == 1 and res.output.count("\n") == 1, res.output


@pytest.mark.parametrize("how", ["header", "size"])
def test_an_array_the_manifest_does_not_declare_is_refused_before_reading(
        good: Path, tmp_path: Path, how: str) -> None:
    """Issue 32, case 4: a 3 GB .npy (here 1 GiB, sparse) was read whole before its sha256
    was checked. The manifest declares every array's shape and dtype; the header and the
    file's size are checked against them first (not re-signed: the checksum would catch it,
    but only after the read)."""
    bad = copy(good, tmp_path / "m")
    n = (1 << 30) // 8
    with open(bad / "rows_t.npy", "wb") as fh:
        header = io.BytesIO()
        shape = (n,) if how == "header" else tuple(json.loads(
            (good / "manifest.json").read_text())["arrays"]["rows_t.npy"]["shape"])
        np.lib.format.write_array_header_1_0(
            header, {"descr": "<f8", "fortran_order": False, "shape": shape})
        fh.write(header.getvalue())
        fh.truncate(len(header.getvalue()) + 8 * n)  # holes: no gigabyte written
    words = ("manifest.json declares",) if how == "header" else ("bytes, its declared shape",)
    refused(bad, "rows_t.npy", *words)


def test_an_artifact_without_array_declarations_is_refused(good: Path, tmp_path: Path) -> None:
    bad = copy(good, tmp_path / "m")
    sign(bad, lambda m: m.pop("arrays"))
    refused(bad, "no array shapes", "rebuild it")


def set_path(manifest: dict[str, Any], dotted: str, value: Any) -> None:
    keys = dotted.split(".")
    node = manifest
    for key in keys[:-1]:
        node = node[int(key)] if isinstance(node, list) else node[key]
    node[keys[-1]] = value


@pytest.mark.parametrize(("field", "value", "words"), [
    ("model.k", 0, ("model.k",)),
    ("model.k", 10**9, ("model.k",)),
    ("parameter_space.0.low", 50.0, ("resolution", "low")),
    ("scaling.parameters.x_scale", float("nan"), ("x_scale",)),
    ("novelty.fallback_params", {"no_such_param": 1.0}, ("no_such_param",)),
    ("novelty.distance", -2.0, ("novelty.distance",)),
    ("novelty.fallback", {"mode": "per_scan", "chosen": "per_scan"},
     ("per_scan", "fallback_params")),
    ("novelty.distance", "far", ("novelty.distance", "finite number")),
    # blocks that are not objects (the fuzz suite's scaling = 1: an AttributeError before)
    ("scaling", 1, ("scaling must be an object", "got 1")),
    ("scaling.environment", [0.5], ("scaling.environment must be an object",)),
    ("scaling.parameters", "x", ("scaling.parameters must be an object",)),
])
def test_bad_manifest_values_are_refused(good: Path, tmp_path: Path, field: str, value: Any,
                                         words: tuple[str, ...]) -> None:
    bad = copy(good, tmp_path / "m")
    sign(bad, lambda m: set_path(m, field, value))
    refused(bad, *words)


@pytest.mark.parametrize(("name", "change", "word"), [
    ("env.npy", lambda a: np.where(np.arange(a.size).reshape(a.shape) == 7, np.nan, a), "finite"),
    ("rows_t.npy", lambda a: a[:, None], "1-D"),
    ("candidates.npy", lambda a: a + 2.0, "[0, 1]"),
    ("pca_scale.npy", lambda a: -a, "pca_scale"),
    ("env_offsets.npy", lambda a: a.astype(np.float64), "env_offsets"),
])
def test_bad_arrays_are_refused(good: Path, tmp_path: Path, name: str,
                                change: Callable[[np.ndarray], np.ndarray], word: str) -> None:
    bad = copy(good, tmp_path / "m")
    np.save(bad / name, change(np.load(good / name)), allow_pickle=False)
    sign(bad)
    refused(bad, name, word)


def test_the_good_model_loads_and_selects(good: Path, tmp_path: Path, kitti_root: Path) -> None:
    model = load_model(good)
    seq = tmp_path / "s.mcap"
    write_tiny_sequence(seq, kitti_root, "04", n=2)
    res = CliRunner().invoke(main, ["select", str(good), str(seq), "--out",
                                    str(tmp_path / "o.parquet")])
    assert res.exit_code == 0, res.output
    assert model.algorithm == "ndt"


@pytest.mark.parametrize("how", ["bytes", "name"])
def test_an_npz_in_place_of_an_npy_is_refused(good: Path, tmp_path: Path, how: str) -> None:
    """A NumPy .npz archive (a zip) under an .npy name, or listed as .npz (issue 13, item 7:
    it was a traceback)."""
    bad = copy(good, tmp_path / "m")
    arr = np.load(good / "env.npy")
    if how == "bytes":
        with open(bad / "env.npy", "wb") as fh:
            np.savez(fh, env=arr)
        sign(bad)
        refused(bad, "env.npy", "not a plain numpy array")
    else:
        np.savez(bad / "env.npz", env=arr)
        (bad / "env.npy").unlink()

        def rename(m: dict[str, Any]) -> None:
            m["files"]["env.npz"] = m["files"].pop("env.npy")

        sign(bad, rename)
        refused(bad, "does not list env.npy")

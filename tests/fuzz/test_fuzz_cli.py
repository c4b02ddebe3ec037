"""Fuzz the command line end to end: ``adaptune ingest kitti`` on a small KITTI layout with
one of its files damaged (fuzz_contract, the CLI's form: exit 1 with one ``adaptune: error:``
line and no output file, or exit 0 with a sequence that reads back; inputs unchanged, no
temporary file left)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from click.testing import CliRunner
from helpers.fuzz_contract import NUMBER_TOKENS, digest, fuzz, mutate, no_hang, scratch
from hypothesis import given
from hypothesis import strategies as st
from test_fuzz_mcap import read_all

from stages.cli import main

FILES = ("velodyne/000000.bin", "velodyne/000001.bin", "times.txt", "calib.txt", "poses")


def kitti_layout(root: Path) -> dict[str, Path]:
    """ROOT/sequences/00 with 2 scans of 40 points, times, calib (Tr) and poses/00.txt."""
    seq = root / "sequences" / "00"
    (seq / "velodyne").mkdir(parents=True)
    (root / "poses").mkdir()
    rng = np.random.default_rng(0)
    paths = {name: seq / name for name in FILES[:4]}
    paths["poses"] = root / "poses" / "00.txt"
    for k in range(2):
        (rng.uniform(-20, 20, (40, 4)).astype("<f4")).tofile(paths[f"velodyne/00000{k}.bin"])
    paths["times.txt"].write_text("0.0\n0.1\n")
    paths["calib.txt"].write_text("P0: 1 0 0 0 0 1 0 0 0 0 1 0\nTr: 0 -1 0 0 0 0 -1 0 1 0 0 0\n")
    paths["poses"].write_text("1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1 0.5\n")
    return paths


@st.composite
def damages(draw: st.DrawFn) -> tuple[str, str, bytes | str]:
    """(file, how, what): bytes of a file mutated, a token of a text file replaced, a file
    removed or a folder in its place."""
    name = draw(st.sampled_from(FILES))
    how = draw(st.sampled_from(["bytes", "bytes", "token", "remove", "folder"]))
    if how == "token":
        return name, how, draw(NUMBER_TOKENS)
    return name, how, draw(st.integers(0, 2**32))


@fuzz(30)
@given(damage=damages(), data=st.data())
def test_ingest_kitti_cli(tmp_path: Path, damage: tuple[str, str, bytes | str],
                          data: st.DataObject) -> None:
    name, how, value = damage
    with scratch(tmp_path) as d:
        paths = kitti_layout(d / "kitti")
        target = paths[name]
        if how == "bytes":
            target.write_bytes(data.draw(mutate(target.read_bytes())))
        elif how == "token":
            tokens = target.read_bytes().decode("latin-1").split(" ")
            tokens[data.draw(st.integers(0, len(tokens) - 1))] = str(value)
            target.write_bytes(" ".join(tokens).encode("latin-1", "replace"))
        elif how == "remove":
            target.unlink()
        else:
            target.unlink()
            target.mkdir()
        out = d / "out" / "seq.mcap"
        before = digest([d / "kitti"])
        with no_hang():
            result = CliRunner().invoke(main, ["ingest", "kitti", str(d / "kitti"), "00",
                                               "--out", str(out)])
        assert digest([d / "kitti"]) == before, "an input file changed"
        assert result.exit_code in (0, 1), (result.exit_code, result.output, result.exception)
        assert "Traceback" not in result.output
        leftovers = [p for p in out.parent.iterdir() if p != out] if out.parent.exists() else []
        assert not leftovers, leftovers
        if result.exit_code == 1:
            lines = result.stderr.strip().splitlines()
            assert len(lines) == 1 and lines[0].startswith("adaptune: error: "), result.stderr
            assert not out.exists()
        else:
            scans, gt = read_all(out)
            no_poses = name == "poses" and how in ("remove", "folder")  # optional: none
            assert len(scans) == 2 and (gt is None) == no_poses

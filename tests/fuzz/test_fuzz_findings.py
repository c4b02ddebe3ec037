"""The defects the fuzz suite found, one test each (each failed before its fix)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner
from test_fuzz_mcap import POSE, pose_cdr, write_mcap

from pipeline.config import load_section
from pipeline.errors import ConfigError, InputError
from pipeline.odometry.base import Schedule
from pipeline.sequence import (
    GT_TOPIC,
    META_FRAMES,
    META_SEQUENCE,
    POINTS_TOPIC,
    SequenceInfo,
    SequenceReader,
)
from pipeline.sources.poses import read_extrinsic
from pipeline.sources.scanfiles import read_pcd
from pipeline.surrogates.section import SurrogateSection
from stages.cli import main


def one_line(exc: pytest.ExceptionInfo) -> str:
    text = str(exc.value)
    assert text and "\n" not in text, text
    return text


def test_an_extrinsic_with_a_line_break_is_refused_in_one_line() -> None:
    with pytest.raises(InputError) as exc:
        read_extrinsic("0\nnan")
    assert "--extrinsic" in one_line(exc)


def test_a_nan_quaternion_of_a_ground_truth_pose_is_an_input_error(tmp_path: Path) -> None:
    from test_fuzz_mcap import CLOUD, cloud_cdr

    layout = {"fields": [("x", 0, 7, 1), ("y", 4, 7, 1), ("z", 8, 7, 1), ("intensity", 12, 7, 1)],
              "height": 1, "width": 1, "point_step": 16, "row_step": 16, "big": False,
              "data": np.ones(4, "<f4").tobytes()}
    for q, word in (([0.0, 0.0, 0.0, np.nan], "quaternion"), ([0.0, 0.0, 0.0, 1.0], None)):
        path = tmp_path / "seq.mcap"
        translation = [1.0, np.inf, 3.0] if word is None else [1.0, 2.0, 3.0]
        write_mcap(path, {META_SEQUENCE: SequenceInfo("s", frame_count=1).to_record(),
                          META_FRAMES: {"stamps_ns": "0"}},
                   [(POINTS_TOPIC, CLOUD, 0, cloud_cdr(0, layout)),
                    (GT_TOPIC, POSE, 0, pose_cdr(0, translation, q))])
        with SequenceReader(path) as r, pytest.raises(InputError) as exc:
            r.ground_truth()
        assert (word or "translation") in one_line(exc)


def test_a_yaml_error_is_one_line(tmp_path: Path) -> None:
    path = tmp_path / "params.yaml"
    path.write_text("\x1f")
    with pytest.raises(ConfigError) as exc:
        load_section(path, "surrogate", SurrogateSection)
    assert "not valid YAML" in one_line(exc)


def test_a_params_file_that_is_not_utf8_is_a_config_error(tmp_path: Path) -> None:
    path = tmp_path / "params.yaml"
    path.write_bytes(b"surrogate:\n  k: \xff\n")
    res = CliRunner().invoke(main, ["params", "ndt", "--params", str(path)])
    assert res.exit_code == 1 and "not UTF-8" in res.stderr, res.output
    assert res.stderr.count("\n") == 1


@pytest.mark.parametrize("value", [".inf", ".nan", "-.inf"])
def test_infinite_or_nan_params_are_refused(tmp_path: Path, value: str) -> None:
    path = tmp_path / "params.yaml"
    path.write_text(f"surrogate:\n  w_e: {value}\n")
    with pytest.raises(ConfigError) as exc:
        load_section(path, "surrogate", SurrogateSection)
    assert "surrogate.w_e" in one_line(exc)


def test_a_damaged_schedule_is_refused_in_one_line(tmp_path: Path) -> None:
    path = tmp_path / "schedule.parquet"
    pq.write_table(pa.table({"frame": pa.array([0], pa.int32()), "x": [1.0]}), path)
    data = bytearray(path.read_bytes())
    data[8:12] = b"\x15\x14L\x15"  # a page header thrift cannot read (a multi-line message)
    data[4:8] = bytes(4)
    path.write_bytes(bytes(data))
    with pytest.raises(InputError) as exc:
        Schedule.read(path)
    assert "not a readable schedule" in one_line(exc)


def test_an_empty_ascii_pcd_reads_without_a_warning(tmp_path: Path) -> None:
    path = tmp_path / "empty.pcd"
    path.write_text("VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 0\n"
                    "HEIGHT 1\nPOINTS 0\nDATA ascii\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert read_pcd(path).points.shape == (0, 4)


def test_an_npy_header_numpy_cannot_tokenize_is_an_artifact_error() -> None:
    from pipeline.errors import ArtifactError
    from pipeline.npy_files import parse_npy

    header = b"{'descr': '<f8', 'fortran_order': False, 'shape': (2,\x00 }"
    data = b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header + bytes(16)
    with pytest.raises(ArtifactError) as exc:
        parse_npy(data, "x.npy")
    assert "not a plain numpy array" in one_line(exc)


def test_the_fuzz_signer_skips_an_npy_header_numpy_cannot_tokenize(tmp_path: Path) -> None:
    """The artifact fuzz target re-signs a damaged model (tests/test_artifact_loader.py's
    ``declare``); a header whose first brace a mutation replaced made numpy's tokenizer raise
    TokenError there, in the test, before the loader ran (make fuzz, 2026-11-27)."""
    from test_artifact_loader import declare

    header = b"z'descr': '<f8', 'fortran_order': False, 'shape': (2,), }  \n"
    path = tmp_path / "x.npy"
    path.write_bytes(b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header
                     + bytes(16))
    manifest = {"arrays": {"x.npy": {"shape": [2], "dtype": "<f8"}}}
    declare(manifest, "x.npy", path)
    assert manifest["arrays"]["x.npy"] == {"shape": [2], "dtype": "<f8"}


def test_a_huge_extrinsic_is_refused_without_a_warning() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(InputError):
            read_extrinsic(" ".join(["1e300"] * 12))

"""The contract every registered descriptor keeps (pipeline/descriptors/__init__.py), run over
the registry, and the width of a descriptor carried through the stages and schemas."""

from __future__ import annotations

import json
from pathlib import Path

import duckdb
import numpy as np
import pytest
from click.testing import CliRunner
from helpers.models import kitti_scan, write_tiny_sequence

from pipeline.config import validate_section
from pipeline.database.store import apply_sql, load_frame_table
from pipeline.descriptors import DESCRIPTORS, Descriptor, descriptor_from_json, make_descriptor
from pipeline.descriptors.dataset import DescriptorsSection
from pipeline.errors import ConfigError
from pipeline.surrogates.writer import artifact_schema
from schemas.arrow import descriptors_schema
from stages.cli import main

NAMES = list(DESCRIPTORS)


@pytest.fixture(params=NAMES)
def descriptor(request: pytest.FixtureRequest) -> Descriptor:
    return make_descriptor(request.param)


def test_registry_and_manifest_schema_agree() -> None:
    schema = artifact_schema()  # the descriptor types come from the registry
    assert schema["properties"]["descriptor"]["properties"]["type"]["enum"] == NAMES
    assert DescriptorsSection().type == NAMES[0]


def test_a_scan_gives_size_non_negative_values(descriptor: Descriptor, kitti_root: Path) -> None:
    assert isinstance(descriptor, Descriptor) and descriptor.size >= 1
    scan = kitti_scan(kitti_root, "04", 2)
    d = descriptor.describe(scan)
    assert d.shape == (descriptor.size,) and d.dtype == np.float32
    assert np.isfinite(d).all() and (d >= 0).all() and d.any()
    np.testing.assert_array_equal(descriptor.describe(scan), d)  # deterministic
    np.testing.assert_array_equal(descriptor.describe(scan[:, :3].copy()), d)  # 4th column
    empty = descriptor.describe(np.zeros((0, 3), np.float32))
    assert empty.shape == (descriptor.size,) and (empty >= 0).all()


def test_json_round_trip_carries_type_and_width(descriptor: Descriptor) -> None:
    record = json.loads(json.dumps(descriptor.to_json()))
    assert record["type"] == descriptor.type and record["size"] == descriptor.size
    assert descriptor_from_json(record) == descriptor
    names = descriptor.value_names()
    assert len(names) == descriptor.size == len(set(names))
    with pytest.raises(ConfigError, match="does not match"):
        descriptor_from_json({**record, "size": descriptor.size + 1})
    with pytest.raises(ConfigError, match="unknown descriptor type"):
        make_descriptor("no_such_descriptor")


def test_the_section_checks_settings_and_width() -> None:
    ok = validate_section(DescriptorsSection, "descriptors", {"range_bins": 2, "pca_dim": 18})
    assert ok.descriptor().size == 18
    for data, words in (({"voxle_size_m": 1.0}, "voxle_size_m"),
                        ({"range_bins": 2, "pca_dim": 19}, "pca_dim must be <= "),
                        ({"range_bins": 2.5}, "range_bins must be an integer"),
                        ({"normalize": "yes"}, "normalize must be true or false")):
        with pytest.raises(ConfigError, match=words) as exc:
            validate_section(DescriptorsSection, "descriptors", data)
        assert "\n" not in str(exc.value)


@pytest.mark.parametrize("range_bins", [1, 4, 10])
def test_the_width_reaches_the_parquet_and_the_database(range_bins: int, tmp_path: Path,
                                                        kitti_root: Path) -> None:
    seq_dir = tmp_path / "sequences"
    seq_dir.mkdir()
    for s in ("04", "06"):
        write_tiny_sequence(seq_dir / f"k{s}.mcap", kitti_root, s, n=3)
    (seq_dir / "index.json").write_text(json.dumps({"train": ["k04", "k06"]}))
    params = tmp_path / "params.yaml"
    params.write_text(f"descriptors:\n  range_bins: {range_bins}\n  pca_dim: 3\n  workers: 1\n")
    out, env = tmp_path / "d.parquet", tmp_path / "e.parquet"
    res = CliRunner().invoke(main, ["descriptors", "--params", str(params), "--sequences",
                                    str(seq_dir), "--out", str(out), "--environment", str(env),
                                    "--pca", str(tmp_path / "pca")])
    assert res.exit_code == 0, res.output
    width = 9 * range_bins
    import pyarrow.parquet as pq

    table = pq.read_table(out)
    assert table.schema.names == descriptors_schema(width).names
    recorded = json.loads(table.schema.metadata[b"adaptune.descriptor"])
    assert recorded["size"] == width and recorded["range_bins"] == range_bins
    con = duckdb.connect()
    apply_sql(con, "tables.sql")
    load_frame_table(con, "descriptors", out)
    load_frame_table(con, "environment", env)
    cols = [r[0] for r in con.execute("DESCRIBE descriptors").fetchall()]
    assert cols[3:] == [f"d{i}" for i in range(width)]
    assert con.execute("SELECT count(*) FROM environment").fetchone()[0] == 6

"""Fuzz the parameter inputs: params.yaml (every section's model), ``--params`` JSON and
parameter schedules (Parquet) (fuzz_contract: refuse in one line or give valid output)."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from helpers.fuzz_contract import RARELY, fuzz, holds, mutate, scratch
from hypothesis import given
from hypothesis import strategies as st

from pipeline.config import BaseSection, Section, load_section
from pipeline.descriptors.dataset import DescriptorsSection
from pipeline.evaluate.section import EvaluateSection
from pipeline.metrics.section import DevkitSection
from pipeline.odometry import get_adapter
from pipeline.odometry.base import Schedule
from pipeline.sim.dataset import SimulateSection
from pipeline.sources.dataset import DataSection
from pipeline.surrogates.section import SurrogateSection
from pipeline.tuning.section import FixedSection, TrialsSection
from stages.run import parse_params

SECTIONS: dict[str, type[Section]] = {
    "base": BaseSection, "simulate": SimulateSection, "data": DataSection,
    "descriptors": DescriptorsSection, "trials": TrialsSection, "fixed": FixedSection,
    "devkit": DevkitSection, "surrogate": SurrogateSection, "evaluate": EvaluateSection,
}
DEFAULTS = yaml.safe_load((Path(__file__).parents[2] / "params.yaml").read_text())

SCALARS = st.one_of(
    st.none(), st.booleans(), st.integers(-(2**65), 2**65), st.floats(),
    st.sampled_from([math.inf, -math.inf, math.nan, 0, -1, 0.5, 1e9]),
    st.sampled_from(["", "ndt", "auto", "train", "1.0", "nan", "data/recordings", "hdl32"]),
    st.text(max_size=5),
)
VALUES = st.recursive(SCALARS, lambda inner: st.lists(inner, max_size=3)
                      | st.dictionaries(st.text(max_size=4) | st.sampled_from(
                          ["low", "high", "default", "log", "cave"]), inner, max_size=3),
                      max_leaves=6)


@st.composite
def params_files(draw: st.DrawFn) -> str:
    """params.yaml text: the repository's file with a few values replaced, keys added or
    sections dropped; sometimes text that is not a mapping at all."""
    if draw(RARELY):
        return draw(st.text(max_size=40) | st.sampled_from(["[1, 2]", "a: [", "- x", "null"]))
    params = json.loads(json.dumps(DEFAULTS))
    for _ in range(draw(st.integers(1, 4))):
        section = draw(st.sampled_from(sorted(params)))
        body = params[section]
        if not isinstance(body, dict) or draw(RARELY):
            params[section] = draw(VALUES)
            continue
        key = draw(st.sampled_from([*sorted(body), "extra_key"]))
        body[key] = draw(VALUES)
    return yaml.safe_dump(params, allow_unicode=True)


def finite_numbers(value: Any) -> bool:
    """No NaN or infinity anywhere in a loaded section."""
    if isinstance(value, float):
        return math.isfinite(value)
    if isinstance(value, dict):
        return all(finite_numbers(v) for v in value.values())
    if isinstance(value, list | tuple):
        return all(finite_numbers(v) for v in value)
    return True


@fuzz(120)
@given(text=params_files(), data=st.data())
def test_params_file(tmp_path: Path, text: str, data: st.DataObject) -> None:
    with scratch(tmp_path) as d:
        path = d / "params.yaml"
        raw = text.encode("utf-8", "surrogatepass")
        path.write_bytes(data.draw(mutate(raw)) if data.draw(RARELY) else raw)
        for name, model in SECTIONS.items():
            section = holds(lambda n=name, m=model: load_section(path, n, m), [path])
            if section is not None:
                assert isinstance(section, model)
                assert finite_numbers(section.model_dump()), (name, section)


JSON = st.recursive(st.none() | st.booleans() | st.integers(-(2**70), 2**70) | st.floats()
                    | st.text(max_size=4), lambda inner: st.lists(inner, max_size=2)
                    | st.dictionaries(st.text(max_size=3), inner, max_size=2), max_leaves=4)


@st.composite
def params_json(draw: st.DrawFn) -> str:
    """``--params`` text: an object of ndt's parameter names (or others) to any JSON value;
    sometimes another JSON value, or not JSON."""
    space = get_adapter("ndt").space
    names = st.sampled_from(space.names)
    numbers = st.floats() | st.integers(-(2**70), 2**70) | st.sampled_from(
        [s.default for s in space.specs] + [s.high for s in space.specs])
    obj = draw(st.dictionaries(names | st.text(max_size=4) if draw(RARELY) else names,
                               numbers | JSON if draw(RARELY) else numbers, max_size=3))
    text = json.dumps(draw(JSON)) if draw(RARELY) else json.dumps(obj)
    if draw(RARELY):
        return draw(st.just(text[: len(text) // 2]) | st.text(max_size=8))
    return text


@fuzz(150)
@given(text=params_json())
def test_params_json(text: str) -> None:
    space = get_adapter("ndt").space
    params = holds(lambda: space.validate(parse_params(text)))
    if params is not None:
        assert set(params) == set(space.names)
        for name, value in params.items():
            assert math.isfinite(value) and space[name].low <= value <= space[name].high


COLUMN_TYPES = st.sampled_from(["int32", "int64", "float64", "float32", "string", "bool",
                                "null"])


@st.composite
def schedules(draw: st.DrawFn) -> Any:
    """A Parquet table: ndt's schedule columns mostly, columns dropped or renamed, other
    types, missing values, NaN; with or without adaptune's schema version."""
    import pyarrow as pa

    n = draw(st.integers(0, 4))
    space = get_adapter("ndt").space
    names = ["frame", "stamp_ns", *space.names]
    if draw(st.booleans()):
        names = [draw(st.just(c) | st.sampled_from(["frame", "x", ""])) for c in names]
    names = list(dict.fromkeys(names))
    cols = []
    for name in names:
        kind = "int32" if name == "frame" else "int64" if name == "stamp_ns" else "float64"
        kind = draw(st.just(kind) | COLUMN_TYPES) if draw(st.booleans()) else kind
        if kind == "null":
            cols.append(pa.nulls(n))
            continue
        if kind == "string":
            cols.append(pa.array(draw(st.lists(st.text(max_size=3), min_size=n, max_size=n))))
            continue
        default = space[name].default if name in space.names else 0.0
        values = draw(st.lists(st.just(default) | st.floats(-1e3, 1e3) | st.floats(),
                               min_size=n, max_size=n))
        if name == "frame" and draw(st.integers(0, 3)):
            values = list(range(n))
        arr = np.array(values)
        if kind.startswith(("int", "bool")):
            arr = np.clip(np.nan_to_num(arr), -(2**31), 2**31 - 1).astype(kind)
        mask = np.array(draw(st.lists(st.booleans(), min_size=n, max_size=n)), bool) \
            if draw(RARELY) else None
        with np.errstate(over="ignore"):  # a float beyond float32 becomes inf: hostile too
            cols.append(pa.array(arr.astype(kind), mask=mask))
    table = pa.table(dict(zip(names, cols, strict=True)))
    if not draw(RARELY):
        table = table.replace_schema_metadata({b"adaptune.schema_version": b"1.0"})
    return table


@fuzz(80)
@given(table=schedules(), damage=st.data())
def test_schedule(tmp_path: Path, table: Any, damage: st.DataObject) -> None:
    import pyarrow.parquet as pq

    space = get_adapter("ndt").space
    with scratch(tmp_path) as d:
        path = d / "schedule.parquet"
        pq.write_table(table, path)
        if damage.draw(RARELY):
            path.write_bytes(damage.draw(mutate(path.read_bytes())))

        def read() -> Schedule:
            schedule = Schedule.read(path)
            schedule.validate(space, table.num_rows)
            return schedule

        schedule = holds(read, [path])
        if schedule is not None:
            assert len(schedule) == table.num_rows and set(schedule.values) == set(space.names)
            for name, values in schedule.values.items():
                assert np.isfinite(values).all() and values.shape == (len(schedule),)
                assert (values >= space[name].low).all() and (values <= space[name].high).all()


NAME_CHARS = st.sampled_from([*"ab0_-. /\\\x00\n~", "..", "é"])


@fuzz(200)
@given(name=st.lists(NAME_CHARS, max_size=6).map("".join) | st.text(max_size=8))
def test_names_that_pass_the_path_guard_stay_in_their_folder(tmp_path: Path, name: str) -> None:
    """Issue 32, case 3 (the path guard, pipeline.io_utils.check_plain_name): a name it
    accepts is one file right inside the output folder, as ``<name>.mcap`` and as a folder
    ``<name>`` (the trials layout's sequence=<name>); any other is one ConfigError line."""
    from pipeline.io_utils import check_plain_name

    if holds(lambda: check_plain_name(name, "name")) is None:
        return
    folder = tmp_path / "out"
    for leaf in (f"{name}.mcap", name):
        path = folder / leaf
        assert path.parent == folder and path.name == leaf, (name, path)
        assert os.path.normpath(path) == str(path), (name, path)

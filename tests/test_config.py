"""params.yaml sections: typed, validated, errors name the value and the rule."""

from __future__ import annotations

from pathlib import Path

import pytest
from pydantic import Field, model_validator

from pipeline.config import BaseSection, Section, load_section, read_params
from pipeline.errors import ConfigError

REPO = Path(__file__).resolve().parents[1]


class RangeSection(Section):
    min_range: float = Field(0.0, ge=0)
    max_range: float = 100.0

    @model_validator(mode="after")
    def _order(self) -> RangeSection:
        if self.max_range <= self.min_range:
            raise ValueError(f"max_range must be > min_range, got (min_range={self.min_range}, "
                             f"max_range={self.max_range})")
        return self


def test_rule_error_names_values(tmp_path: Path) -> None:
    p = tmp_path / "params.yaml"
    p.write_text("r:\n  min_range: 5.0\n  max_range: 2.0\n")
    with pytest.raises(
        ConfigError,
        match=r"max_range must be > min_range, got \(min_range=5.0, max_range=2.0\)",
    ):
        load_section(p, "r", RangeSection)


def test_unknown_key_and_type_error(tmp_path: Path) -> None:
    p = tmp_path / "params.yaml"
    p.write_text("r:\n  min_rnage: 5.0\n")
    with pytest.raises(ConfigError, match=r"r.min_rnage: unknown parameter"):
        load_section(p, "r", RangeSection)
    p.write_text("r:\n  min_range: -1\n")
    with pytest.raises(ConfigError, match=r"r.min_range: .*greater than or equal to 0.*-1"):
        load_section(p, "r", RangeSection)


def test_missing_file_and_bad_yaml(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="no such params file"):
        read_params(tmp_path / "nope.yaml")
    (tmp_path / "bad.yaml").write_text("a: [1, 2\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        read_params(tmp_path / "bad.yaml")


def test_repository_params_file_has_base_section() -> None:
    base = load_section(REPO / "params.yaml", "base", BaseSection)
    assert isinstance(base.seed, int)


def test_length_is_set_once_in_base(tmp_path: Path) -> None:
    """trials, rte and evaluate take L from base.length_m; a copy in a section is refused."""
    from pipeline.database.store import RteSection
    from pipeline.evaluate.section import EvaluateSection
    from pipeline.tuning.smbo import TrialsSection

    p = tmp_path / "params.yaml"
    p.write_text("base:\n  length_m: 100.0\n")
    for name, model in (("trials", TrialsSection), ("rte", RteSection),
                        ("evaluate", EvaluateSection)):
        assert load_section(p, name, model).length_m == 100.0
    p.write_text("base:\n  length_m: 100.0\nrte:\n  length_m: 25.0\n")
    with pytest.raises(ConfigError, match=r"^rte\.length_m: set once in base\.length_m, not per "
                                          r"section, got 25\.0$"):
        load_section(p, "rte", RteSection)
    p.write_text("base:\n  length_m: 0\n")
    with pytest.raises(ConfigError, match=r"^base\.length_m: .*greater than 0"):
        load_section(p, "trials", TrialsSection)

"""params.yaml sections: typed, validated, errors name the value and the rule."""

from __future__ import annotations

from pathlib import Path

import pytest
from pydantic import Field, model_validator

from pipeline.config import (
    SECTIONS,
    BaseSection,
    Section,
    load_params,
    load_section,
    read_params,
    section_model,
    validate_section,
)
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


def test_rule_error_names_values() -> None:
    with pytest.raises(
        ConfigError,
        match=r"max_range must be > min_range, got \(min_range=5.0, max_range=2.0\)",
    ):
        validate_section(RangeSection, "r", {"min_range": 5.0, "max_range": 2.0})


def test_unknown_key_and_type_error() -> None:
    with pytest.raises(ConfigError, match=r"r.min_rnage: unknown parameter"):
        validate_section(RangeSection, "r", {"min_rnage": 5.0})
    with pytest.raises(ConfigError, match=r"r.min_range: .*greater than or equal to 0.*-1"):
        validate_section(RangeSection, "r", {"min_range": -1})


def test_the_root_refuses_unknown_sections_and_keys_whatever_is_read(tmp_path: Path) -> None:
    """A misspelt section or key anywhere in the file is one line naming it, whichever section
    a stage asks for (``surogate: {k: 5}`` used to load silently with k = 20)."""
    p = tmp_path / "params.yaml"
    p.write_text("surogate: {k: 5}\n")
    with pytest.raises(ConfigError, match=r"unknown params section 'surogate' \(known: base, "):
        load_section(p, "base", BaseSection)
    p.write_text("base: {seed: 1}\ntrials: {iteratons: 5}\n")
    with pytest.raises(ConfigError, match=r"^trials.iteratons: unknown parameter"):
        load_section(p, "base", BaseSection)
    with pytest.raises(ConfigError, match=r"^unknown params section 'nope'"):
        section_model("nope")


def test_every_section_has_a_model_and_the_repository_file_loads() -> None:
    params = load_params(REPO / "params.yaml")
    assert list(params) == list(SECTIONS) == list(read_params(REPO / "params.yaml"))
    assert all(isinstance(v, Section) for v in params.values())


@pytest.mark.parametrize(("text", "rule"), [
    ("select: {window: 0}", r"^select.window must be an integer in \[1, 60\], got 0$"),
    ("select: {period_s: 0}", r"^select.period_s must be a finite number > 0, got 0$"),
    ("select: {period_s: .nan}", r"^select.period_s must be a finite number > 0, got nan$"),
    ("select: {hysteresis: -1}", r"^select.hysteresis must be a finite number >= 0, got -1$"),
    ("select: {widow: 3}", r"^select.widow: unknown setting"),
])
def test_select_settings_are_checked_on_load(tmp_path: Path, text: str, rule: str) -> None:
    p = tmp_path / "params.yaml"
    p.write_text(text + "\n")
    with pytest.raises(ConfigError, match=rule):
        load_section(p, "base", BaseSection)


def test_missing_file_and_bad_yaml(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="no such params file"):
        read_params(tmp_path / "nope.yaml")
    (tmp_path / "bad.yaml").write_text("a: [1, 2\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        read_params(tmp_path / "bad.yaml")


def test_repository_params_file_has_base_section() -> None:
    base = load_section(REPO / "params.yaml", "base", BaseSection)
    assert isinstance(base.seed, int)


@pytest.mark.parametrize(("lengths", "rule"), [
    ("[-5]", r"^devkit\.lengths_m: lengths_m must all be > 0, got \[-5\.0\]"),
    ("[10, 10]", r"^devkit\.lengths_m: lengths_m must be distinct, 10 is listed twice"),
    ("[]", r"^devkit\.lengths_m: .*at least 1"),
])
def test_one_devkit_setting_refuses_lengths_that_give_wrong_numbers(
        tmp_path: Path, lengths: str, rule: str) -> None:
    """A negative length gave a negative t_err in evaluate while rte refused it; now both read
    the one ``devkit`` section."""
    from pipeline.evaluate.section import EvaluateSection

    p = tmp_path / "params.yaml"
    p.write_text(f"devkit:\n  lengths_m: {lengths}\n")
    with pytest.raises(ConfigError, match=rule):
        load_section(p, "evaluate", EvaluateSection)


def test_length_is_set_once_in_base(tmp_path: Path) -> None:
    """trials and evaluate take L from base.length_m, evaluate the devkit section; a copy in a
    section is refused."""
    from pipeline.evaluate.section import EvaluateSection
    from pipeline.tuning.section import TrialsSection

    p = tmp_path / "params.yaml"
    p.write_text("base:\n  length_m: 100.0\ndevkit:\n  lengths_m: [20, 10]\n")
    for name, model in (("trials", TrialsSection), ("evaluate", EvaluateSection)):
        assert load_section(p, name, model).length_m == 100.0
    assert load_section(p, "evaluate", EvaluateSection).devkit.lengths_m == (10.0, 20.0)
    p.write_text("base:\n  length_m: 100.0\nevaluate:\n  length_m: 25.0\n")
    with pytest.raises(ConfigError, match=r"^evaluate\.length_m: set once in base\.length_m, "
                                          r"not per section, got 25\.0$"):
        load_section(p, "evaluate", EvaluateSection)
    p.write_text("evaluate:\n  devkit: {lengths_m: [5]}\n")
    with pytest.raises(ConfigError, match=r"^evaluate\.devkit: set once in devkit, not per "):
        load_section(p, "evaluate", EvaluateSection)
    p.write_text("base:\n  length_m: 0\n")
    with pytest.raises(ConfigError, match=r"^base\.length_m: .*greater than 0"):
        load_section(p, "trials", TrialsSection)


def effective(section: Section) -> dict[str, object]:
    """What a section configures: its fields (with the keys it takes from ``base`` and the
    sections it shares), and for sections that hold another home's settings as extra keys
    (``select``, ``descriptors``) those settings resolved, defaults included."""
    extra = section.model_extra or {}
    out = {k: v for k, v in section.model_dump().items() if k not in extra}
    if hasattr(section, "settings"):  # select: pipeline.selection.SelectionSettings
        out["settings"] = section.settings().to_json()
    if hasattr(section, "descriptor"):  # descriptors: the descriptor built from its settings
        out["descriptor"] = section.descriptor().to_json()
    return out


def _differences(code: object, yaml: object, where: str) -> list[str]:
    if isinstance(code, dict) and isinstance(yaml, dict):
        return [d for key in dict.fromkeys([*code, *yaml])
                for d in _differences(code.get(key, "<none>"), yaml.get(key, "<none>"),
                                      f"{where}.{key}")]
    return [] if code == yaml else [f"{where}: code {code!r}, params.yaml {yaml!r}"]


def test_the_codes_defaults_are_the_repositorys_params() -> None:
    """Outside the repository (no params file) every section is what the repository's
    params.yaml sets (issue 34: pruning was on, base.seed 0, fixed.iterations 256 ...), the
    keys taken from base and the shared sections included."""
    code, repo = load_params(None), load_params(REPO / "params.yaml")
    assert list(code) == list(repo) == list(SECTIONS)
    differences = [d for name in SECTIONS
                   for d in _differences(effective(code[name]), effective(repo[name]), name)]
    assert differences == []


def test_the_defaults_check_sees_a_difference(tmp_path: Path) -> None:
    """The comparison above fails on a value params.yaml sets apart from the code, nested
    (trials.pruning.percentile), taken from base (trials.length_m) or resolved (select)."""
    p = tmp_path / "params.yaml"
    p.write_text("base: {length_m: 30.0}\ntrials: {pruning: {percentile: 40}}\n"
                 "select: {window: 2}\n")
    code, other = load_params(None), load_params(p)
    differences = [d for name in SECTIONS
                   for d in _differences(effective(code[name]), effective(other[name]), name)]
    assert {d.split(":")[0] for d in differences} >= {
        "base.length_m", "trials.length_m", "evaluate.length_m", "trials.pruning.percentile",
        "select.settings.window"}


def test_options_of_another_adapter_are_refused_on_load(tmp_path: Path) -> None:
    """trials.adapter_options another algorithm takes (the command adapter's, after a change
    of trials.algorithm) are one line naming them, whichever section a stage reads (issue
    57.6); an algorithm's own options load."""
    from pipeline.config import load_section

    path = tmp_path / "params.yaml"
    path.write_text("trials: {algorithm: kiss_icp, adapter_options: {command: ./tool, "
                    "space: s.yaml, deskew: false}}\n")
    with pytest.raises(ConfigError, match=r"^trials\.adapter_options: command, space are not "
                       r"options of kiss_icp \(its options: deskew, .*\): left by another "
                       r"algorithm\? drop them with `dvc exp run -S trials\.algorithm=kiss_icp "
                       r"-S '~trials\.adapter_options'`"):
        load_section(path, "base", BaseSection)
    path.write_text("trials: {algorithm: kiss_icp, adapter_options: {deskew: false}}\n")
    assert load_section(path, "base", BaseSection).length_m == 25.0

"""params.yaml ``verdict`` (``VerdictSection``): the coverage model's suites and what was frozen
with them before any result was looked at (docs/results/verdict.md, "Protocol").

Frozen: every suite's seed roots, the baseline parameters, the fixed study's least budget, the
oracle's candidate set (the portfolio's grid), the failure threshold and the world generator's
version. The defaults
below are those values (verdict/params.yaml repeats them, as every params file does its code's
defaults).
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field, field_validator, model_validator

from pipeline.config import IterationCount, Section
from pipeline.sequence import Compression
from pipeline.sim.route import LABELS
from pipeline.sim.sensors import SensorName
from studies.suites.worlds import labels_rule, range_rule, seed_roots_rule

FAMILIES = ("id", "ood")
"""The coverage model's two suite families: in distribution (the environments and sensors it
trained on) and out of distribution (the sensor kept out of training)."""


class SuiteDraw(Section):
    """How the worlds of one family are drawn (``studies.verdict.worlds``).

    seed_roots: the root of the dev and of the test suite (world i depends on (root, i) alone);
    worlds: worlds per suite; sensors: world i uses sensors[i % len(sensors)]; labels: the
    environment classes its segments are drawn from; segments: (min, max) segments per world;
    frames: (min, max) frames per world (10 Hz), the segments sharing them.
    """

    seed_roots: dict[str, int]
    worlds: int = Field(ge=1)
    sensors: tuple[SensorName, ...] = Field(min_length=1)
    labels: tuple[str, ...] = LABELS
    segments: tuple[int, int] = (2, 4)
    frames: tuple[int, int] = (900, 1200)

    @field_validator("seed_roots")
    @classmethod
    def _roots(cls, v: dict[str, int]) -> dict[str, int]:
        return seed_roots_rule(v)

    @field_validator("labels")
    @classmethod
    def _labels(cls, v: tuple[str, ...]) -> tuple[str, ...]:
        return labels_rule(v)

    @field_validator("segments", "frames")
    @classmethod
    def _range(cls, v: tuple[int, int]) -> tuple[int, int]:
        return range_rule(v)

    @model_validator(mode="after")
    def _frames(self) -> SuiteDraw:
        if self.frames[0] < 30 * self.segments[1]:
            raise ValueError(f"a world needs >= 30 frames a segment, got frames="
                             f"{list(self.frames)} for up to {self.segments[1]} segments")
        return self


class Suites(Section):
    """The two families' draws."""

    id: SuiteDraw = SuiteDraw(seed_roots={"dev": 70101, "test": 87976}, worlds=40,
                              sensors=("hdl32", "hdl64"))
    ood: SuiteDraw = SuiteDraw(seed_roots={"dev": 54912, "test": 37084}, worlds=16,
                               sensors=("vlp16",))

    @model_validator(mode="after")
    def _distinct(self) -> Suites:
        roots = [r for f in FAMILIES for r in getattr(self, f).seed_roots.values()]
        if len(set(roots)) < len(roots):
            raise ValueError(f"every suite needs a seed root of its own, got {roots}")
        return self

    def draw(self, family: str) -> SuiteDraw:
        return getattr(self, family)  # type: ignore[no-any-return]


class TuningDraw(Section):
    """The coverage model's tuning suite (``studies.verdict.tuning``): ``worlds`` worlds drawn
    exactly as the in-distribution suites draw theirs (``suites.id``: its sensors, labels,
    segments and frames) from ``seed_root``, a root of its own (frozen with the others).
    compression: of the worlds' MCAPs (``pipeline.sequence.Compression``); ``none`` by default:
    three stages read them again at once, and zstd would save a quarter of their size at x3
    the write and x2 the read (docs/performance.md, "The verdict's suites")."""

    seed_root: int = 45453
    worlds: int = Field(default=24, ge=1)
    compression: Compression = "none"


class VerdictSection(Section):
    """params.yaml ``verdict`` (module docstring).

    suite: which suite of each family runs (``test``: reported; ``dev``: where every choice is
    made); world_generator: ``pipeline.sim.GENERATOR_VERSION`` the suites are frozen with (a run on
    another generator is refused); baseline: the baseline parameters (the joint study's stored
    defaults must equal them); fixed_trials / fixed_warm_start: the joint study's least budget
    (``fixed.iterations`` / ``fixed.warm_start`` below them are refused); failure_pct: a
    sub-trajectory with a larger RTE [%] fails (the headroom study's candidate grid is the
    portfolio's, params ``portfolio.grid``: one grid for both); tuning: the tuning suite the
    coverage model's portfolio runs on (``TuningDraw``); borrow_model: with one model per sensor,
    the sensor whose model a sensor without one runs (None: such a world runs the fixed set; hdl64
    chosen on the out-of-distribution dev suite, docs/results/selector-dev.md); replicas: extra runs
    of every setting on every world with the parameters moved by at most ``replica_scale``
    (``pipeline.evaluate.replicas``); targets: per family and ratio, (the geometric mean at most,
    the upper end of its interval below (id) / at most (ood)); closed_gap_target: the headroom's
    closed gap at least (its interval's lower end > 0); confidence / resamples: the bootstrap's
    level and resamples; workers: worlds run at a time (processes); length_m: L (from base). """

    suite: Literal["dev", "test"] = "test"
    world_generator: int = Field(2, ge=1)
    suites: Suites = Suites()
    tuning: TuningDraw = TuningDraw()
    borrow_model: SensorName | None = "hdl64"
    baseline: dict[str, float] = Field(
        default_factory=lambda: {"resolution": 4.0, "keyframe_interval": 4.0})
    fixed_trials: IterationCount = 64
    fixed_warm_start: int = Field(4, ge=0)
    failure_pct: float = Field(10.0, gt=0)
    replicas: int = Field(2, ge=0)
    replica_scale: float = Field(0.005, gt=0, le=0.1)
    targets: dict[str, dict[str, tuple[float, float]]] = Field(default_factory=lambda: {
        "id": {"adaptive_vs_fixed": (0.75, 0.90), "adaptive_vs_baseline": (0.75, 0.90)},
        "ood": {"adaptive_vs_fixed": (1.00, 1.05), "adaptive_vs_baseline": (1.00, 1.05)}})
    closed_gap_target: float = Field(0.5, gt=0, le=1)
    confidence: float = Field(0.95, gt=0, lt=1)
    resamples: int = Field(10000, ge=100)
    workers: int = Field(2, ge=1)
    length_m: float = Field(25.0, gt=0)

    @model_validator(mode="after")
    def _borrowed(self) -> VerdictSection:
        trained = self.suites.id.sensors
        if self.borrow_model is not None and self.borrow_model not in trained:
            raise ValueError(f"borrow_model must be a trained sensor ({', '.join(trained)}) or "
                             f"null, got {self.borrow_model!r}")
        return self

    @model_validator(mode="after")
    def _tuning_root(self) -> VerdictSection:
        roots = {r for f in FAMILIES for r in self.suites.draw(f).seed_roots.values()}
        if self.tuning.seed_root in roots:
            raise ValueError(f"tuning.seed_root must differ from every suite's root, got "
                             f"{self.tuning.seed_root}, which a suite uses")
        return self

    def root(self, family: str) -> int:
        """The seed root of ``family``'s chosen suite."""
        return self.suites.draw(family).seed_roots[self.suite]

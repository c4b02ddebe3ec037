"""params.yaml ``devkit``: the KITTI devkit metric's settings, one home for the stages that
score with it (``rte``: the ``rte_kitti`` table; ``evaluate``: Table II)."""

from __future__ import annotations

from pydantic import Field, field_validator

from pipeline.config import Section
from pipeline.metrics.kitti import LENGTHS_M, STEP_FRAMES


class DevkitSection(Section):
    """lengths_m: the segment lengths [m] (the devkit's 100 .. 800 m; shorter ones for short
    runs), distinct and > 0, scored in ascending order; step_frames: a segment starts every
    step_frames frames (the devkit's 10)."""

    lengths_m: tuple[float, ...] = Field(LENGTHS_M, min_length=1)
    step_frames: int = Field(STEP_FRAMES, ge=1)

    @field_validator("lengths_m")
    @classmethod
    def _lengths(cls, v: tuple[float, ...]) -> tuple[float, ...]:
        if any(not x > 0 for x in v):
            raise ValueError(f"lengths_m must all be > 0, got {list(v)}")
        twice = sorted({x for x in v if v.count(x) > 1})
        if twice:
            raise ValueError(f"lengths_m must be distinct, {twice[0]:g} is listed twice, "
                             f"got {list(v)}")
        return tuple(sorted(v))

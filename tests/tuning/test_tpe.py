"""Search space conversion and ask/tell TPE proposals."""

from __future__ import annotations

import math

import pytest
from helpers.tuning_adapters import SPACE

from pipeline.odometry.base import ParameterSpace, ParamSpec
from pipeline.tuning.space import from_hyperopt_vals, to_hyperopt, to_hyperopt_vals
from pipeline.tuning.tpe import TpeSearch, trial_seed


def objective(p: dict[str, float]) -> float:
    return (p["bias"] - 0.2) ** 2 + math.log(p["gain"]) ** 2 + abs(p["window"] - 4)


def test_space_round_trip() -> None:
    space = ParameterSpace((*SPACE.specs, ParamSpec("k", 1, 64, 8, kind="int", log=True)))
    hp_space = to_hyperopt(space)
    assert set(hp_space) == set(space.names)
    params = space.defaults()
    assert from_hyperopt_vals(space, to_hyperopt_vals(space, params)) == params
    assert from_hyperopt_vals(
        space, {"bias": [2.0], "gain": 0.1, "window": [3.4], "k": [70.0]}
    ) == {"bias": 1.0, "gain": 0.25, "window": 3.0, "k": 64.0}


@pytest.mark.parametrize("startup", [1, 50])  # TPE proper, and its random start-up phase
def test_proposals_in_range_and_integral(startup: int) -> None:
    space = ParameterSpace((*SPACE.specs, ParamSpec("k", 1, 64, 8, kind="int", log=True)))
    search = TpeSearch(space, seed=3, startup_trials=startup)
    search.tell(0, space.defaults(), 5.0)
    seen = []
    for tid in range(1, 40):
        p = search.ask(tid)
        for s in space.specs:
            assert s.low <= p[s.name] <= s.high
            if s.kind == "int":
                assert p[s.name] == round(p[s.name])
        search.tell(tid, p, objective(p))
        seen.append(p)
    assert len({tuple(p.values()) for p in seen}) > 30  # it explores


def test_tpe_improves_over_random_start() -> None:
    search = TpeSearch(SPACE, seed=0, startup_trials=10)
    losses = []
    for tid in range(60):
        p = search.ask(tid)
        losses.append(objective(p))
        search.tell(tid, p, losses[-1])
    assert sorted(losses[40:])[5] < sorted(losses[:10])[5]


def test_asks_are_seeded_and_pending_trials_count() -> None:
    def run(seed: int, pending: bool) -> list[dict[str, float]]:
        s = TpeSearch(SPACE, seed=seed, startup_trials=2)
        for tid in range(4):
            p = s.ask(tid)
            s.tell(tid, p, objective(p))
        if pending:
            s.pending(4, SPACE.defaults())
        return [s.ask(t) for t in (5, 6)]

    assert run(1, False) == run(1, False)
    assert run(1, False) != run(2, False)
    assert run(1, False) != run(1, True)  # a pending trial changes the next proposal
    assert trial_seed(1, 5) != trial_seed(1, 6)
    with pytest.raises(ValueError, match="already proposed"):
        s = TpeSearch(SPACE, seed=0)
        s.ask(0)
        s.ask(0)

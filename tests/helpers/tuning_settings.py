"""Small, fast study settings for the drift adapter of ``helpers.tuning_adapters``, and a
Ctrl-C in the middle of a study."""

from __future__ import annotations

from collections.abc import Callable

from pipeline.tuning.section import TrialsSection

HALVING: dict[str, object] = {"fidelity": "halving", "halving": {"eta": 2, "rungs": 3}}
"""Successive halving for ``settings(**HALVING)``: eta 2, 3 rungs."""


def settings(**kw: object) -> TrialsSection:
    """Small, fast settings for the drift adapter (no pruning unless asked for)."""
    base: dict[str, object] = dict(
        algorithm="helpers.tuning_adapters:drift",
        iterations=6,
        workers=1,
        startup_trials=3,
        length_m=5.0,
        time_limit_s=20.0,
        pruning={"percentile": None},
    )
    base.update(kw)
    return TrialsSection(**base)


class Interrupt(KeyboardInterrupt):
    """Ctrl-C in the middle of a study (raised by an ``on_trial`` callback)."""


def interrupt_after(n: int) -> Callable[[object, object], None]:
    """An ``on_trial`` callback of ``run_trials`` that interrupts the run after its n-th
    finished trial."""
    seen: list[int] = []

    def on_trial(study: object, result: object) -> None:
        seen.append(result.trial)  # type: ignore[attr-defined]
        if len(seen) == n:
            raise Interrupt

    return on_trial

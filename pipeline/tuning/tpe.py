"""hyperopt TPE in ask/tell form.

hyperopt's ``fmin`` owns its loop; here the loop is ours. ``TpeSearch`` keeps the history
(finished trials with their loss, and pending trials that are still running) and, for every
``ask``, rebuilds a ``hyperopt.Trials`` from it and calls ``tpe.suggest([tid], domain, trials,
seed)`` once. Pending trials carry no loss, which TPE counts as an infinite loss (hyperopt's own
rule for new/running jobs), so proposals made while W trials are in flight spread out.

Determinism: the proposal for trial ``tid`` depends only on the history and on
``trial_seed(seed, tid)``; a serial run (one trial in flight) is therefore identical for the
same seed, and so is a resumed one (the history is read back exactly from the trials table).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from pipeline.odometry.base import ParameterSpace, Params
from pipeline.tuning.space import from_hyperopt_vals, to_hyperopt, to_hyperopt_vals


def trial_seed(seed: int, tid: int) -> int:
    """Seed of trial ``tid`` (for tpe.suggest's numpy Generator): 0 <= s < 2**31 - 1."""
    state = np.random.SeedSequence([int(seed) & 0xFFFFFFFF, int(tid)]).generate_state(1)[0]
    return int(state) % (2**31 - 1)


def _evaluated_elsewhere(params: Any) -> None:
    """hyperopt's Domain wants an objective; trials are evaluated by the executor, never here."""
    raise RuntimeError("TpeSearch proposes parameters only; trials run in pipeline.tuning.job")


@dataclass
class _Entry:
    params: Params
    loss: float | None  # None while pending


class TpeSearch:
    """Ask/tell TPE over one parameter space.

    ``startup_trials``: random proposals before TPE takes over (hyperopt's ``n_startup_jobs``;
    counted over finished and pending trials, as hyperopt does).
    """

    def __init__(self, space: ParameterSpace, seed: int, startup_trials: int = 20,
                 n_ei_candidates: int = 24, gamma: float = 0.25) -> None:
        from hyperopt import base

        self.space = space
        self.seed = int(seed)
        self.startup_trials = int(startup_trials)
        self.n_ei_candidates = int(n_ei_candidates)
        self.gamma = float(gamma)
        self._domain = base.Domain(_evaluated_elsewhere, to_hyperopt(space))
        self._history: dict[int, _Entry] = {}

    def __len__(self) -> int:
        return len(self._history)

    def ask(self, tid: int) -> Params:
        """Propose parameters for trial ``tid`` (not yet in the history); marks it pending."""
        from hyperopt import tpe

        if tid in self._history:
            raise ValueError(f"trial {tid} was already proposed")
        docs = tpe.suggest([tid], self._domain, self._trials(), trial_seed(self.seed, tid),
                           n_startup_jobs=self.startup_trials, n_EI_candidates=self.n_ei_candidates,
                           gamma=self.gamma, verbose=False)
        params = from_hyperopt_vals(self.space, docs[0]["misc"]["vals"])
        self.pending(tid, params)
        return params

    def pending(self, tid: int, params: Mapping[str, float]) -> None:
        """Record ``tid`` as running with ``params`` (e.g. the baseline, which is not asked)."""
        self._history[tid] = _Entry(self.space.validate(params), None)

    def reset(self, told: Mapping[int, tuple[Mapping[str, float], float]],
              pending: Mapping[int, Mapping[str, float]]) -> None:
        """Replace the history: ``told`` {tid: (params, loss)} finished, ``pending`` {tid:
        params} running."""
        self._history = {}
        for tid, (params, loss) in told.items():
            self.tell(tid, params, loss)
        for tid, params in pending.items():
            self.pending(tid, params)

    def tell(self, tid: int, params: Mapping[str, float], loss: float) -> None:
        """Record the finished trial ``tid`` (pending or not) with its finite ``loss``."""
        if not np.isfinite(loss):
            raise ValueError(f"trial {tid}: loss must be finite, got {loss}")
        self._history[tid] = _Entry(self.space.validate(params), float(loss))

    def _trials(self) -> Any:
        """A fresh hyperopt Trials holding the history (finished: DONE with loss; pending: NEW)."""
        from hyperopt import JOB_STATE_DONE, JOB_STATE_NEW, STATUS_OK, Trials

        trials = Trials()
        docs = []
        for tid in sorted(self._history):
            entry = self._history[tid]
            vals = to_hyperopt_vals(self.space, entry.params)
            misc = {"tid": tid, "cmd": self._domain.cmd, "workdir": self._domain.workdir,
                    "idxs": {k: [tid] for k in vals}, "vals": vals}
            result = ({"status": "new"} if entry.loss is None
                      else {"status": STATUS_OK, "loss": entry.loss})
            doc = trials.new_trial_docs([tid], [None], [result], [misc])[0]
            doc["state"] = JOB_STATE_NEW if entry.loss is None else JOB_STATE_DONE
            docs.append(doc)
        trials.insert_trial_docs(docs)
        trials.refresh()
        return trials

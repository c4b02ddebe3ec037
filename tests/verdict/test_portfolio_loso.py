"""experiments/portfolio_loso.py's per-label headroom (``label_gains``), on a hand-computed
portfolio: the in-sample best member and the member chosen leave one sequence out differ."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from helpers.scripts import load_script

SCRIPT = Path(__file__).resolve().parents[2] / "experiments" / "portfolio_loso.py"


def _portfolio() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Three sequences of two cave frames each; members 0 (the reference), 1 and 2 with RTE
    A: 2, 1, 4; B: 2, 1, 4; C: 2, 3, 0.5 [%] on both frames; one open frame in A (too few)."""
    per_seq = {"A": [2.0, 1.0, 4.0], "B": [2.0, 1.0, 4.0], "C": [2.0, 3.0, 0.5]}
    y = np.array([per_seq[s] for s in "AABBCC"] + [[9.0, 9.0, 9.0]])
    seq = np.array([*"AABBCC", "A"])
    label = np.array(["cave"] * 6 + ["open"])
    return y, seq, label


def test_label_gains_in_sample_and_held_out() -> None:
    y, seq, label = _portfolio()
    rows = load_script(SCRIPT).label_gains(y, seq, label, ref=0, min_frames=2)
    # log ratios to member 0: member 1 (ln .5, ln .5, ln 1.5), member 2 (ln 2, ln 2, ln .25).
    # In sample member 1 is best: (0.5 * 0.5 * 1.5) ** (1/3). Held out, A and B each see
    # member 2 best on the other two (ln 2 + ln .25 < ln .5 + ln 1.5) and lose x2; C sees
    # member 1 and pays x1.5: (2 * 2 * 1.5) ** (1/3).
    assert len(rows) == 1  # the open label has one frame in one sequence
    lab, n, ref_rte, best, ratio, held_out = rows[0]
    assert (lab, n, best) == ("cave", 3, 1)
    assert ref_rte == pytest.approx(2.0)
    assert ratio == pytest.approx(0.375 ** (1 / 3))
    assert held_out == pytest.approx(6.0 ** (1 / 3))


def test_also_refuses_other_frames() -> None:
    y, seq, label = _portfolio()
    E = np.arange(len(y), dtype=float)[:, None]
    module = load_script(SCRIPT)
    assert module.same_frames((E, y[:, :1], seq, label), E, seq, label).shape == (7, 1)
    with pytest.raises(SystemExit, match="not the first database's"):
        module.same_frames((E + 1.0, y, seq, label), E, seq, label)

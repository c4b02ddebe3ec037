"""experiments/portfolio_loso.py: run on a small results database that the ``rte`` command
built (helpers.results_db: a portfolio of 3 members on 2 sequences), its figures checked
against the database's own rows; its per-label headroom (``label_gains``) on a hand-computed
portfolio, where the in-sample best member and the member chosen leave one sequence out
differ."""

from __future__ import annotations

import re
from pathlib import Path

import duckdb
import numpy as np
import pytest
from helpers.results_db import build_database, make_world
from helpers.scripts import load_script

SCRIPT = Path(__file__).resolve().parents[2] / "experiments" / "portfolio_loso.py"


def test_a_run_on_a_small_database(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    world = build_database(make_world(tmp_path))
    load_script(SCRIPT).main(["--db", str(world.db), "--k", "2,5"])
    lines = capsys.readouterr().out.splitlines()
    assert "2 sequences, 85 frames, 3 members" in lines[0]
    rows = {m[1]: tuple(map(float, m.groups()[1:])) for line in lines[1:]
            if (m := re.fullmatch(r"  (\S+) +(\S+)  (\S+)  (\S+)", line))}
    assert {"k2", "k5", "winners_k2", "sbs", "reference", "label", "frame_oracle"} <= set(rows)
    con = duckdb.connect(str(world.db), read_only=True)
    per_member = dict(con.execute("SELECT trial, avg(y) FROM portfolio_rows GROUP BY trial"
                                  ).fetchall())
    best_each_frame = con.execute("SELECT avg(m) FROM (SELECT min(y) AS m FROM portfolio_rows "
                                  "GROUP BY sequence, frame)").fetchone()[0]
    con.close()
    # the reference: the last member (trial 2), against itself 1
    assert rows["reference"][0] == pytest.approx(per_member[2], abs=5e-4)
    assert rows["reference"][2] == 1.0 and rows["sbs"][1] == 1.0
    assert rows["frame_oracle"][0] == pytest.approx(best_each_frame, abs=5e-4)
    assert all(rows["frame_oracle"][0] <= mean for mean, _, _ in rows.values())


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

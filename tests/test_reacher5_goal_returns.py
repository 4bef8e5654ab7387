"""Where the 5-link reacher's models lose return (Fig. 4.3c): the recorded goal-return table
is the one its code makes from the recorded checkpoints, and its one-line summaries."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from vslbook.data import measurements
from vslbook.experiments import diskill_reacher as R
from vslbook.experiments.figure_sources import figure_set
from vslbook.results import RunDir


def test_the_recorded_table_is_remade_from_the_seed_0_checkpoints(tmp_path, monkeypatch):
    for var in ("VSLBOOK_SOURCE", "VSLBOOK_RETRAIN", "VSLBOOK_BUDGET"):
        monkeypatch.delenv(var, raising=False)
    kept = measurements("reacher5_goal_returns.csv")
    assert sorted(set(zip(kept["method"], kept["seed"], strict=True))) == [
        ("bbrl", 0), ("bbrl", 2), ("diskill", 0), ("diskill", 2),
    ]  # fmt: skip
    sizes = kept.groupby(["method", "seed", "goals"]).size()
    assert set(sizes.xs(R.GOAL_SETS[0], level="goals")) == {72}  # every 5°
    assert set(sizes.xs(R.GOAL_SETS[1], level="goals")) == {75}  # the fixed test goals
    fs = figure_set("fig4-3c", root=tmp_path / "empty", mode="best")  # the recorded set
    assert fs.budget == "full"
    remade = R.goal_returns_table({m: fs.runs[m] for m in ("diskill", "bbrl")}, seeds=(0,))
    old = kept[kept["seed"] == 0].reset_index(drop=True)
    assert remade["run"].tolist() == old["run"].tolist()
    assert remade["goals"].tolist() == old["goals"].tolist()
    assert (remade["expert"].to_numpy() == old["expert"].to_numpy()).all()
    for column in ("angle", "radius", "return", "tip_distance"):
        np.testing.assert_allclose(remade[column], old[column], rtol=1e-6, atol=1e-9)
    # BBRL has one policy, so its mean θ at the run's own test goals is the test it logged
    # last: seed 2's rows agree with the recorded curve of a checkpoint the record lacks
    checked = 0
    for path in fs.runs["bbrl"]:
        seed = RunDir.open(path).config["seed"]
        logged = [r["test_return"] for r in RunDir.open(path).metrics() if "test_return" in r]
        rows = kept[(kept["method"] == "bbrl") & (kept["seed"] == seed)
                    & (kept["goals"] == R.GOAL_SETS[1])]  # fmt: skip
        if len(rows):
            assert rows["return"].mean() == pytest.approx(logged[-1], rel=1e-6)
            checked += 1
    assert checked == 2  # seeds 0 and 2
    with pytest.raises(ValueError, match=r"no run of seeds \(7,\)"):
        R.goal_returns_table({m: fs.runs[m] for m in ("bbrl",)}, seeds=(7,))


def _frame(angles, returns, radius=0.4):
    return pd.DataFrame({"angle": angles, "radius": radius, "expert": 0, "return": returns,
                         "tip_distance": 0.0})  # fmt: skip


def test_ring_summary():
    f = _frame([-180, -150, -90, 0, 90, 155, 175], [-40.0, -2.0, -1.0, -0.5, -6.0, -3.0, -1.0])
    # behind the arm (|angle| >= 150): -40, -2, -3, -1 -> median -2.5, worst -40 at -180;
    # below -5: -40 and -6; median over all seven: -2
    assert R.ring_summary(f) == (
        "median return -2.00 over the ring; behind the arm (|angle| ≥ 150°) median -2.50, "
        "worst -40.0 at -180°; goals below −5: 2 of 7"
    )
    with pytest.raises(ValueError, match="no goal behind the arm"):
        R.ring_summary(_frame([0, 90], [-1.0, -1.0]))


def test_summary_at_test_goals():
    f = _frame([-174, 10, 20, 30], [-160.0, -1.0, -2.0, -3.0], radius=[0.39, 0.1, 0.2, 0.3])
    assert R.summary_at_test_goals(f) == (
        "mean return -41.50 over its 4 test goals; 1 below −5: -160 at -174° (0.39 m); "
        "without them -2.00"
    )
    assert R.summary_at_test_goals(f.iloc[1:]).endswith("0 below −5; without them -2.00")

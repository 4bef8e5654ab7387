"""A chapter's opening figure: its claims drawn, ours beside the thesis's
(vslbook.experiments.reproduction_figure)."""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib
import numpy as np
import pytest

from vslbook.experiments.figure_sources import FigureSet
from vslbook.experiments.reproduction_figure import results_figure

matplotlib.use("Agg")
BP = "vslbook/BeerPong-v0"


def _run(root: Path, name: str, metric: str, finals: list[float], env: str = BP) -> Path:
    path = root / name
    path.mkdir(parents=True)
    (path / "config.json").write_text(json.dumps({"env": env, "seed": 0}))
    rows = [{"step": i, metric: v, "grid_success": v} for i, v in enumerate(finals)]
    (path / "metrics.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    return path


def _points(ax) -> dict[str, float]:
    """The x of each row's marker, by tick label (errorbar lines hold one point each)."""
    labels = [t.get_text() for t in ax.get_yticklabels()]
    out = {}
    for line in ax.lines:
        x, y = line.get_xdata(), line.get_ydata()
        if len(x) == 1 and line.get_marker() == "o":
            out[labels[int(round(float(y[0])))]] = float(x[0])
    return out


def test_beer_pong_panel_puts_ours_beside_the_thesiss_numbers(tmp_path):
    svsl = [_run(tmp_path, f"s{i}", "test_success", [0.0, v])
            for i, v in enumerate((0.7, 0.9, 0.85, 1.0))]  # fmt: skip
    fig = results_figure({"fig3-2": FigureSet("fig3-2", "full", {"SVSL": svsl})}, reps=100)
    (ax,) = fig.axes
    labels = [t.get_text() for t in ax.get_yticklabels()]
    assert labels == ["SVSL (ours, 4 seeds)", "HiREPS (ours): no finished run"]
    assert _points(ax) == {"SVSL (ours, 4 seeds)": pytest.approx(0.875)}  # mean of 0.85, 0.9
    diamonds = sorted(float(line.get_xdata()[0]) for line in ax.lines
                      if line.get_marker() == "D")  # fmt: skip
    assert diamonds == [0.75, 0.92]  # the thesis's numbers, Fig. 3.2e/f
    assert [float(line.get_xdata()[0]) for line in ax.lines
            if line.get_linestyle() == "--"] == [0.8]  # the at_least claim's threshold
    assert "1 met, 1 pending" in ax.get_title()
    smoke = results_figure({"fig3-2": FigureSet("fig3-2", "smoke", {"SVSL": svsl})}, reps=100)
    assert "smoke: code path only" in smoke.axes[0].get_title()


def test_one_panel_per_task_and_chapter4_names(tmp_path):
    di = [_run(tmp_path, f"d{i}", "test_return", [0.0, v], env="r5") for i, v in enumerate((3, 5))]
    bb = [_run(tmp_path, f"b{i}", "test_return", [0.0, v], env="r5") for i, v in enumerate((1, 2))]
    tt = [_run(tmp_path, "t0", "test_success", [0.0, 0.5], env="tt")]
    sets = {"fig4-3c": FigureSet("fig4-3c", "reduced", {"diskill": di, "bbrl": bb}),
            "fig4-3b": FigureSet("fig4-3b", "reduced", {"diskill": tt})}
    fig = results_figure(sets, reps=100)
    assert len(fig.axes) == 2
    reacher, table_tennis = fig.axes
    assert _points(reacher) == {"Di-SkilL (ours, 2 seeds)": 4.0, "BBRL (ours, 2 seeds)": 1.5}
    assert "claims: 1 met" in reacher.get_title() and "Fig. 4.3c" in reacher.get_title()
    assert [float(np.atleast_1d(line.get_xdata())[0]) for line in table_tennis.lines
            if line.get_linestyle() == "--"] == [0.6]  # both at_least claims' one threshold
    assert "claim: Di-SkilL, BBRL ≥ 0.6" in [t.get_text() for t in table_tennis.get_legend().texts]


def test_figures_without_claims_are_refused():
    with pytest.raises(ValueError, match=r"no claims for figures \['fig3-1'\]"):
        results_figure({"fig3-1": FigureSet("fig3-1", "smoke", {})})


def test_a_method_still_training_says_how_far(tmp_path):
    svsl = [_run(tmp_path, "s0", "test_success", [0.0, 0.5])]
    fs = FigureSet("fig3-2", "full", {"SVSL": svsl}, probes={"s0": "300/52600 iterations"})
    (ax,) = results_figure({"fig3-2": fs}, reps=50).axes
    labels = [t.get_text() for t in ax.get_yticklabels()]
    assert labels == ["SVSL (ours): still training (300/52600 iterations)",
                      "HiREPS (ours): no finished run"]  # fmt: skip
    assert _points(ax) == {}  # a probe is drawn by the chapter's figure, not scored here
    assert "2 pending" in ax.get_title()


def test_two_methods_on_par_are_not_drawn_far_apart(tmp_path):
    # hopper jump: 20.78 against 20.70, 0.4 % apart; the axis spans 10 % of 20.78 or more
    di = [_run(tmp_path, "d0", "test_return", [0.0, 20.78], env="hj")]
    bb = [_run(tmp_path, "b0", "test_return", [0.0, 20.70], env="hj")]
    hopper = FigureSet("fig4-4a", "full", {"diskill": di, "bbrl": bb})
    (ax,) = results_figure({"fig4-4a": hopper}, reps=50).axes
    lo, hi = ax.get_xlim()
    assert hi - lo == pytest.approx(0.1 * 20.78, rel=0.01) and lo < 20.70 and hi > 20.78
    assert (lo + hi) / 2 == pytest.approx(20.74, abs=0.01)  # widened about the middle
    # a panel whose values already spread keeps matplotlib's limits
    di5 = [_run(tmp_path, "d5", "test_return", [0.0, -0.72], env="r5")]
    bb5 = [_run(tmp_path, "b5", "test_return", [0.0, -2.35], env="r5")]
    five = FigureSet("fig4-3c", "full", {"diskill": di5, "bbrl": bb5})
    (reacher,) = results_figure({"fig4-3c": five}, reps=50).axes
    lo, hi = reacher.get_xlim()
    assert -2.5 < lo < -2.35 and -0.72 < hi < -0.6

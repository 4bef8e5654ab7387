"""Chapter 4's run sets, curves and the 5LR analysis of Fig. 4.2 (at the smoke budget)."""

from __future__ import annotations

from dataclasses import asdict

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
import pytest

from vslbook.erl.diskill_config import diskill_config
from vslbook.experiments import diskill_reacher as R
from vslbook.experiments import diskill_runs as D
from vslbook.experiments import diskill_scores as DS


def test_counts_scale_only_counts():
    full, red, smoke = (D.counts("reacher5", "diskill", b) for b in ("full", "reduced", "smoke"))
    assert full == {"seeds": 24, "iterations": 3000, "test_every": 5, "test_contexts": 75}
    assert red["iterations"] == 300 and red["seeds"] == 3
    assert smoke["n_experts"] == 2 and smoke["samples_per_expert"] == 4
    assert D.counts("hopper-jump", "bbrl", "reduced")["iterations"] == 28
    bpo = D.counts("box-pushing-obstacle", "diskill", "reduced")
    assert bpo["iterations"] == 90 and bpo["n_experts"] == 5
    assert "n_experts" not in D.counts("box-pushing-obstacle", "bbrl", "reduced")


def test_bad_input():
    with pytest.raises(ValueError, match="figure 'fig4-9' declares no runs; expected one of"):
        D.run_set("4.9", "smoke")
    with pytest.raises(ValueError, match=r"no method\(s\) \['lindiskill'\]"):
        D.run_set("4.3b", "smoke", methods=("lindiskill",))
    with pytest.raises(ValueError, match="task 'beer-pong'"):
        D.env_id("beer-pong")
    with pytest.raises(ValueError, match="n must be an integer >= 2"):
        R.disk_grid(1)


@pytest.fixture(scope="module")
def reacher_runs(tmp_path_factory):
    import os

    os.environ["VSLBOOK_WORKERS"] = "1"
    # the episodic methods of Fig. 4.3c (its PPO runs: test_ppo_ch4_from_the_command_line)
    return D.run_set("4.3c", "smoke", tmp_path_factory.mktemp("runs"),
                     methods=("diskill", "bbrl", "lindiskill"))  # fmt: skip


def test_run_set_and_curves(reacher_runs):
    assert set(reacher_runs) == {"diskill", "bbrl", "lindiskill"}
    curves = D.curves(reacher_runs, reps=50)
    assert set(curves["method"]) == {"Di-SkilL", "BBRL", "LinDi-SkilL"}
    assert np.isfinite(curves["iqm"]).all()
    # at smoke every method draws 4 samples per expert: BBRL 1 x 4, Di-SkilL 2 x 4 per iteration
    bbrl = curves[curves["method"] == "BBRL"]["samples"].max()
    dis = curves[curves["method"] == "Di-SkilL"]["samples"].max()
    assert bbrl == 2 * 4 and dis == 2 * 2 * 4


def test_final_scores_and_the_thesis_pairs(reacher_runs):
    import json

    last = {m: json.loads(
                [line for line in (paths[0] / "metrics.jsonl").read_text().splitlines()
                 if "test_return" in line][-1])["test_return"]
            for m, paths in reacher_runs.items()}  # fmt: skip
    scores, verdicts = DS.final_scores("4.3c", reacher_runs, reps=50)
    assert list(scores["runs"]) == [1, 1, 1]  # one seed each: the IQM is that run's value
    # the median of each run's logged iteration times, read here from the file
    times = {m: np.median([json.loads(line)["iteration_seconds"]
                           for line in (paths[0] / "metrics.jsonl").read_text().splitlines()
                           if "iteration_seconds" in line])
             for m, paths in reacher_runs.items()}  # fmt: skip
    np.testing.assert_allclose(scores.set_index("method")["s_per_iteration"][list(times)],
                               list(times.values()))  # fmt: skip
    np.testing.assert_allclose(scores.set_index("method")["iqm"][list(last)], list(last.values()))
    # PPO did not run: its pair is left out; the other two compare the last evaluations
    assert list(zip(verdicts["ahead"], verdicts["behind"], strict=True)) == [
        ("Di-SkilL", "BBRL"), ("Di-SkilL", "LinDi-SkilL")]  # fmt: skip
    assert list(verdicts["as_in_thesis"]) == [last["diskill"] > last["bbrl"],
                                              last["diskill"] > last["lindiskill"]]  # fmt: skip
    assert list(verdicts["methods"]) == [("diskill", "bbrl"), ("diskill", "lindiskill")]
    # equal IQMs (here the same runs under two names) are no ranking, not a verdict either way
    _, tied = DS.final_scores("4.3c", {"diskill": reacher_runs["bbrl"],
                                      "bbrl": reacher_runs["bbrl"]}, reps=50)  # fmt: skip
    assert list(tied["as_in_thesis"]) == [None]
    with pytest.raises(ValueError, match="unknown figure '4.9'"):
        DS.final_scores("4.9", reacher_runs)
    with pytest.raises(ValueError, match="unknown method"):
        DS.final_scores("4.3c", {"sac": reacher_runs["bbrl"]})


def test_fig_4_2_analysis(reacher_runs):
    model = D.load_model(reacher_runs["diskill"][0])
    assert model.iteration == 2 and model.config.n_experts == 2
    grid = R.disk_grid(11)
    assert (np.hypot(grid[:, 0], grid[:, 1]) <= 0.5).all() and len(grid) > 60
    pref = R.log_preference(model, grid)
    assert pref.shape == (2, len(grid))
    # log π(c|o) − log p(c) integrates to one over p(c): mean of exp over p(c) samples ≈ 1
    c = model.task.sample_contexts(4000, np.random.default_rng(7))
    np.testing.assert_allclose(np.exp(R.log_preference(model, c)).mean(1), 1.0, atol=0.05)
    n = R.active_experts(model, grid)
    assert n.shape == (len(grid),) and n.min() >= 0 and n.max() <= 2
    reaches = R.reaches(model, np.array([0.2, 0.3]))
    assert [r["expert"] for r in reaches] == [0, 1]
    assert abs(sum(r["gating"] for r in reaches) - 1) < 1e-9
    assert all(r["tip"].shape == (201, 3) for r in reaches)
    fig, axes = plt.subplots(1, 3)
    R.draw_context_regions(axes[0], model, grid)
    R.draw_active_experts(axes[1], model, grid)
    R.draw_reaches(axes[2], model, np.array([[0.2, 0.3], [-0.3, -0.1]]))
    # the count of active experts on a discrete scale: one colour and one tick per number
    bar = axes[1].collections[0].colorbar
    assert list(bar.get_ticks()) == list(range(max(int(n.max()), 1) + 1))
    counts = axes[1].collections[0]
    assert counts.cmap.N == len(bar.get_ticks())
    np.testing.assert_array_equal(counts.norm.boundaries, np.arange(len(bar.get_ticks()) + 1) - 0.5)
    plt.close(fig)
    bbrl = D.load_model(reacher_runs["bbrl"][0])
    with pytest.raises(ValueError, match="BBRL"):
        R.log_preference(bbrl, grid)
    expected = diskill_config("reacher5", "bbrl", iterations=2, test_every=1, test_contexts=10,
                              n_experts=1, samples_per_expert=4)  # fmt: skip
    assert asdict(bbrl.config) == asdict(expected)


def test_goal_returns_by_angle(reacher_runs):
    import json
    import math

    goals = R.ring(0.4, 90.0)
    np.testing.assert_allclose(goals, [[-0.4, 0], [0, -0.4], [0.4, 0], [0, 0.4]], atol=1e-12)
    bbrl = D.load_model(reacher_runs["bbrl"][0])
    t = R.goal_returns(bbrl, goals)
    assert list(t.columns) == ["angle", "radius", "expert", "return", "tip_distance"]
    np.testing.assert_allclose(t["angle"], [-180, -90, 0, 90], atol=1e-9)  # from −180° on
    np.testing.assert_allclose(t["radius"], 0.4)
    assert (t["expert"] == 0).all()  # BBRL: one policy
    # on the run's own test contexts BBRL's mean θ gives the test return its run logged last
    lines = (reacher_runs["bbrl"][0] / "metrics.jsonl").read_text().splitlines()
    logged = [json.loads(x)["test_return"] for x in lines if "test_return" in json.loads(x)]
    own = R.goal_returns(bbrl, bbrl.test_contexts)
    assert own["return"].mean() == pytest.approx(logged[-1], rel=1e-9)
    # the final tip distance from the simulated path (Fig. 4.2c's reaches), goal by goal
    dis = D.load_model(reacher_runs["diskill"][0])
    d = R.goal_returns(dis, goals, seed=3)
    assert d.equals(R.goal_returns(dis, goals, seed=3))
    theta = dis.mean_parameters(goals, d["expert"].to_numpy())
    for th, goal, dist in zip(theta, goals, d["tip_distance"], strict=True):
        tip = dis.task.path(th, goal)["fingertip"][-1, :2]
        assert dist == pytest.approx(math.dist(tip, goal), abs=1e-9)
    fig, ax = plt.subplots()
    R.draw_goal_returns(ax, {"Di-SkilL": d, "BBRL": t})
    assert [line.get_label() for line in ax.get_lines()] == ["Di-SkilL", "BBRL"]
    np.testing.assert_allclose(ax.get_lines()[1].get_xdata(), [-180, -90, 0, 90], atol=1e-9)
    assert ax.get_yscale() == "symlog"
    # the shaded bands are the goals behind the arm, |angle| from 150° to 180°
    spans = sorted((p.get_x(), p.get_x() + p.get_width()) for p in ax.patches)
    np.testing.assert_allclose(spans, [[-180, -150], [150, 180]])
    assert R.BEHIND_ARM_DEG == 150
    plt.close(fig)
    with pytest.raises(ValueError, match=r"goals must be an \(M, 2\) array.*\(3,\)"):
        R.goal_returns(bbrl, np.zeros(3))
    with pytest.raises(ValueError, match=r"radius must be in \(0, 0.5\].*0.6"):
        R.ring(0.6)
    with pytest.raises(ValueError, match="step must be in .*got 0"):
        R.ring(0.4, 0)


def test_ppo_ch4_from_the_command_line(tmp_path, monkeypatch):
    """`vslbook run ppo-ch4`: Table B.3 at Di-SkilL's episode count; rows carry `samples`."""
    from vslbook.budget import get_budget
    from vslbook.erl.ppo_ch4 import matched_total_steps
    from vslbook.experiments.ch4_algorithms import ppo_defaults
    from vslbook.results import RunDir

    full = ppo_defaults("vslbook/Reacher5SparseStep-v0", get_budget("full"), {})
    assert full.total_steps == matched_total_steps("reacher5") == 9156 * 16384
    assert (full.learning_rate, full.batch_size, full.net_arch, full.gamma) == (
        3e-4,
        512,
        (32, 32),
        1.0,
    )
    red = ppo_defaults("vslbook/BoxPushingObstacleStep-v0", get_budget("reduced"), {})
    # Di-SkilL at reduced on box pushing: 90 iterations x 5 experts x 50 episodes of 100 steps
    assert red.total_steps == -(-90 * 5 * 50 * 100 // 16384) * 16384
    # 5LR at reduced: Di-SkilL's 300 x 250 episodes of 200 steps (15M) exceed the budget's
    # 5 % of the full run (0.05 x 9156 rollouts = 457.8), so PPO gets 458 rollouts.
    red_5lr = ppo_defaults("vslbook/Reacher5SparseStep-v0", get_budget("reduced"), {})
    assert red_5lr.total_steps == 458 * 16384 < 300 * 250 * 200
    with pytest.raises(ValueError, match="not on 'hopper-jump'"):
        D.ppo_steps("hopper-jump", "reduced")
    monkeypatch.setenv("VSLBOOK_WORKERS", "1")
    ppo = next(r for r in D.figure_runs("fig4-3c", "smoke") if r.method == "ppo")
    assert (ppo.algo, ppo.env, ppo.length, ppo.unit) == (
        "ppo-ch4", "vslbook/Reacher5SparseStep-v0", 16384, "env_steps")  # fmt: skip
    path = ppo.train(tmp_path)
    rows = RunDir.open(path).metrics()
    assert rows[-1]["samples"] == rows[-1]["episodes"] > 0 and rows[-1]["env_steps"] == 16384
    assert ppo.train(tmp_path) == path  # finished: reused
    assert not any(r.method == "ppo" for r in D.figure_runs("fig4-4d", "reduced"))


def test_skills_at_a_context(reacher_runs):
    """Figs. 4.5 / 4.6: the experts the gating picks at a context, most probable first."""
    from vslbook.experiments import diskill_skills as SK

    model = D.load_model(reacher_runs["diskill"][0])
    c = np.array([0.2, 0.3])
    rows = SK.skills(model, c, min_gating=0.0)
    assert sorted(r["expert"] for r in rows) == [0, 1]
    assert rows[0]["gating"] >= rows[1]["gating"]
    assert abs(sum(r["gating"] for r in rows) - 1) < 1e-9
    # the chosen expert's mean at c, computed alone; float32, and a batch of one expert
    # takes other kernels than all experts at once (up to 2e-6 relative on an Intel Xeon)
    alone = model.mean_parameters(c[None], np.array([rows[0]["expert"]]))[0]
    np.testing.assert_allclose(rows[0]["theta"], alone, rtol=1e-5, atol=1e-7)
    other = model.mean_parameters(c[None], np.array([rows[1]["expert"]]))[0]
    assert np.abs(other - alone).max() > 1e-3  # the tolerance tells the experts apart
    assert SK.skills(model, c, min_gating=0.99) == []
    fig, ax = plt.subplots()
    with pytest.raises(ValueError, match="not 'ball'"):
        SK.draw_skills(ax, model, c, "ball")
    plt.close(fig)


def test_chapter4_curves_from_the_command_line(tmp_path, monkeypatch):
    """`vslbook figure fig4-4a`: trains the hopper-jump run set in ./runs and saves the panel,
    whose title says how the counts differ from the thesis's."""
    import vslbook.figures  # noqa: F401 -- registers the figures
    from vslbook.experiments import figure_draws
    from vslbook.registry import FIGURES

    monkeypatch.setenv("VSLBOOK_WORKERS", "1")
    monkeypatch.chdir(tmp_path)
    paths = FIGURES["fig4-4a"].make(budget="smoke", out_dir=tmp_path / "out")
    assert sorted(p.name for p in paths) == ["fig4-4a.pdf", "fig4-4a.png"]
    assert len(list((tmp_path / "runs").glob("*/DONE"))) == 3  # Di-SkilL, BBRL, LinDi-SkilL
    fig = figure_draws.draw_diskill_curves("4.4a", "smoke", tmp_path / "runs", progress=False)
    title = fig.axes[0].get_title()
    assert "the authors' settings, budget smoke: 2 of 1400 iterations, 1 of 24 seeds, " \
           "2 of 3 experts, 4 of 100 samples" in title  # HJ: the code's 100 samples (B.5: 80)
    plt.close(fig)
    with pytest.raises(ValueError, match="unknown figure '4.7'"):
        figure_draws.draw_diskill_curves("4.7", "smoke", tmp_path / "runs")

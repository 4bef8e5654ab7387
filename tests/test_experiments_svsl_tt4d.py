"""SVSL on Chapter 4's table tennis (Fig. 4.3b): Table B.1's preset, the guiding punishment
R_c(c) = −20 d_c² (B.4.1.1) on contexts outside the valid region, a smoke run from the
command line that resumes exactly, and Fig. 4.3b's declared runs."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from vslbook.budget import get_budget
from vslbook.cli import main
from vslbook.registry import get_algorithm
from vslbook.training import run

ENV = "vslbook/TableTennis4D-v0"


def _rows(path):
    return [json.loads(x) for x in (path / "metrics.jsonl").read_text().splitlines()]


def _preset(budget: str = "full", **overrides):
    return get_algorithm("svsl").default_config(ENV, get_budget(budget), overrides)


# ------------------------------------------------------------------------------- preset
def test_full_preset_is_table_b1_and_the_rest_is_chapter_3s_table_tennis():
    c = _preset()
    b1 = (c.iterations_per_expert, c.fine_tune_every, c.n_experts, c.new_samples_expert,
          c.alpha, c.beta, c.kl_expert, c.kl_context)  # fmt: skip
    assert b1 == pytest.approx((1000, 50, 20, 200, 1e-4, 0.5, 0.01, 0.01))
    tt3 = get_algorithm("svsl").default_config("vslbook/TableTennisCh3-v0", get_budget("full"), {})
    for name in ("beta_w", "kl_weights", "delete_threshold", "weight_iterations",
                 "new_samples_context", "delete_local_optima"):  # fmt: skip
        assert getattr(c, name) == getattr(tt3, name), name
    # buffer: 1.5 × the parameters of a quadratic in d = 4 + 23 variables
    assert c.buffer_size == int(1.5 * (1 + 27 + 27 * 28 / 2)) == 609
    # Chapter 3's [goal, ball] initial context spreads in this task's [ball, goal] order
    perm = [2, 3, 0, 1]
    assert c.context_init_offset_std == tuple(np.array(tt3.context_init_offset_std)[perm])
    assert c.context_init_cov == tuple(np.array(tt3.context_init_cov)[perm])
    assert c.expert_init_cov == (1.0,) * 23
    assert c.entropy_draws is None  # Fig. 4.3b draws no entropy


def test_a_budget_changes_only_counts():
    full, smoke = _preset(), _preset("smoke")
    counts = {"n_experts", "iterations_per_expert", "weight_iterations", "test_every",
              "test_contexts"}  # fmt: skip
    for name in full.__dataclass_fields__:
        if name not in counts:
            assert getattr(full, name) == getattr(smoke, name), name
    assert smoke.n_experts * smoke.iterations_per_expert + smoke.weight_iterations == 2


def test_the_baselines_do_not_run_on_chapter_4s_table_tennis():
    for algo in ("hireps", "ladips"):
        with pytest.raises(ValueError, match="no Chapter 3 preset"):
            get_algorithm(algo).default_config(ENV, get_budget("smoke"), {})


# --------------------------------------------------------------------------- punishment
def _valid_box(goal_y: float = 0.65):
    """The valid contexts of the 4D task, from the serve's ballistics written out here:
    the ball starts 1.08 m above the table (1.75 − 0.77 + 0.1) with v_z = 0.5, v_x = 2.5;
    it must clear the 0.1 m net (x + v_x t_net ≥ 0.05) and land before x = 1.1."""
    g, vz, vx, z = 9.81, 0.5, 2.5, 1.75 - 0.77 + 0.1
    t_net = (vz + math.sqrt(vz**2 + 2 * g * (z - 0.1))) / g
    t_land = (vz + math.sqrt(vz**2 + 2 * g * z)) / g
    lo = np.array([max(-1.0, 0.05 - vx * t_net), -0.6, -1.0, -goal_y])
    hi = np.array([min(-0.2, 1.1 - vx * t_land), 0.6, -0.2, goal_y])
    return lo, hi


def test_out_of_region_contexts_get_minus_20_d_squared():
    from vslbook.envs.robot import make_task

    task = make_task("table-tennis-4d")
    lo, hi = _valid_box()
    assert hi[0] == pytest.approx(-0.20741, abs=1e-5)  # the serve rules cut x_ball0
    c = np.array([
        [-0.1, 0.0, -0.5, 0.0],   # x_ball0 beyond the box and the serve: d = 0.1 + 0.0074
        [-0.5, 0.7, -0.5, 0.0],   # y_ball0 0.1 beyond the table's half width (box: 0.05)
        [-1.1, 0.0, -0.1, 0.7],   # three entries out: d² = 0.1² + 0.1² + 0.05²
        [-0.205, -0.62, -1.3, 0.0],  # just past the serve rule, the table, the goal box
        [-0.5, 0.3, -0.6, -0.4],  # valid: no punishment
    ])  # fmt: skip
    by_hand = np.array([
        -20 * (-0.1 - hi[0]) ** 2,
        -20 * 0.1**2,
        -20 * (0.1**2 + 0.1**2 + 0.05**2),
        -20 * ((-0.205 - hi[0]) ** 2 + 0.02**2 + 0.3**2),
        0.0,
    ])  # fmt: skip
    pen = task.context_penalty(c)
    np.testing.assert_allclose(pen, by_hand, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(by_hand[:3], [-0.23075429, -0.2, -0.45], atol=1e-8)
    assert task.context_penalty(c[1]) == pytest.approx(by_hand[1])  # one context
    # SVSL's evaluation: punished, not simulated, not an executed episode
    out = task.evaluate(np.zeros(task.n_params), c[:4], workers=0, out_of_range="penalise")
    np.testing.assert_allclose(out.returns, by_hand[:4])
    assert out.n_executed == 0 and not out.success.any()
    # Di-SkilL's (the default): an out-of-region context is an error, p(c) is valid only
    with pytest.raises(ValueError, match="outside the task's context space"):
        task.evaluate(np.zeros(task.n_params), c[:1], workers=0)
    drawn = task.sample_contexts(500, np.random.default_rng(0))
    assert np.all((drawn >= lo) & (drawn <= hi)) and not task.context_penalty(drawn).any()
    # settings="thesis" narrows the goal y to ±0.6 (B.4.1.1): 0.62 is 0.02 out
    thesis = make_task("table-tennis-4d", settings="thesis")
    assert thesis.context_penalty(np.array([-0.5, 0.0, -0.5, 0.62])) == pytest.approx(-20 * 0.02**2)


# --------------------------------------------------------------------------------- runs
def test_cli_smoke_run_trains_and_resumes_exactly(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("VSLBOOK_WORKERS", "0")  # in-process: no pool start-up in a test
    args = ["run", "svsl", "--env", ENV, "--seed", "0", "--budget", "smoke"]
    assert main([*args, "--root", str(tmp_path / "a")]) == 0
    (whole,) = (tmp_path / "a").iterdir()
    assert (whole / "DONE").exists()
    part = run("svsl", ENV, seed=0, budget="smoke", root=tmp_path / "b", progress=False,
               stop_after=1)  # fmt: skip
    assert not part.done and len(_rows(part.path)) == 1
    part = run("svsl", ENV, seed=0, budget="smoke", root=tmp_path / "b", progress=False)
    assert part.done and part.path.name == whole.name
    drop = {"iteration_seconds", "wall_time", "time"}
    a, b = _rows(whole), _rows(part.path)
    assert [{k: v for k, v in r.items() if k not in drop} for r in a] == [
        {k: v for k, v in r.items() if k not in drop} for r in b
    ]
    assert len(a) == 2 and all("test_success" in r and "samples" in r for r in a)
    # samples are executed episodes: far fewer than the 609 + 2 × 208 drawn (θ starts at
    # τ = delay = 0 ± 1, mostly outside their bounds, and some contexts are punished)
    assert 0 <= a[-1]["samples"] < 609 + 2 * 208


def test_fig_4_3b_declares_svsl_at_every_budget(capsys):
    from vslbook.experiments import diskill_runs as DR

    assert DR.LABELS["svsl"] == "SVSL" and "svsl" in DR.FIGURES["4.3b"][1]
    for budget in ("smoke", "reduced", "full"):
        runs = DR.figure_runs("fig4-3b", budget)
        svsl = [r for r in runs if r.method == "svsl"]
        seeds = DR.counts("table-tennis-4d", "diskill", budget)["seeds"]
        assert [r.seed for r in svsl] == list(range(seeds))  # the other methods' seeds
        cfg = _preset(budget)
        assert {(r.algo, r.env, r.length, r.unit) for r in svsl} == {
            ("svsl", ENV, cfg.total_iterations, "step")
        }
    assert len([r for r in DR.figure_runs("fig4-3b", "full") if r.method == "svsl"]) == 24
    assert _preset("full").total_iterations == 20 * 1000 + 100
    with pytest.raises(ValueError, match="SVSL runs on table-tennis-4d"):
        DR.counts("reacher5", "svsl", "smoke")
    capsys.readouterr()
    assert main(["train", "fig4-3b", "--methods", "svsl", "--dry-run", "--budget", "reduced"]) == 0
    names = capsys.readouterr().out.split()
    assert names == [r.name for r in DR.figure_runs("fig4-3b", "reduced") if r.method == "svsl"]

"""`vslbook run svsl / hireps / ladips / ppo`: the presets per env, exact resume, bad input.

The presets are compared with Tables A.1-A.5 written out here; a run of
:func:`vslbook.training.run` is the one the Chapter 3 figures declare
(:mod:`vslbook.experiments.ch3_runs`), so the command line trains what the figures show.
"""

from __future__ import annotations

import json

import pytest

from vslbook.budget import get_budget
from vslbook.cli import main
from vslbook.registry import get_algorithm
from vslbook.training import run

PLANAR = "vslbook/PlanarReacher-v0"
REACHER = "vslbook/Reacher5Ch3-v0"


def _rows(path):
    return [json.loads(x) for x in (path / "metrics.jsonl").read_text().splitlines()]


def _preset(algo: str, env: str, budget: str = "full", **overrides):
    return get_algorithm(algo).default_config(env, get_budget(budget), overrides)


@pytest.mark.parametrize(
    ("env", "overrides", "table"),
    [  # Table A.1 and A.4: α, β, β_w, N, K, H (table tennis: the authors' K = 1000, which
        # drew Fig. 3.2b; Table A.1's 800 is table_tennis_counts(settings="thesis"))
        ("vslbook/PlanarReacher-v0", {}, (1e-4, 1.0, 1.0, 60, 350, 50)),
        ("vslbook/BeerPong-v0", {}, (1e-3, 0.5, 2.5, 70, 750, 50)),
        ("vslbook/TableTennisCh3-v0", {}, (1e-5, 0.2, 0.2, 50, 1000, 50)),
        (REACHER, {"reward": "3.8"}, (1e-6, 15.0, 15.0, 40, 250, 50)),
        (REACHER, {"reward": "3.9"}, (0.01, 1.0, 2.5, 40, 250, 50)),
        (REACHER, {"reward": "3.10"}, (1.0, 25.0, 25.0, 40, 800, 50)),
    ],
)
def test_svsl_full_presets_are_tables_a1_a4(env, overrides, table):
    c = _preset("svsl", env, **overrides)
    got = (c.alpha, c.beta, c.beta_w, c.n_experts, c.iterations_per_expert, c.fine_tune_every)
    assert got == pytest.approx(table)
    assert c.reward == overrides.get("reward")


def test_baseline_and_ppo_full_presets_are_tables_a2_a3_a5():
    h = _preset("hireps", "vslbook/BeerPong-v0")
    assert (h.eps, h.kappa, h.n_experts) == (0.3, 0.9, 70)  # Table A.2, beer pong
    lad = _preset("ladips", "vslbook/TableTennisCh3-v0")
    assert lad.n_experts == 50  # N of table tennis, as SVSL's
    p = _preset("ppo", "vslbook/Reacher5Ch3Step-v0", reward="3.8")
    table_a5 = (1e-4, 16384, 0.95, 0.99, 64, 0.2, (64, 64), True)
    got = (p.learning_rate, p.n_rollout_steps, p.gae_lambda, p.gamma, p.batch_size,
           p.clip_range, p.net_arch, p.normalize)  # fmt: skip
    assert got == table_a5 and p.reward == "3.8"
    # the baselines are tested as often as SVSL over their run: 750 * 70 + 100 iterations
    # of SVSL tested every 50 give 1052 test points (whole iterations between tests: at
    # least as many, fewer than twice)
    assert 1052 <= h.iterations // h.test_every < 2 * 1052


def test_a_budget_changes_only_counts():
    full, reduced = _preset("svsl", "vslbook/BeerPong-v0"), _preset("svsl", "vslbook/BeerPong-v0",
                                                                      "reduced")  # fmt: skip
    counts = {"n_experts", "iterations_per_expert", "weight_iterations", "test_every",
              "test_contexts", "entropy_draws", "entropy_grid", "entropy_contexts",
              "entropy_every"}  # fmt: skip  (the entropy probe's sizes are counts too)
    for name in full.__dataclass_fields__:
        if name not in counts:
            assert getattr(full, name) == getattr(reduced, name), name
    assert reduced.n_experts < full.n_experts


def test_cli_run_trains_the_notebooks_configuration(tmp_path):
    """`vslbook run svsl` on the planar reacher trains the run Fig. 3.1 (the notebook,
    `vslbook figure fig3-1`) draws: the figure finds it finished and reuses it."""
    from vslbook.experiments.ch3_runs import run_set

    rd = run("svsl", PLANAR, seed=0, budget="smoke", root=tmp_path, progress=False)
    assert rd.done and len(_rows(rd.path)) == 110  # N K + weight iterations: 2 * 50 + 10
    stamp = (rd.path / "DONE").stat().st_mtime_ns
    assert run_set("fig3-1", "smoke", tmp_path, methods=("SVSL",)) == {"SVSL": [rd.path]}
    assert (rd.path / "DONE").stat().st_mtime_ns == stamp


@pytest.mark.parametrize(("algo", "env", "first"), [
    ("svsl", PLANAR, 37), ("hireps", PLANAR, 7),
])  # fmt: skip
def test_interrupted_run_resumes_exactly(algo, env, first, tmp_path):
    whole = run(algo, env, seed=2, budget="smoke", root=tmp_path / "a", progress=False)
    part = run(algo, env, seed=2, budget="smoke", root=tmp_path / "b", progress=False,
               stop_after=first)  # fmt: skip
    assert not part.done and len(_rows(part.path)) == first
    part = run(algo, env, seed=2, budget="smoke", root=tmp_path / "b", progress=False)
    assert part.done
    a, b = _rows(whole.path), _rows(part.path)
    drop = {"iteration_seconds", "wall_time", "time"}
    assert [{k: v for k, v in r.items() if k not in drop} for r in a] == [
        {k: v for k, v in r.items() if k not in drop} for r in b
    ]
    assert any("test_return" in r for r in a)


def test_set_overrides_a_preset(tmp_path):
    rd = run("svsl", PLANAR, budget="smoke", root=tmp_path, progress=False, stop_after=1,
             overrides={"responsibilities": "false", "context_init_cov": "2, 3"})  # fmt: skip
    assert rd.config["responsibilities"] is False
    assert rd.config["context_init_cov"] == [2.0, 3.0]
    assert rd.config["alpha"] == pytest.approx(1e-4)  # the rest is the planar preset


def test_bad_input_names_the_value(tmp_path, capsys):
    with pytest.raises(ValueError, match=r"needs reward= one of 3.8, 3.9, 3.10.*None"):
        run("svsl", REACHER, budget="smoke", root=tmp_path)
    with pytest.raises(ValueError, match=r"needs reward=.*'3.11'"):
        run("svsl", REACHER, budget="smoke", root=tmp_path, overrides={"reward": "3.11"})
    with pytest.raises(ValueError, match=r"reward= only applies to vslbook/Reacher5Ch3-v0"):
        run("svsl", "vslbook/BeerPong-v0", budget="smoke", root=tmp_path,
            overrides={"reward": "3.8"})  # fmt: skip
    with pytest.raises(ValueError, match=r"'ladips' does not support env 'vslbook/PlanarReacher"):
        run("ladips", PLANAR, budget="smoke", root=tmp_path)
    with pytest.raises(ValueError, match=r"cannot convert context_init_cov=.1,x. to tuple\[float"):
        run("svsl", PLANAR, budget="smoke", root=tmp_path,
            overrides={"context_init_cov": "1,x"})  # fmt: skip
    assert not any(tmp_path.iterdir())  # nothing written for a request that was refused
    assert main(["run", "hireps", "--env", REACHER, "--budget", "smoke"]) == 2
    assert "does not support env" in capsys.readouterr().err


def test_reacher_run_is_the_notebooks_and_tested_on_ppos_goals(tmp_path):
    """SVSL on the 5-link reacher with `--set reward=3.8` is Fig. 3.5's run (the same
    directory), tested on PPO's evaluation goals."""
    import numpy as np

    from vslbook.erl.ppo import evaluation_goals
    from vslbook.experiments.ch3_runs import figure_runs
    from vslbook.experiments.svsl_mixtures import load_model

    rd = run("svsl", REACHER, seed=0, budget="smoke", root=tmp_path, progress=False,
             overrides={"reward": "3.8"})  # fmt: skip
    (declared,) = [r for r in figure_runs("fig3-5", "smoke") if r.method == "SVSL Eq. 3.8"]
    assert declared.name == rd.name and declared.train(tmp_path) == rd.path
    rows = _rows(rd.path)
    assert rows[-1]["test_return"] is not None and rd.config["reward"] == "3.8"
    model = load_model(rd.path)  # the last test: θ ~ π(θ | c) on the goals PPO is scored on
    goals = evaluation_goals(rd.config["test_contexts"])
    theta, _ = model.model.sample(goals, np.random.default_rng([0, 2, len(rows)]))
    out = model.task.evaluate(theta, goals, workers=0)
    assert rows[-1]["test_return"] == pytest.approx(float(np.mean(out.returns)), rel=1e-12)


def test_sweep_checks_each_env_against_its_preset(tmp_path):
    from vslbook.sweep import sweep

    paths = sweep("hireps", [PLANAR], [0], grid={"eps": ["0.5"]}, budget="smoke",
                  root=tmp_path, executor="debug")  # fmt: skip
    assert len(paths) == 1
    with pytest.raises(ValueError, match=r"needs reward="):
        sweep("svsl", [REACHER], [0], budget="smoke", root=tmp_path, executor="debug")
    with pytest.raises(ValueError, match=r"has no field 'nope'"):
        sweep("svsl", [PLANAR], [0], grid={"nope": ["1"]}, budget="smoke", root=tmp_path,
              executor="debug")  # fmt: skip

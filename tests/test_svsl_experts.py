"""The per-expert diagnostics of an SVSL model (vslbook.experiments.svsl_experts): experts
placed by hand, each column checked against what the placement implies."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vslbook.envs.robot import make_task
from vslbook.erl.svsl import SVSL
from vslbook.experiments.svsl_experts import COLUMNS, expert_table, load_svsl
from vslbook.experiments.svsl_table_tennis_4d import svsl_tt_config
from vslbook.training import run

ENV = "vslbook/TableTennis4D-v0"


@pytest.fixture(scope="module")
def svsl():
    """An SVSL state on the 4D table tennis with two experts placed by hand: one whose
    contexts all lie far outside the valid region (mean θ = 0.3 in every coordinate), one
    whose contexts all lie at the centre of the valid box with θ = 0 and a narrow
    covariance."""
    task = make_task("table-tennis-4d")
    s = SVSL(task, svsl_tt_config("smoke"), seed=0)
    dc, dt = task.context_dim, task.n_params
    centre = 0.5 * (task.context_low + task.context_high)
    tiny = 1e-8 * np.eye(dc)
    s.model.add_expert(centre + np.array([5.0, 0, 0, 0]), tiny, np.zeros((dt, dc)),
                       np.full(dt, 0.3), 0.5**2 * np.eye(dt))  # fmt: skip
    s.model.add_expert(centre, tiny, np.zeros((dt, dc)), np.zeros(dt), 1e-6**2 * np.eye(dt))
    yield s
    task.close()


def test_columns_follow_from_where_the_experts_were_placed(svsl):
    t = expert_table(svsl, draws=3, workers=0)
    assert tuple(t.columns) == COLUMNS and list(t["expert"]) == [0, 1]
    dt, dc = svsl.task.n_params, svsl.task.context_dim
    # Gaussian entropies written out: ½ d log(2πe σ²)
    h = lambda d, s: 0.5 * d * math.log(2 * math.pi * math.e * s**2)  # noqa: E731
    np.testing.assert_allclose(t["expert_entropy"], [h(dt, 0.5), h(dt, 1e-6)], rtol=1e-10)
    np.testing.assert_allclose(t["expert_entropy_start"], h(dt, 1.0), rtol=1e-10)  # Σ₀ = I
    np.testing.assert_allclose(t["context_entropy"], h(dc, 1e-4), rtol=1e-10)
    np.testing.assert_allclose(t["pi_o"], [0.5, 0.5])
    far, centre = t.iloc[0], t.iloc[1]
    # all of the far expert's contexts are punished and never simulated: −20 d², with d the
    # distance of x_ball0 = −0.6 + 5 past −0.20741 (the serve rule's end of the valid x)
    assert far["context_valid"] == 0 and far["executed"] == 0 and far["success"] == 0
    d = -0.6 + 5.0 - -0.20741
    assert far["return"] == pytest.approx(-20 * d**2, rel=1e-4)
    # the centred expert's contexts are all valid
    assert centre["context_valid"] == 1
    # every test context goes to the expert holding it: the far one holds none
    assert far["test_contexts"] == 0 and math.isnan(far["test_success"])
    assert centre["test_contexts"] == len(svsl.test_contexts)
    assert 0 <= centre["test_success"] <= 1


def test_draws_are_seeded(svsl):
    a = expert_table(svsl, draws=2, seed=3, workers=0)
    b = expert_table(svsl, draws=2, seed=3, workers=0)
    assert a.equals(b)


@pytest.mark.parametrize("draws", [0, -1, 2.5, True, "4"])
def test_bad_draws_are_named(svsl, draws):
    with pytest.raises(ValueError, match=f"draws must be a positive integer, got {draws!r}"):
        expert_table(svsl, draws=draws)


def test_a_model_without_experts_is_an_error():
    task = make_task("table-tennis-4d")
    try:
        with pytest.raises(ValueError, match="no experts yet"):
            expert_table(SVSL(task, svsl_tt_config("smoke"), seed=0))
    finally:
        task.close()


def test_load_svsl_restores_a_run_and_refuses_other_algorithms(tmp_path, monkeypatch):
    monkeypatch.setenv("VSLBOOK_WORKERS", "0")
    r = run("svsl", ENV, seed=0, budget="smoke", root=tmp_path, progress=False)
    s = load_svsl(r.path)
    assert s.iteration == s.config.total_iterations and s.model.n_experts == 1
    assert len(expert_table(s, draws=2, workers=0)) == 1
    (r.path / "config.json").write_text((r.path / "config.json").read_text()
                                        .replace('"algo": "svsl"', '"algo": "hireps"'))  # fmt: skip
    with pytest.raises(ValueError, match="'hireps' run, expected an 'svsl' run"):
        load_svsl(r.path)


def test_test_contexts_are_run_with_the_mean_of_the_expert_holding_them(svsl, monkeypatch):
    """Algorithm 3's inference: each test context c is run with the mean θ of
    argmax_o π(o | c), here the centred expert's θ = 0 for every one, never the far
    expert's 0.3."""
    seen = []
    evaluate = svsl.task.evaluate

    def spy(theta, contexts, **kw):
        seen.append((np.array(theta), np.array(contexts)))
        return evaluate(theta, contexts, **kw)

    monkeypatch.setattr(svsl.task, "evaluate", spy)
    expert_table(svsl, draws=1, workers=0)
    tests = [(th, c) for th, c in seen if np.array_equal(c, svsl.test_contexts)]
    assert len(tests) == 1
    np.testing.assert_array_equal(tests[0][0], np.zeros((len(svsl.test_contexts),
                                                         svsl.task.n_params)))  # fmt: skip


def test_load_svsl_keeps_the_test_contexts_its_run_used(tmp_path, monkeypatch):
    """The Chapter 3 5-link reacher's SVSL is tested on PPO's evaluation goals (Fig. 3.5):
    the loaded model's test contexts are the ones its run logged its success on."""
    from vslbook.erl.ppo import evaluation_goals

    monkeypatch.setenv("VSLBOOK_WORKERS", "0")
    r = run("svsl", "vslbook/Reacher5Ch3-v0", seed=0, budget="smoke", root=tmp_path,
            progress=False, overrides={"reward": "3.8"})  # fmt: skip
    s = load_svsl(r.path)
    np.testing.assert_array_equal(s.test_contexts, evaluation_goals(s.config.test_contexts))

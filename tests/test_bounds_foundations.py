"""Tests for vslbook.bounds: the Check type and the Chapter 2 numerical checks.

Every check must pass for a few seeds, and each key check must fail when handed a wrong
candidate (a non-optimal policy, a wrong variance formula, a loose variational distribution).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.special import softmax
from scipy.stats import norm

from vslbook.bounds import Check, CheckReport, show
from vslbook.bounds import foundations as F
from vslbook.dists import gaussian_kl

SEEDS = (0, 1, 2)
CHECKS = (
    F.check_soft_optimal_policy,
    F.check_self_paced,
    F.check_moe_gating,
    F.check_ou_marginals,
    F.check_kl_chain_rule,
    F.check_mixture_estep_bound,
    F.check_diffusion_kl,
    F.check_maxent_as_inference,
    F.check_mutual_information,
)


# ---------------------------------------------------------------------------- Check


def test_check_relations():
    assert Check("a", "Eq. 1", 1.0, 1.0 + 1e-10, 1e-9).passed
    assert not Check("a", "Eq. 1", 1.0, 1.1, 1e-9).passed
    assert Check("b", "Eq. 1", 1.0, 2.0, 0.0, "<=").passed
    assert Check("b", "Eq. 1", 2.0 + 1e-10, 2.0, 1e-9, "<=").passed
    assert not Check("b", "Eq. 1", 2.1, 2.0, 1e-9, "<=").passed
    assert not Check("c", "Eq. 1", float("nan"), 0.0, 1.0).passed


def test_check_require_and_summary():
    good = Check("identity", "Eq. 2.60", 1.0, 1.0, 1e-9)
    assert good.require() is good
    assert str(good).startswith("[PASS] identity (Eq. 2.60)")
    assert "identity" in good._repr_markdown_()
    bad = Check("bound", "Eq. 2.73", 3.0, 2.0, 0.1, "<=")
    assert "[FAIL]" in str(bad)
    with pytest.raises(AssertionError, match="bound"):
        bad.require()


def test_check_rejects_bad_arguments():
    with pytest.raises(ValueError, match="relation"):
        Check("x", "Eq. 1", 0.0, 0.0, 0.0, ">=")
    with pytest.raises(ValueError, match="tol"):
        Check("x", "Eq. 1", 0.0, 0.0, -1.0)


def test_report_collects_failures():
    report = CheckReport("demo", (Check("ok", "Eq. 1", 0, 0, 0), Check("no", "Eq. 2", 1, 0, 0)))
    assert not report.passed
    assert [c.name for c in report.failed] == ["no"]
    assert report["ok"].passed
    with pytest.raises(AssertionError, match="1 check"):
        report.require()
    assert "demo" in str(report) and "demo" in report._repr_markdown_()


def test_show_prints_outside_a_notebook_and_stops_on_a_failure(capsys):
    good = CheckReport("fine", (Check("ok", "Eq. 1", 0, 0, 0),))
    assert show(good) is good
    assert "[PASS] ok (Eq. 1)" in capsys.readouterr().out
    bad = CheckReport("broken", (Check("no", "Eq. 2", 1, 0, 0),))
    with pytest.raises(AssertionError, match="broken: 1 check"):
        show(bad)
    assert "[FAIL] no (Eq. 2)" in capsys.readouterr().out  # shown before it stops
    with pytest.raises(TypeError, match="CheckReport, got Check"):
        show(good.checks[0])


# ------------------------------------------------------------------- every check passes


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("check", CHECKS, ids=lambda f: f.__name__)
def test_check_passes(check, seed):
    report = check(seed)
    assert isinstance(report, CheckReport) and len(report) > 0
    report.require()


def test_checks_are_deterministic():
    a, b = F.check_ou_marginals(3), F.check_ou_marginals(3)
    assert [c.lhs for c in a] == [c.lhs for c in b]


# ---------------------------------------------------------------- Section 2.4 helpers


def test_soft_value_iteration_limits():
    P, R = F.random_mdp(5, 3, seed=0)
    hard = F.soft_value_iteration(P, R, gamma=0.8, alpha=0.0)
    v = np.zeros(5)
    for _ in range(2000):
        v = (R + 0.8 * P @ v).max(-1)
    np.testing.assert_allclose(hard.v, v, atol=1e-9)
    soft = F.soft_value_iteration(P, R, gamma=0.8, alpha=0.3)
    np.testing.assert_allclose(soft.policy.sum(-1), 1.0)
    np.testing.assert_allclose(soft.v, 0.3 * np.log(np.exp(soft.q / 0.3).sum(-1)), atol=1e-12)


def test_mdp_validation():
    P, R = F.random_mdp(3, 2, seed=0)
    with pytest.raises(ValueError, match="P must be non-negative and sum to 1"):
        F.soft_value_iteration(P * 1.1, R, 0.9, 0.1)
    with pytest.raises(ValueError, match=r"gamma must lie in \[0, 1\)"):
        F.soft_value_iteration(P, R, 1.0, 0.1)
    with pytest.raises(ValueError, match=r"policy must have shape \(3, 2\)"):
        F.soft_policy_evaluation(P, R, np.ones((3, 3)) / 3, 0.9, 0.1)


def test_uniform_policy_is_not_soft_optimal():
    report = F.check_soft_optimal_policy(0, policy=np.full((6, 3), 1 / 3))
    assert not report["policy evaluation of pi equals V_soft in every state"].passed
    assert not report["J(pi) >= J of single-state perturbations of pi"].passed


def test_boltzmann_policy_at_wrong_temperature_is_not_soft_optimal():
    P, R = F.random_mdp(6, 3, seed=0)
    wrong = F.soft_value_iteration(P, R, gamma=0.9, alpha=1.0).policy  # check uses alpha=0.5
    report = F.check_soft_optimal_policy(0, policy=wrong)
    assert not report["J(pi) >= J of single-state perturbations of pi"].passed


# ---------------------------------------------------------------- Section 2.5 helpers


def test_self_paced_optimum_limits():
    _, p, returns = F.self_paced_problem()
    np.testing.assert_allclose(F.self_paced_optimum(1e6, p, returns), p, rtol=1e-5)
    cold = F.self_paced_optimum(1e-3, p, returns)
    assert np.argmax(cold) == np.argmax(returns)


@pytest.mark.parametrize(
    "wrong",
    [
        lambda beta, p, r: softmax(np.log(p) - r / beta),  # sign flipped
        lambda beta, p, r: softmax(np.log(p) + r * beta),  # temperature inverted
    ],
    ids=["sign", "temperature"],
)
def test_wrong_self_paced_optimum_fails(wrong):
    report = F.check_self_paced(0, optimum=wrong)
    assert not report["pi* beats perturbed and Gaussian-shaped context distributions"].passed


# ---------------------------------------------------------------- Section 2.6 helpers


def test_context_blind_gating_fails():
    report = F.check_moe_gating(0, gating=lambda model, c: model.weights.expand(c.shape[0], -1))
    assert not report.passed
    assert report.failed[0].name.startswith("gating pi(o|c) = p(o, c)")


def test_ou_marginal_closed_form_and_simulation_shapes():
    mean, var = F.ou_marginal(2.0, 0.5, beta=1.5, eta=0.7, t=np.array([0.0, 1.0, 50.0]))
    np.testing.assert_allclose(mean, [2.0, 2.0 * math.exp(-1.5), 0.0], atol=1e-12)
    np.testing.assert_allclose(var, [0.5, 0.5 * math.exp(-3) + 0.49 * (1 - math.exp(-3)), 0.49])
    times, paths = F.simulate_ou(np.zeros((4, 3)), beta=1.0, eta=1.0, T=1.0, n_steps=10, seed=0)
    assert times.shape == (11,) and paths.shape == (11, 4, 3)
    np.testing.assert_array_equal(paths, F.simulate_ou(np.zeros((4, 3)), 1.0, 1.0, 1.0, 10, 0)[1])


def test_wrong_ou_variance_formula_fails():
    def wrong(mean0, var0, beta, eta, t):  # e^{-beta t} where e^{-2 beta t} belongs
        decay = np.exp(-beta * t)
        return mean0 * decay, var0 * decay**2 + eta**2 * (1 - decay)

    report = F.check_ou_marginals(0, marginal=wrong)
    failed = [c.name for c in report.failed]
    assert failed and all(name.startswith("sample var") for name in failed)


# ---------------------------------------------------------------- Section 2.7 helpers


def test_kl_that_ignores_means_breaks_the_chain_rule():
    def wrong_kl(mp, cp, mq, cq):
        return gaussian_kl(mp, cp, mp, cq)

    report = F.check_kl_chain_rule(0, kl=wrong_kl)
    assert not report.failed[0].passed
    assert "Eq. 2.60" in report.failed[0].equation


def test_non_tight_variational_distribution_fails():
    report = F.check_mixture_estep_bound(0, variational=lambda x: np.full((x.size, 3), 1 / 3))
    assert [c.name for c in report.failed] == ["bound is tight for q(o|x) = p(o|x)"]


def test_diffusion_kl_with_wrong_kernel_variance_fails():
    # The default chain has beta = eta = T = 1, n_steps = 4: kernel N(0.75 x, 2 * 0.25).
    def wrong_kernel(x_next, x_prev, step):  # drops the factor 2 of eta sqrt(2 beta)
        return norm.logpdf(x_next, 0.75 * x_prev, math.sqrt(0.25))

    report = F.check_diffusion_kl(0, forward_log_kernel=wrong_kernel)
    assert [c.name for c in report.failed] == [
        "Monte Carlo of Eq. 2.66 = closed-form joint KL (4 SE)"
    ]


def test_diffusion_chain_marginals_follow_the_kernels():
    data = F.check_diffusion_kl(1).data  # beta = eta = T = 1, n_steps = 4
    assert data["q_var"].shape == (5,)
    np.testing.assert_allclose(data["q_mean"][1:], 0.75 * data["q_mean"][:-1], atol=1e-12)
    np.testing.assert_allclose(data["q_var"][1:], 0.75**2 * data["q_var"][:-1] + 0.5, atol=1e-12)
    assert data["p_mean"][-1] == pytest.approx(0.0) and data["p_var"][-1] == pytest.approx(1.0)


def test_policy_at_wrong_temperature_is_not_the_inference_solution():
    q = np.random.default_rng([0, 0]).normal(scale=2.0, size=(5, 4))  # the check's Q for seed 0
    report = F.check_maxent_as_inference(0, policy=softmax(q, axis=-1))  # alpha = 1, not 0.7
    assert not report["L(pi) = 0 (the KL objective is minimal)"].passed
    assert not report["pi equals the numerical minimiser of Eq. 2.69"].passed


# ---------------------------------------------------------------- Section 2.8 helpers


def test_loose_variational_posterior_fails():
    report = F.check_mutual_information(0, posterior=lambda p: np.full(p.shape, 1 / p.shape[0]))
    assert [c.name for c in report.failed] == ["bound is tight for q(z|s) = p(z|s)"]


def test_bad_arguments_raise():
    with pytest.raises(ValueError, match="seed must be a non-negative integer"):
        F.check_mutual_information(-1)
    with pytest.raises(ValueError, match="betas must be at least two increasing values"):
        F.check_self_paced(0, betas=(1.0, 0.5))
    with pytest.raises(ValueError, match="multiples of dt"):
        F.check_ou_marginals(0, check_times=(0.123,))
    with pytest.raises(ValueError, match=r"variational\(x\) must have shape"):
        F.check_mixture_estep_bound(0, variational=lambda x: np.ones((x.size, 2)) / 2)


def test_moe_gating_data_for_plots():
    data = F.check_moe_gating(0).data
    assert data["density"].shape == (data["theta"].size, data["contexts"].size)
    np.testing.assert_allclose(data["gating"].sum(-1), 1.0)

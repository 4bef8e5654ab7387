"""Tests for vslbook.bounds.dime: the Chapter 5 numerical checks.

Every check passes for a few seeds, and each fails when handed a wrong candidate (a wrong
entropy formula or bound estimator, a non-contracting Bellman operator, a "policy improvement"
that moves away from the Boltzmann target).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from vslbook.bounds import CheckReport
from vslbook.bounds import dime as D
from vslbook.bounds import foundations as F

SEEDS = (0, 1, 2)
CHECKS = (
    D.check_entropy_lower_bound,
    D.check_soft_bellman_contraction,
    D.check_soft_policy_iteration,
)

# check names used below
H_MINUS_L = "H(pi_0) - ℓ = KL(generative joint || noising joint from pi_0)"
L_LE_H = "ℓ <= H(pi_0)"
SAMPLEWISE = "entropy_bound sample = log ratio of Eq. 5.15 from the documented kernels"
MC_BOUND = "Monte Carlo E[entropy_bound] = closed-form ℓ (5 SE)"
MC_GAP = "Monte Carlo of -(entropy_bound + log pi_0(x^0)) = KL (5 SE)"
CONTRACTION = "||TQ1 - TQ2|| <= gamma ||Q1 - Q2|| (sup norm) for 300 random pairs"
SHIFT = "constant shifts: ||TQ1 - TQ2|| = gamma ||Q1 - Q2|| (the modulus is attained)"
FIXED_POINT = "T Q^pi = Q^pi (fixed point)"
CONVERGED = "Q^k -> Q^pi (soft_policy_evaluation) after 300 iterations"
KL_ZERO = "exact step: KL(pi_new || exp(Q/alpha)/Z) = 0 (the minimiser of Eq. 5.22)"
MONOTONE = "exact step: Q^pi_new >= Q^pi_old elementwise, every iteration"
TO_OPTIMUM = "exact iteration: Q^pi_i -> Q* (soft value iteration)"


def failed_names(report: CheckReport) -> set[str]:
    return {check.name for check in report.failed}


# ------------------------------------------------------------------- every check passes


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("check", CHECKS, ids=lambda f: f.__name__)
def test_check_passes(check, seed):
    report = check(seed)
    assert isinstance(report, CheckReport) and len(report) >= 6
    report.require()


def test_dime_checks_and_determinism():
    reports = D.dime_checks(1)
    assert len(reports) == 8 and all(r.passed for r in reports)
    again = D.dime_checks(1)
    for a, b in zip(reports, again, strict=True):
        assert [c.lhs for c in a] == [c.lhs for c in b]
        for key in a.data:
            np.testing.assert_array_equal(a.data[key], b.data[key])


def test_entropy_check_leaves_torch_global_state_alone():
    torch.manual_seed(123)
    expected = torch.rand(3)
    torch.manual_seed(123)
    D.check_entropy_lower_bound(0, n_samples=100, n_series_samples=10)
    np.testing.assert_array_equal(torch.rand(3), expected)


# ------------------------------------------------------------ Section 5.4.1: the bound ℓ


def test_entropy_report_data():
    report = D.check_entropy_lower_bound(0, n_steps=3, act_dim=1, n_samples=500)
    data = report.data
    assert data["etas"].shape == (3, 1)
    assert data["step_contributions"].shape == data["step_contributions_mc"].shape == (4,)
    assert data["bound_samples"].shape == data["gap_samples"].shape == (500,)
    assert data["latent"].shape == (500, 1)
    np.testing.assert_allclose(data["step_contributions"].sum(), data["bound"])
    np.testing.assert_allclose(data["entropy"] - data["bound"], data["gap"], rtol=1e-12)
    assert data["gap"] > 0 and data["target_kl"][0] <= data["target_kl"][1]
    np.testing.assert_array_equal(data["series_steps"], [1, 2, 4, 8, 16])
    for key in ("series_entropy", "series_bound", "series_gap", "series_bound_mc"):
        assert data[key].shape == (5,)
    np.testing.assert_allclose(
        data["series_entropy"] - data["series_bound"], data["series_gap"], rtol=1e-10
    )


def test_gap_vanishes_with_more_steps_when_the_prior_is_kept():
    """With f_theta = 0 the only gap is the discretisation error of the stationary chain."""
    gap0 = D.check_entropy_lower_bound(0, n_samples=100, n_series_samples=10).data[
        "series_gap_zero_drift"
    ]
    assert np.all(np.diff(gap0) < 0) and gap0[-1] < 1e-3 and gap0[0] > 10 * gap0[-1]


def test_linear_gaussian_chain_one_step_by_hand():
    eta, sigma0, slope, offset = 0.3, 1.2, -0.4, 0.7
    chain = D.linear_gaussian_chain(np.array([[eta]]), sigma0, slope, offset)
    a = 1 + eta * (slope - 1 / sigma0**2)
    var0 = a**2 * sigma0**2 + 2 * eta
    np.testing.assert_allclose(chain.marginal_mean, [eta * offset])
    np.testing.assert_allclose(chain.marginal_var, [var0])
    np.testing.assert_allclose(chain.entropy, [0.5 * math.log(2 * math.pi * math.e * var0)])
    np.testing.assert_allclose(
        chain.gen_cov[0], [[sigma0**2, a * sigma0**2], [a * sigma0**2, var0]]
    )
    np.testing.assert_allclose(chain.entropy - chain.bound, chain.kl, rtol=1e-12)
    assert chain.kl[0] > 0


def test_linear_gaussian_policy_matches_requested_chain():
    policy = D.linear_gaussian_policy(2, 1.5, 1.0, [0.5, 2.0], [-0.3, 0.0], [1.0, -2.0], seed=4)
    np.testing.assert_allclose(policy.noise_var.detach().numpy(), [0.5, 2.0])
    x = torch.randn(5, 2, dtype=torch.float64)
    emb = policy.score_net.embed_steps(torch.ones(1, dtype=torch.float64))[0]
    drift = policy.score_net(x, emb, torch.zeros(5, 1, dtype=torch.float64))
    expected = x.numpy() * [-0.3, 0.0] + [1.0, -2.0]
    np.testing.assert_allclose(drift.detach().numpy(), expected, rtol=1e-15, atol=0)
    with pytest.raises(ValueError, match="equal length"):
        D.linear_gaussian_policy(2, 1.5, 1.0, [1.0], [0.0, 0.0], [0.0])


@pytest.mark.parametrize(
    "wrong",
    [
        lambda mean, var: float(np.sum(0.5 * np.log(var))),  # drops the 2 pi e
        lambda mean, var: D.gaussian_entropy(np.full_like(var, 1.5**2)),  # the prior's entropy
    ],
    ids=["no_2pie", "prior_entropy"],
)
def test_wrong_entropy_formula_fails(wrong):
    report = D.check_entropy_lower_bound(0, marginal_entropy=wrong)
    assert H_MINUS_L in failed_names(report)
    assert SAMPLEWISE not in failed_names(report) and MC_BOUND not in failed_names(report)


def test_entropy_formula_without_2pie_breaks_the_inequality():
    report = D.check_entropy_lower_bound(0, marginal_entropy=lambda m, v: np.sum(np.log(v) / 2))
    assert L_LE_H in failed_names(report)


@pytest.mark.parametrize(
    "wrong",
    [
        lambda sample: -sample.running_cost,  # forgets -log p_N(x^N)
        lambda sample: sample.cost,  # the cost, i.e. the sign flipped
        lambda sample: -(sample.running_cost - sample.terminal_cost),  # prior term sign
    ],
    ids=["no_prior_term", "sign", "prior_sign"],
)
def test_wrong_bound_estimator_fails(wrong):
    report = D.check_entropy_lower_bound(0, bound_estimator=wrong)
    failed = failed_names(report)
    assert {SAMPLEWISE, MC_BOUND, MC_GAP} <= failed
    assert H_MINUS_L not in failed  # the closed forms do not depend on the estimator


# ---------------------------------------------------- Section 5.4.2: Bellman operator


def _operator(seed: int, gamma: float, entropy_sign: float = 1.0, alpha: float = 0.5):
    data = D.check_soft_bellman_contraction(seed).data
    P, R = F.random_mdp(8, 4, seed)
    pi, entropy = data["policy"], data["entropy"]

    def operator(q: np.ndarray) -> np.ndarray:
        return R + gamma * P @ ((pi * q).sum(-1) + entropy_sign * alpha * entropy)

    return operator


def test_soft_bellman_operator_matches_policy_evaluation():
    P, R = F.random_mdp(5, 3, seed=2)
    pi = np.random.default_rng(0).dirichlet(np.ones(3), size=5)
    _, q_pi = F.soft_policy_evaluation(P, R, pi, 0.8, 0.3)
    np.testing.assert_allclose(D.soft_bellman_operator(q_pi, P, R, pi, 0.8, 0.3), q_pi)
    batch = np.random.default_rng(1).normal(size=(4, 5, 3))
    out = D.soft_bellman_operator(batch, P, R, pi, 0.8, 0.3)
    np.testing.assert_allclose(out[2], D.soft_bellman_operator(batch[2], P, R, pi, 0.8, 0.3))
    zero_bonus = D.soft_bellman_operator(q_pi, P, R, pi, 0.8, 0.3, bonus=np.zeros(5))
    assert np.all(zero_bonus < q_pi)
    with pytest.raises(ValueError, match="q must have shape"):
        D.soft_bellman_operator(np.zeros((5, 2)), P, R, pi, 0.8, 0.3)
    with pytest.raises(ValueError, match="bonus must have shape"):
        D.soft_bellman_operator(q_pi, P, R, pi, 0.8, 0.3, bonus=np.zeros(3))
    with pytest.raises(ValueError, match="gamma must lie"):
        D.soft_bellman_operator(q_pi, P, R, pi, 1.1, 0.3)


def test_operator_with_discount_above_one_fails():
    report = D.check_soft_bellman_contraction(0, operator=_operator(0, gamma=1.1))
    assert {CONTRACTION, SHIFT, FIXED_POINT, CONVERGED} <= failed_names(report)
    errors = report.data["errors"]
    assert errors[-1] > 1e6 * errors[0]  # the iterates diverge


def test_operator_with_larger_discount_is_not_a_gamma_contraction():
    report = D.check_soft_bellman_contraction(0, operator=_operator(0, gamma=0.95))
    assert {CONTRACTION, SHIFT} <= failed_names(report)


def test_operator_with_wrong_entropy_sign_contracts_to_the_wrong_point():
    report = D.check_soft_bellman_contraction(0, operator=_operator(0, 0.9, entropy_sign=-1.0))
    failed = failed_names(report)
    assert {FIXED_POINT, CONVERGED} <= failed
    assert CONTRACTION not in failed and SHIFT not in failed


def test_correct_hand_written_operator_passes():
    D.check_soft_bellman_contraction(0, operator=_operator(0, gamma=0.9)).require()


# ------------------------------------------------ Section 5.4.2: policy improvement


def test_mirror_step_endpoints_and_monotone_kl():
    rng = np.random.default_rng(0)
    pi, q = rng.dirichlet(np.ones(4), size=3), rng.normal(size=(3, 4))
    np.testing.assert_allclose(D.mirror_step(pi, q, 0.5, 0.0), pi)
    np.testing.assert_allclose(D.mirror_step(pi, q, 0.5, 1.0), F.boltzmann_policy(q, 0.5))
    target = F.boltzmann_policy(q, 0.5)

    def kl(p: np.ndarray) -> np.ndarray:
        return np.sum(p * (np.log(p) - np.log(target)), -1)

    kls = np.array([kl(D.mirror_step(pi, q, 0.5, t)) for t in np.linspace(-0.5, 1.0, 16)])
    assert np.all(np.diff(kls, axis=0) < 0) and np.allclose(kls[-1], 0.0, atol=1e-12)
    with_zero = pi.copy()
    with_zero[0] = [0.5, 0.0, 0.25, 0.25]  # step 1 reaches the target even where pi = 0
    np.testing.assert_allclose(D.mirror_step(with_zero, q, 0.5, 1.0), target)


def test_moving_away_from_the_boltzmann_target_fails():
    report = D.check_soft_policy_iteration(0, improve=lambda q, pi: F.boltzmann_policy(-q, 0.5))
    assert {KL_ZERO, MONOTONE, TO_OPTIMUM} <= failed_names(report)


def test_no_improvement_is_monotone_but_does_not_converge():
    report = D.check_soft_policy_iteration(0, improve=lambda q, pi: pi)
    failed = failed_names(report)
    assert {KL_ZERO, TO_OPTIMUM} <= failed and MONOTONE not in failed


def test_negative_mirror_step_increases_kl_and_lowers_q():
    report = D.check_soft_policy_iteration(0, step_size=-0.3)
    failed = failed_names(report)
    assert "mirror step (-0.3): KL to the target does not increase" in failed
    assert "mirror step (-0.3): Q^pi_new >= Q^pi_old elementwise" in failed
    assert not any(name.startswith("exact") or name.startswith("restricted") for name in failed)


def test_policy_iteration_data():
    report = D.check_soft_policy_iteration(1, n_iter=20)
    data = report.data
    for key in ("j_exact", "j_mirror", "j_restricted", "q_error_exact", "q_error_mirror"):
        assert data[key].shape == (21,)
    for key in ("kl_exact", "kl_mirror", "kl_restricted"):
        assert data[key].shape == (20, 2)
    assert np.all(np.diff(data["j_exact"]) >= -1e-12)
    assert np.all(np.diff(data["j_restricted"]) >= -1e-12)
    assert data["j_exact"][-1] == pytest.approx(float(data["j_optimal"]), abs=1e-9)
    assert data["j_restricted"][-1] < float(data["j_optimal"]) - 1e-3  # a restricted family
    assert np.all(data["j_random"] <= data["j_optimal"] + 1e-9)

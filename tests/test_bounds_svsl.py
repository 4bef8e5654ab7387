"""Tests for vslbook.bounds.svsl: the lower bounds of Chapter 3 (Section 3.3, Appendix A.1).

Every report passes with the thesis's quantities for a few seeds and fails with a wrong
candidate: a flipped responsibility sign, a missing entropy bonus, ``beta < alpha``, the
unweighted context entropy of Eq. A.5 as printed, or a weight update without trust region.
The lower bound itself is recomputed here by hand from scipy densities.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy.special import softmax
from scipy.stats import norm, truncnorm

from vslbook.bounds import CheckReport
from vslbook.bounds import svsl as S

SEEDS = (0, 1)
CHECKS = (
    S.check_objective_decomposition,
    S.check_expert_bound,
    S.check_context_bound,
    S.check_weight_bound,
    S.check_reps_weights,
)


# ------------------------------------------------------------ an independent bound by hand


def _by_hand_bound(problem, model, log_aux_t, log_aux_c, sign=1.0):
    """Eq. A.4's bound from scipy densities, summing expert by expert with explicit loops."""
    c, wc = problem.contexts
    t, wt = problem.thetas
    a, b = problem.alpha, problem.beta
    total = 0.0
    for o in range(model.n_components):
        m, s = model.context_mean[o], model.context_std[o]
        lo, hi = (problem.low - m) / s, (problem.high - m) / s
        ctx = truncnorm.pdf(c, lo, hi, m, s)
        value = 0.0
        for i, ci in enumerate(c):
            expert = norm.pdf(t, model.gain[o] * ci + model.offset[o], model.std[o])
            reward = S.bimodal_reward(ci, t) + sign * a * log_aux_t[o, i]
            inner = np.sum(wt * expert * reward)
            value += (
                wc[i]
                * ctx[i]
                * (inner - b * math.log(problem.high - problem.low) + (b - a) * log_aux_c[o, i])
            )
        h_theta = 0.5 * math.log(2 * math.pi * math.e * model.std[o] ** 2)
        h_ctx = float(truncnorm.entropy(lo, hi, m, s))
        w = model.weights[o]
        total += w * (value + a * h_theta + b * h_ctx - b * math.log(w))
    return total


def _flipped_sign_bound(problem, model, log_aux_t, log_aux_c):
    return _by_hand_bound(problem, model, log_aux_t, log_aux_c, sign=-1.0)


def test_lower_bound_matches_by_hand_computation():
    problem = S.ToyProblem(n_context=24, n_theta=301)
    model = S.random_toy_moe(0)
    aux_model = S.random_toy_moe(5)
    aux = S.responsibilities(problem, aux_model)
    assert S.lower_bound(problem, model, *aux) == pytest.approx(
        _by_hand_bound(problem, model, *aux), abs=1e-10
    )


def test_decomposition_equals_a_monte_carlo_estimate_of_eq_3_3():
    """Eq. 3.3 by sampling the mixture: a route that shares no quadrature with the module."""
    problem = S.ToyProblem()
    model = S.random_toy_moe(1)
    rng = np.random.default_rng(0)
    n = 200_000
    o = rng.choice(model.n_components, size=n, p=model.weights)
    m, s = model.context_mean[o], model.context_std[o]
    c = truncnorm.rvs((problem.low - m) / s, (problem.high - m) / s, m, s, random_state=rng)
    theta = rng.normal(model.gain[o] * c + model.offset[o], model.std[o])
    k = np.arange(model.n_components)[:, None]
    mk, sk = model.context_mean[k], model.context_std[k]
    pc_o = truncnorm.pdf(c, (problem.low - mk) / sk, (problem.high - mk) / sk, mk, sk)
    joint_c = model.weights[k] * pc_o  # pi(o, c)
    pc = joint_c.sum(0)
    pt_c = (joint_c / pc * norm.pdf(theta, model.gain[k] * c + model.offset[k], model.std[k])).sum(
        0
    )
    samples = (
        S.bimodal_reward(c, theta)
        - problem.alpha * np.log(pt_c)
        - problem.beta * (np.log(pc) - problem.log_p)
    )
    exact = S.decomposed_objective(problem, model)
    assert abs(samples.mean() - exact) < 4 * samples.std() / math.sqrt(n)


# ------------------------------------------------------------------- every check passes


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("check", CHECKS, ids=lambda f: f.__name__)
def test_check_passes(check, seed):
    report = check(seed)
    assert isinstance(report, CheckReport) and len(report) >= 4
    report.require()


def test_checks_are_deterministic():
    a, b = S.check_expert_bound(3), S.check_expert_bound(3)
    assert [c.lhs for c in a] == [c.lhs for c in b]


def test_svsl_checks_runs_all():
    reports = S.svsl_checks(2)
    assert len(reports) == len(CHECKS) and all(r.passed for r in reports)


# --------------------------------------------------------------- wrong candidates fail


def test_by_hand_bound_passes_and_flipped_sign_fails():
    assert S.check_objective_decomposition(0, n_auxiliaries=2, bound=_by_hand_bound).passed
    report = S.check_objective_decomposition(0, n_auxiliaries=2, bound=_flipped_sign_bound)
    assert not report.passed
    name = "J = bound + alpha E[KL_theta] + (beta-alpha) E[KL_c] for 3 auxiliaries"
    assert not report[name].passed


@pytest.mark.parametrize("seed", SEEDS)
def test_beta_below_alpha_breaks_the_bound(seed):
    report = S.check_objective_decomposition(seed, alpha=1.0, beta=0.2)
    assert not report["bound <= J for 7 auxiliaries (needs beta >= alpha)"].passed
    # the identity of Eq. A.4 itself holds for any beta
    assert report["J = bound + alpha E[KL_theta] + (beta-alpha) E[KL_c] for 7 auxiliaries"].passed


@pytest.mark.parametrize("seed", SEEDS)
def test_context_bound_fails_without_beta(seed):
    report = S.check_context_bound(seed, alpha=0.5, beta=0.0)
    assert not report[
        "bound(new; aux = old) <= J(new) for 6 perturbed context distributions"
    ].passed


def _expert_entropy(model, o):
    return 0.5 * math.log(2 * math.pi * math.e * model.std[o] ** 2)


def test_expert_objective_without_entropy_bonus_fails():
    def no_entropy(problem, model, log_aux_t, o):
        return S.expert_objective(problem, model, log_aux_t, o) - problem.alpha * _expert_entropy(
            model, o
        )

    report = S.check_expert_bound(0, objective=no_entropy)
    assert not report.passed


def test_expert_objective_with_flipped_responsibility_sign_fails():
    def flipped(problem, model, log_aux_t, o):
        # E[R] + alpha E[log aux] + alpha H from the module; rebuild with -alpha E[log aux]
        doubled = replace(problem, alpha=2 * problem.alpha)
        with_aux = S.expert_objective(problem, model, log_aux_t, o)
        e_log_aux_plus_h = (S.expert_objective(doubled, model, log_aux_t, o) - with_aux) / (
            problem.alpha
        )
        e_log_aux = e_log_aux_plus_h - _expert_entropy(model, o)
        return with_aux - 2 * problem.alpha * e_log_aux

    assert not S.check_expert_bound(0, objective=flipped).passed


def test_context_objective_missing_responsibility_term_fails():
    def no_context_responsibility(problem, model, log_aux_t, log_aux_c, o):
        # Eq. 3.6 as if beta == alpha: the (beta - alpha) log aux(o|c) reward is lost
        return S.context_objective(
            replace(problem, beta=problem.alpha), model, log_aux_t, log_aux_c, o
        ) + (problem.beta - problem.alpha) * _ctx_entropy(problem, model, o)

    assert not S.check_context_bound(0, objective=no_context_responsibility).passed


def _ctx_entropy(problem, model, o):
    m, s = model.context_mean[o], model.context_std[o]
    return float(truncnorm.entropy((problem.low - m) / s, (problem.high - m) / s, m, s))


def test_eq_a5_as_printed_is_not_the_bound():
    """A.5 writes beta H[pi(c|o)] outside the weight pi(o); Eq. 3.7 weights it."""

    def printed_a5(problem, model, log_aux_t, log_aux_c):
        r = S.weight_rewards(problem, model, log_aux_t, log_aux_c)
        h = np.array([_ctx_entropy(problem, model, o) for o in range(model.n_components)])
        # sum_o pi(o) r'_o = sum_o pi(o) (r_o - beta H_o) + beta sum_o H_o
        return r - problem.beta * h + problem.beta * h / model.weights

    report = S.check_weight_bound(0, rewards=printed_a5)
    assert not report.passed


def test_reps_without_trust_region_fails():
    report = S.check_reps_weights(0, update=lambda p, r, b, e: softmax(r / b))
    assert not report["KL(p_new || p_old) <= eps"].passed


def test_reps_with_wrong_exponent_fails():
    def wrong(p_old, r, beta, eps):
        _, eta = S.reps_categorical(p_old, r, beta, eps)
        return softmax((beta * np.log(p_old) + r) / (eta + beta))

    assert not S.check_reps_weights(0, update=wrong).passed


# ----------------------------------------------------------------------- closed forms


def test_reps_limits():
    rng = np.random.default_rng(0)
    p_old, r = rng.dirichlet(np.ones(5)), rng.normal(size=5)
    p, eta = S.reps_categorical(p_old, r, 0.3, 1e6)
    assert eta == 0.0
    np.testing.assert_allclose(p, softmax(r / 0.3), atol=1e-15)
    p, eta = S.reps_categorical(p_old, r, 0.3, 1e-6)
    assert eta > 0
    np.testing.assert_allclose(p, p_old, atol=3e-3)
    kl = np.sum(p * np.log(p / p_old))
    assert kl == pytest.approx(1e-6, rel=1e-6)


def test_weight_objective_maximiser_is_softmax():
    r, beta = np.array([0.3, -1.0, 0.8]), 0.7
    best = S.weight_objective(softmax(r / beta), r, beta)
    rng = np.random.default_rng(1)
    for w in rng.dirichlet(np.ones(3), size=200):
        assert S.weight_objective(w, r, beta) <= best + 1e-12
    assert best == pytest.approx(beta * np.log(np.sum(np.exp(r / beta))))


# -------------------------------------------------------------------------- bad input


def test_bad_input():
    with pytest.raises(ValueError, match="weights must be positive and sum to 1"):
        S.ToyMoE([0.5, 0.6], [0, 0], [1, 1], [0, 0], [0, 0], [1, 1])
    with pytest.raises(ValueError, match=r"std must have shape \(2,\)"):
        S.ToyMoE([0.5, 0.5], [0, 0], [1, 1], [0, 0], [0, 0], [1, 1, 1])
    with pytest.raises(ValueError, match="context_std must be positive"):
        S.ToyMoE([0.5, 0.5], [0, 0], [1, -1], [0, 0], [0, 0], [1, 1])
    with pytest.raises(ValueError, match="alpha must be a finite number > 0"):
        S.ToyProblem(alpha=0.0)
    with pytest.raises(ValueError, match="context interval"):
        S.ToyProblem(low=1.0, high=0.0)
    with pytest.raises(ValueError, match="seed must be a non-negative integer"):
        S.check_expert_bound(-1)
    with pytest.raises(ValueError, match="outside the parameter grid"):
        S.responsibilities(S.ToyProblem(theta_low=-1, theta_high=1), S.random_toy_moe(0))
    problem, model = S.ToyProblem(), S.random_toy_moe(0)
    log_t, log_c = S.responsibilities(problem, model)
    with pytest.raises(ValueError, match="log-probabilities over experts"):
        S.lower_bound(problem, model, log_t + 0.1, log_c)
    with pytest.raises(ValueError, match="log_aux_context must have shape"):
        S.lower_bound(problem, model, log_t, log_c[:, :3])
    with pytest.raises(ValueError, match=r"expert index o must be an integer in \[0, 3\)"):
        S.expert_objective(problem, model, log_t, 3)
    with pytest.raises(ValueError, match="p_old must be positive and sum to 1"):
        S.reps_categorical(np.array([0.5, 0.6]), np.zeros(2), 1.0, 0.1)
    with pytest.raises(ValueError, match="eps must be a finite number > 0"):
        S.reps_categorical(np.array([0.5, 0.5]), np.zeros(2), 1.0, 0.0)

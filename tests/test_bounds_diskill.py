"""Tests for vslbook.bounds.diskill: the Chapter 4 objective, bounds and sample forms.

Every report passes with the thesis's formulas for two seeds and fails with a wrong candidate
(a missing ``beta log K`` or entropy bonus, ``beta`` in place of ``beta - alpha``, the
normaliser of the categorical taken for the integral, a gating normalised over contexts).
The building blocks are compared with independent computations: a Monte-Carlo estimate of
Eq. 4.3 from samples of the mixture, trapezoid integrals, ``scipy.integrate.quad`` over the
parameter, ``torch.distributions.Categorical`` entropies and closed forms.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import torch
from scipy.integrate import quad
from scipy.special import log_softmax, softmax
from scipy.stats import norm

from vslbook.bounds import CheckReport
from vslbook.bounds import diskill as D
from vslbook.bounds.svsl_toy import ToyProblem, bimodal_reward

SEEDS = (0, 1)
CHECKS = (
    D.check_curriculum_objective,
    D.check_expert_bound,
    D.check_context_bound,
    D.check_sample_context_objective,
    D.check_energy_normaliser,
    D.check_gating,
)


# ------------------------------------------------------------------- every check passes


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("check", CHECKS, ids=lambda f: f.__name__)
def test_check_passes(check, seed):
    report = check(seed)
    assert isinstance(report, CheckReport) and len(report) >= 3
    report.require()


def test_checks_are_deterministic():
    a = D.check_sample_context_objective(3, sizes=(1_000, 10_000))
    b = D.check_sample_context_objective(3, sizes=(1_000, 10_000))
    assert [(c.lhs, c.rhs) for c in a] == [(c.lhs, c.rhs) for c in b]
    a, b = D.check_gating(3, n_repeats=10), D.check_gating(3, n_repeats=10)
    assert [(c.lhs, c.rhs) for c in a] == [(c.lhs, c.rhs) for c in b]


def test_diskill_checks_runs_all():
    reports = D.diskill_checks(2)
    assert len(reports) == len(CHECKS) and all(r.passed for r in reports)


# ------------------------------------------------------ independent routes to the pieces


def _fine_energy(model, o, problem, n=20_001):
    c = np.linspace(problem.low, problem.high, n)
    a, s, b = model.amplitude[o], model.slope[o], model.shift[o]
    return c, np.tanh(np.multiply.outer(c, s) + b) @ a


def test_normaliser_and_entropy_against_the_trapezoid_rule():
    problem, model = ToyProblem(), D.random_energy_moe(4)
    log_z = D.ebm_log_normaliser(problem, model)
    h = D.ebm_context_entropy(problem, model)
    for o in range(model.n_components):
        c, phi = _fine_energy(model, o, problem)
        z = np.trapezoid(np.exp(phi), c)
        dens = np.exp(phi) / z
        assert log_z[o] == pytest.approx(math.log(z), abs=1e-7)
        assert h[o] == pytest.approx(-np.trapezoid(dens * np.log(dens), c), abs=1e-7)


def test_eq_b1_equals_a_monte_carlo_estimate_of_eq_4_3():
    """Eq. 4.3 by sampling the mixture (inverse CDF for the EBMs): shares no quadrature."""
    problem, model = ToyProblem(), D.random_energy_moe(1)
    k = model.n_components
    rng = np.random.default_rng(0)
    n = 200_000
    o = rng.integers(k, size=n)  # pi(o) = 1/K
    grid, zs, cdfs = None, [], []
    for j in range(k):
        grid, phi = _fine_energy(model, j, problem)
        w = np.exp(phi)
        cdf = np.concatenate([[0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) * np.diff(grid))])
        zs.append(cdf[-1])
        cdfs.append(cdf / cdf[-1])
    u = rng.uniform(size=n)
    c = np.empty(n)
    for j in range(k):
        c[o == j] = np.interp(u[o == j], cdfs[j], grid)
    theta = rng.normal(model.gain[o] * c + model.offset[o], model.std[o])
    phi_all = np.stack(
        [
            np.tanh(np.multiply.outer(c, model.slope[j]) + model.shift[j]) @ model.amplitude[j]
            for j in range(k)
        ]
    )
    joint_c = np.exp(phi_all) / np.array(zs)[:, None] / k  # pi(c|o) pi(o)
    pc = joint_c.sum(0)
    kk = np.arange(k)[:, None]
    pt_c = joint_c / pc * norm.pdf(theta, model.gain[kk] * c + model.offset[kk], model.std[kk])
    samples = (
        bimodal_reward(c, theta)
        - problem.alpha * np.log(pt_c.sum(0))
        - problem.beta * (np.log(pc) - problem.log_p)
    )
    exact = D.ebm_lower_bound(problem, model, *D.ebm_responsibilities(problem, model))
    assert abs(samples.mean() - exact) < 4 * samples.std() / math.sqrt(n)


def test_context_values_against_quad_over_theta():
    problem, model = ToyProblem(alpha=0.7), D.random_energy_moe(2)
    c = np.array([problem.low, -0.61, 1.21, problem.high])
    l_c, log_gate = D.expert_context_values(problem, model, c)
    log_z = D.ebm_log_normaliser(problem, model)
    for i, ci in enumerate(c):
        phi = np.sum(model.amplitude * np.tanh(model.slope * ci + model.shift), axis=1)
        gate = np.exp(phi - log_z) / np.sum(np.exp(phi - log_z))
        np.testing.assert_allclose(np.exp(log_gate[:, i]), gate, atol=1e-12)
        mu = model.gain * ci + model.offset
        for o in range(model.n_components):

            def integrand(t, o=o, mu=mu, ci=ci, gate=gate):
                dens = norm.pdf(t, mu, model.std) * gate
                return norm.pdf(t, mu[o], model.std[o]) * (
                    bimodal_reward(ci, t) + problem.alpha * math.log(dens[o] / dens.sum())
                )

            lo, hi = mu[o] - 12 * model.std[o], mu[o] + 12 * model.std[o]
            value = quad(integrand, lo, hi, epsabs=1e-12, epsrel=1e-12, limit=100)[0]
            value += problem.alpha * norm.entropy(scale=model.std[o])
            assert l_c[o, i] == pytest.approx(value, abs=1e-8)


def test_sample_objective_against_torch_categorical_entropy():
    rng = np.random.default_rng(5)
    n, alpha, beta = 500, 0.3, 1.2
    phi, l_c = rng.normal(size=n), rng.normal(size=n)
    log_aux = np.log(rng.uniform(0.05, 1.0, n))
    q = softmax(phi)
    h = float(torch.distributions.Categorical(logits=torch.tensor(phi)).entropy())
    expected = q @ l_c + (beta - alpha) * q @ log_aux + beta * h
    value = D.sample_context_objective(log_softmax(phi), l_c, log_aux, alpha, beta)
    assert value == pytest.approx(expected, abs=1e-12)


def test_constant_is_log_n_over_v_for_a_flat_energy():
    """phi = 0: the categorical is uniform over N points (entropy log N), the density uniform
    on an interval of length V (entropy log V): Eq. 4.8 - Eq. 4.5 = beta log(N/V) exactly."""
    problem = ToyProblem(alpha=0.5, beta=1.3)
    model = replace(D.random_energy_moe(0), amplitude=np.zeros((3, 4)))
    v = problem.high - problem.low
    assert D.ebm_context_entropy(problem, model) == pytest.approx(np.full(3, math.log(v)))
    n = 777
    value = D.sample_context_objective(np.full(n, -math.log(n)), np.zeros(n), np.zeros(n), 0.5, 1.3)
    assert value - 1.3 * math.log(v) == pytest.approx(1.3 * math.log(n / v), abs=1e-12)


def test_mc_normaliser_closed_form_and_softmax_invariance():
    rng = np.random.default_rng(0)
    a, n = 1.7, 400_000
    c = rng.uniform(0.0, 2.0, n)
    z = (math.exp(2 * a) - 1) / a  # int_0^2 exp(a c) dc
    est = D.mc_normaliser(a * c, 2.0)
    se = 2.0 * np.std(np.exp(a * c)) / math.sqrt(n)
    assert abs(est - z) < 4 * se
    # the thesis's sum_i exp(phi_i) is N/V times the estimate; the categorical is unchanged
    assert np.exp(a * c).sum() == pytest.approx(n / 2.0 * est, rel=1e-12)


def test_gating_is_bayes_rule_with_uniform_prior():
    rng = np.random.default_rng(1)
    log_p = rng.normal(size=(4, 9))
    g = D.uniform_prior_gating(log_p)
    joint = np.exp(log_p) * 0.25
    np.testing.assert_allclose(g, joint / joint.sum(0), atol=1e-15)


# --------------------------------------------------------------- wrong candidates fail


def test_bound_without_beta_log_k_fails():
    def no_log_k(problem, model, log_t, log_c):
        return D.ebm_lower_bound(problem, model, log_t, log_c) - problem.beta * math.log(3)

    report = D.check_curriculum_objective(0, n_auxiliaries=2, bound=no_log_k)
    name = "Eq. 4.3 (mixture densities) = Eq. B.1 (own responsibilities, beta log K)"
    assert not report[name].passed


def test_bound_with_flipped_aux_sign_fails():
    def flipped(problem, model, log_t, log_c):
        # - alpha E[log aux(o|c, theta)] instead of + alpha, the expectation taken by hand
        c, wc = problem.contexts
        t, wt = problem.thetas
        ctx = np.exp(D.ebm_log_contexts(problem, model))
        mean = model.gain[:, None] * c + model.offset[:, None]
        dens = norm.pdf(t[None, None, :], mean[:, :, None], model.std[:, None, None])
        e_log_aux = np.einsum("kc,c,kct,t,kct->k", ctx, wc, dens, wt, log_t).mean()
        return D.ebm_lower_bound(problem, model, log_t, log_c) - 2 * problem.alpha * e_log_aux

    assert not D.check_curriculum_objective(0, n_auxiliaries=2, bound=flipped).passed


def test_beta_below_alpha_breaks_the_bound():
    report = D.check_curriculum_objective(0, alpha=1.0, beta=0.2)
    assert not report["bound <= J for 7 auxiliaries (needs beta >= alpha)"].passed
    name = "J = bound + alpha E[KL_theta] + (beta-alpha) E[KL_c] for 7 auxiliaries"
    assert report[name].passed  # the identity itself holds for any beta


def test_expert_objective_without_entropy_bonus_fails():
    def no_entropy(problem, model, log_t, o):
        h = norm.entropy(scale=model.std[o])
        return D.ebm_expert_objective(problem, model, log_t, o) - problem.alpha * h

    report = D.check_expert_bound(0, objective=no_entropy)
    assert not report["change of the bound = pi(o) x change of the experts objective"].passed


def test_context_objective_with_beta_on_log_aux_fails():
    def beta_not_beta_minus_alpha(problem, model, log_t, log_c, o):
        # (beta - alpha) E[log aux] -> beta E[log aux]: add alpha E_pi(c|o)[log aux(o|c)]
        c_w = problem.contexts[1]
        ctx = np.exp(D.ebm_log_contexts(problem, model))[o]
        extra = problem.alpha * float(np.sum(c_w * ctx * log_c[o]))
        return D.ebm_context_objective(problem, model, log_t, log_c, o) + extra

    report = D.check_context_bound(0, objective=beta_not_beta_minus_alpha)
    assert not report["change of the bound = pi(o) x change of the energies objective"].passed


def test_context_objective_without_entropy_fails():
    def no_entropy(problem, model, log_t, log_c, o):
        h = D.ebm_context_entropy(problem, model)[o]
        return D.ebm_context_objective(problem, model, log_t, log_c, o) - problem.beta * h

    assert not D.check_context_bound(0, objective=no_entropy).passed


def _eq48_beta_on_aux(log_q, l_c, log_aux, alpha, beta):
    q = np.exp(log_q)
    return float(q @ l_c + q @ (beta * log_aux - beta * log_q))


def _eq48_no_entropy(log_q, l_c, log_aux, alpha, beta):
    q = np.exp(log_q)
    return float(q @ l_c + q @ ((beta - alpha) * log_aux))


def _eq48_density_entropy(log_q, l_c, log_aux, alpha, beta):
    # "corrects" the categorical to the density: the constant disappears
    v = 3.0
    return D.sample_context_objective(log_q, l_c, log_aux, alpha, beta) - beta * math.log(
        log_q.size / v
    )


@pytest.mark.parametrize(
    "candidate",
    [_eq48_beta_on_aux, _eq48_no_entropy, _eq48_density_entropy],
    ids=lambda f: f.__name__,
)
def test_wrong_sample_objectives_fail(candidate):
    report = D.check_sample_context_objective(0, sizes=(1_000, 10_000), objective=candidate)
    assert not report.passed


def test_unnormalised_categorical_sum_is_not_the_integral():
    """The thesis's Z ~ sum_i exp(phi(c_i)) normalises the categorical, not the density."""
    report = D.check_energy_normaliser(0, estimator=lambda phi, v: float(np.exp(phi).sum()))
    assert not report.passed
    report = D.check_energy_normaliser(0, estimator=lambda phi, v: float(np.exp(phi).mean()))
    assert not report.passed


@pytest.mark.parametrize(
    "candidate",
    [
        lambda lp: softmax(lp, axis=1),  # normalised over contexts, not experts
        lambda lp: softmax(lp + np.log([[0.5], [0.3], [0.2]]), axis=0),  # non-uniform prior
    ],
    ids=["over_contexts", "non_uniform_prior"],
)
def test_wrong_gating_fails(candidate):
    assert not D.check_gating(0, n_repeats=4, gating=candidate).passed


# -------------------------------------------------------------------------- bad input


def test_bad_input():
    m = D.random_energy_moe(0)
    with pytest.raises(ValueError, match=r"std must have shape \(3,\)"):
        m.replace(std=np.ones(2))
    with pytest.raises(ValueError, match="std must be positive"):
        m.replace(std=np.array([1.0, -1.0, 1.0]))
    with pytest.raises(ValueError, match=r"slope must have shape \(3, 4\)"):
        m.replace(slope=np.ones((3, 2)))
    with pytest.raises(ValueError, match="amplitude must be finite"):
        m.replace(amplitude=np.full((3, 4), np.nan))
    with pytest.raises(ValueError, match="n_features must be an integer >= 1"):
        D.random_energy_moe(0, n_features=0)
    with pytest.raises(ValueError, match="seed must be a non-negative integer"):
        D.check_gating(-1)
    with pytest.raises(ValueError, match="log_probs must be normalised"):
        D.sample_context_objective(np.zeros(3), np.zeros(3), np.zeros(3), 0.5, 1.0)
    with pytest.raises(ValueError, match=r"l_c and log_aux_context must have shape \(3,\)"):
        D.sample_context_objective(np.full(3, -math.log(3)), np.zeros(2), np.zeros(3), 0.5, 1.0)
    with pytest.raises(ValueError, match="alpha must be a finite number > 0"):
        D.sample_context_objective(np.full(3, -math.log(3)), np.zeros(3), np.zeros(3), 0.0, 1.0)
    with pytest.raises(ValueError, match="volume must be a finite number > 0"):
        D.mc_normaliser(np.zeros(4), 0.0)
    with pytest.raises(ValueError, match="phi must be finite"):
        D.mc_normaliser(np.array([0.0, np.inf]), 1.0)
    with pytest.raises(ValueError, match="log_context_probs must be a non-empty 2-D array"):
        D.uniform_prior_gating(np.zeros(3))
    with pytest.raises(ValueError, match="values must have shape"):
        D.self_normalised_expectation(np.zeros(3), np.zeros(4))
    problem = ToyProblem()
    with pytest.raises(ValueError, match=r"contexts must lie in \[-1.5, 1.5\]"):
        D.expert_context_values(problem, m, np.array([0.0, 2.0]))
    log_t, log_c = D.ebm_responsibilities(problem, m)
    with pytest.raises(ValueError, match=r"expert index o must be an integer in \[0, 3\)"):
        D.ebm_context_objective(problem, m, log_t, log_c, 3)
    with pytest.raises(ValueError, match="log_aux_context must have shape"):
        D.ebm_lower_bound(problem, m, log_t, log_c[:, :5])
    with pytest.raises(ValueError, match="sizes must be at least two increasing batch sizes"):
        D.check_sample_context_objective(0, sizes=(1000, 100))
    with pytest.raises(ValueError, match="batch_sizes must be increasing"):
        D.check_gating(0, batch_sizes=(5000, 75))

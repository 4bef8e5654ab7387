"""Numerical checks of Section 5.6 (DIME): general bridges, Eqs. 5.29-5.38.

* :func:`check_general_bridge`: a two-dimensional bridge with affine, time-dependent drifts and
  a Gaussian target, where everything has a closed form
  (:mod:`vslbook.bounds.dime_bridges_linear`): Monte Carlo of the samplers and estimators
  against it, the bound and its gap, the inference form, Euler-Maruyama against the SDEs, and
  the controls that make the chains each other's time reversal.
* :func:`check_bridge_quadrature`, re-exported here: a one-dimensional bridge with nonlinear
  drifts and a double-well target, where no closed form exists; the same quantities by
  brute-force quadrature on a grid against Monte Carlo. It lives in
  :mod:`vslbook.bounds.dime_bridges_quadrature`.
* DIME as the special case is checked in :mod:`vslbook.bounds.dime_bridges_special`.

Import from :mod:`vslbook.bounds.dime`, which re-exports everything public here.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from vslbook.bounds import Check, CheckReport, relative_tol
from vslbook.bounds.dime_bridges import (
    BoundEstimator,
    GeneralBridge,
    KLEstimator,
    bridge_kl_samples,
    entropy_bound_samples,
    make_bridge,
    sample_backward,
    sample_forward,
)
from vslbook.bounds.dime_bridges_linear import linear_bridge_closed_form, linear_sde_moments
from vslbook.bounds.dime_bridges_quadrature import check_bridge_quadrature
from vslbook.bounds.toy_numerics import check_count, mc_mean_stderr, seeded_rng, worst_check

__all__ = ["check_bridge_quadrature", "check_general_bridge"]


def _quadratic_q(mu: np.ndarray, cov: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    prec = np.linalg.inv(cov)
    return lambda a: -0.5 * np.einsum("bi,ij,bj->b", a - mu, prec, a - mu)


def _affine_family(seed: int, dim: int) -> dict[str, np.ndarray]:
    """Seeded coefficients of ``f(a) = F a``, ``u = (U0 + t U1) a + u0`` and
    ``v = (V0 + t V1) a + v0``, the target ``N(mu, sigma)`` and ``beta``."""
    rng = seeded_rng(seed, 37)
    skew = rng.normal(scale=0.3, size=(dim, dim))
    return {
        "F": -0.5 * np.eye(dim) + skew - skew.T,
        "U0": rng.normal(scale=0.3, size=(dim, dim)),
        "U1": rng.normal(scale=0.3, size=(dim, dim)),
        "u0": rng.normal(scale=0.3, size=dim),
        "V0": -0.5 * np.eye(dim) + rng.normal(scale=0.4, size=(dim, dim)),
        "V1": rng.normal(scale=0.3, size=(dim, dim)),
        "v0": rng.normal(scale=0.5, size=dim),
        "beta": rng.uniform(0.6, 1.2, size=(1, dim)),
        "mu": rng.normal(scale=0.7, size=dim),
        "sigma": np.diag(rng.uniform(0.3, 0.7, dim)) + 0.1,
    }


def _affine_bridge(c: dict[str, np.ndarray], n_steps: int, horizon: float) -> GeneralBridge:
    delta = horizon / n_steps

    def f(a: np.ndarray, n: int) -> np.ndarray:
        return a @ c["F"].T

    def u(a: np.ndarray, n: int) -> np.ndarray:
        return a @ (c["U0"] + n * delta * c["U1"]).T + c["u0"]

    def v(a: np.ndarray, n: int) -> np.ndarray:
        return a @ (c["V0"] + n * delta * c["V1"]).T + c["v0"]

    return make_bridge(f, u, v, c["beta"], delta, n_steps, c["mu"].size)


def _sde_errors(c: dict[str, np.ndarray], steps: Sequence[int], horizon: float) -> np.ndarray:
    """``(len(steps), 2)``: max moment error of the forward chain at ``T`` against Eq. 5.29 and
    of the backward chain at ``0`` against Eq. 5.30."""
    beta = c["beta"][0]
    d = beta.size
    diag = np.diag(beta)
    fwd_sde = linear_sde_moments(
        lambda t: (c["F"] + diag @ (c["U0"] + t * c["U1"]), beta * c["u0"]),
        beta,
        c["mu"],
        c["sigma"],
        horizon,
    )
    # Eq. 5.30 in reversed time tau = T - t: drift -(f - beta v)(x, T - tau)
    bwd_sde = linear_sde_moments(
        lambda tau: (-c["F"] + diag @ (c["V0"] + (horizon - tau) * c["V1"]), beta * c["v0"]),
        beta,
        np.zeros(d),
        np.eye(d),
        horizon,
    )
    errors = []
    for n in steps:
        cf = linear_bridge_closed_form(_affine_bridge(c, n, horizon), c["mu"], c["sigma"])
        m_n, p_n = cf.forward_marginals[0][-1], cf.forward_marginals[1][-1]
        errors.append(
            [
                max(np.abs(m_n - fwd_sde[0]).max(), np.abs(p_n - fwd_sde[1]).max()),
                max(
                    np.abs(cf.marginal_mean - bwd_sde[0]).max(),
                    np.abs(cf.marginal_cov - bwd_sde[1]).max(),
                ),
            ]
        )
    return np.array(errors)


def _reversal_kls(seed: int, steps: Sequence[int], horizon: float) -> np.ndarray:
    """``(len(steps), 2)``: Eq. 5.37 when ``v = 2 grad log ->pi_n - u`` (Nelson's relation),
    for a general forward control and for DIME's ``f = -beta a``, ``u = 0``, in 1-D."""
    rng = seeded_rng(seed, 41)
    mu, var = rng.normal(scale=0.5), rng.uniform(0.2, 0.5)
    slope, offset = rng.uniform(0.2, 0.6), rng.normal(scale=0.3)
    cases = (
        (lambda a, n: -0.5 * a, lambda dl: lambda a, n: (slope + 0.5 * n * dl) * a + offset),
        (lambda a, n: -1.0 * a, lambda dl: lambda a, n: np.zeros_like(a)),
    )
    out = np.empty((len(steps), len(cases)))
    for i, n_steps in enumerate(steps):
        delta = horizon / n_steps
        for j, (f, control) in enumerate(cases):
            u = control(delta)
            forward = make_bridge(f, u, None, 1.0, delta, n_steps, 1)
            means, covs = linear_bridge_closed_form(forward, [mu], [[var]]).forward_marginals
            variances = covs[:, 0, 0]

            def v(a, n, u=u, means=means, variances=variances):
                return -2 * (a - means[n]) / variances[n] - u(a, n)

            bridge = make_bridge(f, u, v, 1.0, delta, n_steps, 1, variances[-1], means[-1])
            out[i, j] = linear_bridge_closed_form(bridge, [mu], [[var]]).kl
    return out


def check_general_bridge(
    seed: int = 0,
    n_steps: int = 6,
    n_samples: int = 20_000,
    horizon: float = 1.0,
    sde_steps: Sequence[int] = (8, 16, 32, 64),
    reversal_steps: Sequence[int] = (16, 32, 64, 128),
    kl_estimator: KLEstimator | None = None,
    bound_estimator: BoundEstimator | None = None,
) -> CheckReport:
    """Eqs. 5.29-5.38 on a two-dimensional affine bridge, against closed forms.

    Seeded ``f(a) = F a``, ``u(a, t) = (U0 + t U1) a + u0``, ``v(a, t) = (V0 + t V1) a + v0``,
    per-dimension constant ``beta``, ``N(0, I)`` prior (Eq. 5.30) and the target ``N(mu,
    Sigma)``, the Boltzmann policy of a quadratic ``Q`` (Eq. 5.38). Checks:

    * the samplers (Eqs. 5.31-5.32): sample moments of ``a^0`` on backward chains and of
      ``a^N`` on forward chains from the target equal the closed-form joints (5 SE);
    * the bound in general form: the Monte-Carlo mean of :func:`entropy_bound_samples` equals
      the closed-form ``ℓ`` (5 SE), ``ℓ <= H(pi~_0)``, and ``H - ℓ = KL(pi~_{0:N} || pi~_0
      ->pi_{1:N|0})`` (Appendix C.1 with the bridge's kernels);
    * the objective: the Monte-Carlo mean of :func:`bridge_kl_samples` equals the closed-form
      Eq. 5.37 (5 SE), Eq. 5.37 ``= -E[Q] - ℓ + log Z`` (Eq. C.11 for bridges), and the action
      marginal's KL to the target is at most Eq. 5.37 (data processing, as Eq. 5.20);
    * discretisation: the Euler-Maruyama moments at ``T`` (forward) and at ``0`` (backward)
      approach the moment ODEs of Eqs. 5.29 and 5.30, the error falling with ``delta`` and
      halving with it over the last doubling of ``N``;
    * time reversal (1-D): with ``v = 2 grad log ->pi_n - u`` (the forward marginal's score,
      Nelson's relation, and the backward chain started at ``->pi_N``) Eq. 5.37 tends to zero
      at first order in the same sense, for a general ``u`` and for DIME's ``f = -beta a,
      u = 0`` alike.

    Args:
        kl_estimator: candidate ``(bridge, traj, Q, log Z) -> (B,)`` estimate of Eq. 5.37;
            defaults to :func:`bridge_kl_samples`.
        bound_estimator: candidate ``(bridge, traj) -> (B,)`` estimate of ``ℓ``; defaults to
            :func:`entropy_bound_samples`.

    Returns:
        Report with data ``kl``, ``bound``, ``entropy``, ``gap`` (closed forms), ``kl_mc``,
        ``kl_stderr``, ``bound_mc``, ``bound_stderr``, ``kl_samples``, ``actions`` (the first
        2000 ``a^0``), ``marginal_mean``, ``marginal_cov``, ``target_mean``, ``target_cov``,
        ``sde_steps``, ``sde_errors`` (steps x [forward, backward]), ``reversal_steps`` and
        ``reversal_kl`` (steps x [general u, DIME]).
    """
    n_samples = check_count("n_samples", n_samples, 10)
    kl_est = kl_estimator or bridge_kl_samples
    bound_est = bound_estimator or entropy_bound_samples
    c = _affine_family(seed, 2)
    bridge = _affine_bridge(c, check_count("n_steps", n_steps), horizon)
    cf = linear_bridge_closed_form(bridge, c["mu"], c["sigma"])
    q = _quadratic_q(c["mu"], c["sigma"])

    traj = sample_backward(bridge, n_samples, seed)
    kl_samples = kl_est(bridge, traj, q, cf.log_z)
    kl_mc, kl_se = mc_mean_stderr(kl_samples)
    bound_mc, bound_se = mc_mean_stderr(bound_est(bridge, traj))
    a0 = traj[0]
    cov_se = np.sqrt(
        (np.diag(cf.marginal_cov)[:, None] * np.diag(cf.marginal_cov)[None, :] + cf.marginal_cov**2)
        / n_samples
    )
    rng = seeded_rng(seed, 43)
    start = c["mu"] + rng.standard_normal((n_samples, 2)) @ np.linalg.cholesky(c["sigma"]).T
    a_n = sample_forward(bridge, start, seed)[-1]
    end_mean, end_cov = cf.forward_marginals[0][-1], cf.forward_marginals[1][-1]

    steps = [check_count("sde_steps entry", n) for n in sde_steps]
    sde_err = _sde_errors(c, steps, horizon)
    rev_steps = [check_count("reversal_steps entry", n) for n in reversal_steps]
    rev_kl = _reversal_kls(seed, rev_steps, horizon)
    tol = relative_tol(cf.kl, cf.bound, cf.entropy, cf.expected_q, cf.log_z)
    checks = (
        worst_check(
            "sample mean of a^0 on backward chains = closed form (5 SE)",
            "Eqs. 5.32, 5.34",
            a0.mean(0),
            cf.marginal_mean,
            5 * np.sqrt(np.diag(cf.marginal_cov) / n_samples),
        ),
        worst_check(
            "sample covariance of a^0 on backward chains = closed form (5 SE)",
            "Eqs. 5.32, 5.34",
            np.cov(a0.T),
            cf.marginal_cov,
            5 * cov_se,
        ),
        worst_check(
            "sample mean of a^N on forward chains from the target = closed form (5 SE)",
            "Eqs. 5.31, 5.33",
            a_n.mean(0),
            end_mean,
            5 * np.sqrt(np.diag(end_cov) / n_samples),
        ),
        Check(
            "Monte Carlo of the bound estimator = closed-form ℓ (5 SE)",
            "Eqs. 5.15, 5.35-5.36",
            bound_mc,
            cf.bound,
            5 * bound_se,
        ),
        Check(
            "ℓ <= H(pi~_0) with the bridge's kernels",
            "Eqs. 5.15, C.2",
            cf.bound,
            cf.entropy,
            tol,
            "<=",
        ),
        Check(
            "H(pi~_0) - ℓ = KL(pi~_{0:N} || pi~_0 ->pi_{1:N|0})",
            "Eq. C.2",
            cf.entropy - cf.bound,
            cf.gap_kl,
            tol,
        ),
        Check(
            "Monte Carlo of Eq. 5.37 = closed-form joint KL (5 SE)",
            "Eqs. 5.37-5.38",
            kl_mc,
            cf.kl,
            5 * kl_se,
        ),
        Check(
            "Eq. 5.37 = -E[Q(a^0)] - ℓ + log Z",
            "Eqs. 5.37-5.38, C.11",
            cf.kl,
            -cf.expected_q - cf.bound + cf.log_z,
            tol,
        ),
        Check(
            "KL(pi~_0 || exp Q / Z) <= Eq. 5.37 (data processing)",
            "Eqs. 5.20, 5.37",
            cf.marginal_kl,
            cf.kl,
            tol,
            "<=",
        ),
        worst_check(
            f"Euler-Maruyama vs the SDEs: the error falls with delta (N = {steps})",
            "Eqs. 5.29-5.32",
            np.diff(sde_err, axis=0),
            0.0,
            0.0,
            "<=",
        ),
        worst_check(
            f"... and halves when delta halves (first order; N = {steps[-2]} -> {steps[-1]})",
            "Eqs. 5.29-5.32",
            sde_err[-1] / sde_err[-2],
            0.5,
            0.05,
        ),
        worst_check(
            f"v = 2 grad log ->pi_n - u: Eq. 5.37 falls with delta (N = {rev_steps})",
            "Eqs. 5.29-5.30, 5.37",
            np.diff(rev_kl, axis=0),
            0.0,
            0.0,
            "<=",
        ),
        worst_check(
            f"... and halves when delta halves (N = {rev_steps[-2]} -> {rev_steps[-1]})",
            "Eqs. 5.29-5.30, 5.37",
            rev_kl[-1] / rev_kl[-2],
            0.5,
            0.05,
        ),
    )
    data = {
        "kl": np.array(cf.kl),
        "bound": np.array(cf.bound),
        "entropy": np.array(cf.entropy),
        "gap": np.array(cf.gap_kl),
        "marginal_kl": np.array(cf.marginal_kl),
        "kl_mc": np.array(kl_mc),
        "kl_stderr": np.array(kl_se),
        "bound_mc": np.array(bound_mc),
        "bound_stderr": np.array(bound_se),
        "kl_samples": kl_samples,
        "actions": a0[:2000],
        "marginal_mean": cf.marginal_mean,
        "marginal_cov": cf.marginal_cov,
        "target_mean": c["mu"],
        "target_cov": c["sigma"],
        "sde_steps": np.array(steps),
        "sde_errors": sde_err,
        "reversal_steps": np.array(rev_steps),
        "reversal_kl": rev_kl,
    }
    return CheckReport("General bridges, affine drifts (Section 5.6)", checks, data)

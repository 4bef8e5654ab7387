"""Section 2.7 of the thesis: variational inference (Eqs. 2.56-2.71): the KL chain rule,
the mixture E-step bound, the KL of diffusion chains and max-ent RL as inference.

Part of :mod:`vslbook.bounds.foundations` (Chapter 2's checks).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import torch
from scipy.optimize import minimize
from scipy.special import log_softmax, logsumexp, softmax, xlogy
from scipy.stats import norm

from vslbook.bounds import Check, CheckReport, relative_tol
from vslbook.bounds.toy_numerics import (
    check_count,
    check_distribution,
    check_positive,
    linear_gaussian_joint,
    random_spd,
    seeded_rng,
    to_numpy,
    to_tensor,
    worst_check,
)
from vslbook.dists import condition_gaussian, gaussian_kl, log_responsibilities, moe_log_prob

KLFn = Callable[[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor], torch.Tensor]


def _gauss_hermite(mean: np.ndarray, cov: np.ndarray, n_nodes: int) -> tuple[np.ndarray, ...]:
    """Tensor-product Gauss-Hermite nodes ``(m, d)`` and weights ``(m,)`` for ``N(mean, cov)``.

    Exact for polynomials of degree ``<= 2 n_nodes - 1`` in each coordinate.
    """
    u, w = np.polynomial.hermite_e.hermegauss(n_nodes)
    d = mean.shape[0]
    grids = np.meshgrid(*([u] * d), indexing="ij")
    nodes = np.stack([g.ravel() for g in grids], axis=-1)
    weights = np.prod(np.stack(np.meshgrid(*([w] * d), indexing="ij"), -1).reshape(-1, d), -1)
    return mean + nodes @ np.linalg.cholesky(cov).T, weights / weights.sum()


def check_kl_chain_rule(
    seed: int = 0,
    dim_x: int = 2,
    dim_z: int = 2,
    n_samples: int = 5000,
    kl: KLFn = gaussian_kl,
) -> CheckReport:
    """Chain rule of the KL (Eq. 2.60) on random joint Gaussians ``p(x, z)``, ``q(x, z)``.

    ``KL(p(x) || q(x)) = KL(p(x, z) || q(x, z)) - E_p(x)[KL(p(z|x) || q(z|x))]``, with the
    expectation computed exactly (Gauss-Hermite cubature; the integrand is quadratic in ``x``)
    and by Monte Carlo (tolerance 4 standard errors). Posteriors come from
    :func:`~vslbook.dists.condition_gaussian`.

    Args:
        kl: the Gaussian KL ``(mean_p, cov_p, mean_q, cov_q) -> KL`` used for every term.

    Returns:
        Report with data ``marginal_kl``, ``joint_kl``, ``expected_posterior_kl`` (exact),
        ``posterior_kl_samples`` (n_samples,).
    """
    dx, dz = check_count("dim_x", dim_x), check_count("dim_z", dim_z)
    rng = seeded_rng(seed)
    d = dx + dz
    mp, mq = rng.normal(size=d), rng.normal(size=d)
    sp, sq = random_spd(rng, d), random_spd(rng, d, 1.5)
    ix = list(range(dx))

    def f(*args: np.ndarray) -> float:
        return float(to_numpy(kl(*(to_tensor(a) for a in args))))

    def posterior_kl(x: np.ndarray) -> np.ndarray:
        p_mean, p_cov = condition_gaussian(to_tensor(mp), to_tensor(sp), ix, to_tensor(x))
        q_mean, q_cov = condition_gaussian(to_tensor(mq), to_tensor(sq), ix, to_tensor(x))
        return to_numpy(kl(p_mean, p_cov, q_mean, q_cov))

    marginal = f(mp[:dx], sp[:dx, :dx], mq[:dx], sq[:dx, :dx])
    joint = f(mp, sp, mq, sq)
    nodes, weights = _gauss_hermite(mp[:dx], sp[:dx, :dx], 4)
    expected = float(weights @ posterior_kl(nodes))
    x = rng.multivariate_normal(mp[:dx], sp[:dx, :dx], size=check_count("n_samples", n_samples, 2))
    samples = posterior_kl(x)
    mc, se = float(samples.mean()), float(samples.std(ddof=1) / math.sqrt(n_samples))
    tol = relative_tol(joint, marginal)
    checks = (
        Check(
            "KL(p(x)||q(x)) = KL(p(x,z)||q(x,z)) - E[KL(p(z|x)||q(z|x))] (exact expectation)",
            "Eq. 2.60",
            marginal,
            joint - expected,
            tol,
        ),
        Check(
            "KL(p(x)||q(x)) = KL(p(x,z)||q(x,z)) - E[KL(p(z|x)||q(z|x))] (Monte Carlo, 4 SE)",
            "Eq. 2.60",
            marginal,
            joint - mc,
            4 * se,
        ),
        Check("KL(p(x)||q(x)) <= KL(p(x,z)||q(x,z))", "Eq. 2.60", marginal, joint, tol, "<="),
    )
    data = {
        "marginal_kl": np.array(marginal),
        "joint_kl": np.array(joint),
        "expected_posterior_kl": np.array(expected),
        "posterior_kl_samples": samples,
    }
    return CheckReport(
        "Chain rule of the KL for Gaussian latent variable models (Section 2.7.1)", checks, data
    )


def check_mixture_estep_bound(
    seed: int = 0,
    n_components: int = 3,
    n_variational: int = 20,
    variational: Callable[[np.ndarray], np.ndarray] | None = None,
) -> CheckReport:
    """Upper bound ``L(theta, q(o|x)) >= KL(p(x) || q(x))`` for mixtures, tight at Eq. 2.64.

    ``p(x)`` is a random 1-D Gaussian mixture, ``q(x)`` a random two-component target and
    ``L = KL(p(x, o) || q(o|x) q(x))`` (Eqs. 2.60-2.61 with ``z = o``), all integrated on a fine
    grid. Checks: the grid integrates ``p`` to 1; ``L >= KL`` for ``n_variational`` random
    logistic ``q(o|x)`` and the uniform one; the gap equals ``E_p(x)[KL(p(o|x) || q(o|x))]``;
    and the bound is tight for ``variational`` (default: the responsibilities ``p(o|x)``).

    Args:
        variational: candidate ``x (n,) -> q(o|x) (n, K)`` for the tightness check.

    Returns:
        Report with data ``x``, ``p``, ``q`` (densities on the grid), ``responsibilities``
        (n, K), ``kl`` and ``bounds`` (the bound for each random variational distribution).
    """
    k = check_count("n_components", n_components)
    rng = seeded_rng(seed)
    weights = rng.dirichlet(np.full(k, 3.0))
    means = rng.uniform(-3.0, 3.0, k)
    covs = rng.uniform(0.4, 1.2, k) ** 2
    q_weights, q_means = np.array([0.6, 0.4]), rng.uniform(-2.0, 2.0, 2)
    q_covs = rng.uniform(0.8, 1.5, 2) ** 2
    x = np.linspace(-15.0, 15.0, 6001)
    dx = x[1] - x[0]
    args = (to_tensor(np.log(weights)), to_tensor(means[:, None]), to_tensor(covs[:, None, None]))
    log_pxo = np.log(weights) + norm.logpdf(x[:, None], means, np.sqrt(covs))
    log_p = to_numpy(moe_log_prob(to_tensor(x[:, None]), *args))
    log_q = to_numpy(
        moe_log_prob(
            to_tensor(x[:, None]),
            to_tensor(np.log(q_weights)),
            to_tensor(q_means[:, None]),
            to_tensor(q_covs[:, None, None]),
        )
    )
    log_resp = to_numpy(log_responsibilities(to_tensor(x[:, None]), *args))
    p = np.exp(log_p)

    def integrate(values: np.ndarray) -> float:
        return float(np.trapezoid(values, dx=dx))

    kl_true = integrate(p * (log_p - log_q))

    def bound(log_qo: np.ndarray) -> float:
        return integrate(np.sum(np.exp(log_pxo) * (log_pxo - log_qo - log_q[:, None]), -1))

    def expected_posterior_kl(log_qo: np.ndarray) -> float:
        return integrate(p * np.sum(np.exp(log_resp) * (log_resp - log_qo), -1))

    arbitrary = [np.full((x.size, k), -math.log(k))]
    for _ in range(check_count("n_variational", n_variational)):
        slope, offset = rng.normal(size=k), rng.normal(scale=2.0, size=k)
        arbitrary.append(log_softmax(slope * x[:, None] + offset, axis=-1))
    bounds = np.array([bound(lq) for lq in arbitrary])
    gaps = np.array([expected_posterior_kl(lq) for lq in arbitrary])
    if variational is None:
        log_cand = log_resp
    else:
        cand = check_distribution("variational(x)", variational(x), (x.size, k))
        with np.errstate(divide="ignore"):
            log_cand = np.log(cand)
    tol = relative_tol(kl_true)
    checks = (
        Check("integral of p(x) dx = 1 on the grid", "Eq. 2.47", integrate(p), 1.0, 1e-9),
        Check(
            f"KL(p||q) <= L(theta, q(o|x)) for {len(arbitrary)} arbitrary q(o|x)",
            "Eq. 2.60",
            kl_true,
            bounds.min(),
            tol,
            "<=",
        ),
        worst_check(
            "L - KL(p||q) = E_p(x)[KL(p(o|x)||q(o|x))]", "Eq. 2.60", bounds - kl_true, gaps, tol
        ),
        Check("bound is tight for q(o|x) = p(o|x)", "Eq. 2.64", bound(log_cand), kl_true, tol),
    )
    data = {
        "x": x,
        "p": p,
        "q": np.exp(log_q),
        "responsibilities": np.exp(log_resp),
        "kl": np.array(kl_true),
        "bounds": bounds,
    }
    return CheckReport("E-step bound for mixture models (Section 2.7.2)", checks, data)


def check_diffusion_kl(
    seed: int = 0,
    n_steps: int = 4,
    beta: float = 1.0,
    eta: float = 1.0,
    T: float = 1.0,
    n_samples: int = 100_000,
    forward_log_kernel: Callable[[np.ndarray, np.ndarray, int], np.ndarray] | None = None,
) -> CheckReport:
    """Joint KL of a linear-Gaussian denoising chain (Eqs. 2.65-2.66) and its chain rule.

    The noising chain ``q`` starts at a Gaussian target ``q(x^0)`` and uses the Euler-Maruyama
    kernels of Eq. 2.51, ``x^n | x^{n-1} ~ N((1 - beta dt) x^{n-1}, 2 beta eta^2 dt)``. The
    model ``p`` starts at ``x^N ~ N(0, eta^2)`` and uses random linear-Gaussian backward kernels
    ``x^{n-1} | x^n ~ N(a_n x^n + b_n, v_n)`` (Eq. 2.54). Both joints over ``x^{0:N}`` are
    Gaussian, so ``KL(p || q)`` is closed form. Checks: the Monte-Carlo estimate of the
    expectation in Eq. 2.66 (using ``forward_log_kernel`` for ``log q(x^n | x^{n-1})``) agrees
    within 4 standard errors; the joint KL bounds the marginal ``KL(p(x^0) || q(x^0))``; and the
    gap equals the expected posterior KL of Eq. 2.60 (Gauss-Hermite over ``x^0``).

    Returns:
        Report with data ``p_mean``, ``p_var``, ``q_mean``, ``q_var`` (marginals of ``x^n``,
        n = 0..N), ``joint_kl``, ``marginal_kl``, ``expected_posterior_kl``, ``mc_estimate``,
        ``mc_stderr`` and ``log_ratio_samples`` (the first 2000 Monte-Carlo terms).
    """
    n = check_count("n_steps", n_steps)
    dt = check_positive("T", T) / n
    decay = 1 - check_positive("beta", beta) * dt
    if not decay > 0:
        raise ValueError(f"beta * T / n_steps must be < 1 for a stable chain, got {beta * dt:g}")
    kernel_var = 2 * beta * check_positive("eta", eta) ** 2 * dt
    rng = seeded_rng(seed)
    target_mean, target_std = rng.uniform(-1.0, 1.0), rng.uniform(0.5, 1.5)
    gains = rng.uniform(0.9, 1.4, n)  # gains[n - 1] maps x^n to x^{n-1}
    shifts = rng.normal(scale=0.3, size=n)
    variances = rng.uniform(0.2, 0.6, n) * kernel_var

    # Variables ordered x^0, ..., x^N.
    m_q, c_q = np.zeros((n + 1, n + 1)), np.zeros(n + 1)
    c_q[0] = target_mean
    m_q[np.arange(1, n + 1), np.arange(n)] = decay
    std_q = np.r_[target_std, np.full(n, math.sqrt(kernel_var))]
    m_p, c_p = np.zeros((n + 1, n + 1)), np.r_[shifts, 0.0]
    m_p[np.arange(n), np.arange(1, n + 1)] = gains
    std_p = np.r_[np.sqrt(variances), eta]
    mean_q, cov_q = linear_gaussian_joint(m_q, c_q, std_q)
    mean_p, cov_p = linear_gaussian_joint(m_p, c_p, std_p)

    joint = float(
        gaussian_kl(to_tensor(mean_p), to_tensor(cov_p), to_tensor(mean_q), to_tensor(cov_q))
    )
    marginal = float(
        gaussian_kl(
            to_tensor(mean_p[:1]),
            to_tensor(cov_p[:1, :1]),
            to_tensor(mean_q[:1]),
            to_tensor(cov_q[:1, :1]),
        )
    )
    nodes, weights = _gauss_hermite(mean_p[:1], cov_p[:1, :1], 8)
    post_p = condition_gaussian(to_tensor(mean_p), to_tensor(cov_p), [0], to_tensor(nodes))
    post_q = condition_gaussian(to_tensor(mean_q), to_tensor(cov_q), [0], to_tensor(nodes))
    expected = float(weights @ to_numpy(gaussian_kl(*post_p, *post_q)))

    if forward_log_kernel is None:

        def forward_log_kernel(x_next: np.ndarray, x_prev: np.ndarray, step: int) -> np.ndarray:
            return norm.logpdf(x_next, decay * x_prev, math.sqrt(kernel_var))

    rng_mc = seeded_rng(seed, 1)
    n_samples = check_count("n_samples", n_samples, 2)
    x = eta * rng_mc.standard_normal(n_samples)
    log_ratio = norm.logpdf(x, 0.0, eta)
    for step in range(n, 0, -1):
        x_prev = gains[step - 1] * x + shifts[step - 1]
        x_prev = x_prev + math.sqrt(variances[step - 1]) * rng_mc.standard_normal(n_samples)
        log_ratio += norm.logpdf(
            x_prev, gains[step - 1] * x + shifts[step - 1], math.sqrt(variances[step - 1])
        )
        log_ratio -= forward_log_kernel(x, x_prev, step)
        x = x_prev
    log_ratio -= norm.logpdf(x, target_mean, target_std)
    mc = float(log_ratio.mean())
    se = float(log_ratio.std(ddof=1) / math.sqrt(n_samples))
    tol = relative_tol(joint)
    checks = (
        Check(
            "Monte Carlo of Eq. 2.66 = closed-form joint KL (4 SE)",
            "Eqs. 2.65-2.66",
            mc,
            joint,
            4 * se,
        ),
        Check("KL(p(x^0)||q(x^0)) <= joint KL", "Eqs. 2.60, 2.65", marginal, joint, tol, "<="),
        Check(
            "joint KL - marginal KL = E_p(x^0)[KL(p(x^1:N|x^0)||q(x^1:N|x^0))]",
            "Eq. 2.60",
            joint - marginal,
            expected,
            tol,
        ),
    )
    data = {
        "p_mean": mean_p,
        "p_var": np.diag(cov_p),
        "q_mean": mean_q,
        "q_var": np.diag(cov_q),
        "joint_kl": np.array(joint),
        "marginal_kl": np.array(marginal),
        "expected_posterior_kl": np.array(expected),
        "mc_estimate": np.array(mc),
        "mc_stderr": np.array(se),
        "log_ratio_samples": log_ratio[:2000],
    }
    return CheckReport(
        "Joint KL of a linear-Gaussian diffusion chain (Section 2.7.3)", checks, data
    )


def check_maxent_as_inference(
    seed: int = 0,
    n_states: int = 5,
    n_actions: int = 4,
    alpha: float = 0.7,
    n_random: int = 200,
    policy: np.ndarray | None = None,
) -> CheckReport:
    """Max-ent RL as inference on a discrete action set (Eqs. 2.69-2.71).

    For a random ``Q(s, a)`` and state distribution ``rho(s)``, checks that Eq. 2.70
    (``exp(Q / alpha) / Z``) equals Eq. 2.71 (``exp((Q - V) / alpha)`` with
    ``V = alpha log Z``); that the candidate ``policy`` (default Eq. 2.71) attains
    ``L = 0`` in Eq. 2.69, is no worse than ``n_random`` random policies and agrees with a
    numerical (L-BFGS) minimiser of Eq. 2.69; and that
    ``KL(pi || exp(Q / alpha) / Z) = -(E_pi[Q] / alpha + H(pi)) + log Z`` for random policies.

    Returns:
        Report with data ``q``, ``v``, ``policy`` (the candidate), ``pi_star`` (Eq. 2.71),
        ``pi_numerical`` and ``l_random`` (the objective of each random policy).
    """
    S, A = check_count("n_states", n_states), check_count("n_actions", n_actions)
    alpha = check_positive("alpha", alpha)
    rng = seeded_rng(seed)
    q = rng.normal(scale=2.0, size=(S, A))
    rho = rng.dirichlet(np.ones(S))
    log_z = logsumexp(q / alpha, axis=-1)
    v = alpha * log_z
    log_target = q / alpha - log_z[:, None]
    pi_270 = np.exp(q / alpha) / np.exp(log_z)[:, None]
    pi_271 = np.exp((q - v[:, None]) / alpha)
    cand = pi_271 if policy is None else check_distribution("policy", policy, (S, A))

    def objective(pi: np.ndarray) -> float:  # Eq. 2.69
        return float(rho @ np.sum(xlogy(pi, pi) - pi * log_target, -1))

    def identity(pi: np.ndarray) -> float:
        entropy = -xlogy(pi, pi).sum(-1)
        return float(rho @ (-(np.sum(pi * q, -1) / alpha + entropy) + log_z))

    def loss_and_grad(logits: np.ndarray) -> tuple[float, np.ndarray]:
        log_pi = log_softmax(logits.reshape(S, A), axis=-1)
        pi = np.exp(log_pi)
        kl = np.sum(pi * (log_pi - log_target), -1)
        grad = rho[:, None] * pi * (log_pi - log_target - kl[:, None])
        return float(rho @ kl), grad.ravel()

    result = minimize(
        loss_and_grad,
        np.zeros(S * A),
        jac=True,
        method="L-BFGS-B",
        options={"gtol": 1e-12, "ftol": 1e-15, "maxiter": 1000},
    )
    pi_numerical = softmax(result.x.reshape(S, A), axis=-1)
    randoms = [rng.dirichlet(np.ones(A), size=S) for _ in range(check_count("n_random", n_random))]
    l_random = np.array([objective(pi) for pi in randoms])
    checks = (
        worst_check(
            "Eq. 2.70 exp(Q/alpha)/Z = Eq. 2.71 exp((Q - V)/alpha), V = alpha log Z",
            "Eqs. 2.70-2.71",
            pi_270,
            pi_271,
            1e-12,
        ),
        Check("L(pi) = 0 (the KL objective is minimal)", "Eq. 2.69", objective(cand), 0.0, 1e-10),
        Check(
            f"L(pi) <= L of {n_random} random policies",
            "Eq. 2.69",
            objective(cand),
            l_random.min(),
            1e-12,
            "<=",
        ),
        worst_check(
            "pi equals the numerical minimiser of Eq. 2.69", "Eq. 2.69", cand, pi_numerical, 1e-5
        ),
        worst_check(
            "KL(pi||exp(Q/alpha)/Z) = -(E_pi[Q]/alpha + H(pi)) + log Z",
            "Eq. 2.69",
            l_random,
            [identity(pi) for pi in randoms],
            1e-10,
        ),
    )
    data = {
        "q": q,
        "v": v,
        "policy": cand,
        "pi_star": pi_271,
        "pi_numerical": pi_numerical,
        "l_random": l_random,
    }
    return CheckReport("Maximum entropy RL as variational inference (Section 2.7.5)", checks, data)

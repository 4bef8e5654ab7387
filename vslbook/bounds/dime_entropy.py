"""Numerical checks of Section 5.4.1 (DIME): the entropy lower bound of a diffusion policy.

The bound ``ℓ`` of Eq. 5.15 (derived in Eq. C.2), its gap, the KL between the generative and the
noising chain (Eqs. 5.18-5.20) and the approximate inference form of Eq. C.11.
:func:`check_entropy_lower_bound` runs :class:`~vslbook.srl.DiffusionPolicy` itself with an
affine score network (:func:`linear_gaussian_policy`), so its chain is linear-Gaussian and every
quantity has a closed form (:func:`linear_gaussian_chain`, in
:mod:`vslbook.bounds.dime_linear_chain`, re-exported here).

Import from :mod:`vslbook.bounds.dime`, which re-exports everything public here.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager

import numpy as np
import torch
from torch import Tensor

from vslbook.bounds import Check, CheckReport, relative_tol
from vslbook.bounds.dime_linear_chain import (
    AffineScore,
    LinearGaussianChain,
    gaussian_entropy,
    gaussian_kl_np,
    linear_gaussian_chain,
    linear_gaussian_policy,
    noising_joint,
)
from vslbook.bounds.toy_numerics import check_count, seeded_rng, to_numpy, worst_check
from vslbook.srl.diffusion_policy import DiffusionPolicy, PolicySample

__all__ = [
    "AffineScore",
    "LinearGaussianChain",
    "check_entropy_lower_bound",
    "gaussian_entropy",
    "linear_gaussian_chain",
    "linear_gaussian_policy",
    "single_thread",
]


def _log_normal(x: np.ndarray, mean: np.ndarray, var: np.ndarray) -> np.ndarray:
    return -0.5 * ((x - mean) ** 2 / var + np.log(2 * math.pi * var))


@contextmanager
def single_thread() -> Iterator[None]:
    """Run torch on one thread, restoring the previous setting afterwards.

    The chains here are tiny; on a loaded machine torch's thread pool costs far more than the
    arithmetic, so the check pins itself to one thread (its results do not depend on it).
    """
    previous = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(previous)


def _sample_chain(
    policy: DiffusionPolicy,
    n_samples: int,
    seed: int,
    bound_estimator: Callable[[PolicySample], Tensor],
) -> tuple[np.ndarray, np.ndarray]:
    """The estimator's samples ``(n,)`` and the trajectories ``(N+1, n, d)`` (seeded)."""
    obs = torch.zeros(n_samples, 1, dtype=torch.float64)
    generator = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        out = policy.sample(obs, generator=generator, return_trajectory=True)
    return to_numpy(bound_estimator(out)).astype(float), to_numpy(out.trajectory)


def _log_ratio_terms(
    trajectory: np.ndarray, etas: np.ndarray, sigma0: float, slope: np.ndarray, offset: np.ndarray
) -> np.ndarray:
    """Per-sample terms ``(N+1, n)`` of the log ratio in Eq. 5.15 from the documented kernels.

    Row 0 is ``-log p_N(x^N)``; row ``k >= 1`` is ``log ->pi(X_{k-1}|X_k) - log pi(X_k|X_{k-1})``.
    """
    x = trajectory
    terms = [-_log_normal(x[0], 0.0, sigma0**2).sum(-1)]
    for k, eta in enumerate(etas):
        gen_mean = x[k] + eta * (-x[k] / sigma0**2 + slope * x[k] + offset)
        noising_mean = x[k + 1] - eta * x[k + 1] / sigma0**2
        log_noising = _log_normal(x[k], noising_mean, 2 * eta).sum(-1)
        log_generative = _log_normal(x[k + 1], gen_mean, 2 * eta).sum(-1)
        terms.append(log_noising - log_generative)
    return np.stack(terms)


def _mc(samples: np.ndarray) -> tuple[float, float]:
    return float(samples.mean()), float(samples.std(ddof=1) / math.sqrt(samples.size))


def check_entropy_lower_bound(
    seed: int = 0,
    n_steps: int = 4,
    sigma0: float = 1.5,
    act_dim: int = 2,
    n_samples: int = 20_000,
    total_time: float = 1.0,
    n_steps_series: Sequence[int] = (1, 2, 4, 8, 16),
    n_series_samples: int = 4000,
    marginal_entropy: Callable[[np.ndarray, np.ndarray], float] | None = None,
    bound_estimator: Callable[[PolicySample], Tensor] | None = None,
) -> CheckReport:
    """The diffusion policy's entropy bound ``ℓ <= H`` and its gap (Eqs. 5.15, 5.18-5.20, C.2).

    Runs :func:`linear_gaussian_policy`, the real :class:`~vslbook.srl.DiffusionPolicy` with
    ``f_theta(x) = slope x + offset`` (seeded ``slope``, ``offset`` and noise scales) and no
    tanh, so every quantity has a closed form (:func:`linear_gaussian_chain`). What the policy's
    ``entropy_bound`` estimates is the single-sample log ratio of Eq. 5.15,

        log ->pi_{1:N|0}(x^{1:N}|x^0) - log pi_{0:N}(x^{0:N})
          = sum_n [log ->pi_{n|n-1} - log pi_{n-1|n}] - log p_N(x^N),

    with ``x^{0:N}`` drawn from the generative chain (prior ``pi_N = p_N = N(0, sigma0^2)``).
    By Eq. C.2 its mean ``ℓ`` is ``H(pi_0) - KL(pi_{0:N} || pi_0 ->pi_{1:N|0})``: the gap is the
    KL between the generative joint and the noising joint started at the generative marginal.

    Checks: the policy's samples equal the log ratio recomputed from the documented kernels;
    the sample moments of ``x^0`` match the closed-form marginal; the Monte-Carlo mean of the
    estimator matches ``ℓ`` (5 standard errors), in total and step by step; ``ℓ <= H``;
    ``H - ℓ = KL`` in closed form and by Monte Carlo of ``-(estimate + log pi_0(x^0))``; for a
    Gaussian target ``exp Q / Z`` Eq. 5.20 (marginal KL <= joint KL) and Eq. C.11
    (joint KL = ``-E[Q] - ℓ + log Z``); and, for every ``n_steps`` in ``n_steps_series`` (same
    total time), ``ℓ <= H``, ``H - ℓ = KL`` and Monte Carlo = closed form.

    Args:
        marginal_entropy: candidate ``(mean, var) -> H`` for the ``x^0`` marginal (independent
            dimensions); defaults to :func:`gaussian_entropy`.
        bound_estimator: candidate ``PolicySample -> (n,)`` estimate of ``ℓ``; defaults to
            ``sample.entropy_bound``.

    Returns:
        Report with data ``etas`` (N, d), ``step_contributions`` (N+1,: prior term, then one
        per step in sampling order, summed over dimensions) and ``step_contributions_mc``,
        ``entropy``, ``bound``, ``gap`` (the closed-form KL), ``bound_mc``, ``bound_stderr``,
        ``gap_mc``, ``gap_stderr``, ``bound_samples`` (n_samples,), ``gap_samples``, ``latent``
        (the first 2000 actions x^0), ``marginal_mean``, ``marginal_var``, ``target_kl``
        (marginal, joint) and per ``series_steps``: ``series_entropy``, ``series_bound``,
        ``series_gap``, ``series_bound_mc``, ``series_bound_stderr``, ``series_gap_zero_drift``
        (the gap of the same chain with ``f_theta = 0``).
    """
    with single_thread():
        return _entropy_lower_bound(
            seed,
            n_steps,
            sigma0,
            act_dim,
            n_samples,
            total_time,
            n_steps_series,
            n_series_samples,
            marginal_entropy,
            bound_estimator,
        )


def _entropy_lower_bound(
    seed: int,
    n_steps: int,
    sigma0: float,
    act_dim: int,
    n_samples: int,
    total_time: float,
    n_steps_series: Sequence[int],
    n_series_samples: int,
    marginal_entropy: Callable[[np.ndarray, np.ndarray], float] | None,
    bound_estimator: Callable[[PolicySample], Tensor] | None,
) -> CheckReport:
    """The body of :func:`check_entropy_lower_bound`."""
    d = check_count("act_dim", act_dim)
    n_samples = check_count("n_samples", n_samples, 2)
    n_series_samples = check_count("n_series_samples", n_series_samples, 2)
    series = [check_count("n_steps_series entry", n) for n in n_steps_series]
    entropy_of = marginal_entropy or (lambda mean, var: gaussian_entropy(var))
    estimator = bound_estimator or (lambda sample: sample.entropy_bound)
    rng = seeded_rng(seed)
    noise_var = rng.uniform(0.5, 1.5, d)
    slope, offset = rng.uniform(-0.5, 0.0, d), rng.normal(scale=1.0, size=d)
    target_mean, target_std = rng.normal(size=d), rng.uniform(0.5, 1.5, d)

    def setup(n: int) -> tuple[DiffusionPolicy, np.ndarray, LinearGaussianChain]:
        policy = linear_gaussian_policy(n, sigma0, total_time, noise_var, slope, offset, seed)
        etas = to_numpy(policy.step_sizes)
        return policy, etas, linear_gaussian_chain(etas, sigma0, slope, offset)

    policy, etas, chain = setup(check_count("n_steps", n_steps))
    samples, trajectory = _sample_chain(policy, n_samples, seed, estimator)
    terms = _log_ratio_terms(trajectory, etas, sigma0, slope, offset)
    x0 = trajectory[-1]
    entropy = float(entropy_of(chain.marginal_mean, chain.marginal_var))
    bound, kl = float(chain.bound.sum()), float(chain.kl.sum())
    bound_mc, bound_se = _mc(samples)
    log_marginal = _log_normal(x0, chain.marginal_mean, chain.marginal_var).sum(-1)
    gap_samples = -(samples + log_marginal)
    gap_mc, gap_se = _mc(gap_samples)
    steps_cf = chain.step_contributions.sum(0)
    steps_mc, steps_se = terms.mean(1), terms.std(1, ddof=1) / math.sqrt(n_samples)
    mean_se = np.sqrt(chain.marginal_var / n_samples)
    var_se = chain.marginal_var * math.sqrt(2 / (n_samples - 1))

    # Eq. 5.20 and C.11 for a Gaussian target exp(Q)/Z, Q(a) = -sum_d (a_d - mu_d)^2 / (2 s_d^2).
    joint_target = []
    for j in range(d):
        mean_f, cov_f = noising_joint(
            etas[:, j], sigma0, 0.0, 0.0, target_mean[j], target_std[j] ** 2
        )
        joint_target.append((mean_f, cov_f))
    kl_joint_target = float(
        gaussian_kl_np(
            chain.gen_mean,
            chain.gen_cov,
            np.stack([m for m, _ in joint_target]),
            np.stack([c for _, c in joint_target]),
        ).sum()
    )
    kl_marginal_target = float(
        gaussian_kl_np(
            chain.marginal_mean[:, None],
            chain.marginal_var[:, None, None],
            target_mean[:, None],
            (target_std**2)[:, None, None],
        ).sum()
    )
    expected_q = float(
        -np.sum(((chain.marginal_mean - target_mean) ** 2 + chain.marginal_var) / target_std**2) / 2
    )
    log_z = float(np.sum(0.5 * np.log(2 * math.pi * target_std**2)))

    s_entropy, s_bound, s_gap, s_mc, s_se, s_gap0 = ([] for _ in range(6))
    for i, n in enumerate(series):
        s_policy, s_etas, s_chain = setup(n)
        s_samples, _ = _sample_chain(s_policy, n_series_samples, seed + 1 + i, estimator)
        mc, se = _mc(s_samples)
        s_entropy.append(entropy_of(s_chain.marginal_mean, s_chain.marginal_var))
        s_bound.append(s_chain.bound.sum())
        s_gap.append(s_chain.kl.sum())
        s_mc.append(mc)
        s_se.append(se)
        s_gap0.append(linear_gaussian_chain(s_etas, sigma0).kl.sum())
    s_entropy, s_bound, s_gap, s_mc, s_se, s_gap0 = (
        np.array(v, dtype=float) for v in (s_entropy, s_bound, s_gap, s_mc, s_se, s_gap0)
    )

    tol = relative_tol(entropy, bound, kl)
    checks = (
        worst_check(
            "entropy_bound sample = log ratio of Eq. 5.15 from the documented kernels",
            "Eqs. 5.12-5.15",
            samples,
            terms.sum(0),
            relative_tol(float(np.abs(samples).max())),
        ),
        worst_check(
            "sample mean of x^0 = closed-form marginal mean (5 SE)",
            "Eq. 5.14",
            x0.mean(0),
            chain.marginal_mean,
            5 * mean_se,
        ),
        worst_check(
            "sample var of x^0 = closed-form marginal var (5 SE)",
            "Eq. 5.14",
            x0.var(0, ddof=1),
            chain.marginal_var,
            5 * var_se,
        ),
        Check(
            "Monte Carlo E[entropy_bound] = closed-form ℓ (5 SE)",
            "Eq. 5.15",
            bound_mc,
            bound,
            5 * bound_se,
        ),
        worst_check(
            "per-step Monte Carlo contributions to ℓ = closed form (5 SE)",
            "Eqs. 5.15, C.2",
            steps_mc,
            steps_cf,
            5 * steps_se,
        ),
        Check("ℓ <= H(pi_0)", "Eqs. 5.15, C.2", bound, entropy, tol, "<="),
        Check(
            "H(pi_0) - ℓ = KL(generative joint || noising joint from pi_0)",
            "Eqs. 5.18, C.2",
            entropy - bound,
            kl,
            tol,
        ),
        Check(
            "Monte Carlo of -(entropy_bound + log pi_0(x^0)) = KL (5 SE)",
            "Eqs. 5.18, C.2",
            gap_mc,
            kl,
            5 * gap_se,
        ),
        Check(
            "KL(pi_0 || exp Q / Z) <= KL(pi_{0:N} || ->pi_{0:N}) (data processing)",
            "Eq. 5.20",
            kl_marginal_target,
            kl_joint_target,
            relative_tol(kl_joint_target),
            "<=",
        ),
        Check(
            "KL(pi_{0:N} || ->pi_{0:N}) = -E[Q(x^0)] - ℓ + log Z",
            "Eqs. 5.18-5.19, C.11",
            kl_joint_target,
            -expected_q - bound + log_z,
            relative_tol(kl_joint_target, expected_q, bound, log_z),
        ),
        worst_check(
            f"ℓ <= H for n_steps in {tuple(series)}",
            "Eqs. 5.15, C.2",
            s_bound,
            s_entropy,
            relative_tol(*s_entropy, *s_bound),
            "<=",
        ),
        worst_check(
            f"H - ℓ = KL for n_steps in {tuple(series)}",
            "Eqs. 5.18, C.2",
            s_entropy - s_bound,
            s_gap,
            relative_tol(*s_entropy, *s_bound),
        ),
        worst_check(
            f"Monte Carlo E[entropy_bound] = ℓ for n_steps in {tuple(series)} (5 SE)",
            "Eq. 5.15",
            s_mc,
            s_bound,
            5 * s_se,
        ),
    )
    data = {
        "etas": etas,
        "step_contributions": steps_cf,
        "step_contributions_mc": steps_mc,
        "entropy": np.array(entropy),
        "bound": np.array(bound),
        "gap": np.array(kl),
        "bound_mc": np.array(bound_mc),
        "bound_stderr": np.array(bound_se),
        "gap_mc": np.array(gap_mc),
        "gap_stderr": np.array(gap_se),
        "bound_samples": samples,
        "gap_samples": gap_samples,
        "latent": x0[:2000],
        "marginal_mean": chain.marginal_mean,
        "marginal_var": chain.marginal_var,
        "target_kl": np.array([kl_marginal_target, kl_joint_target]),
        "series_steps": np.array(series),
        "series_entropy": s_entropy,
        "series_bound": s_bound,
        "series_gap": s_gap,
        "series_bound_mc": s_mc,
        "series_bound_stderr": s_se,
        "series_gap_zero_drift": s_gap0,
    }
    return CheckReport("Entropy lower bound of the diffusion policy (Section 5.4.1)", checks, data)

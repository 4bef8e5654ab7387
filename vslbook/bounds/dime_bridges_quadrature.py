"""Numerical check of Section 5.6 (DIME) against quadrature: general bridges without closed form.

:func:`check_bridge_quadrature`: a one-dimensional bridge with nonlinear drifts and a
double-well target, where no closed form exists; Eqs. 5.31-5.38 by brute-force quadrature on a
grid (the chain's kernels applied as matrices) against Monte Carlo. The checks against closed
forms (affine drifts) are in :mod:`vslbook.bounds.dime_bridges_checks`, DIME as the special
case in :mod:`vslbook.bounds.dime_bridges_special`.

Import from :mod:`vslbook.bounds.dime`, which re-exports everything public here.
"""

from __future__ import annotations

import math
from collections.abc import Callable

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
)
from vslbook.bounds.toy_numerics import check_count, mc_mean_stderr, seeded_rng

__all__ = ["check_bridge_quadrature"]


def _nonlinear_bridge(seed: int, n_steps: int, horizon: float) -> GeneralBridge:
    rng = seeded_rng(seed, 47)
    a1, a2, a3 = rng.uniform(0.5, 1.0, 3)

    def f(a: np.ndarray, n: int) -> np.ndarray:
        return -0.5 * a + 0.3 * np.sin(2 * a)

    def u(a: np.ndarray, n: int) -> np.ndarray:
        return a1 * np.tanh(a) - 0.4 * n / n_steps

    def v(a: np.ndarray, n: int) -> np.ndarray:
        return -3.0 * a + 2 * a2 * np.tanh(2 * a) + 0.3 * a3 * np.cos(a)

    return make_bridge(f, u, v, 1.0, horizon / n_steps, n_steps, 1)


def _double_well(seed: int) -> Callable[[np.ndarray], np.ndarray]:
    tilt = seeded_rng(seed, 53).uniform(-0.4, 0.4)
    return lambda a: -1.5 * (np.asarray(a)[..., 0] ** 2 - 1) ** 2 + tilt * np.asarray(a)[..., 0]


def _log_gauss(x: np.ndarray, mean: np.ndarray, var: float) -> np.ndarray:
    return -0.5 * ((x - mean) ** 2 / var + math.log(2 * math.pi * var))


def _quadrature(
    bridge: GeneralBridge, q: Callable[[np.ndarray], np.ndarray], grid: np.ndarray
) -> dict[str, float | np.ndarray]:
    """Brute-force quadrature of a 1-D bridge: the backward chain's marginals are propagated
    on ``grid`` with its kernels as matrices; every expectation is a sum over the grid."""
    h = grid[1] - grid[0]
    col = grid[:, None]
    log_p = _log_gauss(grid, bridge.prior_mean[0], bridge.prior_var[0])
    p = np.exp(log_p)
    log_prior = float(np.sum(p * log_p) * h)  # E[log pi~_N]
    fwd_terms, bwd_terms = 0.0, 0.0
    for n in range(bridge.n_steps, 0, -1):
        var = float(bridge.kernel_var(n)[0])
        # log pi~_{n-1|n}(y | x): rows y = a^{n-1}, columns x = a^n
        log_bwd = _log_gauss(grid[:, None], bridge.backward_mean(col, n)[:, 0][None, :], var)
        log_fwd = _log_gauss(grid[None, :], bridge.forward_mean(col, n - 1)[:, 0][:, None], var)
        pair = np.exp(log_bwd) * p[None, :] * h * h  # mass of (a^{n-1}, a^n) cells
        bwd_terms += float(np.sum(pair * log_bwd))
        fwd_terms += float(np.sum(pair * log_fwd))
        p = pair.sum(1) / h
    q_grid = q(col)
    top = float(q_grid.max())
    log_z = top + float(np.log(np.sum(np.exp(q_grid - top)) * h))
    log_target = q_grid - log_z
    target = np.exp(log_target)
    with np.errstate(divide="ignore", invalid="ignore"):
        plogp = np.where(p > 0, p * np.log(p), 0.0)
    entropy = float(-np.sum(plogp) * h)
    bound = fwd_terms - log_prior - bwd_terms
    expected_q = float(np.sum(p * q_grid) * h)
    mask = p > 0
    marginal_kl = float(np.sum(p[mask] * (np.log(p[mask]) - log_target[mask])) * h)
    return {
        "density": p,
        "target": target,
        "mass": float(p.sum() * h),
        "mean": float(np.sum(p * grid) * h),
        "var": float(np.sum(p * grid**2) * h - np.sum(p * grid * h) ** 2),
        "entropy": entropy,
        "bound": bound,
        "kl": log_prior + bwd_terms - expected_q + log_z - fwd_terms,
        "marginal_kl": marginal_kl,
        "log_z": log_z,
    }


def check_bridge_quadrature(
    seed: int = 0,
    n_steps: int = 4,
    n_samples: int = 20_000,
    horizon: float = 1.0,
    grid_size: int = 1001,
    kl_estimator: KLEstimator | None = None,
    bound_estimator: BoundEstimator | None = None,
) -> CheckReport:
    """Eqs. 5.31-5.38 with nonlinear drifts and a double-well target, against quadrature.

    A one-dimensional bridge with ``f(a) = -a/2 + 0.3 sin 2a``, ``u`` and ``v`` built from
    ``tanh`` and ``cos`` (seeded), ``beta = 1``, ``N(0, 1)`` prior, and the target ``exp Q /
    Z`` with ``Q(a) = -1.5 (a^2 - 1)^2 + c a`` (two modes, Eq. 5.38). No closed form exists;
    the reference is brute force: the backward chain's marginal is propagated on a grid of
    ``grid_size`` points by applying each Gaussian kernel of Eq. 5.36 as a matrix, and every
    expectation in ``ℓ`` and Eq. 5.37 (the log-kernels of Eqs. 5.35-5.36 under the
    joint of two consecutive steps) is a sum over the grid.

    Checks: the grid's mass, sample mean and variance of ``a^0`` (5 SE), the Monte-Carlo means
    of the ``ℓ`` and Eq. 5.37 estimators (5 SE) against quadrature, ``ℓ <= H(pi~_0)`` and the
    data-processing inequality of Eq. 5.20 for the bridge.

    Returns:
        Report with data ``grid``, ``density`` (of ``a^0``, quadrature), ``target``,
        ``actions`` (the first 5000 ``a^0``), ``entropy``, ``bound``, ``kl``, ``kl_mc``,
        ``kl_stderr``, ``bound_mc``, ``bound_stderr``, ``marginal_kl``.
    """
    n_samples = check_count("n_samples", n_samples, 10)
    kl_est = kl_estimator or bridge_kl_samples
    bound_est = bound_estimator or entropy_bound_samples
    bridge = _nonlinear_bridge(seed, check_count("n_steps", n_steps), horizon)
    q = _double_well(seed)
    grid = np.linspace(-10.0, 10.0, check_count("grid_size", grid_size, 101))
    quad = _quadrature(bridge, q, grid)
    traj = sample_backward(bridge, n_samples, seed)
    kl_mc, kl_se = mc_mean_stderr(kl_est(bridge, traj, q, quad["log_z"]))
    bound_mc, bound_se = mc_mean_stderr(bound_est(bridge, traj))
    a0 = traj[0, :, 0]
    tol = relative_tol(quad["kl"], quad["bound"], quad["entropy"], rtol=1e-9)
    checks = (
        Check("grid quadrature keeps the probability mass", "Eq. 5.34", quad["mass"], 1.0, 1e-6),
        Check(
            "sample mean of a^0 = quadrature (5 SE)",
            "Eqs. 5.32, 5.34",
            a0.mean(),
            quad["mean"],
            5 * math.sqrt(quad["var"] / n_samples),
        ),
        Check(
            "sample variance of a^0 = quadrature (5 SE)",
            "Eqs. 5.32, 5.34",
            a0.var(ddof=1),
            quad["var"],
            5 * quad["var"] * math.sqrt(2 / (n_samples - 1)),
        ),
        Check(
            "Monte Carlo of the bound estimator = quadrature ℓ (5 SE)",
            "Eqs. 5.15, 5.35-5.36",
            bound_mc,
            quad["bound"],
            5 * bound_se,
        ),
        Check(
            "Monte Carlo of Eq. 5.37 = quadrature (5 SE)",
            "Eqs. 5.37-5.38",
            kl_mc,
            quad["kl"],
            5 * kl_se,
        ),
        Check(
            "ℓ <= H(pi~_0) (quadrature)",
            "Eqs. 5.15, C.2",
            quad["bound"],
            quad["entropy"],
            tol,
            "<=",
        ),
        Check(
            "KL(pi~_0 || exp Q / Z) <= Eq. 5.37 (quadrature)",
            "Eqs. 5.20, 5.37",
            quad["marginal_kl"],
            quad["kl"],
            tol,
            "<=",
        ),
    )
    data = {
        "grid": grid,
        "density": quad["density"],
        "target": quad["target"],
        "actions": a0[:5000],
        "entropy": np.array(quad["entropy"]),
        "bound": np.array(quad["bound"]),
        "kl": np.array(quad["kl"]),
        "marginal_kl": np.array(quad["marginal_kl"]),
        "kl_mc": np.array(kl_mc),
        "kl_stderr": np.array(kl_se),
        "bound_mc": np.array(bound_mc),
        "bound_stderr": np.array(bound_se),
    }
    return CheckReport(
        "General bridges, nonlinear drifts, by quadrature (Section 5.6)", checks, data
    )

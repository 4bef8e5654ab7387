"""Section 2.6.3 of the thesis: the Ornstein-Uhlenbeck forward process (Eq. 2.51), its
closed-form marginals against a simulation.

Part of :mod:`vslbook.bounds.foundations` (Chapter 2's checks).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from vslbook.bounds import Check, CheckReport
from vslbook.bounds.toy_numerics import check_count, check_positive, seeded_rng


def ou_marginal(
    mean0: float | np.ndarray,
    var0: float | np.ndarray,
    beta: float,
    eta: float,
    t: float | np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Exact marginal of the OU process ``dx = -beta x dt + eta sqrt(2 beta) dB`` (Eq. 2.51).

    For constant ``beta`` and ``x_0`` with mean ``mean0`` and variance ``var0``:
    ``E[x_t] = mean0 e^{-beta t}`` and ``Var[x_t] = var0 e^{-2 beta t} + eta^2 (1 - e^{-2 beta t})``
    (Gaussian when ``x_0`` is Gaussian; the stationary law is ``N(0, eta^2)``).

    Returns:
        ``(mean, var)`` broadcast over ``t``.
    """
    t = np.asarray(t, dtype=float)
    if np.any(t < 0):
        raise ValueError(f"t must be non-negative, got {t}")
    decay = np.exp(-check_positive("beta", beta) * t)
    var_inf = float(eta) ** 2
    return np.asarray(mean0) * decay, np.asarray(var0) * decay**2 + var_inf * (1 - decay**2)


def simulate_ou(
    x0_samples: np.ndarray, beta: float, eta: float, T: float, n_steps: int, seed: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """Euler-Maruyama simulation of the OU forward process of Eq. 2.51.

    ``x_{k+1} = x_k - beta x_k dt + eta sqrt(2 beta dt) xi_k`` with ``dt = T / n_steps``.

    Args:
        x0_samples: initial samples, any shape (each entry is an independent 1-D process).

    Returns:
        ``(times, paths)``: ``times`` of shape ``(n_steps + 1,)`` and ``paths`` of shape
        ``(n_steps + 1, *x0_samples.shape)``.
    """
    x = np.array(x0_samples, dtype=float)
    beta, T = check_positive("beta", beta), check_positive("T", T)
    n_steps = check_count("n_steps", n_steps)
    if not eta >= 0:
        raise ValueError(f"eta must be non-negative, got {eta!r}")
    rng = seeded_rng(seed)
    dt = T / n_steps
    paths = np.empty((n_steps + 1, *x.shape))
    paths[0] = x
    noise = eta * math.sqrt(2 * beta * dt)
    for k in range(n_steps):
        x = x - beta * x * dt + noise * rng.standard_normal(x.shape)
        paths[k + 1] = x
    return np.linspace(0.0, T, n_steps + 1), paths


def check_ou_marginals(
    seed: int = 0,
    beta: float = 1.0,
    eta: float = 1.0,
    mean0: float = 2.0,
    var0: float = 0.25,
    T: float = 2.0,
    n_steps: int = 200,
    n_samples: int = 10_000,
    check_times: tuple[float, ...] = (0.1, 0.25, 0.5, 1.0, 2.0),
    marginal: Callable[..., tuple[np.ndarray, np.ndarray]] = ou_marginal,
) -> CheckReport:
    """Sample moments of the simulated OU process match the closed form (Eq. 2.51).

    Simulates :func:`simulate_ou` from ``x_0 ~ N(mean0, var0)`` and compares the sample mean and
    variance with ``marginal(mean0, var0, beta, eta, t)`` at ``check_times``. The tolerance is 4
    Monte-Carlo standard errors (``sqrt(var / n)`` for the mean, ``var sqrt(2 / (n - 1))`` for
    the variance) plus the known Euler-Maruyama bias, i.e. the gap between the exact moments of
    the discretised recursion and the continuous-time ones.

    Returns:
        Report with data ``times``, ``sample_mean``, ``sample_var``, ``exact_mean`` and
        ``exact_var`` (all per step) and ``paths`` (the first 50 sample paths).
    """
    rng = seeded_rng(seed, 1)
    x0 = mean0 + math.sqrt(check_positive("var0", var0)) * rng.standard_normal(
        check_count("n_samples", n_samples, 2)
    )
    times, paths = simulate_ou(x0, beta, eta, T, n_steps, seed)
    dt = T / n_steps
    idx = np.array([int(round(t / dt)) for t in check_times])
    if np.any(idx < 0) or np.any(idx > n_steps) or not np.allclose(idx * dt, check_times):
        raise ValueError(f"check_times must be multiples of dt={dt:g} in [0, T], got {check_times}")
    sample_mean, sample_var = paths.mean(1), paths.var(1, ddof=1)
    exact_mean, exact_var = ou_marginal(mean0, var0, beta, eta, times)
    cand_mean, cand_var = (
        np.broadcast_to(np.asarray(v, dtype=float), times.shape)
        for v in marginal(mean0, var0, beta, eta, times)
    )
    a = 1 - beta * dt
    steps = np.arange(n_steps + 1)
    em_mean = mean0 * a**steps
    em_var = var0 * a ** (2 * steps) + 2 * beta * eta**2 * dt * (1 - a ** (2 * steps)) / (1 - a**2)
    se_mean = np.sqrt(sample_var / n_samples)
    se_var = sample_var * math.sqrt(2 / (n_samples - 1))
    tol_mean = 4 * se_mean + np.abs(em_mean - exact_mean)
    tol_var = 4 * se_var + np.abs(em_var - exact_var)
    checks = tuple(
        check
        for i, t in zip(idx, check_times, strict=True)
        for check in (
            Check(
                f"sample mean = mean0 e^(-beta t) at t = {t:g}",
                "Eq. 2.51",
                sample_mean[i],
                cand_mean[i],
                tol_mean[i],
            ),
            Check(
                f"sample var = var0 e^(-2 beta t) + eta^2 (1 - e^(-2 beta t)) at t = {t:g}",
                "Eq. 2.51",
                sample_var[i],
                cand_var[i],
                tol_var[i],
            ),
        )
    )
    data = {
        "times": times,
        "sample_mean": sample_mean,
        "sample_var": sample_var,
        "exact_mean": exact_mean,
        "exact_var": exact_var,
        "paths": paths[:, :50],
    }
    return CheckReport("Ornstein-Uhlenbeck forward process marginals (Section 2.6.3)", checks, data)

"""Section 2.5 of the thesis: the self-paced curriculum objective (Eq. 2.44) and its
closed-form optimum, checked against a numerical optimiser.

Part of :mod:`vslbook.bounds.foundations` (Chapter 2's checks).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.special import logsumexp, softmax, xlogy

from vslbook.bounds import Check, CheckReport, relative_tol
from vslbook.bounds.toy_numerics import (
    check_count,
    check_distribution,
    check_positive,
    seeded_rng,
    worst_check,
)


def self_paced_problem(
    n_points: int = 201, low: float = 0.0, high: float = 4.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Toy curriculum: 1-D contexts on a grid, uniform ``p(c)``, return high for easy contexts.

    Returns:
        ``(contexts, p, returns)``: the grid ``(n,)``, the probability masses of the uniform
        ``p(c)`` and ``R(c) = 2 exp(-(c / 1.5)^2)`` (contexts near 0 are easy).
    """
    n_points = check_count("n_points", n_points, 2)
    if not high > low:
        raise ValueError(f"high must exceed low, got low={low!r}, high={high!r}")
    contexts = np.linspace(low, high, n_points)
    return contexts, np.full(n_points, 1.0 / n_points), 2.0 * np.exp(-((contexts / 1.5) ** 2))


def _check_curriculum(p: np.ndarray, returns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    returns = np.asarray(returns, dtype=float)
    if returns.ndim != 1:
        raise ValueError(f"returns must have shape (n,), got {returns.shape}")
    return check_distribution("p", p, returns.shape), returns


def self_paced_objective(pi: np.ndarray, p: np.ndarray, returns: np.ndarray, beta: float) -> float:
    """Self-paced objective ``E_pi[R] - beta KL(pi || p)`` of Eq. 2.44 on a discrete grid."""
    p, returns = _check_curriculum(p, returns)
    pi = check_distribution("pi", pi, p.shape)
    kl = float(np.sum(xlogy(pi, pi) - xlogy(pi, p)))
    return float(pi @ returns) - beta * kl


def self_paced_optimum(beta: float, p: np.ndarray, returns: np.ndarray) -> np.ndarray:
    """Maximiser of Eq. 2.44: ``pi*(c) ∝ p(c) exp(R(c) / beta)``, as masses on the grid."""
    p, returns = _check_curriculum(p, returns)
    return softmax(np.log(p) + returns / check_positive("beta", beta))


def check_self_paced(
    seed: int = 0,
    betas: tuple[float, ...] = (0.05, 0.1, 0.3, 1.0, 3.0, 10.0, 100.0, 1000.0),
    n_perturb: int = 60,
    optimum: Callable[[float, np.ndarray, np.ndarray], np.ndarray] = self_paced_optimum,
) -> CheckReport:
    """Closed-form self-paced curriculum ``pi* ∝ p exp(R / beta)`` (Eq. 2.44).

    On :func:`self_paced_problem` checks, for every ``beta``, that ``optimum`` beats random
    tilts of itself and Gaussian-shaped context distributions, that its value equals the free
    energy ``beta log E_p[exp(R / beta)]``, that ``KL(pi* || p)`` and ``E_pi*[R]`` decrease
    as ``beta`` grows, and that at the largest ``beta`` the KL matches its asymptote
    ``Var_p[R] / (2 beta^2)`` (``pi* -> p``).

    Args:
        betas: increasing temperatures.
        optimum: candidate closed form ``(beta, p, returns) -> pi``.

    Returns:
        Report with data ``contexts``, ``p``, ``returns``, ``betas``, ``pi`` (n_beta, n),
        ``kl``, ``expected_return`` and ``objective`` per beta.
    """
    betas = np.asarray([check_positive("beta", b) for b in betas])
    if betas.size < 2 or np.any(np.diff(betas) <= 0):
        raise ValueError(f"betas must be at least two increasing values, got {betas}")
    rng = seeded_rng(seed)
    contexts, p, returns = self_paced_problem()
    pis = np.stack([optimum(b, p, returns) for b in betas])
    kl = np.array([np.sum(xlogy(pi, pi) - xlogy(pi, p)) for pi in pis])
    objective = np.array(
        [self_paced_objective(pi, p, returns, b) for pi, b in zip(pis, betas, strict=True)]
    )
    free_energy = betas * logsumexp(returns[None] / betas[:, None], b=p[None], axis=-1)
    best_other = np.empty_like(betas)
    for i, (pi, b) in enumerate(zip(pis, betas, strict=True)):
        others = [p]
        for eps in (0.01, 0.1, 1.0):
            for g in rng.normal(size=(n_perturb // 3, p.size)):
                tilt = pi * np.exp(eps * g)
                others.append(tilt / tilt.sum())
        for mean, std in zip(
            rng.uniform(contexts[0], contexts[-1], n_perturb),
            rng.uniform(0.05, 3.0, n_perturb),
            strict=True,
        ):
            others.append(softmax(np.log(p) - 0.5 * ((contexts - mean) / std) ** 2))
        best_other[i] = max(self_paced_objective(o, p, returns, b) for o in others)
    tol = relative_tol(*objective)
    var_r = float(p @ (returns - p @ returns) ** 2)
    asymptote = var_r / (2 * betas[-1] ** 2)
    checks = (
        worst_check(
            "pi* beats perturbed and Gaussian-shaped context distributions",
            "Eq. 2.44",
            best_other,
            objective,
            tol,
            "<=",
        ),
        worst_check(
            "J(pi*) = beta log E_p[exp(R / beta)]", "Eq. 2.44", objective, free_energy, tol
        ),
        worst_check(
            "KL(pi*_beta || p) decreases as beta grows", "Eq. 2.44", kl[1:], kl[:-1], 1e-12, "<="
        ),
        worst_check(
            "E_pi*[R] decreases as beta grows (easy contexts first)",
            "Eq. 2.44",
            pis[1:] @ returns,
            pis[:-1] @ returns,
            1e-12,
            "<=",
        ),
        Check(
            f"KL(pi* || p) -> Var_p[R] / (2 beta^2) at beta = {betas[-1]:g}",
            "Eq. 2.44",
            kl[-1],
            asymptote,
            0.02 * asymptote,
        ),
    )
    data = {
        "contexts": contexts,
        "p": p,
        "returns": returns,
        "betas": betas,
        "pi": pis,
        "kl": kl,
        "expected_return": pis @ returns,
        "objective": objective,
    }
    return CheckReport("Self-paced curriculum optimum (Section 2.5)", checks, data)

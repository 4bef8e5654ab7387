"""Per-part objectives of the SVSL lower-bound decomposition (Sections 3.3.2-3.3.3, A.1.2-A.1.4).

With the auxiliary responsibilities fixed, the lower bound of Eq. A.4 splits into one
objective per part of the mixture: the per-expert objective of Eq. 3.5 (A.1.2), the per-expert
context objective of Eq. 3.6 (A.1.3) and the max-ent problem over the weights of Eq. 3.7
(A.1.4, printed as Eq. A.5), whose per-expert rewards do not depend on ``pi(o)``. The weights
are updated by REPS: the closed form with its 1-D dual, and the primal problem solved by SLSQP
as an independent reference. All of it works on the toy model of :mod:`vslbook.bounds.svsl_toy`.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import brentq, minimize
from scipy.special import logsumexp, softmax

from vslbook.bounds.svsl_toy import (
    ToyMoE,
    ToyProblem,
    augmented_expert_rewards,
    check_aux,
    context_entropy,
    expert_entropy,
    log_contexts,
)
from vslbook.bounds.toy_numerics import check_finite, discrete_entropy, discrete_kl

__all__ = [
    "brute_force_reps",
    "context_objective",
    "expert_objective",
    "reps_categorical",
    "reps_dual",
    "reps_solution",
    "weight_objective",
    "weight_rewards",
]


# ------------------------------------------------------------- per-part objectives (3.5-3.7)


def _component(model: ToyMoE, o: int) -> int:
    k = model.n_components
    if isinstance(o, bool) or not isinstance(o, (int, np.integer)) or not 0 <= o < k:
        raise ValueError(f"expert index o must be an integer in [0, {k}), got {o!r}")
    return int(o)


def expert_objective(
    problem: ToyProblem, model: ToyMoE, log_aux_theta: np.ndarray, o: int
) -> float:
    """Eq. 3.5 with ``pi(o|c, theta)`` replaced by the auxiliary ``aux(o|c, theta)`` (A.1.2).

    ``E_pi(c|o) pi(theta|c,o)[R + alpha log aux(o|c,theta)] + alpha E_pi(c|o)[H[pi(theta|c,o)]]``.
    """
    o = _component(model, o)
    c_w = problem.contexts[1]
    ctx = np.exp(log_contexts(problem, model))[o]
    aug = augmented_expert_rewards(problem, model, log_aux_theta)[o]
    return float(np.sum(c_w * ctx * aug) + problem.alpha * expert_entropy(model)[o])


def _context_values(
    problem: ToyProblem, model: ToyMoE, log_aux_theta: np.ndarray, log_aux_context: np.ndarray
) -> np.ndarray:
    """``E_pi(c|o)[L_c(o, c) + (beta - alpha) log aux(o|c)] + beta H[pi(c|o)]``, shape (K,)."""
    log_aux_theta, log_aux_context = check_aux(problem, model, log_aux_theta, log_aux_context)
    c_w = problem.contexts[1]
    a, b = problem.alpha, problem.beta
    l_c = (
        augmented_expert_rewards(problem, model, log_aux_theta) + a * expert_entropy(model)[:, None]
    )  # L_c(o, c) of Eq. 3.6
    ctx = np.exp(log_contexts(problem, model))
    return (ctx * (l_c + (b - a) * log_aux_context)) @ c_w + b * context_entropy(problem, model)


def context_objective(
    problem: ToyProblem,
    model: ToyMoE,
    log_aux_theta: np.ndarray,
    log_aux_context: np.ndarray,
    o: int,
) -> float:
    """Eq. 3.6 (= ``L_{c,k}`` of A.1.3 for one expert).

    ``E_pi(c|o)[L_c(o, c) + (beta - alpha) log aux(o|c)] + beta H[pi(c|o)]`` with
    ``L_c(o, c) = E_pi(theta|c,o)[R + alpha log aux(o|c,theta)] + alpha H[pi(theta|c,o)]``.
    """
    o = _component(model, o)
    return float(_context_values(problem, model, log_aux_theta, log_aux_context)[o])


def weight_rewards(
    problem: ToyProblem, model: ToyMoE, log_aux_theta: np.ndarray, log_aux_context: np.ndarray
) -> np.ndarray:
    """The per-expert rewards ``r_o`` of Eq. 3.7: the bracket multiplying ``pi(o)``, shape (K,).

    They do not depend on ``pi(o)`` once the auxiliaries are fixed, so Eq. 3.7 is a max-ent
    problem over a categorical distribution.
    """
    return _context_values(problem, model, log_aux_theta, log_aux_context)


def weight_objective(weights: np.ndarray, rewards: np.ndarray, beta: float) -> float:
    """Eq. 3.7: ``sum_o pi(o) r_o + beta H[pi(o)]``."""
    weights, rewards = np.asarray(weights, dtype=float), np.asarray(rewards, dtype=float)
    if weights.shape != rewards.shape or weights.ndim != 1:
        raise ValueError(
            f"weights and rewards must be 1-D of equal shape, got {weights.shape}, {rewards.shape}"
        )
    return float(weights @ rewards + check_finite("beta", beta, 0.0) * discrete_entropy(weights))


# ---------------------------------------------------------------- REPS for the weights


def reps_dual(eta: float, p_old: np.ndarray, rewards: np.ndarray, beta: float, eps: float) -> float:
    """Dual of ``max_p sum p r + beta H(p)`` s.t. ``KL(p || p_old) <= eps`` (Eq. 3.7 with REPS).

    ``g(eta) = eta eps + (eta + beta) log sum_o p_old(o)^(eta/(eta+beta)) exp(r_o/(eta+beta))``.
    """
    p_old, rewards = np.asarray(p_old, dtype=float), np.asarray(rewards, dtype=float)
    tau = eta + beta
    return float(eta * eps + tau * logsumexp((eta * np.log(p_old) + rewards) / tau))


def reps_solution(eta: float, p_old: np.ndarray, rewards: np.ndarray, beta: float) -> np.ndarray:
    """The REPS solution ``softmax((eta log p_old + r) / (eta + beta))`` at multiplier ``eta``."""
    return softmax((eta * np.log(p_old) + rewards) / (eta + beta))


def reps_categorical(
    p_old: np.ndarray, rewards: np.ndarray, beta: float, eps: float
) -> tuple[np.ndarray, float]:
    """REPS update of a categorical distribution with entropy bonus (Eq. 3.7).

    Solves ``max_p sum_o p(o) r_o + beta H(p)`` s.t. ``KL(p || p_old) <= eps``. The solution
    is ``p ∝ p_old^(eta/(eta+beta)) exp(r/(eta+beta))`` with ``eta >= 0`` minimising the 1-D
    dual :func:`reps_dual`, whose derivative is ``eps - KL(p_eta || p_old)``. When
    ``softmax(r / beta)`` already satisfies the trust region, ``eta = 0`` and the update *is*
    that softmax; otherwise the root of the derivative is found by Brent's method.

    Returns:
        ``(p_new, eta)``.
    """
    p_old = np.asarray(p_old, dtype=float)
    rewards = np.asarray(rewards, dtype=float)
    if p_old.ndim != 1 or p_old.shape != rewards.shape:
        raise ValueError(
            f"p_old and rewards must be 1-D of equal shape, got {p_old.shape}, {rewards.shape}"
        )
    if np.any(p_old <= 0) or abs(p_old.sum() - 1) > 1e-10:
        raise ValueError(f"p_old must be positive and sum to 1, got {p_old}")
    beta = check_finite("beta", beta, 0.0, strict=True)
    eps = check_finite("eps", eps, 0.0, strict=True)

    def excess(eta: float) -> float:
        return discrete_kl(reps_solution(eta, p_old, rewards, beta), p_old) - eps

    if excess(0.0) <= 0.0:
        return reps_solution(0.0, p_old, rewards, beta), 0.0
    upper = 1.0
    while excess(upper) > 0.0:
        upper *= 4.0
        if upper > 1e15:  # pragma: no cover - KL(p_eta || p_old) -> 0 as eta -> inf
            raise RuntimeError("could not bracket the REPS multiplier")
    eta = brentq(excess, 0.0, upper, xtol=1e-14, rtol=1e-14, maxiter=500)
    return reps_solution(eta, p_old, rewards, beta), float(eta)


def brute_force_reps(p_old: np.ndarray, rewards: np.ndarray, beta: float, eps: float):
    """The primal problem of :func:`reps_categorical` by SLSQP over the simplex."""
    k = p_old.size

    def negative(p: np.ndarray) -> float:
        p = np.clip(p, 1e-300, None)
        return -(p @ rewards - beta * np.sum(p * np.log(p)))

    def negative_grad(p: np.ndarray) -> np.ndarray:
        return -(rewards - beta * (np.log(np.clip(p, 1e-300, None)) + 1.0))

    constraints = (
        {"type": "eq", "fun": lambda p: p.sum() - 1.0, "jac": lambda p: np.ones_like(p)},
        {
            "type": "ineq",
            "fun": lambda p: eps - discrete_kl(np.clip(p, 1e-300, None), p_old),
            "jac": lambda p: -(np.log(np.clip(p, 1e-300, None) / p_old) + 1.0),
        },
    )
    best = None
    for start in (p_old, np.full(k, 1.0 / k)):
        res = minimize(
            negative,
            start,
            jac=negative_grad,
            method="SLSQP",
            bounds=[(1e-15, 1.0)] * k,
            constraints=constraints,
            options={"ftol": 1e-15, "maxiter": 1000},
        )
        p = np.clip(res.x, 0.0, None)
        p = p / p.sum()
        if discrete_kl(p, p_old) <= eps + 1e-9 and (best is None or negative(p) < negative(best)):
            best = p
    if best is None:  # pragma: no cover - p_old itself is feasible
        best = p_old
    return best

"""Section 2.4 of the thesis: maximum-entropy RL on a small tabular MDP.

Soft value iteration and the Boltzmann policy (Eqs. 2.39-2.42), checked against the
max-ent objective of every deterministic-support alternative.

Part of :mod:`vslbook.bounds.foundations` (Chapter 2's checks).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import xlogy

from vslbook.bounds import Check, CheckReport, relative_tol
from vslbook.bounds.toy_numerics import (
    check_count,
    check_distribution,
    check_positive,
    seeded_rng,
    worst_check,
)


def random_mdp(n_states: int = 6, n_actions: int = 3, seed: int = 0) -> tuple[np.ndarray, ...]:
    """A random tabular MDP.

    Returns:
        ``(P, R)``: transition probabilities ``P[s, a, s']`` of shape ``(S, A, S)`` (Eq. 2.1,
        rows from a Dirichlet(0.5)) and rewards ``R[s, a]`` uniform in ``[-1, 1]``.
    """
    n_states, n_actions = check_count("n_states", n_states), check_count("n_actions", n_actions)
    rng = seeded_rng(seed)
    P = rng.dirichlet(np.full(n_states, 0.5), size=(n_states, n_actions))
    R = rng.uniform(-1.0, 1.0, size=(n_states, n_actions))
    return P, R


def check_mdp(P: np.ndarray, R: np.ndarray, gamma: float, alpha: float) -> tuple[np.ndarray, ...]:
    """``(P, R)`` as float arrays; ValueError unless ``R`` is ``(S, A)``, ``P`` an ``(S, A, S)``
    transition kernel, ``0 <= gamma < 1`` and ``alpha >= 0``."""
    P, R = np.asarray(P, dtype=float), np.asarray(R, dtype=float)
    if R.ndim != 2:
        raise ValueError(f"R must have shape (S, A), got {R.shape}")
    S, A = R.shape
    check_distribution("P", P, (S, A, S))
    if not 0.0 <= gamma < 1.0:
        raise ValueError(f"gamma must lie in [0, 1), got {gamma!r}")
    if not alpha >= 0.0:
        raise ValueError(f"alpha must be non-negative, got {alpha!r}")
    return P, R


def soft_value(q: np.ndarray, alpha: float) -> np.ndarray:
    """Soft value ``V(s) = alpha log sum_a exp(Q(s, a) / alpha)`` (Eq. 2.41); ``max_a Q`` at 0."""
    q = np.asarray(q, dtype=float)
    q_max = q.max(-1)
    if alpha == 0:
        return q_max
    # log-sum-exp by hand: scipy's version costs more than the whole backup on tiny arrays.
    return q_max + alpha * np.log(np.exp((q - q_max[..., None]) / alpha).sum(-1))


def boltzmann_policy(q: np.ndarray, alpha: float) -> np.ndarray:
    """Energy-based policy ``exp((Q - V) / alpha)`` (Eq. 2.42); greedy (ties split) at 0."""
    q = np.asarray(q, dtype=float)
    if alpha == 0:
        best = np.isclose(q, q.max(-1, keepdims=True), rtol=0.0, atol=1e-12)
        return best / best.sum(-1, keepdims=True)
    return np.exp((q - soft_value(q, alpha)[..., None]) / alpha)


@dataclass(frozen=True)
class SoftValueResult:
    """Fixed point of soft value iteration.

    Attributes:
        q: soft Q-function ``Q(s, a)``, shape ``(S, A)`` (Eq. 2.40).
        v: soft value ``V(s)``, shape ``(S,)`` (Eq. 2.41).
        policy: Boltzmann policy ``pi(a | s)``, shape ``(S, A)`` (Eq. 2.42).
        n_iter: iterations until ``max |V_new - V| < tol``.
    """

    q: np.ndarray
    v: np.ndarray
    policy: np.ndarray
    n_iter: int


def soft_value_iteration(
    P: np.ndarray,
    R: np.ndarray,
    gamma: float,
    alpha: float,
    tol: float = 1e-10,
    max_iter: int = 100_000,
) -> SoftValueResult:
    """Soft value iteration ``Q = R + gamma P V``, ``V = alpha log sum_a exp(Q / alpha)``.

    The soft Bellman backup whose fixed point gives the soft Q-function of Eq. 2.40, the soft
    value of Eq. 2.41 and the optimal policy of Eq. 2.42. ``alpha = 0`` is ordinary (hard-max)
    value iteration.

    Args:
        P: transitions, shape ``(S, A, S)``.
        R: rewards, shape ``(S, A)``.
        gamma: discount in ``[0, 1)``.
        alpha: entropy temperature ``>= 0``.
        tol: stop when the sup-norm change of ``V`` drops below ``tol``.
        max_iter: iteration cap; ``RuntimeError`` if it is reached.
    """
    P, R = check_mdp(P, R, gamma, alpha)
    check_positive("tol", tol)
    max_iter = check_count("max_iter", max_iter)
    v, n_iter, change = np.zeros(R.shape[0]), 0, np.inf
    while change >= tol:
        if n_iter == max_iter:
            raise RuntimeError(f"soft value iteration did not converge in {max_iter} iterations")
        v_new = soft_value(R + gamma * P @ v, alpha)
        change, v, n_iter = np.max(np.abs(v_new - v)), v_new, n_iter + 1
    q = R + gamma * P @ v
    return SoftValueResult(
        q=q, v=soft_value(q, alpha), policy=boltzmann_policy(q, alpha), n_iter=n_iter
    )


def soft_policy_evaluation(
    P: np.ndarray, R: np.ndarray, policy: np.ndarray, gamma: float, alpha: float
) -> tuple[np.ndarray, np.ndarray]:
    """Entropy-augmented value of a fixed policy by one linear solve.

    ``V(s) = sum_a pi(a|s) [R(s, a) - alpha log pi(a|s)] + gamma sum_a pi(a|s) P(s'|s, a) V(s')``,
    the per-state version of Eq. 2.39; ``Q = R + gamma P V`` is Eq. 2.40.

    Returns:
        ``(v, q)`` of shapes ``(S,)`` and ``(S, A)``.
    """
    P, R = check_mdp(P, R, gamma, alpha)
    policy = check_distribution("policy", policy, R.shape)
    entropy = -xlogy(policy, policy).sum(-1)
    r_pi = (policy * R).sum(-1) + alpha * entropy
    p_pi = np.einsum("sa,sat->st", policy, P)
    v = np.linalg.solve(np.eye(R.shape[0]) - gamma * p_pi, r_pi)
    return v, R + gamma * P @ v


def maxent_objective(
    P: np.ndarray,
    R: np.ndarray,
    policy: np.ndarray,
    gamma: float,
    alpha: float,
    rho0: np.ndarray | None = None,
) -> float:
    """Maximum entropy objective ``J(pi)`` of Eq. 2.39 for initial distribution ``rho0``.

    ``rho0`` defaults to uniform over states.
    """
    v, _ = soft_policy_evaluation(P, R, policy, gamma, alpha)
    rho0 = (
        np.full(v.shape, 1 / v.size) if rho0 is None else check_distribution("rho0", rho0, v.shape)
    )
    return float(rho0 @ v)


def check_soft_optimal_policy(
    seed: int = 0,
    n_states: int = 6,
    n_actions: int = 3,
    gamma: float = 0.9,
    alpha: float = 0.5,
    n_random: int = 200,
    policy: np.ndarray | None = None,
) -> CheckReport:
    """The Boltzmann policy of the soft Q-function is max-ent optimal (Eqs. 2.39-2.42).

    On :func:`random_mdp` checks that (a) evaluating the policy with the entropy bonus gives back
    ``V_soft`` in every state, (b) its objective ``J`` (Eq. 2.39, uniform start) is at least
    that of ``n_random`` random stochastic policies and of single-state perturbations of itself
    (tilts ``pi(.|s) exp(eps g)`` and a one-state soft policy-improvement step), and (c)
    ``alpha -> 0`` recovers hard value iteration, within the bound
    ``0 <= V_soft - V* <= alpha log|A| / (1 - gamma)``.

    Args:
        policy: candidate ``(S, A)`` policy for (a) and (b); defaults to the Boltzmann policy.

    Returns:
        Report with data ``q``, ``v_soft``, ``policy`` (the candidate), ``j_policy``,
        ``j_random`` (n_random,), ``j_perturbed``, ``alphas``, ``v_gap`` (max_s V_alpha - V*
        per alpha) and ``v_gap_bound``.
    """
    P, R = random_mdp(n_states, n_actions, seed)
    rng = seeded_rng(seed, 1)
    sol = soft_value_iteration(P, R, gamma, alpha)
    pi = sol.policy if policy is None else check_distribution("policy", policy, R.shape)
    v_pi, q_pi = soft_policy_evaluation(P, R, pi, gamma, alpha)
    j_pi = float(v_pi.mean())

    def j(p: np.ndarray) -> float:
        return maxent_objective(P, R, p, gamma, alpha)

    j_random = np.array(
        [
            j(rng.dirichlet(np.ones(n_actions), size=n_states))
            for _ in range(check_count("n_random", n_random))
        ]
    )
    j_perturbed = []
    for s in range(n_states):
        candidates = []
        for g in rng.normal(size=(4, n_actions)):
            for eps in (-0.3, -0.03, 0.03, 0.3):
                candidates.append(pi[s] * np.exp(eps * g))
        if alpha > 0:
            candidates.append(np.exp((q_pi[s] - q_pi[s].max()) / alpha))
        for row in candidates:
            p = pi.copy()
            p[s] = row / row.sum()
            j_perturbed.append(j(p))
    j_perturbed = np.array(j_perturbed)

    alphas = np.logspace(-4, 0, 9) * max(alpha, 1e-3)
    v_hard = soft_value_iteration(P, R, gamma, 0.0).v
    v_alpha = np.stack([soft_value_iteration(P, R, gamma, a).v for a in alphas])
    bound = alphas * math.log(n_actions) / (1 - gamma)
    tol = relative_tol(*sol.v)
    checks = (
        worst_check(
            "policy evaluation of pi equals V_soft in every state",
            "Eqs. 2.40-2.42",
            v_pi,
            sol.v,
            tol,
        ),
        Check(
            f"J(pi) >= J of {n_random} random stochastic policies",
            "Eq. 2.39",
            j_random.max(),
            j_pi,
            tol,
            "<=",
        ),
        Check(
            "J(pi) >= J of single-state perturbations of pi",
            "Eq. 2.39",
            j_perturbed.max(),
            j_pi,
            tol,
            "<=",
        ),
        worst_check(
            "V_soft -> V* as alpha -> 0 (within alpha log|A| / (1 - gamma))",
            "Eq. 2.41",
            v_alpha[0],
            v_hard,
            bound[0],
        ),
        worst_check("V_soft >= V* for every alpha", "Eq. 2.41", v_hard[None], v_alpha, tol, "<="),
    )
    data = {
        "q": sol.q,
        "v_soft": sol.v,
        "policy": pi,
        "j_policy": np.array(j_pi),
        "j_random": j_random,
        "j_perturbed": j_perturbed,
        "alphas": alphas,
        "v_gap": (v_alpha - v_hard).max(-1),
        "v_gap_bound": bound,
    }
    return CheckReport("Soft-optimal policy on a random MDP (Section 2.4.1)", checks, data)

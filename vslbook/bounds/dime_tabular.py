"""Numerical checks of Section 5.4.2 (DIME) on tabular MDPs: SAC's soft policy iteration.

The Bellman operator of Eq. 5.21 (a gamma-contraction whose fixed point is the soft Q-function,
Proposition 5.4.1) here; policy improvement (Proposition 5.4.2, Eqs. 5.22-5.23, proof Eqs.
C.15-C.28) and policy iteration (Proposition 5.4.3) in
:mod:`vslbook.bounds.dime_tabular_iteration`, re-exported here; all on random tabular MDPs with a
discrete-action policy and its exact entropy: the argument of the propositions in the setting of
SAC, which Section 5.4.2 generalises. No diffusion chain and no bound ``ℓ`` appear here;
:mod:`vslbook.bounds.dime_policy_iteration` checks the propositions with the diffusion policies
of Section 5.4.1.

Import from :mod:`vslbook.bounds.dime`, which re-exports everything public here.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.special import xlogy

from vslbook.bounds import Check, CheckReport, relative_tol
from vslbook.bounds.dime_tabular_iteration import check_soft_policy_iteration, mirror_step
from vslbook.bounds.foundations_maxent import (
    check_mdp,
    random_mdp,
    soft_policy_evaluation,
)
from vslbook.bounds.toy_numerics import (
    check_count,
    check_distribution,
    check_positive,
    seeded_rng,
    worst_check,
)

__all__ = [
    "check_soft_bellman_contraction",
    "check_soft_policy_iteration",
    "mirror_step",
    "policy_entropy",
    "soft_bellman_operator",
]


def policy_entropy(policy: np.ndarray) -> np.ndarray:
    """Exact entropy ``H(pi(.|s)) = -sum_a pi log pi`` per state, shape ``(S,)``."""
    return -xlogy(policy, policy).sum(-1)


def _backup(
    q: np.ndarray, P: np.ndarray, R: np.ndarray, policy: np.ndarray, gamma: float, bonus: np.ndarray
) -> np.ndarray:
    v = (policy * q).sum(-1) + bonus
    return R + gamma * np.einsum("sat,...t->...sa", P, v)


def soft_bellman_operator(
    q: np.ndarray,
    P: np.ndarray,
    R: np.ndarray,
    policy: np.ndarray,
    gamma: float,
    alpha: float,
    bonus: np.ndarray | None = None,
) -> np.ndarray:
    """The Bellman backup of Eq. 5.21 on a tabular MDP.

    ``(T Q)(s, a) = R(s, a) + gamma sum_s' P(s'|s, a) [sum_a' pi(a'|s') Q(s', a') + bonus(s')]``
    with ``bonus = alpha H(pi(.|s'))`` (exact entropy; Eq. 5.5) by default. Eq. 5.21 uses the
    entropy lower bound ``ℓ`` instead; pass it as ``bonus`` (any per-state bonus keeps the
    operator a gamma-contraction).

    Args:
        q: Q-function(s), shape ``(..., S, A)``.
        P, R, policy: transitions ``(S, A, S)``, rewards and policy ``(S, A)``.
        bonus: per-state bonus ``(S,)``.
    """
    P, R = check_mdp(P, R, gamma, alpha)
    policy = check_distribution("policy", policy, R.shape)
    q = np.asarray(q, dtype=float)
    if q.shape[-2:] != R.shape:
        raise ValueError(f"q must have shape (..., {R.shape[0]}, {R.shape[1]}), got {q.shape}")
    bonus = alpha * policy_entropy(policy) if bonus is None else np.asarray(bonus, dtype=float)
    if bonus.shape != R.shape[:1]:
        raise ValueError(f"bonus must have shape ({R.shape[0]},), got {bonus.shape}")
    return _backup(q, P, R, policy, gamma, bonus)


def _fixed_point(
    P: np.ndarray, R: np.ndarray, policy: np.ndarray, gamma: float, bonus: np.ndarray
) -> np.ndarray:
    """Fixed point of :func:`soft_bellman_operator` with ``bonus`` by one linear solve."""
    p_pi = np.einsum("sa,sat->st", policy, P)
    w = np.linalg.solve(np.eye(R.shape[0]) - gamma * p_pi, (policy * R).sum(-1) + bonus)
    return R + gamma * P @ w


def check_soft_bellman_contraction(
    seed: int = 0,
    n_states: int = 8,
    n_actions: int = 4,
    gamma: float = 0.9,
    alpha: float = 0.5,
    n_pairs: int = 300,
    n_iter: int = 300,
    operator: Callable[[np.ndarray], np.ndarray] | None = None,
) -> CheckReport:
    """The soft Bellman operator is a gamma-contraction with fixed point ``Q^pi`` (Prop. 5.4.1).

    Tabular, with a discrete policy (the bound ``ℓ`` of a diffusion chain enters only as an
    arbitrary per-state bonus ``<= H``; :mod:`vslbook.bounds.dime_policy_iteration` uses the
    real one). On :func:`~vslbook.bounds.foundations.random_mdp` with a random stochastic policy
    ``pi`` and the exact tabular entropy, checks that
    ``||T Q1 - T Q2||_inf <= gamma ||Q1 - Q2||_inf`` for ``n_pairs`` random pairs (dense
    differences, single-entry differences and constant shifts, for which the modulus
    ``gamma`` is attained), that ``Q^pi`` of
    :func:`~vslbook.bounds.foundations.soft_policy_evaluation` is the fixed point, that the
    iterates ``Q^{k+1} = T Q^k`` stay within ``gamma^k ||Q^0 - Q^pi||_inf`` of it and converge
    to it, and that replacing the entropy by a lower bound ``ℓ <= H`` (Eq. 5.21) lowers the
    fixed point everywhere (``Q^pi`` with ``ℓ`` <= with ``H``, Eqs. 5.16-5.17).

    Args:
        operator: candidate ``Q (S, A) -> T Q``; defaults to :func:`soft_bellman_operator`.

    Returns:
        Report with data ``ratios`` (n_pairs,), ``pair_kind`` (0 dense, 1 single entry,
        2 constant shift), ``diff_norms``, ``errors`` (n_iter+1,: ``||Q^k - Q^pi||_inf``),
        ``error_bound`` (``gamma^k ||Q^0 - Q^pi||_inf``), ``policy`` (the fixed ``pi``),
        ``q_pi``, ``q_lower`` (fixed point with the bonus ``alpha ℓ``), ``entropy``
        (``H(pi(.|s))``) and ``lower_bound`` (``ℓ(s) <= H``, per state).
    """
    P, R = random_mdp(n_states, n_actions, seed)
    check_mdp(P, R, gamma, check_positive("alpha", alpha))
    rng = seeded_rng(seed, 1)
    policy = rng.dirichlet(np.ones(n_actions), size=n_states)
    entropy = policy_entropy(policy)
    _, q_pi = soft_policy_evaluation(P, R, policy, gamma, alpha)
    scale = float(np.abs(q_pi).max())

    def default(q: np.ndarray) -> np.ndarray:
        return _backup(q, P, R, policy, gamma, alpha * entropy)

    T = operator or default
    ratios, kinds, norms = [], [], []
    for i in range(check_count("n_pairs", n_pairs)):
        q1 = scale * rng.normal(size=R.shape)
        kind = i % 3
        if kind == 0:
            diff = 10 ** rng.uniform(-1, 1) * rng.normal(size=R.shape)
        elif kind == 1:
            diff = np.zeros(R.shape)
            diff[rng.integers(n_states), rng.integers(n_actions)] = rng.normal(scale=3.0)
        else:
            diff = np.full(R.shape, rng.normal(scale=3.0))
        q2 = q1 + diff
        norm = np.abs(q1 - q2).max()
        ratios.append(np.abs(T(q1) - T(q2)).max() / norm)
        kinds.append(kind)
        norms.append(norm)
    ratios, kinds, norms = np.array(ratios), np.array(kinds), np.array(norms)

    q = scale * rng.normal(size=R.shape)
    errors = [np.abs(q - q_pi).max()]
    for _ in range(check_count("n_iter", n_iter)):
        q = T(q)
        errors.append(np.abs(q - q_pi).max())
    errors = np.array(errors)
    error_bound = gamma ** np.arange(n_iter + 1) * errors[0]

    lower = entropy * (1 - rng.uniform(0.0, 1.0, n_states))  # any ℓ(s) <= H(pi(.|s))
    q_lower = _fixed_point(P, R, policy, gamma, alpha * lower)
    tol = relative_tol(scale)
    checks = (
        Check(
            f"||TQ1 - TQ2|| <= gamma ||Q1 - Q2|| (sup norm) for {n_pairs} random pairs",
            "Eq. 5.21, Prop. 5.4.1",
            ratios.max(),
            gamma,
            1e-9,
            "<=",
        ),
        worst_check(
            "constant shifts: ||TQ1 - TQ2|| = gamma ||Q1 - Q2|| (the modulus is attained)",
            "Eq. 5.21",
            ratios[kinds == 2],
            gamma,
            1e-9,
        ),
        worst_check("T Q^pi = Q^pi (fixed point)", "Eq. 5.21, Prop. 5.4.1", T(q_pi), q_pi, tol),
        worst_check(
            "||Q^k - Q^pi|| <= gamma^k ||Q^0 - Q^pi|| for every iterate",
            "Prop. 5.4.1",
            errors,
            error_bound,
            tol,
            "<=",
        ),
        Check(
            f"Q^k -> Q^pi (soft_policy_evaluation) after {n_iter} iterations",
            "Prop. 5.4.1",
            errors[-1],
            0.0,
            relative_tol(scale, rtol=1e-8),
        ),
        worst_check(
            "Q^pi with the lower bound ℓ <= Q^pi with the exact entropy",
            "Eqs. 5.16-5.17, 5.21",
            q_lower,
            q_pi,
            tol,
            "<=",
        ),
    )
    data = {
        "ratios": ratios,
        "pair_kind": kinds,
        "diff_norms": norms,
        "errors": errors,
        "error_bound": error_bound,
        "policy": policy,
        "q_pi": q_pi,
        "q_lower": q_lower,
        "entropy": entropy,
        "lower_bound": lower,
    }
    return CheckReport(
        "The soft Bellman operator is a gamma-contraction (Section 5.4.2)", checks, data
    )

"""Numerical checks of Section 5.4.2 (DIME) on tabular MDPs: SAC's soft policy iteration.

The Bellman operator of Eq. 5.21 (a gamma-contraction whose fixed point is the soft Q-function,
Proposition 5.4.1), policy improvement (Proposition 5.4.2, Eqs. 5.22-5.23, proof Eqs.
C.15-C.28) and policy iteration (Proposition 5.4.3) on random tabular MDPs with a
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
from vslbook.bounds._helpers import _check_distribution, _count, _positive, _rng, _worst
from vslbook.bounds.foundations_maxent import (
    _check_mdp,
    boltzmann_policy,
    maxent_objective,
    random_mdp,
    soft_policy_evaluation,
    soft_value_iteration,
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
    P, R = _check_mdp(P, R, gamma, alpha)
    policy = _check_distribution("policy", policy, R.shape)
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
    _check_mdp(P, R, gamma, _positive("alpha", alpha))
    rng = _rng(seed, 1)
    policy = rng.dirichlet(np.ones(n_actions), size=n_states)
    entropy = policy_entropy(policy)
    _, q_pi = soft_policy_evaluation(P, R, policy, gamma, alpha)
    scale = float(np.abs(q_pi).max())

    def default(q: np.ndarray) -> np.ndarray:
        return _backup(q, P, R, policy, gamma, alpha * entropy)

    T = operator or default
    ratios, kinds, norms = [], [], []
    for i in range(_count("n_pairs", n_pairs)):
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
    for _ in range(_count("n_iter", n_iter)):
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
        _worst(
            "constant shifts: ||TQ1 - TQ2|| = gamma ||Q1 - Q2|| (the modulus is attained)",
            "Eq. 5.21",
            ratios[kinds == 2],
            gamma,
            1e-9,
        ),
        _worst("T Q^pi = Q^pi (fixed point)", "Eq. 5.21, Prop. 5.4.1", T(q_pi), q_pi, tol),
        _worst(
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
        _worst(
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


def _log_softmax(logits: np.ndarray) -> np.ndarray:
    """``log softmax`` over the last axis (scipy's version is slow on tiny arrays)."""
    shifted = logits - logits.max(-1, keepdims=True)
    return shifted - np.log(np.exp(shifted).sum(-1, keepdims=True))


def _kl_to_boltzmann(policy: np.ndarray, q: np.ndarray, alpha: float) -> np.ndarray:
    """``KL(pi(.|s) || exp(Q(s, .) / alpha) / Z(s))`` per state (Eqs. 5.3, 5.22)."""
    log_target = _log_softmax(q / alpha)
    return np.sum(xlogy(policy, policy) - policy * log_target, -1)


def mirror_step(policy: np.ndarray, q: np.ndarray, alpha: float, step_size: float) -> np.ndarray:
    """Partial improvement ``pi_new ∝ pi_old^(1 - step) (exp(Q / alpha))^step``.

    The geometric path from ``pi_old`` (step 0) to the Boltzmann target of Eq. 5.23 (step 1);
    ``KL(pi_new || target)`` decreases monotonically in ``step_size`` on ``[0, 1]`` (its
    derivative is ``(step - 1) Var[log target - log pi_old]`` under ``pi_new``), so a step in
    ``(0, 1)`` lowers the KL without minimising it, step 1 minimises it, and a negative step
    moves away from the target.
    """
    policy = np.asarray(policy, dtype=float)
    if step_size == 1:  # 0 * log 0 = 0: step 1 gives the target even where pi_old = 0
        old = np.zeros_like(policy)
    else:
        with np.errstate(divide="ignore"):
            old = (1 - step_size) * np.log(policy)
    return np.exp(_log_softmax(old + step_size * np.asarray(q, dtype=float) / alpha))


def _restricted_projection(
    weights: np.ndarray,
    features: np.ndarray,
    q: np.ndarray,
    alpha: float,
    n_inner: int,
) -> np.ndarray:
    """Gradient steps on ``KL(softmax(features w_s) || exp(Q / alpha) / Z)`` for every state.

    Backtracking (Armijo) per state from the current ``w``, so the KL never increases.
    """
    log_target = _log_softmax(q / alpha)

    def kl(w: np.ndarray) -> np.ndarray:
        log_p = _log_softmax(w @ features.T)
        return np.sum(np.exp(log_p) * (log_p - log_target), -1)

    trial = 2.0 ** -np.arange(30)
    for _ in range(n_inner):
        log_p = _log_softmax(weights @ features.T)
        p = np.exp(log_p)
        g = log_p - log_target
        value = np.sum(p * g, -1)
        grad = (p * (g - value[:, None])) @ features
        sq = np.sum(grad**2, -1)
        candidates = weights[None] - trial[:, None, None] * grad[None]
        ok = kl(candidates) <= value[None] - 0.5 * trial[:, None] * sq[None]
        first = np.where(ok.any(0), ok.argmax(0), -1)
        step = np.where(first >= 0, trial[first], 0.0)
        weights = weights - step[:, None] * grad
    return weights


def check_soft_policy_iteration(
    seed: int = 0,
    n_states: int = 8,
    n_actions: int = 4,
    gamma: float = 0.9,
    alpha: float = 0.5,
    n_iter: int = 60,
    step_size: float = 0.3,
    n_features: int = 2,
    n_random: int = 100,
    improve: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
) -> CheckReport:
    """Tabular soft policy improvement and iteration (the argument of Props. 5.4.2-5.4.3).

    What this shows: the proof structure of Props. 5.4.2-5.4.3 (Eqs. 5.22-5.23, C.15-C.28)
    for a *discrete-action* policy with its *exact* entropy ``-sum_a pi log pi``, i.e. the soft
    policy iteration of SAC (Haarnoja et al., 2018b) that Section 5.4.2 generalises: a policy
    whose KL to ``exp(Q / alpha) / Z`` does not exceed the old policy's has a ``Q`` at least as
    large, and iterating converges. What it does not show: anything about diffusion policies.
    No diffusion chain, no bound ``ℓ`` and no joint KL of Eq. 5.22 appear here; the KL is the
    one between the action distributions.
    :func:`~vslbook.bounds.dime_policy_iteration.check_diffusion_policy_iteration` checks the
    propositions with the chains of Section 5.4.1 and ``ℓ`` in place of the entropy.

    On :func:`~vslbook.bounds.foundations.random_mdp` (finite actions, as Section 5.4.2
    assumes) runs three policy-iteration schemes from a random policy, each evaluating
    ``Q^pi`` exactly (:func:`~vslbook.bounds.foundations.soft_policy_evaluation`):

    * exact: ``pi_new = improve(Q^pi_old, pi_old)``, by default ``exp(Q / alpha) / Z``, the
      minimiser of the KL of Eq. 5.22 over all policies;
    * mirror: :func:`mirror_step` with ``step_size``, which lowers the KL without minimising it;
    * restricted: a log-linear family ``softmax(Phi w_s)`` with ``n_features < |A|`` random
      features, improved by KL-decreasing gradient steps (Eq. 5.22 over a restricted set,
      starting from the uniform policy, which lies in the family).

    The proof of Prop. 5.4.2 uses only ``KL(pi_new || target) <= KL(pi_old || target)`` per
    state (Eq. C.16; ``pi_old`` is a feasible candidate), so all three must improve ``Q``
    elementwise. Checks: the exact step attains ``KL = 0`` and improves ``Q``; it converges to
    :func:`~vslbook.bounds.foundations.soft_value_iteration`'s ``Q*`` and policy, and ``Q*``
    dominates ``Q^pi`` of ``n_random`` random policies (Prop. 5.4.3); the mirror steps lower
    the KL, improve ``Q`` and converge to the same optimum; the restricted steps lower the KL,
    improve ``Q`` and never beat the optimum. Optimality within the restricted family is not
    checked: the argument of Prop. 5.4.3 gives convergence of the monotone sequence, not that
    its limit dominates every member of a restricted family.

    Args:
        improve: candidate improvement ``(Q, pi_old) -> pi_new`` for the exact scheme.

    Returns:
        Report with data ``j_exact``, ``j_mirror``, ``j_restricted`` (n_iter+1,: the objective
        of Eq. 5.1 per iteration, uniform start), ``j_optimal``, ``j_random`` (n_random,),
        ``q_error_exact``, ``q_error_mirror`` (``||Q^pi_i - Q*||_inf``), ``kl_exact``,
        ``kl_mirror``, ``kl_restricted`` (n_iter, 2: mean KL to the target before and after
        each improvement) and ``policy_exact``, ``policy_optimal``, ``policy_restricted``.
    """
    P, R = random_mdp(n_states, n_actions, seed)
    alpha = _positive("alpha", alpha)
    _check_mdp(P, R, gamma, alpha)
    n_iter = _count("n_iter", n_iter)
    n_features = _count("n_features", n_features)
    rng = _rng(seed, 2)
    policy0 = rng.dirichlet(np.ones(n_actions), size=n_states)
    features = rng.normal(size=(n_actions, n_features))
    optimum = soft_value_iteration(P, R, gamma, alpha, tol=1e-12)
    improve = improve or (lambda q, pi: boltzmann_policy(q, alpha))

    def evaluate(pi: np.ndarray) -> tuple[float, np.ndarray]:
        v, q = soft_policy_evaluation(P, R, pi, gamma, alpha)
        return float(v.mean()), q  # J of Eq. 5.1 from a uniform start, as maxent_objective

    def run(step: Callable[[np.ndarray, np.ndarray], np.ndarray], pi: np.ndarray):
        js, qs, kls = [], [], []
        for i in range(n_iter + 1):
            j, q = evaluate(pi)
            js.append(j)
            qs.append(q)
            if i < n_iter:
                new = step(q, pi)
                kls.append([_kl_to_boltzmann(pi, q, alpha), _kl_to_boltzmann(new, q, alpha)])
                pi = new
        return np.array(js), np.array(qs), np.array(kls), pi

    def exact_step(q: np.ndarray, pi: np.ndarray) -> np.ndarray:
        return _check_distribution("improve(Q, pi)", improve(q, pi), R.shape)

    def mirror(q: np.ndarray, pi: np.ndarray) -> np.ndarray:
        return mirror_step(pi, q, alpha, step_size)

    weights = np.zeros((n_states, n_features))

    def restricted(q: np.ndarray, pi: np.ndarray) -> np.ndarray:
        nonlocal weights
        weights = _restricted_projection(weights, features, q, alpha, n_inner=10)
        return np.exp(_log_softmax(weights @ features.T))

    j_exact, q_exact, kl_exact, pi_exact = run(exact_step, policy0)
    j_mirror, q_mirror, kl_mirror, _ = run(mirror, policy0)
    uniform = np.full((n_states, n_actions), 1 / n_actions)
    j_restricted, q_restricted, kl_restricted, pi_restricted = run(restricted, uniform)
    randoms = [rng.dirichlet(np.ones(n_actions), size=n_states) for _ in range(n_random)]
    evaluated = [evaluate(pi) for pi in randoms]
    j_random = np.array([j for j, _ in evaluated])
    q_random = np.array([q for _, q in evaluated])
    j_optimal = maxent_objective(P, R, optimum.policy, gamma, alpha)
    tol = relative_tol(float(np.abs(optimum.q).max()))
    checks = (
        _worst(
            "exact step: KL(pi_new || exp(Q/alpha)/Z) = 0 (the minimiser of Eq. 5.22)",
            "Eqs. 5.6, 5.22-5.23",
            kl_exact[:, 1],
            0.0,
            1e-10,
        ),
        _worst(
            "exact step: Q^pi_new >= Q^pi_old elementwise, every iteration",
            "Prop. 5.4.2",
            q_exact[:-1],
            q_exact[1:],
            tol,
            "<=",
        ),
        _worst(
            "exact iteration: Q^pi_i -> Q* (soft value iteration)",
            "Prop. 5.4.3",
            q_exact[-1],
            optimum.q,
            relative_tol(float(np.abs(optimum.q).max()), rtol=1e-8),
        ),
        _worst(
            "exact iteration: pi_i -> soft-optimal policy",
            "Prop. 5.4.3",
            pi_exact,
            optimum.policy,
            1e-8,
        ),
        _worst(
            f"Q* >= Q^pi of {n_random} random policies elementwise",
            "Prop. 5.4.3",
            q_random,
            optimum.q[None],
            tol,
            "<=",
        ),
        _worst(
            f"mirror step ({step_size:g}): KL to the target does not increase",
            "Eq. C.16",
            kl_mirror[:, 1],
            kl_mirror[:, 0],
            1e-12,
            "<=",
        ),
        _worst(
            f"mirror step ({step_size:g}): Q^pi_new >= Q^pi_old elementwise",
            "Prop. 5.4.2, Eqs. C.16-C.28",
            q_mirror[:-1],
            q_mirror[1:],
            tol,
            "<=",
        ),
        _worst(
            f"mirror iteration ({step_size:g}): Q^pi_i -> Q*",
            "Prop. 5.4.3",
            q_mirror[-1],
            optimum.q,
            relative_tol(float(np.abs(optimum.q).max()), rtol=1e-6),
        ),
        _worst(
            f"restricted family ({n_features} features): KL to the target does not increase",
            "Eqs. 5.22, C.16",
            kl_restricted[:, 1],
            kl_restricted[:, 0],
            1e-12,
            "<=",
        ),
        _worst(
            f"restricted family ({n_features} features): Q^pi_new >= Q^pi_old elementwise",
            "Prop. 5.4.2, Eqs. C.16-C.28",
            q_restricted[:-1],
            q_restricted[1:],
            tol,
            "<=",
        ),
        _worst(
            "restricted family: J(pi_i) <= J(pi*) every iteration",
            "Prop. 5.4.3",
            j_restricted,
            j_optimal,
            tol,
            "<=",
        ),
    )
    data = {
        "j_exact": j_exact,
        "j_mirror": j_mirror,
        "j_restricted": j_restricted,
        "j_optimal": np.array(j_optimal),
        "j_random": j_random,
        "q_error_exact": np.abs(q_exact - optimum.q).max((-2, -1)),
        "q_error_mirror": np.abs(q_mirror - optimum.q).max((-2, -1)),
        "kl_exact": kl_exact.mean(-1),
        "kl_mirror": kl_mirror.mean(-1),
        "kl_restricted": kl_restricted.mean(-1),
        "policy_exact": pi_exact,
        "policy_optimal": optimum.policy,
        "policy_restricted": pi_restricted,
    }
    return CheckReport("Soft policy improvement and policy iteration (Section 5.4.2)", checks, data)

"""Numerical checks of Section 5.4.2 (DIME) on tabular MDPs: soft policy improvement and
iteration.

Policy improvement (Proposition 5.4.2, Eqs. 5.22-5.23, proof Eqs. C.15-C.28) and policy
iteration (Proposition 5.4.3) on random tabular MDPs with a discrete-action policy and its
exact entropy, SAC's setting (:func:`mirror_step`, :func:`check_soft_policy_iteration`). The
Bellman operator of Eq. 5.21 (Proposition 5.4.1) is checked in
:mod:`vslbook.bounds.dime_tabular`, which re-exports these names.

Import from :mod:`vslbook.bounds.dime`, which re-exports everything public here.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.special import xlogy

from vslbook.bounds import CheckReport, relative_tol
from vslbook.bounds.foundations_maxent import (
    boltzmann_policy,
    check_mdp,
    maxent_objective,
    random_mdp,
    soft_policy_evaluation,
    soft_value_iteration,
)
from vslbook.bounds.toy_numerics import (
    check_count,
    check_distribution,
    check_positive,
    seeded_rng,
    worst_check,
)

__all__ = ["check_soft_policy_iteration", "mirror_step"]


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
    alpha = check_positive("alpha", alpha)
    check_mdp(P, R, gamma, alpha)
    n_iter = check_count("n_iter", n_iter)
    n_features = check_count("n_features", n_features)
    rng = seeded_rng(seed, 2)
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
        return check_distribution("improve(Q, pi)", improve(q, pi), R.shape)

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
        worst_check(
            "exact step: KL(pi_new || exp(Q/alpha)/Z) = 0 (the minimiser of Eq. 5.22)",
            "Eqs. 5.6, 5.22-5.23",
            kl_exact[:, 1],
            0.0,
            1e-10,
        ),
        worst_check(
            "exact step: Q^pi_new >= Q^pi_old elementwise, every iteration",
            "Prop. 5.4.2",
            q_exact[:-1],
            q_exact[1:],
            tol,
            "<=",
        ),
        worst_check(
            "exact iteration: Q^pi_i -> Q* (soft value iteration)",
            "Prop. 5.4.3",
            q_exact[-1],
            optimum.q,
            relative_tol(float(np.abs(optimum.q).max()), rtol=1e-8),
        ),
        worst_check(
            "exact iteration: pi_i -> soft-optimal policy",
            "Prop. 5.4.3",
            pi_exact,
            optimum.policy,
            1e-8,
        ),
        worst_check(
            f"Q* >= Q^pi of {n_random} random policies elementwise",
            "Prop. 5.4.3",
            q_random,
            optimum.q[None],
            tol,
            "<=",
        ),
        worst_check(
            f"mirror step ({step_size:g}): KL to the target does not increase",
            "Eq. C.16",
            kl_mirror[:, 1],
            kl_mirror[:, 0],
            1e-12,
            "<=",
        ),
        worst_check(
            f"mirror step ({step_size:g}): Q^pi_new >= Q^pi_old elementwise",
            "Prop. 5.4.2, Eqs. C.16-C.28",
            q_mirror[:-1],
            q_mirror[1:],
            tol,
            "<=",
        ),
        worst_check(
            f"mirror iteration ({step_size:g}): Q^pi_i -> Q*",
            "Prop. 5.4.3",
            q_mirror[-1],
            optimum.q,
            relative_tol(float(np.abs(optimum.q).max()), rtol=1e-6),
        ),
        worst_check(
            f"restricted family ({n_features} features): KL to the target does not increase",
            "Eqs. 5.22, C.16",
            kl_restricted[:, 1],
            kl_restricted[:, 0],
            1e-12,
            "<=",
        ),
        worst_check(
            f"restricted family ({n_features} features): Q^pi_new >= Q^pi_old elementwise",
            "Prop. 5.4.2, Eqs. C.16-C.28",
            q_restricted[:-1],
            q_restricted[1:],
            tol,
            "<=",
        ),
        worst_check(
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

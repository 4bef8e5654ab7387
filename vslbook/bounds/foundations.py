"""Numerical checks of the results of Chapter 2 (Foundations).

Each ``check_*`` function builds a small, seeded problem, computes both sides of an equation
or inequality of the thesis and returns a :class:`~vslbook.bounds.CheckReport`: a tuple of
:class:`~vslbook.bounds.Check` plus the arrays a notebook needs to plot the experiment. Several
checks take an optional candidate (a policy, a closed form, a variational distribution); the
default is the thesis's answer, and passing a wrong one makes the report fail, which is how the
tests show that the checks have teeth.

Sections covered: 2.4 (soft value iteration, Eqs. 2.39-2.42), 2.5 (self-paced curricula,
Eq. 2.44), 2.6.2 (mixture-of-experts gating, Eqs. 2.47-2.49), 2.6.3 (Ornstein-Uhlenbeck forward
process, Eq. 2.51), 2.7 (variational inference, Eqs. 2.60-2.71) and 2.8 (mutual information,
Eqs. 2.72-2.74). Every function runs in well under a second.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch
from scipy.optimize import minimize
from scipy.special import log_softmax, logsumexp, softmax, xlogy
from scipy.stats import multivariate_normal, norm

from vslbook.bounds import Check, CheckReport, relative_tol
from vslbook.dists import (
    LinearGaussianMoE,
    condition_gaussian,
    gaussian_kl,
    log_responsibilities,
    moe_log_prob,
)

__all__ = [
    "SoftValueResult",
    "boltzmann_policy",
    "check_diffusion_kl",
    "check_kl_chain_rule",
    "check_maxent_as_inference",
    "check_mixture_estep_bound",
    "check_moe_gating",
    "check_mutual_information",
    "check_ou_marginals",
    "check_self_paced",
    "check_soft_optimal_policy",
    "foundations_checks",
    "maxent_objective",
    "ou_marginal",
    "random_mdp",
    "self_paced_objective",
    "self_paced_optimum",
    "self_paced_problem",
    "simulate_ou",
    "soft_policy_evaluation",
    "soft_value",
    "soft_value_iteration",
]


# ----------------------------------------------------------------------------- helpers


def _rng(seed: int, stream: int = 0) -> np.random.Generator:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    return np.random.default_rng([int(seed), stream])


def _worst(
    name: str,
    equation: str,
    lhs: np.ndarray | float,
    rhs: np.ndarray | float,
    tol: np.ndarray | float,
    relation: str = "==",
) -> Check:
    """The :class:`Check` of the worst element of an element-wise comparison."""
    lhs, rhs, tol = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (lhs, rhs, tol)))
    excess = np.abs(lhs - rhs) - tol if relation == "==" else lhs - rhs - tol
    excess = np.where(np.isnan(excess), np.inf, excess)
    i = np.unravel_index(np.argmax(excess), excess.shape) if excess.ndim else ()
    return Check(name, equation, lhs[i], rhs[i], tol[i], relation)


def _positive(name: str, value: float) -> float:
    if not (isinstance(value, (int, float, np.floating)) and value > 0 and math.isfinite(value)):
        raise ValueError(f"{name} must be a positive finite number, got {value!r}")
    return float(value)


def _count(name: str, value: int, minimum: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def _t(x: np.ndarray | float) -> torch.Tensor:
    return torch.as_tensor(np.asarray(x, dtype=float), dtype=torch.float64)


def _np(x: torch.Tensor | np.ndarray | float) -> np.ndarray:
    if isinstance(x, torch.Tensor):
        return x.detach().cpu().numpy()
    return np.asarray(x, dtype=float)


def _random_spd(rng: np.random.Generator, d: int, scale: float = 1.0) -> np.ndarray:
    a = rng.normal(size=(d, d)) / math.sqrt(d)
    return scale * (a @ a.T + 0.5 * np.eye(d))


def _check_distribution(name: str, probs: np.ndarray, shape: tuple[int, ...], axis: int = -1):
    probs = np.asarray(probs, dtype=float)
    if probs.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {probs.shape}")
    if np.any(probs < 0) or not np.allclose(probs.sum(axis), 1.0, atol=1e-8):
        raise ValueError(
            f"{name} must be non-negative and sum to 1 along axis {axis}; sums are "
            f"{np.round(probs.sum(axis), 6)}"
        )
    return probs


# ------------------------------------------------- Section 2.4: maximum entropy RL (tabular)


def random_mdp(n_states: int = 6, n_actions: int = 3, seed: int = 0) -> tuple[np.ndarray, ...]:
    """A random tabular MDP.

    Returns:
        ``(P, R)``: transition probabilities ``P[s, a, s']`` of shape ``(S, A, S)`` (Eq. 2.1,
        rows from a Dirichlet(0.5)) and rewards ``R[s, a]`` uniform in ``[-1, 1]``.
    """
    n_states, n_actions = _count("n_states", n_states), _count("n_actions", n_actions)
    rng = _rng(seed)
    P = rng.dirichlet(np.full(n_states, 0.5), size=(n_states, n_actions))
    R = rng.uniform(-1.0, 1.0, size=(n_states, n_actions))
    return P, R


def _check_mdp(P: np.ndarray, R: np.ndarray, gamma: float, alpha: float) -> tuple[np.ndarray, ...]:
    P, R = np.asarray(P, dtype=float), np.asarray(R, dtype=float)
    if R.ndim != 2:
        raise ValueError(f"R must have shape (S, A), got {R.shape}")
    S, A = R.shape
    _check_distribution("P", P, (S, A, S))
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
    P, R = _check_mdp(P, R, gamma, alpha)
    _positive("tol", tol)
    max_iter = _count("max_iter", max_iter)
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
    P, R = _check_mdp(P, R, gamma, alpha)
    policy = _check_distribution("policy", policy, R.shape)
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
        np.full(v.shape, 1 / v.size) if rho0 is None else _check_distribution("rho0", rho0, v.shape)
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
    rng = _rng(seed, 1)
    sol = soft_value_iteration(P, R, gamma, alpha)
    pi = sol.policy if policy is None else _check_distribution("policy", policy, R.shape)
    v_pi, q_pi = soft_policy_evaluation(P, R, pi, gamma, alpha)
    j_pi = float(v_pi.mean())

    def j(p: np.ndarray) -> float:
        return maxent_objective(P, R, p, gamma, alpha)

    j_random = np.array(
        [
            j(rng.dirichlet(np.ones(n_actions), size=n_states))
            for _ in range(_count("n_random", n_random))
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
        _worst(
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
        _worst(
            "V_soft -> V* as alpha -> 0 (within alpha log|A| / (1 - gamma))",
            "Eq. 2.41",
            v_alpha[0],
            v_hard,
            bound[0],
        ),
        _worst("V_soft >= V* for every alpha", "Eq. 2.41", v_hard[None], v_alpha, tol, "<="),
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


# ------------------------------------------------------- Section 2.5: self-paced curricula


def self_paced_problem(
    n_points: int = 201, low: float = 0.0, high: float = 4.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Toy curriculum: 1-D contexts on a grid, uniform ``p(c)``, return high for easy contexts.

    Returns:
        ``(contexts, p, returns)``: the grid ``(n,)``, the probability masses of the uniform
        ``p(c)`` and ``R(c) = 2 exp(-(c / 1.5)^2)`` (contexts near 0 are easy).
    """
    n_points = _count("n_points", n_points, 2)
    if not high > low:
        raise ValueError(f"high must exceed low, got low={low!r}, high={high!r}")
    contexts = np.linspace(low, high, n_points)
    return contexts, np.full(n_points, 1.0 / n_points), 2.0 * np.exp(-((contexts / 1.5) ** 2))


def _check_curriculum(p: np.ndarray, returns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    returns = np.asarray(returns, dtype=float)
    if returns.ndim != 1:
        raise ValueError(f"returns must have shape (n,), got {returns.shape}")
    return _check_distribution("p", p, returns.shape), returns


def self_paced_objective(pi: np.ndarray, p: np.ndarray, returns: np.ndarray, beta: float) -> float:
    """Self-paced objective ``E_pi[R] - beta KL(pi || p)`` of Eq. 2.44 on a discrete grid."""
    p, returns = _check_curriculum(p, returns)
    pi = _check_distribution("pi", pi, p.shape)
    kl = float(np.sum(xlogy(pi, pi) - xlogy(pi, p)))
    return float(pi @ returns) - beta * kl


def self_paced_optimum(beta: float, p: np.ndarray, returns: np.ndarray) -> np.ndarray:
    """Maximiser of Eq. 2.44: ``pi*(c) ∝ p(c) exp(R(c) / beta)``, as masses on the grid."""
    p, returns = _check_curriculum(p, returns)
    return softmax(np.log(p) + returns / _positive("beta", beta))


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
    betas = np.asarray([_positive("beta", b) for b in betas])
    if betas.size < 2 or np.any(np.diff(betas) <= 0):
        raise ValueError(f"betas must be at least two increasing values, got {betas}")
    rng = _rng(seed)
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
        _worst(
            "pi* beats perturbed and Gaussian-shaped context distributions",
            "Eq. 2.44",
            best_other,
            objective,
            tol,
            "<=",
        ),
        _worst("J(pi*) = beta log E_p[exp(R / beta)]", "Eq. 2.44", objective, free_energy, tol),
        _worst(
            "KL(pi*_beta || p) decreases as beta grows", "Eq. 2.44", kl[1:], kl[:-1], 1e-12, "<="
        ),
        _worst(
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


# -------------------------------------------------------- Section 2.6.2: mixture of experts


def _trapezoid_grid(lo: np.ndarray, hi: np.ndarray, n: int) -> tuple[np.ndarray, float]:
    """Tensor grid of shape ``(n, ..., n, d)`` on the box ``[lo, hi]`` and its cell volume."""
    axes = [np.linspace(a, b, n) for a, b in zip(lo, hi, strict=True)]
    volume = float(np.prod([(b - a) / (n - 1) for a, b in zip(lo, hi, strict=True)]))
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1), volume


def _trapezoid_sum(values: np.ndarray, n_axes: int, volume: float) -> float:
    w = values
    for _ in range(n_axes):
        w = np.trapezoid(w, axis=0, dx=1.0)
    return float(w * volume)


def check_moe_gating(
    seed: int = 0,
    n_components: int = 3,
    gating: Callable[[LinearGaussianMoE, torch.Tensor], torch.Tensor] | None = None,
) -> CheckReport:
    """Bayes-rule gating and normalisation of the linear-Gaussian MoE (Eqs. 2.47-2.49).

    Checks that ``gating(model, c)`` equals ``p(o, c) / sum_o' p(o', c)`` computed directly
    from scipy densities, that it sums to 1, that ``log pi(theta | c) = log p(theta, c) -
    log p(c)``, that ``pi(theta | c)`` integrates to 1 over 1-D and 2-D parameter grids, that
    the joint ``p(theta, c)`` integrates to 1 over a 2-D grid, and that samples from
    ``LinearGaussianMoE.sample`` have the mixture mean.

    Args:
        gating: candidate ``(model, contexts) -> probabilities (..., K)``; defaults to
            ``model.gating``.

    Returns:
        Report with data ``contexts`` (n_c,), ``gating`` (n_c, K), ``theta`` (n_t,) and
        ``density`` (n_t, n_c) = ``pi(theta | c)`` of a model with 1-D context and parameter.
    """
    n_components = _count("n_components", n_components)
    gating = gating or (lambda model, c: model.gating(c))
    gen = torch.Generator().manual_seed(int(_rng(seed).integers(2**31)))
    model = LinearGaussianMoE.random(n_components, 2, 2, seed=seed)
    c, _ = model.sample_contexts(40, gen)
    cand = _np(gating(model, c))
    joint = np.stack(
        [
            _np(model.weights[o])
            * multivariate_normal(_np(model.context_means[o]), _np(model.context_covs[o])).pdf(
                _np(c)
            )
            for o in range(n_components)
        ],
        axis=-1,
    )
    direct = joint / joint.sum(-1, keepdims=True)

    theta, _ = model.sample(c, gen)
    lhs_cond = _np(model.log_prob(theta, c))
    rhs_cond = _np(model.joint_log_prob(theta, c) - model.context_log_prob(c))

    # pi(theta | c) over a 2-D parameter grid, for a few contexts.
    masses_2d = []
    for ci in c[:3]:
        means = _np(model.expert_means(ci))
        std = np.sqrt(np.max(np.linalg.eigvalsh(_np(model.covs))))
        grid, vol = _trapezoid_grid(means.min(0) - 9 * std, means.max(0) + 9 * std, 141)
        dens = np.exp(_np(model.log_prob(_t(grid), ci)))
        masses_2d.append(_trapezoid_sum(dens, 2, vol))

    # 1-D context and parameter: conditional and joint normalisation.
    m1 = LinearGaussianMoE.random(n_components, 1, 1, seed=seed + 1)
    c_std = float(np.sqrt(_np(m1.context_covs).max()))
    c_lo = float(_np(m1.context_means).min()) - 9 * c_std
    c_hi = float(_np(m1.context_means).max()) + 9 * c_std
    t_std = float(np.sqrt(_np(m1.covs).max()))
    ends = _np(m1.expert_means(_t([[c_lo], [c_hi]])))
    t_lo, t_hi = float(ends.min()) - 9 * t_std, float(ends.max()) + 9 * t_std
    contexts = np.linspace(c_lo, c_hi, 161)
    thetas = np.linspace(t_lo, t_hi, 401)
    tt, cc = np.meshgrid(thetas, contexts, indexing="ij")
    cond = np.exp(_np(m1.log_prob(_t(tt[..., None]), _t(cc[..., None]))))
    joint_2d = np.exp(_np(m1.joint_log_prob(_t(tt[..., None]), _t(cc[..., None]))))
    dt, dc = thetas[1] - thetas[0], contexts[1] - contexts[0]
    masses_1d = np.trapezoid(cond, dx=dt, axis=0)
    joint_mass = np.trapezoid(np.trapezoid(joint_2d, dx=dt, axis=0), dx=dc)
    context_mass = np.trapezoid(np.exp(_np(m1.context_log_prob(_t(contexts[:, None])))), dx=dc)

    # Sampling: mean of theta | c against sum_o pi(o | c) mu_o(c).
    c0 = c[:1].expand(20000, 2)
    samples, _ = model.sample(c0, gen)
    mix_mean = _np(model.gating(c[0]) @ model.expert_means(c[0]))
    se = _np(samples.std(0)) / math.sqrt(samples.shape[0])

    checks = (
        _worst(
            "gating pi(o|c) = p(o, c) / sum_o' p(o', c) (scipy densities)",
            "Eqs. 2.48, 2.64",
            cand,
            direct,
            1e-10,
        ),
        _worst("gating sums to 1 over experts", "Eq. 2.48", cand.sum(-1), 1.0, 1e-12),
        _worst(
            "log pi(theta|c) = log p(theta, c) - log p(c)", "Eq. 2.48", lhs_cond, rhs_cond, 1e-10
        ),
        _worst("integral of pi(theta|c) d theta = 1 (1-D grid)", "Eq. 2.48", masses_1d, 1.0, 1e-6),
        _worst(
            "integral of pi(theta|c) d theta = 1 (2-D grid)",
            "Eq. 2.48",
            np.array(masses_2d),
            1.0,
            1e-6,
        ),
        Check("integral of p(c) dc = 1 (1-D grid)", "Eq. 2.47", context_mass, 1.0, 1e-6),
        Check(
            "integral of p(theta, c) d theta dc = 1 (2-D grid)", "Eq. 2.47", joint_mass, 1.0, 1e-6
        ),
        _worst(
            "sample mean of theta|c = sum_o pi(o|c) mu_o(c) (4 standard errors)",
            "Eq. 2.48",
            _np(samples.mean(0)),
            mix_mean,
            4 * se,
        ),
    )
    data = {
        "contexts": contexts,
        "gating": _np(m1.gating(_t(contexts[:, None]))),
        "theta": thetas,
        "density": cond,
    }
    return CheckReport("Mixture-of-experts gating by Bayes' rule (Section 2.6.2)", checks, data)


# -------------------------------------------------- Section 2.6.3: the OU forward process


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
    decay = np.exp(-_positive("beta", beta) * t)
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
    beta, T = _positive("beta", beta), _positive("T", T)
    n_steps = _count("n_steps", n_steps)
    if not eta >= 0:
        raise ValueError(f"eta must be non-negative, got {eta!r}")
    rng = _rng(seed)
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
    rng = _rng(seed, 1)
    x0 = mean0 + math.sqrt(_positive("var0", var0)) * rng.standard_normal(
        _count("n_samples", n_samples, 2)
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


# -------------------------------------------- Section 2.7: variational inference (Eqs. 2.56-)

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
    dx, dz = _count("dim_x", dim_x), _count("dim_z", dim_z)
    rng = _rng(seed)
    d = dx + dz
    mp, mq = rng.normal(size=d), rng.normal(size=d)
    sp, sq = _random_spd(rng, d), _random_spd(rng, d, 1.5)
    ix = list(range(dx))

    def f(*args: np.ndarray) -> float:
        return float(_np(kl(*(_t(a) for a in args))))

    def posterior_kl(x: np.ndarray) -> np.ndarray:
        p_mean, p_cov = condition_gaussian(_t(mp), _t(sp), ix, _t(x))
        q_mean, q_cov = condition_gaussian(_t(mq), _t(sq), ix, _t(x))
        return _np(kl(p_mean, p_cov, q_mean, q_cov))

    marginal = f(mp[:dx], sp[:dx, :dx], mq[:dx], sq[:dx, :dx])
    joint = f(mp, sp, mq, sq)
    nodes, weights = _gauss_hermite(mp[:dx], sp[:dx, :dx], 4)
    expected = float(weights @ posterior_kl(nodes))
    x = rng.multivariate_normal(mp[:dx], sp[:dx, :dx], size=_count("n_samples", n_samples, 2))
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
    k = _count("n_components", n_components)
    rng = _rng(seed)
    weights = rng.dirichlet(np.full(k, 3.0))
    means = rng.uniform(-3.0, 3.0, k)
    covs = rng.uniform(0.4, 1.2, k) ** 2
    q_weights, q_means = np.array([0.6, 0.4]), rng.uniform(-2.0, 2.0, 2)
    q_covs = rng.uniform(0.8, 1.5, 2) ** 2
    x = np.linspace(-15.0, 15.0, 6001)
    dx = x[1] - x[0]
    args = (_t(np.log(weights)), _t(means[:, None]), _t(covs[:, None, None]))
    log_pxo = np.log(weights) + norm.logpdf(x[:, None], means, np.sqrt(covs))
    log_p = _np(moe_log_prob(_t(x[:, None]), *args))
    log_q = _np(
        moe_log_prob(
            _t(x[:, None]), _t(np.log(q_weights)), _t(q_means[:, None]), _t(q_covs[:, None, None])
        )
    )
    log_resp = _np(log_responsibilities(_t(x[:, None]), *args))
    p = np.exp(log_p)

    def integrate(values: np.ndarray) -> float:
        return float(np.trapezoid(values, dx=dx))

    kl_true = integrate(p * (log_p - log_q))

    def bound(log_qo: np.ndarray) -> float:
        return integrate(np.sum(np.exp(log_pxo) * (log_pxo - log_qo - log_q[:, None]), -1))

    def expected_posterior_kl(log_qo: np.ndarray) -> float:
        return integrate(p * np.sum(np.exp(log_resp) * (log_resp - log_qo), -1))

    arbitrary = [np.full((x.size, k), -math.log(k))]
    for _ in range(_count("n_variational", n_variational)):
        slope, offset = rng.normal(size=k), rng.normal(scale=2.0, size=k)
        arbitrary.append(log_softmax(slope * x[:, None] + offset, axis=-1))
    bounds = np.array([bound(lq) for lq in arbitrary])
    gaps = np.array([expected_posterior_kl(lq) for lq in arbitrary])
    if variational is None:
        log_cand = log_resp
    else:
        cand = _check_distribution("variational(x)", variational(x), (x.size, k))
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
        _worst(
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


def _linear_gaussian_joint(
    coupling: np.ndarray, offset: np.ndarray, std: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Mean and covariance of ``x = M x + m + diag(std) eps`` with ``M`` nilpotent."""
    a = np.linalg.inv(np.eye(offset.size) - coupling)
    s = a * std[None, :]
    return a @ offset, s @ s.T


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
    n = _count("n_steps", n_steps)
    dt = _positive("T", T) / n
    decay = 1 - _positive("beta", beta) * dt
    if not decay > 0:
        raise ValueError(f"beta * T / n_steps must be < 1 for a stable chain, got {beta * dt:g}")
    kernel_var = 2 * beta * _positive("eta", eta) ** 2 * dt
    rng = _rng(seed)
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
    mean_q, cov_q = _linear_gaussian_joint(m_q, c_q, std_q)
    mean_p, cov_p = _linear_gaussian_joint(m_p, c_p, std_p)

    joint = float(gaussian_kl(_t(mean_p), _t(cov_p), _t(mean_q), _t(cov_q)))
    marginal = float(
        gaussian_kl(_t(mean_p[:1]), _t(cov_p[:1, :1]), _t(mean_q[:1]), _t(cov_q[:1, :1]))
    )
    nodes, weights = _gauss_hermite(mean_p[:1], cov_p[:1, :1], 8)
    post_p = condition_gaussian(_t(mean_p), _t(cov_p), [0], _t(nodes))
    post_q = condition_gaussian(_t(mean_q), _t(cov_q), [0], _t(nodes))
    expected = float(weights @ _np(gaussian_kl(*post_p, *post_q)))

    if forward_log_kernel is None:

        def forward_log_kernel(x_next: np.ndarray, x_prev: np.ndarray, step: int) -> np.ndarray:
            return norm.logpdf(x_next, decay * x_prev, math.sqrt(kernel_var))

    rng_mc = _rng(seed, 1)
    n_samples = _count("n_samples", n_samples, 2)
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
    S, A = _count("n_states", n_states), _count("n_actions", n_actions)
    alpha = _positive("alpha", alpha)
    rng = _rng(seed)
    q = rng.normal(scale=2.0, size=(S, A))
    rho = rng.dirichlet(np.ones(S))
    log_z = logsumexp(q / alpha, axis=-1)
    v = alpha * log_z
    log_target = q / alpha - log_z[:, None]
    pi_270 = np.exp(q / alpha) / np.exp(log_z)[:, None]
    pi_271 = np.exp((q - v[:, None]) / alpha)
    cand = pi_271 if policy is None else _check_distribution("policy", policy, (S, A))

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
    randoms = [rng.dirichlet(np.ones(A), size=S) for _ in range(_count("n_random", n_random))]
    l_random = np.array([objective(pi) for pi in randoms])
    checks = (
        _worst(
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
        _worst(
            "pi equals the numerical minimiser of Eq. 2.69", "Eq. 2.69", cand, pi_numerical, 1e-5
        ),
        _worst(
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


# ------------------------------------------------- Section 2.8: mutual information


def _entropy(p: np.ndarray, axis: int = -1) -> np.ndarray:
    return -xlogy(p, p).sum(axis)


def check_mutual_information(
    seed: int = 0,
    n_z: int = 4,
    n_s: int = 6,
    n_random: int = 50,
    posterior: Callable[[np.ndarray], np.ndarray] | None = None,
) -> CheckReport:
    """Mutual information identities and the variational lower bound (Eqs. 2.72-2.74).

    On a random joint ``p(z, s)`` (shape ``(n_z, n_s)``) checks Eq. 2.72 = 2.73 = 2.74,
    ``I >= 0``, ``I >= H(z) + E_p(z,s)[log q(z|s)]`` for ``n_random`` random ``q(z|s)``, that the
    gap is ``E_p(s)[KL(p(z|s) || q(z|s))]``, and that the bound is tight for ``posterior``.

    Args:
        posterior: candidate ``p_zs -> q(z|s)`` of shape ``(n_z, n_s)`` (columns sum to 1);
            defaults to the true posterior ``p(z|s)``.

    Returns:
        Report with data ``p_zs``, ``mi`` and ``bounds`` (one per random ``q``).
    """
    nz, ns = _count("n_z", n_z), _count("n_s", n_s)
    rng = _rng(seed)
    p_zs = rng.dirichlet(np.ones(nz * ns)).reshape(nz, ns)
    p_z, p_s = p_zs.sum(1), p_zs.sum(0)
    p_z_given_s = p_zs / p_s[None, :]
    p_s_given_z = p_zs / p_z[:, None]
    mi_72 = float(np.sum(p_zs * np.log(p_zs / np.outer(p_z, p_s))))
    mi_73 = float(_entropy(p_z) - p_s @ _entropy(p_z_given_s, axis=0))
    mi_74 = float(_entropy(p_s) - p_z @ _entropy(p_s_given_z, axis=1))

    def bound(q_z_given_s: np.ndarray) -> float:
        with np.errstate(divide="ignore"):
            return float(_entropy(p_z) + np.sum(p_zs * np.log(q_z_given_s)))

    def gap(q_z_given_s: np.ndarray) -> float:
        kl = np.sum(xlogy(p_z_given_s, p_z_given_s) - p_z_given_s * np.log(q_z_given_s), 0)
        return float(p_s @ kl)

    randoms = [rng.dirichlet(np.ones(nz), size=ns).T for _ in range(_count("n_random", n_random))]
    bounds = np.array([bound(q) for q in randoms])
    cand = (
        p_z_given_s
        if posterior is None
        else _check_distribution("posterior(p_zs)", posterior(p_zs), (nz, ns), axis=0)
    )
    tol = relative_tol(mi_72)
    checks = (
        Check("Eq. 2.72 = Eq. 2.73 (H(z) - E_p(s)[H(z|s)])", "Eqs. 2.72-2.73", mi_72, mi_73, tol),
        Check("Eq. 2.72 = Eq. 2.74 (H(s) - E_p(z)[H(s|z)])", "Eqs. 2.72, 2.74", mi_72, mi_74, tol),
        Check("I(z, s) >= 0", "Eq. 2.72", 0.0, mi_72, tol, "<="),
        Check(
            f"H(z) + E[log q(z|s)] <= I(z, s) for {n_random} random q",
            "Eq. 2.73",
            bounds.max(),
            mi_72,
            tol,
            "<=",
        ),
        _worst(
            "I - bound = E_p(s)[KL(p(z|s)||q(z|s))]",
            "Eq. 2.73",
            mi_72 - bounds,
            [gap(q) for q in randoms],
            tol,
        ),
        Check("bound is tight for q(z|s) = p(z|s)", "Eq. 2.73", bound(cand), mi_72, tol),
    )
    return CheckReport(
        "Mutual information and its variational bound (Section 2.8)",
        checks,
        {"p_zs": p_zs, "mi": np.array(mi_72), "bounds": bounds},
    )


def foundations_checks(seed: int = 0) -> list[CheckReport]:
    """Run every Chapter 2 check with default settings (about a second in total)."""
    return [
        check_soft_optimal_policy(seed),
        check_self_paced(seed),
        check_moe_gating(seed),
        check_ou_marginals(seed),
        check_kl_chain_rule(seed),
        check_mixture_estep_bound(seed),
        check_diffusion_kl(seed),
        check_maxent_as_inference(seed),
        check_mutual_information(seed),
    ]

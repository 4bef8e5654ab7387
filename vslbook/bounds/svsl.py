"""Numerical checks of the lower bounds of Chapter 3 (SVSL, Section 3.3 and Appendix A.1).

The checks work on a small mixture of experts in which every expectation can be computed by
quadrature to about ten digits: a 1-D context ``c`` on a bounded interval with uniform
``p(c)``, a 1-D parameter ``theta`` and two or three experts, each with

* a per-expert context distribution ``pi(c|o)``: a Gaussian truncated to the context interval
  (so that ``KL(pi(c) || p(c))`` is finite and ``E_pi(c|o)[log p(c)]`` is the constant
  ``-log(high - low)``),
* a linear-Gaussian expert ``pi(theta|c, o) = N(k_o c + b_o, s_o^2)``,
* a weight ``pi(o)``,

and a smooth bimodal reward ``R(c, theta)``. Context integrals use Gauss-Legendre nodes on the
interval, parameter integrals the trapezoid rule on a wide uniform grid (spectrally accurate
for the Gaussian tails). Entropies of the single experts and context distributions come from
their closed forms (scipy), never from the quadrature, so the two sides of every identity are
computed along different routes.

Each ``check_*`` function returns a :class:`~vslbook.bounds.CheckReport`. Several take an
optional candidate (a lower-bound function, a per-expert objective, a REPS update); the default
is the thesis's formula, and a wrong candidate (a flipped sign, the unweighted entropy of
Eq. A.5 as printed, a weight update that ignores the trust region) or ``beta < alpha`` makes
the report fail, which is how the tests show that the checks have teeth.

Covered: Eqs. 3.1-3.4 and A.1-A.4 (:func:`check_objective_decomposition`), the expert bound
Eq. 3.5 / A.1.2 (:func:`check_expert_bound`), the context bound Eq. 3.6 / A.1.3
(:func:`check_context_bound`), the weight bound Eq. 3.7 / A.5 (:func:`check_weight_bound`) and
the REPS update of the weights (:func:`check_reps_weights`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np
from scipy.optimize import brentq, minimize
from scipy.special import log_softmax, logsumexp, softmax
from scipy.stats import truncnorm

from vslbook.bounds import Check, CheckReport, relative_tol

__all__ = [
    "BoundFn",
    "ToyMoE",
    "ToyProblem",
    "bimodal_reward",
    "check_context_bound",
    "check_expert_bound",
    "check_objective_decomposition",
    "check_reps_weights",
    "check_weight_bound",
    "context_objective",
    "decomposed_objective",
    "expected_responsibility_kls",
    "expert_objective",
    "lower_bound",
    "maxent_curriculum_objective",
    "random_toy_moe",
    "reps_categorical",
    "reps_dual",
    "responsibilities",
    "svsl_checks",
    "weight_objective",
    "weight_rewards",
]

_LOG_2PI = math.log(2.0 * math.pi)


# ----------------------------------------------------------------------------- helpers


def _rng(seed: int, stream: int = 0) -> np.random.Generator:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    return np.random.default_rng([int(seed), stream])


def _count(name: str, value: int, minimum: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def _finite(name: str, value: float, minimum: float = -math.inf, strict: bool = False) -> float:
    ok = isinstance(value, (int, float, np.floating, np.integer)) and not isinstance(value, bool)
    ok = ok and math.isfinite(value) and (value > minimum if strict else value >= minimum)
    if not ok:
        bound = f"> {minimum}" if strict else f">= {minimum}"
        raise ValueError(f"{name} must be a finite number {bound}, got {value!r}")
    return float(value)


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


def _lse0(a: np.ndarray, keepdims: bool = False) -> np.ndarray:
    """``log sum exp`` over axis 0 (the experts); scipy's version is slow on these sizes."""
    m = a.max(axis=0, keepdims=True)
    out = m + np.log(np.exp(a - m).sum(axis=0, keepdims=True))
    return out if keepdims else out[0]


def _entropy(p: np.ndarray) -> float:
    p = np.asarray(p, dtype=float)
    nz = p > 0
    return float(-np.sum(p[nz] * np.log(p[nz])))


def _kl(p: np.ndarray, q: np.ndarray) -> float:
    p, q = np.asarray(p, dtype=float), np.asarray(q, dtype=float)
    nz = p > 0
    return float(np.sum(p[nz] * (np.log(p[nz]) - np.log(q[nz]))))


# ----------------------------------------------------------------------- the toy model


def bimodal_reward(c: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """``R(c, theta) = -(theta^2 - g(c)^2)^2 / 4`` with ``g(c) = 1 + sin(2c) / 2``.

    Two equally good solutions ``theta = +-g(c)`` for every context: the kind of multimodal
    task a mixture of experts is meant for (Section 3.3).
    """
    g = 1.0 + 0.5 * np.sin(2.0 * np.asarray(c, dtype=float))
    return -0.25 * (np.asarray(theta, dtype=float) ** 2 - g**2) ** 2


@dataclass(frozen=True)
class ToyMoE:
    """A 1-D mixture of experts with per-expert context distributions (Eq. 3.1).

    ``pi(theta|c) = sum_o pi(c|o) pi(o) / pi(c) * pi(theta|c, o)`` with

    Attributes:
        weights: ``pi(o)``, shape ``(K,)``, positive, summing to 1.
        context_mean, context_std: location and scale of ``pi(c|o)``, a Gaussian truncated
            to the problem's context interval, shape ``(K,)``.
        gain, offset, std: the expert ``pi(theta|c, o) = N(gain_o c + offset_o, std_o^2)``,
            shape ``(K,)``.
    """

    weights: np.ndarray
    context_mean: np.ndarray
    context_std: np.ndarray
    gain: np.ndarray
    offset: np.ndarray
    std: np.ndarray

    def __post_init__(self) -> None:
        names = ("weights", "context_mean", "context_std", "gain", "offset", "std")
        arrays = {n: np.array(getattr(self, n), dtype=np.float64) for n in names}
        k = arrays["weights"].shape
        if len(k) != 1 or k[0] < 1:
            raise ValueError(f"weights must be a non-empty 1-D array, got shape {k}")
        for n, a in arrays.items():
            if a.shape != k:
                raise ValueError(f"{n} must have shape {k} like weights, got {a.shape}")
            if not np.all(np.isfinite(a)):
                raise ValueError(f"{n} must be finite, got {a}")
            a.setflags(write=False)
            object.__setattr__(self, n, a)
        w = arrays["weights"]
        if np.any(w <= 0) or abs(w.sum() - 1.0) > 1e-10:
            raise ValueError(f"weights must be positive and sum to 1, got {w} (sum {w.sum()})")
        for n in ("context_std", "std"):
            if np.any(arrays[n] <= 0):
                raise ValueError(f"{n} must be positive, got {arrays[n]}")

    @property
    def n_components(self) -> int:
        """Number of experts ``K``."""
        return int(self.weights.shape[0])

    def replace(self, **changes: np.ndarray) -> ToyMoE:
        """A copy with some fields replaced (validated again)."""
        return replace(self, **changes)


def random_toy_moe(seed: int = 0, n_components: int = 3) -> ToyMoE:
    """A random :class:`ToyMoE` whose experts sit on distinct solution branches.

    Context means are spread over ``[-1, 1]`` (scales 0.3-0.6), expert offsets around
    ``linspace(-1.2, 1.2, K)`` with gains in ``[-0.6, 0.6]`` and standard deviations 0.3-0.5,
    weights from a Dirichlet(3).
    """
    k = _count("n_components", n_components)
    rng = _rng(seed, 1)
    centres = np.linspace(-1.2, 1.2, k) if k > 1 else np.zeros(1)
    return ToyMoE(
        weights=rng.dirichlet(np.full(k, 3.0)),
        context_mean=rng.permutation(np.linspace(-0.8, 0.8, k)) + rng.normal(0, 0.15, k),
        context_std=rng.uniform(0.3, 0.6, k),
        gain=rng.uniform(-0.6, 0.6, k),
        offset=centres + rng.normal(0, 0.15, k),
        std=rng.uniform(0.3, 0.5, k),
    )


@dataclass(frozen=True)
class ToyProblem:
    """Temperatures, context interval, reward and quadrature of the toy problem.

    Attributes:
        alpha: entropy temperature of the experts (Eq. 3.3), ``> 0``.
        beta: temperature of the context KL (Eq. 3.3), ``>= 0``. The bounds of Eqs. A.4-A.5
            need ``beta >= alpha``; smaller values are accepted so that the checks can show
            the bound breaking.
        low, high: context interval; ``p(c) = 1 / (high - low)`` on it.
        theta_low, theta_high: parameter range of the trapezoid grid.
        n_context: Gauss-Legendre nodes on ``[low, high]``.
        n_theta: trapezoid points on ``[theta_low, theta_high]``.
        reward: ``R(c, theta)``, broadcasting over arrays.
    """

    alpha: float = 0.5
    beta: float = 1.0
    low: float = -1.5
    high: float = 1.5
    theta_low: float = -10.0
    theta_high: float = 10.0
    n_context: int = 64
    n_theta: int = 601
    reward: Callable[[np.ndarray, np.ndarray], np.ndarray] = field(default=bimodal_reward)

    def __post_init__(self) -> None:
        _finite("alpha", self.alpha, 0.0, strict=True)
        _finite("beta", self.beta, 0.0)
        for lo, hi, what in (
            (self.low, self.high, "context interval"),
            (self.theta_low, self.theta_high, "parameter range"),
        ):
            if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
                raise ValueError(f"{what} must satisfy low < high (finite), got [{lo}, {hi}]")
        _count("n_context", self.n_context, 8)
        _count("n_theta", self.n_theta, 16)

    @property
    def log_p(self) -> float:
        """``log p(c)`` of the uniform task distribution (Eq. 3.3)."""
        return -math.log(self.high - self.low)

    @cached_property
    def contexts(self) -> tuple[np.ndarray, np.ndarray]:
        """Gauss-Legendre nodes ``(n_context,)`` and weights on ``[low, high]``."""
        x, w = np.polynomial.legendre.leggauss(self.n_context)
        half = 0.5 * (self.high - self.low)
        return self.low + half * (x + 1.0), half * w

    @cached_property
    def thetas(self) -> tuple[np.ndarray, np.ndarray]:
        """Uniform grid ``(n_theta,)`` and trapezoid weights."""
        t = np.linspace(self.theta_low, self.theta_high, self.n_theta)
        w = np.full(self.n_theta, t[1] - t[0])
        w[[0, -1]] *= 0.5
        return t, w

    @cached_property
    def rewards(self) -> np.ndarray:
        """``R(c, theta)`` on the grid, shape ``(n_context, n_theta)``."""
        c, _ = self.contexts
        t, _ = self.thetas
        r = np.asarray(self.reward(c[:, None], t[None, :]), dtype=np.float64)
        if r.shape != (c.size, t.size) or not np.all(np.isfinite(r)):
            raise ValueError("reward(c, theta) must broadcast to finite values on the grid")
        return r


# ------------------------------------------------------------------ densities on the grid


def _log_contexts(problem: ToyProblem, model: ToyMoE) -> np.ndarray:
    """``log pi(c|o)`` at the context nodes, shape ``(K, n_c)``."""
    c, _ = problem.contexts
    m, s = model.context_mean[:, None], model.context_std[:, None]
    return truncnorm.logpdf(c[None, :], (problem.low - m) / s, (problem.high - m) / s, m, s)


def _log_experts(problem: ToyProblem, model: ToyMoE) -> np.ndarray:
    """``log pi(theta|c, o)`` on the grid, shape ``(K, n_c, n_theta)``."""
    c, _ = problem.contexts
    t, _ = problem.thetas
    mean = model.gain[:, None] * c[None, :] + model.offset[:, None]
    reach = np.abs(model.gain) * max(abs(problem.low), abs(problem.high))
    lo, hi = model.offset - reach - 8 * model.std, model.offset + reach + 8 * model.std
    if np.any(lo < problem.theta_low) or np.any(hi > problem.theta_high):
        raise ValueError(
            f"experts reach [{lo.min():.3g}, {hi.max():.3g}] (mean +- 8 std), outside the "
            f"parameter grid [{problem.theta_low}, {problem.theta_high}]; widen the grid"
        )
    z = (t[None, None, :] - mean[:, :, None]) / model.std[:, None, None]
    return -0.5 * z**2 - np.log(model.std)[:, None, None] - 0.5 * _LOG_2PI


def _expert_entropy(model: ToyMoE) -> np.ndarray:
    """``H[pi(theta|c, o)] = log(2 pi e s_o^2) / 2`` for every expert, shape ``(K,)``."""
    return 0.5 * (_LOG_2PI + 1.0) + np.log(model.std)


def _context_entropy(problem: ToyProblem, model: ToyMoE) -> np.ndarray:
    """``H[pi(c|o)]`` of the truncated Gaussians (scipy closed form), shape ``(K,)``."""
    m, s = model.context_mean, model.context_std
    return np.asarray(truncnorm.entropy((problem.low - m) / s, (problem.high - m) / s, m, s))


def responsibilities(problem: ToyProblem, model: ToyMoE) -> tuple[np.ndarray, np.ndarray]:
    """Log responsibilities of ``model`` on the grid (Eq. 3.4, text below it).

    Returns:
        ``(log pi(o|c, theta), log pi(o|c))`` of shapes ``(K, n_c, n_theta)`` and ``(K, n_c)``,
        with ``pi(o|c) = pi(c|o) pi(o) / pi(c)`` and
        ``pi(o|c, theta) = pi(theta|c, o) pi(o|c) / pi(theta|c)``.
    """
    log_joint_c = np.log(model.weights)[:, None] + _log_contexts(problem, model)
    log_gate = log_joint_c - _lse0(log_joint_c, keepdims=True)
    log_joint_t = log_gate[:, :, None] + _log_experts(problem, model)
    return log_joint_t - _lse0(log_joint_t, keepdims=True), log_gate


def maxent_curriculum_objective(problem: ToyProblem, model: ToyMoE) -> float:
    """The curriculum max-ent objective of Eq. 3.3 (= A.1), straight from the mixture densities.

    ``E_pi(c)[E_pi(theta|c)[R] + alpha H[pi(theta|c)]] - beta KL(pi(c) || p(c))`` with the
    mixture ``pi(c) = sum_o pi(c|o) pi(o)`` and ``pi(theta|c)`` of Eq. 3.1 evaluated on the
    grid; no responsibilities, no per-component entropies.
    """
    c_w = problem.contexts[1]
    t_w = problem.thetas[1]
    log_joint_c = np.log(model.weights)[:, None] + _log_contexts(problem, model)
    log_pc = _lse0(log_joint_c)  # log pi(c)
    log_gate = log_joint_c - log_pc
    log_pt = _lse0(log_gate[:, :, None] + _log_experts(problem, model))
    inner = np.exp(log_pt) * (problem.rewards - problem.alpha * log_pt)
    per_context = inner @ t_w
    pc = np.exp(log_pc)
    kl = float(np.sum(c_w * pc * (log_pc - problem.log_p)))
    return float(np.sum(c_w * pc * per_context)) - problem.beta * kl


BoundFn = Callable[[ToyProblem, ToyMoE, np.ndarray, np.ndarray], float]
"""``(problem, model, log_aux_theta (K, n_c, n_t), log_aux_context (K, n_c)) -> value``."""


def _augmented_expert_rewards(
    problem: ToyProblem, model: ToyMoE, log_aux_theta: np.ndarray, sign: float = 1.0
) -> np.ndarray:
    """``E_pi(theta|c,o)[R + alpha log aux(o|c, theta)]`` per expert and context, ``(K, n_c)``."""
    t_w = problem.thetas[1]
    integrand = problem.rewards[None] + sign * problem.alpha * log_aux_theta
    return (np.exp(_log_experts(problem, model)) * integrand) @ t_w


def _check_aux(problem: ToyProblem, model: ToyMoE, log_aux_theta, log_aux_context):
    k, nc, nt = model.n_components, problem.n_context, problem.n_theta
    log_aux_theta = np.asarray(log_aux_theta, dtype=float)
    log_aux_context = np.asarray(log_aux_context, dtype=float)
    if log_aux_theta.shape != (k, nc, nt):
        raise ValueError(f"log_aux_theta must have shape {(k, nc, nt)}, got {log_aux_theta.shape}")
    if log_aux_context.shape != (k, nc):
        raise ValueError(f"log_aux_context must have shape {(k, nc)}, got {log_aux_context.shape}")
    # normalisation over experts, checked on a sub-grid (the full check costs more than the bound)
    for name, a in (
        ("log_aux_theta", log_aux_theta[:, ::7, ::37]),
        ("log_aux_context", log_aux_context),
    ):
        if not np.all(np.abs(_lse0(a)) <= 1e-8):
            raise ValueError(f"{name} must be log-probabilities over experts (axis 0 sums to 1)")
    return log_aux_theta, log_aux_context


def lower_bound(
    problem: ToyProblem, model: ToyMoE, log_aux_theta: np.ndarray, log_aux_context: np.ndarray
) -> float:
    """The lower bound of Eq. A.4: the objective with auxiliary responsibilities, KLs dropped.

    ``sum_o pi(o) E_pi(c|o)[E_pi(theta|c,o)[R + alpha log aux(o|c,theta)] + beta log p(c)
    + (beta - alpha) log aux(o|c)] + alpha E[H[pi(theta|c,o)]] + beta E_pi(o)[H[pi(c|o)]]
    + beta H[pi(o)]``. The ``beta log p(c)`` term, dropped in the thesis because ``p(c)`` is
    uniform, is kept so that the bound is comparable with Eq. 3.3. It equals Eq. 3.3 minus
    ``alpha E[KL(pi(o|c,theta) || aux)] + (beta - alpha) E[KL(pi(o|c) || aux)]`` (Eq. A.4),
    hence a lower bound when ``beta >= alpha``.
    """
    log_aux_theta, log_aux_context = _check_aux(problem, model, log_aux_theta, log_aux_context)
    c_w = problem.contexts[1]
    a, b = problem.alpha, problem.beta
    ctx = np.exp(_log_contexts(problem, model))
    per_context = (
        _augmented_expert_rewards(problem, model, log_aux_theta)
        + b * problem.log_p
        + (b - a) * log_aux_context
    )
    expected = (ctx * per_context) @ c_w
    w = model.weights
    return float(
        w @ expected
        + a * w @ _expert_entropy(model)
        + b * w @ _context_entropy(problem, model)
        + b * _entropy(w)
    )


def decomposed_objective(problem: ToyProblem, model: ToyMoE) -> float:
    """Eq. 3.4 (= A.3): the lower bound of Eq. A.4 with the model's own responsibilities."""
    return lower_bound(problem, model, *responsibilities(problem, model))


def expected_responsibility_kls(
    problem: ToyProblem, model: ToyMoE, log_aux_theta: np.ndarray, log_aux_context: np.ndarray
) -> tuple[float, float]:
    """The two gaps of Eq. A.4.

    Returns:
        ``(E_pi(c),pi(theta|c)[KL(pi(o|c,theta) || aux(o|c,theta))],
        E_pi(c)[KL(pi(o|c) || aux(o|c))])`` for the responsibilities of ``model``.
    """
    log_aux_theta, log_aux_context = _check_aux(problem, model, log_aux_theta, log_aux_context)
    c_w, t_w = problem.contexts[1], problem.thetas[1]
    log_rt, log_rc = responsibilities(problem, model)
    log_joint_c = np.log(model.weights)[:, None] + _log_contexts(problem, model)
    pc = np.exp(_lse0(log_joint_c))
    # pi(c) pi(theta|c) pi(o|c,theta) = pi(o) pi(c|o) pi(theta|c,o)
    joint = np.exp(log_joint_c[:, :, None] + _log_experts(problem, model))
    kl_theta = float(np.einsum("kct,kct,c,t->", joint, log_rt - log_aux_theta, c_w, t_w))
    kl_ctx = float(np.sum(c_w * pc * np.sum(np.exp(log_rc) * (log_rc - log_aux_context), 0)))
    return kl_theta, kl_ctx


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
    ctx = np.exp(_log_contexts(problem, model))[o]
    aug = _augmented_expert_rewards(problem, model, log_aux_theta)[o]
    return float(np.sum(c_w * ctx * aug) + problem.alpha * _expert_entropy(model)[o])


def _context_values(
    problem: ToyProblem, model: ToyMoE, log_aux_theta: np.ndarray, log_aux_context: np.ndarray
) -> np.ndarray:
    """``E_pi(c|o)[L_c(o, c) + (beta - alpha) log aux(o|c)] + beta H[pi(c|o)]``, shape (K,)."""
    log_aux_theta, log_aux_context = _check_aux(problem, model, log_aux_theta, log_aux_context)
    c_w = problem.contexts[1]
    a, b = problem.alpha, problem.beta
    l_c = (
        _augmented_expert_rewards(problem, model, log_aux_theta)
        + a * _expert_entropy(model)[:, None]
    )  # L_c(o, c) of Eq. 3.6
    ctx = np.exp(_log_contexts(problem, model))
    return (ctx * (l_c + (b - a) * log_aux_context)) @ c_w + b * _context_entropy(problem, model)


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
    return float(weights @ rewards + _finite("beta", beta, 0.0) * _entropy(weights))


# ---------------------------------------------------------------- REPS for the weights


def reps_dual(eta: float, p_old: np.ndarray, rewards: np.ndarray, beta: float, eps: float) -> float:
    """Dual of ``max_p sum p r + beta H(p)`` s.t. ``KL(p || p_old) <= eps`` (Eq. 3.7 with REPS).

    ``g(eta) = eta eps + (eta + beta) log sum_o p_old(o)^(eta/(eta+beta)) exp(r_o/(eta+beta))``.
    """
    p_old, rewards = np.asarray(p_old, dtype=float), np.asarray(rewards, dtype=float)
    tau = eta + beta
    return float(eta * eps + tau * logsumexp((eta * np.log(p_old) + rewards) / tau))


def _reps_solution(eta: float, p_old: np.ndarray, rewards: np.ndarray, beta: float) -> np.ndarray:
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
    beta = _finite("beta", beta, 0.0, strict=True)
    eps = _finite("eps", eps, 0.0, strict=True)

    def excess(eta: float) -> float:
        return _kl(_reps_solution(eta, p_old, rewards, beta), p_old) - eps

    if excess(0.0) <= 0.0:
        return _reps_solution(0.0, p_old, rewards, beta), 0.0
    upper = 1.0
    while excess(upper) > 0.0:
        upper *= 4.0
        if upper > 1e15:  # pragma: no cover - KL(p_eta || p_old) -> 0 as eta -> inf
            raise RuntimeError("could not bracket the REPS multiplier")
    eta = brentq(excess, 0.0, upper, xtol=1e-14, rtol=1e-14, maxiter=500)
    return _reps_solution(eta, p_old, rewards, beta), float(eta)


def _brute_force_reps(p_old: np.ndarray, rewards: np.ndarray, beta: float, eps: float):
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
            "fun": lambda p: eps - _kl(np.clip(p, 1e-300, None), p_old),
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
        if _kl(p, p_old) <= eps + 1e-9 and (best is None or negative(p) < negative(best)):
            best = p
    if best is None:  # pragma: no cover - p_old itself is feasible
        best = p_old
    return best


# ------------------------------------------------------------------------------ checks


def _tol(*values: float) -> float:
    return relative_tol(*values, rtol=1e-8)


def _random_aux(rng: np.random.Generator, problem: ToyProblem, k: int, scale: float):
    """Random auxiliary responsibilities: log-softmax of random quadratics in (c, theta)."""
    c, _ = problem.contexts
    t, _ = problem.thetas
    coef = rng.normal(0.0, scale, size=(k, 4))
    logits_t = (
        coef[:, 0, None, None] * c[None, :, None]
        + coef[:, 1, None, None] * t[None, None, :]
        + 0.1 * coef[:, 2, None, None] * t[None, None, :] ** 2
        + coef[:, 3, None, None]
    )
    coef_c = rng.normal(0.0, scale, size=(k, 2))
    logits_c = coef_c[:, 0, None] * c[None, :] + coef_c[:, 1, None]
    return log_softmax(logits_t, axis=0), log_softmax(logits_c, axis=0)


def check_objective_decomposition(
    seed: int = 0,
    alpha: float = 0.5,
    beta: float = 1.0,
    n_auxiliaries: int = 6,
    bound: BoundFn | None = None,
) -> CheckReport:
    """Eq. 3.3 = Eq. 3.4 (A.1-A.3), and the auxiliary-distribution identity of Eq. A.4.

    On a random 3-expert :class:`ToyMoE`: the curriculum max-ent objective computed directly
    from the mixture densities (Eq. 3.3) equals the decomposed form with the model's own
    responsibilities (Eq. 3.4, ``beta log p(c)`` kept); for ``n_auxiliaries`` random
    auxiliary distributions plus one that is exact in ``theta`` and wrong in ``c``,
    ``J = bound + alpha E[KL_theta] + (beta - alpha) E[KL_c]`` (Eq. A.4); ``bound <= J`` (which
    needs ``beta >= alpha``: with ``beta < alpha`` this check fails); and the bound is tight
    at the model's responsibilities.

    Args:
        alpha, beta: temperatures of Eq. 3.3.
        bound: candidate lower bound ``(problem, model, log_aux_theta, log_aux_context)``;
            defaults to :func:`lower_bound`.

    Returns:
        Report with data ``objective`` (Eq. 3.3), ``bounds`` (per auxiliary), ``kl_theta``,
        ``kl_context``, ``contexts``, ``gating`` (K, n_c) and ``context_density`` (K, n_c).
    """
    problem = ToyProblem(alpha=alpha, beta=beta)
    bound = bound or lower_bound
    rng = _rng(seed, 2)
    model = random_toy_moe(seed)
    k = model.n_components
    objective = maxent_curriculum_objective(problem, model)
    log_rt, log_rc = responsibilities(problem, model)
    auxes = [
        _random_aux(rng, problem, k, 1.0) for _ in range(_count("n_auxiliaries", n_auxiliaries))
    ]
    auxes.append((log_rt, _random_aux(rng, problem, k, 2.0)[1]))  # exact in theta, wrong in c
    bounds, kl_t, kl_c = [], [], []
    for aux in auxes:
        bounds.append(float(bound(problem, model, *aux)))
        kt, kc = expected_responsibility_kls(problem, model, *aux)
        kl_t.append(kt)
        kl_c.append(kc)
    bounds, kl_t, kl_c = np.array(bounds), np.array(kl_t), np.array(kl_c)
    identity_rhs = bounds + alpha * kl_t + (beta - alpha) * kl_c
    tol = _tol(objective, *bounds)
    own = float(bound(problem, model, log_rt, log_rc))
    # the same objective from a finer quadrature: the grid is not what makes them agree
    fine = ToyProblem(alpha=alpha, beta=beta, n_context=128, n_theta=1201)
    fine_objective = maxent_curriculum_objective(fine, model)
    checks = (
        Check(
            "Eq. 3.3 (mixture densities) = Eq. 3.4 (own responsibilities, beta log p kept)",
            "Eqs. 3.3, 3.4, A.1-A.3",
            objective,
            own,
            tol,
        ),
        Check(
            "Eq. 3.3 on a 2x finer grid agrees (quadrature converged)",
            "Eq. 3.3",
            fine_objective,
            objective,
            tol,
        ),
        _worst(
            f"J = bound + alpha E[KL_theta] + (beta-alpha) E[KL_c] for {len(auxes)} auxiliaries",
            "Eq. A.4",
            np.full(bounds.shape, objective),
            identity_rhs,
            tol,
        ),
        _worst(
            f"bound <= J for {len(auxes)} auxiliaries (needs beta >= alpha)",
            "Eq. A.4",
            bounds,
            objective,
            tol,
            "<=",
        ),
        _worst("expected KLs are non-negative", "Eq. A.4", -np.r_[kl_t, kl_c], 0.0, 1e-12, "<="),
    )
    c, _ = problem.contexts
    data = {
        "objective": np.array(objective),
        "bounds": bounds,
        "kl_theta": kl_t,
        "kl_context": kl_c,
        "contexts": c,
        "gating": np.exp(log_rc),
        "context_density": np.exp(_log_contexts(problem, model)),
    }
    return CheckReport(
        "Decomposition of the curriculum max-ent objective (Section 3.3.1)", checks, data
    )


def _perturb_expert(model: ToyMoE, rng: np.random.Generator, o: int, t: float, d=None):
    d = rng.normal(size=3) if d is None else d
    gain, offset, std = model.gain.copy(), model.offset.copy(), model.std.copy()
    gain[o] += 0.25 * t * d[0]
    offset[o] += 0.4 * t * d[1]
    std[o] *= math.exp(0.25 * t * d[2])
    return model.replace(gain=gain, offset=offset, std=std), d


def _perturb_context(model: ToyMoE, rng: np.random.Generator, o: int, t: float, d=None):
    d = rng.normal(size=2) if d is None else d
    mean, std = model.context_mean.copy(), model.context_std.copy()
    mean[o] += 0.4 * t * d[0]
    std[o] *= math.exp(0.3 * t * d[1])
    return model.replace(context_mean=mean, context_std=std), d


def _perturb_weights(model: ToyMoE, rng: np.random.Generator, o: int, t: float, d=None):
    d = rng.normal(size=model.n_components) if d is None else d
    return model.replace(weights=softmax(np.log(model.weights) + 0.8 * t * d)), d


def _bound_check(
    kind: str,
    seed: int,
    alpha: float,
    beta: float,
    n_perturbations: int,
    perturb: Callable,
    surrogate: Callable[[ToyProblem, ToyMoE, np.ndarray, np.ndarray, int], float],
    surrogate_scale: Callable[[ToyMoE, int], float],
    equation: str,
    title: str,
) -> CheckReport:
    """Shared body of the expert, context and weight bound checks."""
    problem = ToyProblem(alpha=alpha, beta=beta)
    rng = _rng(seed, 3)
    old = random_toy_moe(seed)
    aux = responsibilities(problem, old)
    j_old = maxent_curriculum_objective(problem, old)
    lb_old = lower_bound(problem, old, *aux)
    s_old = [surrogate(problem, old, *aux, o) for o in range(old.n_components)]
    j_new, lb_new, gap_pred, d_lb, d_sur = [], [], [], [], []
    for _ in range(_count("n_perturbations", n_perturbations)):
        o = int(rng.integers(old.n_components))
        new, _ = perturb(old, rng, o, 1.0)
        j = maxent_curriculum_objective(problem, new)
        lb = lower_bound(problem, new, *aux)
        kt, kc = expected_responsibility_kls(problem, new, *aux)
        j_new.append(j)
        lb_new.append(lb)
        gap_pred.append(alpha * kt + (beta - alpha) * kc)
        d_lb.append(lb - lb_old)
        d_sur.append(surrogate_scale(old, o) * (surrogate(problem, new, *aux, o) - s_old[o]))
    j_new, lb_new, gap_pred = np.array(j_new), np.array(lb_new), np.array(gap_pred)
    d_lb, d_sur = np.array(d_lb), np.array(d_sur)
    tol = _tol(j_old, *j_new, *lb_new)

    # one perturbation path through the current model, for plotting
    ts = np.linspace(-1.0, 1.0, 11)
    o_path = int(rng.integers(old.n_components))
    _, d = perturb(old, rng, o_path, 0.0)
    path_j, path_lb = [], []
    for t in ts:
        m, _ = perturb(old, rng, o_path, float(t), d)
        path_j.append(maxent_curriculum_objective(problem, m))
        path_lb.append(lower_bound(problem, m, *aux))
    checks = (
        _worst(
            f"bound(new; aux = old) <= J(new) for {len(j_new)} perturbed {kind}",
            equation,
            lb_new,
            j_new,
            tol,
            "<=",
        ),
        Check("bound is tight at new = old", equation, lb_old, j_old, tol),
        _worst(
            "J(new) - bound(new) = alpha E[KL_theta] + (beta-alpha) E[KL_c]",
            "Eq. A.4",
            j_new - lb_new,
            gap_pred,
            tol,
        ),
        _worst(
            f"change of the bound = change of the {kind} objective (it holds all the dependence)",
            equation,
            d_lb,
            d_sur,
            tol,
        ),
        _worst(
            "J(new) - J(old) >= change of the bound (monotonic improvement)",
            equation,
            d_lb,
            j_new - j_old,
            tol,
            "<=",
        ),
    )
    data = {
        "t": ts,
        "path_objective": np.array(path_j),
        "path_bound": np.array(path_lb),
        "objective_new": j_new,
        "bound_new": lb_new,
        "objective_old": np.array(j_old),
    }
    return CheckReport(title, checks, data)


def check_expert_bound(
    seed: int = 0,
    alpha: float = 0.5,
    beta: float = 1.0,
    n_perturbations: int = 6,
    objective: Callable[[ToyProblem, ToyMoE, np.ndarray, int], float] | None = None,
) -> CheckReport:
    """The expert lower bound, Eq. 3.5 with ``aux(o|c, theta) = pi_old(o|c, theta)`` (A.1.2).

    For random perturbations of one expert ``pi(theta|c, o)`` of a random :class:`ToyMoE`,
    with the auxiliaries fixed to the old model's responsibilities: the bound of Eq. A.4 never
    exceeds the true objective (Eq. 3.3) of the new model, touches it at ``new = old``, its gap
    is ``alpha E[KL(pi_new(o|c,theta) || pi_old(o|c,theta))]`` (the gating, and so the context
    gap, does not move), its change equals ``pi(o)`` times the change of the per-expert
    objective (Eq. 3.5 with the auxiliary), and hence the true objective improves at least
    as much as the bound does.

    Args:
        objective: candidate per-expert objective ``(problem, model, log_aux_theta, o)``;
            defaults to :func:`expert_objective`.

    Returns:
        Report with data ``t``, ``path_objective`` and ``path_bound`` along one perturbation
        path through the current model (``t = 0``), ``objective_new``, ``bound_new`` and
        ``objective_old``.
    """
    objective = objective or expert_objective
    return _bound_check(
        "experts",
        seed,
        alpha,
        beta,
        n_perturbations,
        _perturb_expert,
        lambda problem, model, aux_t, aux_c, o: objective(problem, model, aux_t, o),
        lambda model, o: float(model.weights[o]),
        "Eq. 3.5, A.1.2",
        "Lower bound for the experts (Section 3.3.2)",
    )


def check_context_bound(
    seed: int = 0,
    alpha: float = 0.5,
    beta: float = 1.0,
    n_perturbations: int = 6,
    objective: Callable[[ToyProblem, ToyMoE, np.ndarray, np.ndarray, int], float] | None = None,
) -> CheckReport:
    """The context lower bound, Eq. 3.6 with both auxiliaries from the old model (A.1.3).

    As :func:`check_expert_bound`, for perturbations of one ``pi(c|o)`` (mean and scale).
    Moving a context distribution moves the gating ``pi(o|c)`` and with it ``pi(o|c, theta)``,
    so the gap is ``alpha E[KL_theta] + (beta - alpha) E[KL_c]``: non-negative only because
    ``beta >= alpha`` (with ``beta = 0`` it equals ``-alpha E_c[KL(pi_new(theta|c) ||
    pi_old(theta|c))] < 0`` and the check fails).

    Args:
        objective: candidate per-expert context objective
            ``(problem, model, log_aux_theta, log_aux_context, o)``; defaults to
            :func:`context_objective`.
    """
    objective = objective or context_objective
    return _bound_check(
        "context distributions",
        seed,
        alpha,
        beta,
        n_perturbations,
        _perturb_context,
        objective,
        lambda model, o: float(model.weights[o]),
        "Eq. 3.6, A.1.3",
        "Lower bound for the per-expert context distributions (Section 3.3.3)",
    )


def check_weight_bound(
    seed: int = 0,
    alpha: float = 0.5,
    beta: float = 1.0,
    n_perturbations: int = 6,
    rewards: BoundFn | None = None,
) -> CheckReport:
    """The weight lower bound, Eq. 3.7 / A.5 with both auxiliaries from the old model.

    As :func:`check_expert_bound`, for perturbations of ``pi(o)``; the bound changes exactly
    as Eq. 3.7, ``sum_o pi(o) r_o + beta H[pi(o)]`` with the per-expert rewards ``r_o`` of
    :func:`weight_rewards` (which do not depend on ``pi(o)``). Two extra checks: the maximiser
    of Eq. 3.7, ``softmax(r / beta)``, improves the true objective (Eq. 3.3); and the printed
    form of Eq. A.5, which leaves ``beta H[pi(c|o)]`` unweighted by ``pi(o)``, is not what the
    bound contains (pass it as ``rewards`` to see the report fail).

    Args:
        rewards: candidate ``(problem, model, log_aux_theta, log_aux_context) -> r (K,)``
            such that Eq. 3.7 is ``sum_o pi(o) r_o + beta H[pi(o)]``; defaults to
            :func:`weight_rewards`.

    Returns:
        As :func:`check_expert_bound`, plus ``rewards`` (``r_o``), ``weights_old`` and
        ``weights_softmax``.
    """
    rewards = rewards or weight_rewards

    def surrogate(problem, model, aux_t, aux_c, o):
        r = np.asarray(rewards(problem, model, aux_t, aux_c), dtype=float)
        return weight_objective(model.weights, r, problem.beta)

    report = _bound_check(
        "weights",
        seed,
        alpha,
        beta,
        n_perturbations,
        _perturb_weights,
        surrogate,
        lambda model, o: 1.0,
        "Eq. 3.7, A.5",
        "Lower bound for the expert weights (Section 3.3.3)",
    )
    problem = ToyProblem(alpha=alpha, beta=beta)
    old = random_toy_moe(seed)
    aux = responsibilities(problem, old)
    r = np.asarray(rewards(problem, old, *aux), dtype=float)
    w_soft = softmax(r / beta) if beta > 0 else np.eye(r.size)[np.argmax(r)]
    w_soft = np.clip(w_soft, 1e-300, None)
    w_soft = w_soft / w_soft.sum()
    better = old.replace(weights=w_soft)
    j_old = maxent_curriculum_objective(problem, old)
    j_soft = maxent_curriculum_objective(problem, better)
    lb_soft = lower_bound(problem, better, *aux)
    tol = _tol(j_old, j_soft)
    extra = (
        Check(
            "bound at softmax(r / beta) = Eq. 3.7 there + beta log p(c)",
            "Eq. 3.7",
            lb_soft,
            weight_objective(w_soft, r, beta) + beta * problem.log_p,
            tol,
        ),
        Check(
            "J(old) <= J(softmax(r / beta)) (the maximiser of Eq. 3.7 improves Eq. 3.3)",
            "Eqs. 3.3, 3.7",
            j_old,
            j_soft,
            tol,
            "<=",
        ),
    )
    data = dict(report.data)
    data.update(rewards=r, weights_old=old.weights.copy(), weights_softmax=w_soft)
    return CheckReport(report.title, report.checks + extra, data)


def check_reps_weights(
    seed: int = 0,
    n_components: int = 6,
    beta: float = 0.5,
    epsilons: tuple[float, ...] = (0.01, 0.05, 0.2, 0.5, 2.0, 50.0),
    update: Callable[[np.ndarray, np.ndarray, float, float], np.ndarray] | None = None,
) -> CheckReport:
    """REPS update of the weights (Eq. 3.7 with a KL trust region) against brute force.

    For a random categorical ``p_old`` and rewards ``r``: the closed form
    ``p ∝ p_old^(eta/(eta+beta)) exp(r/(eta+beta))`` (``eta`` from the 1-D dual) attains the
    optimum of the primal found by SLSQP over the simplex, stays inside ``KL <= eps``, its
    dual value equals the primal value (strong duality), and for ``eps`` large enough
    (``eps >= KL(softmax(r/beta) || p_old)``) it *is* ``softmax(r / beta)``, the unconstrained
    maximiser of Eq. 3.7.

    Args:
        update: candidate ``(p_old, r, beta, eps) -> p_new``; defaults to
            :func:`reps_categorical` (its first output).

    Returns:
        Report with data ``eps_path``, ``kl_path`` (``KL(p_eps || p_old)``) and
        ``distance_to_softmax`` (``max |p_eps - softmax(r/beta)|``) over a log-spaced range of
        ``eps``, and ``kl_softmax``.
    """
    k = _count("n_components", n_components, 2)
    beta = _finite("beta", beta, 0.0, strict=True)
    if not epsilons or any(not (e > 0 and math.isfinite(e)) for e in epsilons):
        raise ValueError(f"epsilons must be positive finite numbers, got {epsilons!r}")
    update = update or (lambda p, r, b, e: reps_categorical(p, r, b, e)[0])
    rng = _rng(seed, 4)
    p_old = rng.dirichlet(np.full(k, 2.0))
    r = rng.normal(0.0, 1.0, k)
    target = softmax(r / beta)
    kl_soft = _kl(target, p_old)
    obj_cand, obj_brute, kls, primal, dual = [], [], [], [], []
    for eps in epsilons:
        p = np.asarray(update(p_old, r, beta, eps), dtype=float)
        if p.shape != (k,):
            raise ValueError(f"update must return shape {(k,)}, got {p.shape}")
        brute = _brute_force_reps(p_old, r, beta, eps)
        obj_cand.append(weight_objective(p, r, beta))
        obj_brute.append(weight_objective(brute, r, beta))
        kls.append(_kl(p, p_old))
        _, eta = reps_categorical(p_old, r, beta, eps)
        dual.append(reps_dual(eta, p_old, r, beta, eps))
        primal.append(weight_objective(_reps_solution(eta, p_old, r, beta), r, beta))
    large = [e for e in epsilons if e >= kl_soft]
    if large:
        p_large = np.asarray(update(p_old, r, beta, max(large)), dtype=float)
        softmax_gap = float(np.max(np.abs(p_large - target)))
    else:
        softmax_gap = math.nan
    eps_path = np.geomspace(1e-3, max(10.0, 2 * kl_soft), 20)
    p_path = np.array([np.asarray(update(p_old, r, beta, e), dtype=float) for e in eps_path])
    checks = (
        _worst(
            "closed form attains the SLSQP optimum of the primal",
            "Eq. 3.7 (REPS)",
            obj_cand,
            obj_brute,
            1e-7,
        ),
        _worst("KL(p_new || p_old) <= eps", "Eq. 3.7 (REPS)", kls, list(epsilons), 1e-9, "<="),
        _worst("dual value = primal value (strong duality)", "Eq. 3.7 (REPS)", dual, primal, 1e-9),
        Check(
            f"eps >= KL(softmax(r/beta) || p_old) = {kl_soft:.3g}: update = softmax(r / beta)",
            "Eq. 3.7",
            softmax_gap,
            0.0,
            1e-12,
        ),
    )
    data = {
        "eps_path": eps_path,
        "kl_path": np.array([_kl(p, p_old) for p in p_path]),
        "distance_to_softmax": np.max(np.abs(p_path - target), axis=1),
        "kl_softmax": np.array(kl_soft),
        "p_old": p_old,
        "rewards": r,
    }
    return CheckReport("REPS update of the expert weights (Section 3.3.3)", checks, data)


def svsl_checks(seed: int = 0) -> list[CheckReport]:
    """Run every Chapter 3 derivation check with default settings."""
    return [
        check_objective_decomposition(seed),
        check_expert_bound(seed),
        check_context_bound(seed),
        check_weight_bound(seed),
        check_reps_weights(seed),
    ]

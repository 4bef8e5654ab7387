"""The toy mixture of experts on which the Chapter 3 bounds are checked (Section 3.3.1, A.1.1).

A small mixture of experts in which every expectation can be computed by quadrature to about
ten digits: a 1-D context ``c`` on a bounded interval with uniform ``p(c)``, a 1-D parameter
``theta`` and two or three experts, each with

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

Holds the model (:class:`ToyMoE`, :class:`ToyProblem`, :func:`random_toy_moe`), its densities
and responsibilities (Eq. 3.4), the curriculum max-ent objective (Eq. 3.3 = A.1), its
decomposed form (Eq. 3.4 = A.3), the lower bound with auxiliary responsibilities and its two
gaps (Eq. A.4), and the random auxiliaries and perturbations that the checks of
:mod:`vslbook.bounds.svsl` draw. The small numerical helpers it shares with the other bound
checks (seeded streams, argument validation, discrete entropies) are in
:mod:`vslbook.bounds.toy_numerics`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np
from scipy.special import log_softmax, softmax
from scipy.stats import truncnorm

from vslbook.bounds.toy_numerics import (
    check_count,
    check_finite,
    discrete_entropy,
    logsumexp0,
    seeded_rng,
)

__all__ = [
    "BoundFn",
    "ToyMoE",
    "ToyProblem",
    "augmented_expert_rewards",
    "bimodal_reward",
    "check_aux",
    "context_entropy",
    "decomposed_objective",
    "expected_responsibility_kls",
    "expert_entropy",
    "log_contexts",
    "log_experts",
    "lower_bound",
    "maxent_curriculum_objective",
    "perturb_context",
    "perturb_expert",
    "perturb_weights",
    "random_aux",
    "random_toy_moe",
    "responsibilities",
]

_LOG_2PI = math.log(2.0 * math.pi)


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
    k = check_count("n_components", n_components)
    rng = seeded_rng(seed, 1)
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
        check_finite("alpha", self.alpha, 0.0, strict=True)
        check_finite("beta", self.beta, 0.0)
        for lo, hi, what in (
            (self.low, self.high, "context interval"),
            (self.theta_low, self.theta_high, "parameter range"),
        ):
            if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
                raise ValueError(f"{what} must satisfy low < high (finite), got [{lo}, {hi}]")
        check_count("n_context", self.n_context, 8)
        check_count("n_theta", self.n_theta, 16)

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


def log_contexts(problem: ToyProblem, model: ToyMoE) -> np.ndarray:
    """``log pi(c|o)`` at the context nodes, shape ``(K, n_c)``."""
    c, _ = problem.contexts
    m, s = model.context_mean[:, None], model.context_std[:, None]
    return truncnorm.logpdf(c[None, :], (problem.low - m) / s, (problem.high - m) / s, m, s)


def log_experts(problem: ToyProblem, model: ToyMoE) -> np.ndarray:
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


def expert_entropy(model: ToyMoE) -> np.ndarray:
    """``H[pi(theta|c, o)] = log(2 pi e s_o^2) / 2`` for every expert, shape ``(K,)``."""
    return 0.5 * (_LOG_2PI + 1.0) + np.log(model.std)


def context_entropy(problem: ToyProblem, model: ToyMoE) -> np.ndarray:
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
    log_joint_c = np.log(model.weights)[:, None] + log_contexts(problem, model)
    log_gate = log_joint_c - logsumexp0(log_joint_c, keepdims=True)
    log_joint_t = log_gate[:, :, None] + log_experts(problem, model)
    return log_joint_t - logsumexp0(log_joint_t, keepdims=True), log_gate


def maxent_curriculum_objective(problem: ToyProblem, model: ToyMoE) -> float:
    """The curriculum max-ent objective of Eq. 3.3 (= A.1), straight from the mixture densities.

    ``E_pi(c)[E_pi(theta|c)[R] + alpha H[pi(theta|c)]] - beta KL(pi(c) || p(c))`` with the
    mixture ``pi(c) = sum_o pi(c|o) pi(o)`` and ``pi(theta|c)`` of Eq. 3.1 evaluated on the
    grid; no responsibilities, no per-component entropies.
    """
    c_w = problem.contexts[1]
    t_w = problem.thetas[1]
    log_joint_c = np.log(model.weights)[:, None] + log_contexts(problem, model)
    log_pc = logsumexp0(log_joint_c)  # log pi(c)
    log_gate = log_joint_c - log_pc
    log_pt = logsumexp0(log_gate[:, :, None] + log_experts(problem, model))
    inner = np.exp(log_pt) * (problem.rewards - problem.alpha * log_pt)
    per_context = inner @ t_w
    pc = np.exp(log_pc)
    kl = float(np.sum(c_w * pc * (log_pc - problem.log_p)))
    return float(np.sum(c_w * pc * per_context)) - problem.beta * kl


BoundFn = Callable[[ToyProblem, ToyMoE, np.ndarray, np.ndarray], float]
"""``(problem, model, log_aux_theta (K, n_c, n_t), log_aux_context (K, n_c)) -> value``."""


def augmented_expert_rewards(
    problem: ToyProblem, model: ToyMoE, log_aux_theta: np.ndarray, sign: float = 1.0
) -> np.ndarray:
    """``E_pi(theta|c,o)[R + alpha log aux(o|c, theta)]`` per expert and context, ``(K, n_c)``."""
    t_w = problem.thetas[1]
    integrand = problem.rewards[None] + sign * problem.alpha * log_aux_theta
    return (np.exp(log_experts(problem, model)) * integrand) @ t_w


def check_aux(problem: ToyProblem, model: ToyMoE, log_aux_theta, log_aux_context):
    """The auxiliary responsibilities as float arrays; ValueError unless they have shapes
    ``(K, n_c, n_theta)`` and ``(K, n_c)`` and are log-probabilities over the experts."""
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
        if not np.all(np.abs(logsumexp0(a)) <= 1e-8):
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
    log_aux_theta, log_aux_context = check_aux(problem, model, log_aux_theta, log_aux_context)
    c_w = problem.contexts[1]
    a, b = problem.alpha, problem.beta
    ctx = np.exp(log_contexts(problem, model))
    per_context = (
        augmented_expert_rewards(problem, model, log_aux_theta)
        + b * problem.log_p
        + (b - a) * log_aux_context
    )
    expected = (ctx * per_context) @ c_w
    w = model.weights
    return float(
        w @ expected
        + a * w @ expert_entropy(model)
        + b * w @ context_entropy(problem, model)
        + b * discrete_entropy(w)
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
    log_aux_theta, log_aux_context = check_aux(problem, model, log_aux_theta, log_aux_context)
    c_w, t_w = problem.contexts[1], problem.thetas[1]
    log_rt, log_rc = responsibilities(problem, model)
    log_joint_c = np.log(model.weights)[:, None] + log_contexts(problem, model)
    pc = np.exp(logsumexp0(log_joint_c))
    # pi(c) pi(theta|c) pi(o|c,theta) = pi(o) pi(c|o) pi(theta|c,o)
    joint = np.exp(log_joint_c[:, :, None] + log_experts(problem, model))
    kl_theta = float(np.einsum("kct,kct,c,t->", joint, log_rt - log_aux_theta, c_w, t_w))
    kl_ctx = float(np.sum(c_w * pc * np.sum(np.exp(log_rc) * (log_rc - log_aux_context), 0)))
    return kl_theta, kl_ctx


# ------------------------------------------------------- random auxiliaries, perturbations


def random_aux(rng: np.random.Generator, problem: ToyProblem, k: int, scale: float):
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


def perturb_expert(model: ToyMoE, rng: np.random.Generator, o: int, t: float, d=None):
    """``model`` with expert ``o``'s gain, offset and std moved by ``t`` along direction ``d``
    (drawn from ``rng`` when None); returns ``(model, d)``."""
    d = rng.normal(size=3) if d is None else d
    gain, offset, std = model.gain.copy(), model.offset.copy(), model.std.copy()
    gain[o] += 0.25 * t * d[0]
    offset[o] += 0.4 * t * d[1]
    std[o] *= math.exp(0.25 * t * d[2])
    return model.replace(gain=gain, offset=offset, std=std), d


def perturb_context(model: ToyMoE, rng: np.random.Generator, o: int, t: float, d=None):
    """``model`` with the mean and std of ``pi(c|o)`` moved by ``t`` along direction ``d``
    (drawn from ``rng`` when None); returns ``(model, d)``."""
    d = rng.normal(size=2) if d is None else d
    mean, std = model.context_mean.copy(), model.context_std.copy()
    mean[o] += 0.4 * t * d[0]
    std[o] *= math.exp(0.3 * t * d[1])
    return model.replace(context_mean=mean, context_std=std), d


def perturb_weights(model: ToyMoE, rng: np.random.Generator, o: int, t: float, d=None):
    """``model`` with the logits of ``pi(o)`` moved by ``t`` along direction ``d`` (drawn from
    ``rng`` when None; ``o`` is unused, kept for a common signature); returns ``(model, d)``."""
    d = rng.normal(size=model.n_components) if d is None else d
    return model.replace(weights=softmax(np.log(model.weights) + 0.8 * t * d)), d

"""The toy of the Chapter 4 checks: a 1-D mixture with energy-based context distributions.

:class:`EnergyMoE` sits on the :class:`~vslbook.bounds.svsl_toy.ToyProblem` of Chapter 3 (a
bounded context interval with uniform ``p(c)``, a 1-D parameter, linear-Gaussian experts, a
bimodal reward) and replaces each Gaussian context distribution by an energy-based one,
``pi(c|o) = exp(phi_o(c)) / Z_o`` (Eq. 4.6), whose energy is a few fixed tanh features, so that
every expectation can be computed by quadrature to about ten digits.

Holds the model, its densities and responsibilities (Appendix B.1), the curriculum objective
(Eq. 4.3) and its bound with auxiliary responsibilities (Eq. B.1), the per-expert objectives
(Eqs. 4.4, 4.5), and the sample forms that Di-SkilL actually optimises: the context values
``L_c`` at sampled contexts, the categorical objective Eq. 4.8, the Monte-Carlo normaliser of
Eq. 4.6, self-normalised expectations and the gating with a uniform prior. The checks that use
them are in :mod:`vslbook.bounds.diskill`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from scipy.integrate import quad
from scipy.special import logsumexp, softmax

from vslbook.bounds.svsl_toy import (
    ToyProblem,
    augmented_expert_rewards,
    check_aux,
    expert_entropy,
    log_experts,
    random_toy_moe,
)
from vslbook.bounds.toy_numerics import check_count, check_finite, logsumexp0, seeded_rng

__all__ = [
    "EnergyBoundFn",
    "EnergyMoE",
    "ebm_context_entropy",
    "ebm_context_objective",
    "ebm_curriculum_objective",
    "ebm_expected_responsibility_kls",
    "ebm_expert_objective",
    "ebm_log_contexts",
    "ebm_log_normaliser",
    "ebm_lower_bound",
    "ebm_responsibilities",
    "energy_fn",
    "expert_context_values",
    "integrate_quad",
    "mc_normaliser",
    "random_energy_moe",
    "sample_context_objective",
    "self_normalised_expectation",
    "uniform_prior_gating",
]


def _array(name: str, value, ndim: int) -> np.ndarray:
    a = np.array(value, dtype=np.float64)
    if a.ndim != ndim or a.size == 0:
        raise ValueError(f"{name} must be a non-empty {ndim}-D array, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite, got {a}")
    return a


# ----------------------------------------------------------------------- the EBM toy


@dataclass(frozen=True)
class EnergyMoE:
    """A 1-D mixture of experts with energy-based context distributions (Eqs. 4.2, 4.6).

    ``pi(o) = 1 / K`` (fixed, B.3.1); ``pi(c|o) = exp(phi_o(c)) / Z_o`` on the problem's context
    interval with ``phi_o(c) = sum_j amplitude_oj tanh(slope_oj c + shift_oj)``; the expert
    ``pi(theta|c, o) = N(gain_o c + offset_o, std_o^2)`` as in
    :class:`~vslbook.bounds.svsl_toy.ToyMoE`.

    Attributes:
        gain, offset, std: the experts, shape ``(K,)``, ``std > 0``.
        amplitude, slope, shift: the energy features, shape ``(K, J)``.
    """

    gain: np.ndarray
    offset: np.ndarray
    std: np.ndarray
    amplitude: np.ndarray
    slope: np.ndarray
    shift: np.ndarray

    def __post_init__(self) -> None:
        arrays = {n: _array(n, getattr(self, n), 1) for n in ("gain", "offset", "std")}
        arrays.update({n: _array(n, getattr(self, n), 2) for n in ("amplitude", "slope", "shift")})
        k = arrays["gain"].shape[0]
        for n in ("offset", "std"):
            if arrays[n].shape != (k,):
                raise ValueError(f"{n} must have shape {(k,)} like gain, got {arrays[n].shape}")
        features = arrays["amplitude"].shape
        if features[0] != k:
            raise ValueError(f"amplitude must have shape (K={k}, J), got {features}")
        for n in ("slope", "shift"):
            if arrays[n].shape != features:
                raise ValueError(
                    f"{n} must have shape {features} like amplitude, got {arrays[n].shape}"
                )
        if np.any(arrays["std"] <= 0):
            raise ValueError(f"std must be positive, got {arrays['std']}")
        for n, a in arrays.items():
            a.setflags(write=False)
            object.__setattr__(self, n, a)

    @property
    def n_components(self) -> int:
        """Number of experts ``K``."""
        return int(self.gain.shape[0])

    @property
    def weights(self) -> np.ndarray:
        """The fixed uniform prior ``pi(o) = 1 / K`` (B.3.1)."""
        return np.full(self.n_components, 1.0 / self.n_components)

    def energy(self, c: np.ndarray) -> np.ndarray:
        """``phi_o(c)`` for every expert, shape ``(K, *c.shape)``."""
        c = np.asarray(c, dtype=np.float64)
        flat = c.reshape(-1)
        z = self.slope[:, :, None] * flat[None, None, :] + self.shift[:, :, None]
        phi = np.einsum("kj,kjn->kn", self.amplitude, np.tanh(z))
        return phi.reshape(self.n_components, *c.shape)

    def replace(self, **changes: np.ndarray) -> EnergyMoE:
        """A copy with some fields replaced (validated again)."""
        return replace(self, **changes)


def random_energy_moe(seed: int = 0, n_components: int = 3, n_features: int = 4) -> EnergyMoE:
    """A random :class:`EnergyMoE` with the experts of the Chapter 3 toy.

    The experts are those of :func:`~vslbook.bounds.svsl_toy.random_toy_moe` with the same
    seed; the energy features have amplitudes ``N(0, 0.8^2)``, slopes ``U(-4, 4)`` and shifts
    ``N(0, 1.5^2)`` (several smooth bumps and steps on the interval: steep enough to make the
    densities multimodal, smooth enough for 64 Gauss-Legendre nodes to integrate them).
    """
    k = check_count("n_components", n_components)
    j = check_count("n_features", n_features)
    base = random_toy_moe(seed, k)
    rng = seeded_rng(seed, 11)
    return EnergyMoE(
        gain=base.gain,
        offset=base.offset,
        std=base.std,
        amplitude=rng.normal(0.0, 0.8, (k, j)),
        slope=rng.uniform(-4.0, 4.0, (k, j)),
        shift=rng.normal(0.0, 1.5, (k, j)),
    )


def energy_fn(model: EnergyMoE, o: int) -> Callable[[float], float]:
    """``phi_o(c) = sum_j amplitude_oj tanh(slope_oj c + shift_oj)`` as a function of ``c``."""
    a, s, b = model.amplitude[o], model.slope[o], model.shift[o]
    return lambda c: float(a @ np.tanh(s * c + b))


def integrate_quad(fn: Callable[[float], float], low: float, high: float) -> float:
    """``int_low^high fn`` by adaptive Gauss-Kronrod quadrature to about 13 digits."""
    value, _ = quad(fn, low, high, epsabs=1e-14, epsrel=1e-13, limit=200)
    return float(value)


def ebm_log_normaliser(problem: ToyProblem, model: EnergyMoE) -> np.ndarray:
    """``log Z_o = log int exp(phi_o(c)) dc`` over the context interval (Eq. 4.6), ``(K,)``.

    Computed by adaptive quadrature, not on the Gauss-Legendre nodes of the toy.
    """
    out = np.empty(model.n_components)
    for o in range(model.n_components):
        phi = energy_fn(model, o)
        out[o] = math.log(
            integrate_quad(lambda c, phi=phi: math.exp(phi(c)), problem.low, problem.high)
        )
    return out


def ebm_context_entropy(
    problem: ToyProblem, model: EnergyMoE, log_z: np.ndarray | None = None
) -> np.ndarray:
    """``H[pi(c|o)] = log Z_o - E_pi(c|o)[phi_o(c)]`` (Eq. 4.6), by adaptive quadrature, ``(K,)``.

    Never evaluates ``pi log pi`` on the context grid, so it is an independent route to the
    entropy term of Eqs. 4.5 and B.1.
    """
    log_z = ebm_log_normaliser(problem, model) if log_z is None else np.asarray(log_z)
    out = np.empty(model.n_components)
    for o in range(model.n_components):
        phi, lz = energy_fn(model, o), float(log_z[o])
        mean_phi = integrate_quad(
            lambda c, phi=phi, lz=lz: phi(c) * math.exp(phi(c) - lz), problem.low, problem.high
        )
        out[o] = lz - mean_phi
    return out


def ebm_log_contexts(
    problem: ToyProblem, model: EnergyMoE, log_z: np.ndarray | None = None
) -> np.ndarray:
    """``log pi(c|o) = phi_o(c) - log Z_o`` at the context nodes, shape ``(K, n_c)``."""
    log_z = ebm_log_normaliser(problem, model) if log_z is None else log_z
    return model.energy(problem.contexts[0]) - np.asarray(log_z)[:, None]


def _grid_log_contexts(problem: ToyProblem, model: EnergyMoE) -> np.ndarray:
    """As :func:`ebm_log_contexts` with ``Z_o`` from the Gauss-Legendre nodes themselves."""
    c, w = problem.contexts
    phi = model.energy(c)
    return phi - logsumexp(phi + np.log(w)[None, :], axis=1, keepdims=True)


def ebm_responsibilities(problem: ToyProblem, model: EnergyMoE) -> tuple[np.ndarray, np.ndarray]:
    """Log responsibilities of ``model`` on the grid (the closed forms of B.1).

    Returns:
        ``(log pi(o|c, theta), log pi(o|c))`` of shapes ``(K, n_c, n_theta)`` and
        ``(K, n_c)``: ``pi(o|c) = pi(c|o) pi(o) / pi(c)`` and
        ``pi(o|c, theta) = pi(theta|c, o) pi(o|c) / pi(theta|c)``.
    """
    log_joint_c = np.log(model.weights)[:, None] + ebm_log_contexts(problem, model)
    log_gate = log_joint_c - logsumexp0(log_joint_c, keepdims=True)
    log_joint_t = log_gate[:, :, None] + log_experts(problem, model)
    return log_joint_t - logsumexp0(log_joint_t, keepdims=True), log_gate


def ebm_curriculum_objective(problem: ToyProblem, model: EnergyMoE) -> float:
    """Eq. 4.3 straight from the mixture densities.

    ``E_pi(c)[E_pi(theta|c)[R] + alpha H[pi(theta|c)]] - beta KL(pi(c) || p(c))`` with
    ``pi(c) = sum_o pi(c|o) / K`` and ``pi(theta|c)`` of Eq. 4.2 on the grid, the energies
    normalised on the Gauss-Legendre nodes; no responsibilities, no per-part entropies.
    """
    c_w, t_w = problem.contexts[1], problem.thetas[1]
    log_joint_c = np.log(model.weights)[:, None] + _grid_log_contexts(problem, model)
    log_pc = logsumexp0(log_joint_c)
    log_pt = logsumexp0((log_joint_c - log_pc)[:, :, None] + log_experts(problem, model))
    per_context = (np.exp(log_pt) * (problem.rewards - problem.alpha * log_pt)) @ t_w
    pc = np.exp(log_pc)
    kl = float(np.sum(c_w * pc * (log_pc - problem.log_p)))
    return float(np.sum(c_w * pc * per_context)) - problem.beta * kl


EnergyBoundFn = Callable[[ToyProblem, EnergyMoE, np.ndarray, np.ndarray], float]
"""``(problem, model, log_aux_theta (K, n_c, n_t), log_aux_context (K, n_c)) -> value``."""


def ebm_lower_bound(
    problem: ToyProblem, model: EnergyMoE, log_aux_theta: np.ndarray, log_aux_context: np.ndarray
) -> float:
    """Eq. B.1 with the responsibilities replaced by auxiliaries (the bound behind 4.4, 4.5).

    ``E_pi(o),pi(c|o)[E_pi(theta|c,o)[R + alpha log aux(o|c,theta)] + beta log p(c)
    + (beta - alpha) log aux(o|c)] + alpha E[H[pi(theta|c,o)]] + beta E_pi(o)[H[pi(c|o)]]
    + beta H[pi(o)]`` with ``pi(o) = 1/K`` (so ``beta H[pi(o)] = beta log K``), ``Z_o`` by
    adaptive quadrature and ``H[pi(c|o)]`` from :func:`ebm_context_entropy`. With the model's
    own responsibilities it is Eq. B.1 itself (= Eq. 4.3); otherwise it is Eq. 4.3 minus
    ``alpha E[KL_theta] + (beta - alpha) E[KL_c]``.
    """
    log_aux_theta, log_aux_context = check_aux(problem, model, log_aux_theta, log_aux_context)
    c_w = problem.contexts[1]
    a, b = problem.alpha, problem.beta
    log_z = ebm_log_normaliser(problem, model)
    ctx = np.exp(ebm_log_contexts(problem, model, log_z))
    per_context = (
        augmented_expert_rewards(problem, model, log_aux_theta)
        + b * problem.log_p
        + (b - a) * log_aux_context
    )
    per_expert = (
        (ctx * per_context) @ c_w
        + a * expert_entropy(model)
        + b * ebm_context_entropy(problem, model, log_z)
    )
    return float(np.mean(per_expert) + b * math.log(model.n_components))


def ebm_expected_responsibility_kls(
    problem: ToyProblem, model: EnergyMoE, log_aux_theta: np.ndarray, log_aux_context: np.ndarray
) -> tuple[float, float]:
    """``(E[KL(pi(o|c,theta) || aux(o|c,theta))], E_pi(c)[KL(pi(o|c) || aux(o|c))])``."""
    log_aux_theta, log_aux_context = check_aux(problem, model, log_aux_theta, log_aux_context)
    c_w, t_w = problem.contexts[1], problem.thetas[1]
    log_rt, log_rc = ebm_responsibilities(problem, model)
    log_joint_c = np.log(model.weights)[:, None] + ebm_log_contexts(problem, model)
    pc = np.exp(logsumexp0(log_joint_c))
    joint = np.exp(log_joint_c[:, :, None] + log_experts(problem, model))
    kl_theta = float(np.einsum("kct,kct,c,t->", joint, log_rt - log_aux_theta, c_w, t_w))
    kl_ctx = float(np.sum(c_w * pc * np.sum(np.exp(log_rc) * (log_rc - log_aux_context), 0)))
    return kl_theta, kl_ctx


def _component(model: EnergyMoE, o: int) -> int:
    k = model.n_components
    if isinstance(o, bool) or not isinstance(o, (int, np.integer)) or not 0 <= o < k:
        raise ValueError(f"expert index o must be an integer in [0, {k}), got {o!r}")
    return int(o)


def ebm_expert_objective(
    problem: ToyProblem, model: EnergyMoE, log_aux_theta: np.ndarray, o: int
) -> float:
    """Eq. 4.4 for expert ``o`` with the auxiliary ``aux(o|c, theta)``.

    ``E_pi(c|o),pi(theta|c,o)[R + alpha log aux(o|c,theta)] + alpha E_pi(c|o)[H[pi(theta|c,o)]]``.
    """
    o = _component(model, o)
    log_aux_theta, _ = check_aux(
        problem,
        model,
        log_aux_theta,
        np.full((model.n_components, problem.n_context), -math.log(model.n_components)),
    )
    ctx = np.exp(ebm_log_contexts(problem, model))[o]
    aug = augmented_expert_rewards(problem, model, log_aux_theta)[o]
    return float(np.sum(problem.contexts[1] * ctx * aug) + problem.alpha * expert_entropy(model)[o])


def ebm_context_objective(
    problem: ToyProblem,
    model: EnergyMoE,
    log_aux_theta: np.ndarray,
    log_aux_context: np.ndarray,
    o: int,
) -> float:
    """Eq. 4.5 for expert ``o`` with the auxiliaries ``aux(o|c, theta)``, ``aux(o|c)``.

    ``E_pi(c|o)[L_c(o,c) + (beta-alpha) log aux(o|c)] + beta H[pi(c|o)]`` with
    ``L_c(o, c) = E_pi(theta|c,o)[R + alpha log aux(o|c,theta)] + alpha H[pi(theta|c,o)]``;
    ``pi(c|o)`` is the energy-based density of Eq. 4.6.
    """
    o = _component(model, o)
    log_aux_theta, log_aux_context = check_aux(problem, model, log_aux_theta, log_aux_context)
    a, b = problem.alpha, problem.beta
    log_z = ebm_log_normaliser(problem, model)
    ctx = np.exp(ebm_log_contexts(problem, model, log_z))[o]
    l_c = augmented_expert_rewards(problem, model, log_aux_theta)[o] + a * expert_entropy(model)[o]
    expected = float(np.sum(problem.contexts[1] * ctx * (l_c + (b - a) * log_aux_context[o])))
    return expected + b * float(ebm_context_entropy(problem, model, log_z)[o])


# -------------------------------------------------------------- sample forms (4.6, 4.8)


def expert_context_values(
    problem: ToyProblem, model: EnergyMoE, contexts: np.ndarray, n_nodes: int = 128
) -> tuple[np.ndarray, np.ndarray]:
    """``L_c(o, c)`` of Eq. 4.5 and ``log pi(o|c)`` at arbitrary contexts, for every expert.

    The auxiliaries are the model's own responsibilities (the closed forms of B.1 with
    ``pi_old = pi``). ``log pi(o|c)`` is evaluated pointwise (``Z_o`` from
    :func:`ebm_log_normaliser`); ``L_c`` is computed on ``n_nodes`` Gauss-Legendre nodes (the
    trapezoid rule in ``theta``) and interpolated by the Legendre polynomial through them,
    which converges geometrically for the smooth energies of :class:`EnergyMoE`.

    Returns:
        ``(L_c, log_gate)``, both of shape ``(K, n)``.
    """
    c = _array("contexts", contexts, 1)
    if np.any(c < problem.low) or np.any(c > problem.high):
        raise ValueError(
            f"contexts must lie in [{problem.low}, {problem.high}], got [{c.min()}, {c.max()}]"
        )
    n = check_count("n_nodes", n_nodes, 8)
    nodes = replace(problem, n_context=n)
    log_rt, _ = ebm_responsibilities(nodes, model)
    l_nodes = (
        augmented_expert_rewards(nodes, model, log_rt)
        + problem.alpha * expert_entropy(model)[:, None]
    )  # (K, n)
    x, w = np.polynomial.legendre.leggauss(n)
    vander = np.polynomial.legendre.legvander(x, n - 1)  # (n, n)
    # Legendre coefficients of the interpolant, by the discrete orthogonality of the nodes
    coef = (vander.T @ (w[:, None] * l_nodes.T)) * (np.arange(n) + 0.5)[:, None]  # (n, K)
    u = 2.0 * (c - problem.low) / (problem.high - problem.low) - 1.0
    l_c = np.polynomial.legendre.legval(u, coef)  # (K, len(c))
    log_z = ebm_log_normaliser(problem, model)
    log_joint = np.log(model.weights)[:, None] + model.energy(c) - log_z[:, None]
    return l_c, log_joint - logsumexp0(log_joint, keepdims=True)


def sample_context_objective(
    log_probs: np.ndarray,
    l_c: np.ndarray,
    log_aux_context: np.ndarray,
    alpha: float,
    beta: float,
) -> float:
    """Eq. 4.8 for one expert: sums over ``N`` contexts ``c_i ~ p(c)``.

    ``sum_i pi(c_i|o) L_c(o, c_i) + sum_i pi(c_i|o) ((beta - alpha) log aux(o|c_i)
    - beta log pi(c_i|o))`` with the categorical ``pi(c_i|o) = softmax_i phi_o(c_i)``.

    Args:
        log_probs: ``log pi(c_i|o)``, shape ``(N,)``, normalised over the batch.
        l_c: ``L_c(o, c_i)``, shape ``(N,)``.
        log_aux_context: ``log aux(o|c_i)``, shape ``(N,)``.
        alpha, beta: the temperatures of Eq. 4.3.
    """
    log_probs = _array("log_probs", log_probs, 1)
    l_c, log_aux_context = _array("l_c", l_c, 1), _array("log_aux_context", log_aux_context, 1)
    if l_c.shape != log_probs.shape or log_aux_context.shape != log_probs.shape:
        raise ValueError(
            f"l_c and log_aux_context must have shape {log_probs.shape} like log_probs, got "
            f"{l_c.shape} and {log_aux_context.shape}"
        )
    if abs(logsumexp(log_probs)) > 1e-8:
        raise ValueError("log_probs must be normalised over the batch (logsumexp = 0)")
    a = check_finite("alpha", alpha, 0.0, strict=True)
    b = check_finite("beta", beta, 0.0)
    q = np.exp(log_probs)
    return float(q @ l_c + q @ ((b - a) * log_aux_context - b * log_probs))


def mc_normaliser(phi: np.ndarray, volume: float) -> float:
    """``Z ~ (V / N) sum_i exp(phi(c_i))`` for ``c_i ~ U(box)`` of volume ``V`` (Eq. 4.6).

    The thesis writes ``Z ~ sum_i exp(phi(c_i))``: the normaliser of the categorical over the
    batch, which is ``N / V`` times this estimate of the integral; the factor cancels in
    ``softmax_i phi(c_i)``, and it is what turns into ``beta log(N / V)`` in Eq. 4.8.
    """
    phi = _array("phi", phi, 1)
    v = check_finite("volume", volume, 0.0, strict=True)
    return float(v * np.exp(logsumexp(phi) - math.log(phi.size)))


def self_normalised_expectation(phi: np.ndarray, values: np.ndarray) -> float:
    """``sum_i softmax_i(phi(c_i)) f(c_i)``: ``E_pi(c)[f]`` under the batch categorical."""
    phi, values = _array("phi", phi, 1), _array("values", values, 1)
    if values.shape != phi.shape:
        raise ValueError(f"values must have shape {phi.shape} like phi, got {values.shape}")
    return float(softmax(phi) @ values)


def uniform_prior_gating(log_context_probs: np.ndarray) -> np.ndarray:
    """``pi(o|c) = pi(c|o) / sum_o' pi(c|o')`` (Alg. 3, B.3.1 with uniform ``pi(o)``).

    Args:
        log_context_probs: ``log pi(c|o)``, shape ``(K, M)`` (expert, context).

    Returns:
        The gating, shape ``(K, M)``, summing to one over the experts.
    """
    lp = _array("log_context_probs", log_context_probs, 2)
    return softmax(lp, axis=0)

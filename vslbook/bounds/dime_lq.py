"""The linear-quadratic problem behind the checks of Section 5.4.2 (DIME).

A one-dimensional state and action, linear dynamics and a quadratic reward, with diffusion
policies whose chains are linear-Gaussian (Section 5.4.1): every quantity of Propositions
5.4.1-5.4.3 (the Bellman backup with the entropy lower bound, the joint KL of the
improvement step, the objective) has a closed form or a Gauss-Hermite quadrature here.
Used by :func:`vslbook.bounds.dime_policy_iteration.check_diffusion_policy_iteration`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cache

import numpy as np
from scipy.optimize import minimize_scalar

from vslbook.bounds.dime_linear_chain import gaussian_kl_np, generative_joint, noising_joint


def lq_features(s: np.ndarray | float, a: np.ndarray | float) -> np.ndarray:
    """The basis ``(s^2, s a, a^2, s, a, 1)`` of the quadratic Q-functions, shape ``(..., 6)``."""
    s, a = np.broadcast_arrays(np.asarray(s, dtype=float), np.asarray(a, dtype=float))
    return np.stack([s * s, s * a, a * a, s, a, np.ones_like(s)], -1)


def lq_quadratic(coef: np.ndarray, s: np.ndarray | float) -> np.ndarray:
    """``coef[0] s^2 + coef[1] s + coef[2]``."""
    s = np.asarray(s, dtype=float)
    return coef[0] * s * s + coef[1] * s + coef[2]


@dataclass(frozen=True)
class LinearQuadratic:
    """``s' = A s + B a + w`` with ``w ~ N(0, W)``, ``r(s, a) = -(k_s (s - goal)^2 + k_a a^2) / 2``.

    ``alpha`` weighs the entropy bound, ``gamma`` discounts, and the start state is drawn from
    ``N(start_mean, start_var)``.
    """

    A: float
    B: float
    W: float
    k_s: float
    k_a: float
    goal: float
    gamma: float
    alpha: float
    start_mean: float
    start_var: float

    @property
    def reward(self) -> np.ndarray:
        """``r`` in the basis of :func:`lq_features`."""
        k_s, g = self.k_s, self.goal
        return np.array([-k_s / 2, 0.0, -self.k_a / 2, k_s * g, 0.0, -k_s * g * g / 2])


@dataclass(frozen=True)
class Marginal:
    """A policy of the family as the evaluation sees it, at every state ``s``.

    ``pi_0(a|s) = N(mean_c + mean_g s, var)`` and ``ℓ(s) = bound @ (s^2, s, 1)``.
    """

    mean_c: float
    mean_g: float
    var: float
    bound: np.ndarray

    @property
    def entropy(self) -> float:
        """``H(pi_0(.|s))``, the same at every state."""
        return 0.5 * math.log(2 * math.pi * math.e * self.var)


@dataclass(frozen=True)
class ChainFamily:
    """The linear-Gaussian diffusion policies ``Π̃`` of the check.

    ``theta = (slope, c_1..c_N, g_1..g_N)``; step ``k`` (sampling order) uses the score
    ``f_k(x, s) = slope x + c_k + g_k s`` in the generative kernel of Eq. 5.12,
    ``X_{k+1} | X_k ~ N(X_k + eta_k (-X_k / sigma0^2 + f_k(X_k, s)), 2 eta_k)``, from the prior
    ``X_0 ~ N(0, sigma0^2)``; the noising kernels of Eq. 5.13 are DIME's fixed OU steps.
    """

    eta: np.ndarray
    sigma0: float
    _cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    @property
    def n(self) -> int:
        return self.eta.size

    def split(self, theta: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        """``(slope, c, g)``."""
        return float(theta[0]), theta[1 : self.n + 1], theta[self.n + 1 :]

    def offsets(self, theta: np.ndarray, states: np.ndarray) -> np.ndarray:
        """The per-step offsets ``c_k + g_k s`` at each state, shape ``(len(states), N)``."""
        _, c, g = self.split(theta)
        return c[None] + np.asarray(states, dtype=float)[:, None] * g[None]

    def maps(self, slope: float) -> tuple[np.ndarray, np.ndarray]:
        """``(G, cov)``: the generative joint has mean ``G @ offsets`` and covariance ``cov``."""
        return self._slope_terms(slope)[:2]

    def _slope_terms(self, slope: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """``(G, cov, R G, const)``: what depends on the slope alone (cached; the optimisers'
        finite differences move one coordinate at a time, mostly not the slope).

        ``R`` maps the joint to the noising residuals ``u_k = X_k - (1 - eta_k / sigma0^2)
        X_{k+1}`` and ``const = H(p_N) + sum_k (1/2 - Var[u_k] / (4 eta_k))``.
        """
        key = float(slope)
        if key not in self._cache:
            n, eta = self.n, self.eta
            inv = np.linalg.inv(np.eye(n + 1) - np.diag(1 + eta * (key - self.sigma0**-2), -1))
            scaled = inv * np.r_[self.sigma0, np.sqrt(2 * eta)][None]
            G, cov = inv[:, 1:] * eta[None], scaled @ scaled.T
            rows = np.eye(n, n + 1) - np.diag(1 - eta / self.sigma0**2, 1)[:n]
            var_u = np.einsum("ki,ij,kj->k", rows, cov, rows)
            prior = 0.5 * math.log(2 * math.pi * math.e * self.sigma0**2)
            const = prior + float(np.sum(0.5 - var_u / (4 * eta)))
            self._cache[key] = (G, cov, rows @ G, const)
        return self._cache[key]

    def marginal(self, theta: np.ndarray) -> Marginal:
        """The action marginal and ``ℓ(s)`` of Eq. 5.15 from the expected log kernels.

        ``ℓ = H(p_N) + sum_k (1/2 - E[u_k^2] / (4 eta_k))`` with the noising residual
        ``u_k = X_k - (1 - eta_k / sigma0^2) X_{k+1}`` (as :func:`linear_gaussian_chain`); the
        means of ``u_k`` are affine in ``s``, so ``ℓ`` is quadratic in ``s``.
        """
        slope, c, g = self.split(theta)
        G, cov, residual, const = self._slope_terms(slope)
        u_c, u_g = residual @ c, residual @ g
        w = 1 / (4 * self.eta)
        bound = np.array([-w @ u_g**2, -2 * w @ (u_c * u_g), const - w @ u_c**2])
        return Marginal(float(G[-1] @ c), float(G[-1] @ g), float(cov[-1, -1]), bound)


def evaluate_policy(
    problem: LinearQuadratic, pi: Marginal, bonus: np.ndarray
) -> tuple[np.ndarray, np.ndarray] | None:
    """Closed-form ``V^pi`` (coefficients of ``(s^2, s, 1)``) and ``Q^pi`` (:func:`lq_features`).

    Per-state bonus ``alpha * bonus @ (s^2, s, 1)`` (``ℓ`` for Eqs. 5.16-5.17). ``None`` when
    the closed loop does not contract under the discount (``gamma F^2 >= 1``): ``V = -inf``.
    """
    p = problem
    gain, shift, spread = p.A + p.B * pi.mean_g, p.B * pi.mean_c, p.B**2 * pi.var + p.W
    if not p.gamma * gain**2 < 1:
        return None
    # b(s) = E_pi[r(s, a)] + alpha bonus(s), with E[a^2] = (mean_c + mean_g s)^2 + var
    b = (
        np.array([-p.k_s / 2, p.k_s * p.goal, -p.k_s * p.goal**2 / 2])
        - p.k_a / 2 * np.array([pi.mean_g**2, 2 * pi.mean_c * pi.mean_g, pi.mean_c**2 + pi.var])
        + p.alpha * np.asarray(bonus, dtype=float)
    )
    # V(s) = b(s) + gamma E[V(s')], s' | s ~ N(gain s + shift, spread), matched per power of s
    v2 = b[0] / (1 - p.gamma * gain**2)
    v1 = (b[1] + 2 * p.gamma * v2 * gain * shift) / (1 - p.gamma * gain)
    v0 = (b[2] + p.gamma * (v2 * (shift**2 + spread) + v1 * shift)) / (1 - p.gamma)
    A, B = p.A, p.B
    q = p.reward + p.gamma * np.array(
        [v2 * A * A, 2 * v2 * A * B, v2 * B * B, v1 * A, v1 * B, v2 * p.W + v0]
    )
    return np.array([v2, v1, v0]), q


def lq_objective(problem: LinearQuadratic, value: np.ndarray | None) -> float:
    """``E_{s_0 ~ rho_0}[V(s_0)]`` (Eq. 5.16 from the start distribution); ``-inf`` if unstable."""
    if value is None:
        return -math.inf
    return float(lq_quadratic(value, problem.start_mean) + value[0] * problem.start_var)


@cache
def _hermite(n_nodes: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Hermite nodes and weights for ``E[h(x)]``, ``x ~ N(0, 1)``."""
    x, w = np.polynomial.hermite_e.hermegauss(n_nodes)
    return x, w / w.sum()


def lq_backup(
    problem: LinearQuadratic,
    pi: Marginal,
    q: Callable[[np.ndarray, np.ndarray], np.ndarray],
    s: np.ndarray,
    a: np.ndarray,
    n_nodes: int,
    entropy_sign: float = 1.0,
) -> np.ndarray:
    """``(T Q)(s, a) = r + gamma E[Q(s', a') + entropy_sign alpha ℓ(s')]`` (Eq. 5.21).

    The expectation over ``s' = A s + B a + w`` and ``a' ~ pi_0(.|s')`` by a product
    Gauss-Hermite rule with ``n_nodes`` nodes per variable (exact for polynomials of degree
    ``< 2 n_nodes``), for any vectorised ``q``.
    """
    p = problem
    x, w = _hermite(n_nodes)
    s, a = np.broadcast_arrays(np.asarray(s, dtype=float), np.asarray(a, dtype=float))
    s_next = (p.A * s + p.B * a)[..., None] + math.sqrt(p.W) * x
    a_next = (pi.mean_c + pi.mean_g * s_next)[..., None] + math.sqrt(pi.var) * x
    inner = q(s_next[..., None], a_next) @ w + entropy_sign * p.alpha * lq_quadratic(
        pi.bound, s_next
    )
    return lq_features(s, a) @ p.reward + p.gamma * (inner @ w)


@dataclass(frozen=True)
class Target:
    """The noising joint of Eq. 5.13 started at ``exp(Q(s, .) / alpha) / Z(s)`` (Eq. 5.23).

    For ``Q = q @ features`` with ``q[2] < 0`` the start is ``N(mean_c + mean_g s, var)``;
    with zero noising drift the joint's mean is ``(mean_c + mean_g s) * unit`` and its
    covariance ``cov`` does not depend on ``s``.
    """

    mean_c: float
    mean_g: float
    var: float
    unit: np.ndarray
    cov: np.ndarray

    @classmethod
    def of(cls, q: np.ndarray, alpha: float, eta: np.ndarray, sigma0: float) -> Target | None:
        if not q[2] < 0:
            return None  # exp(Q / alpha) is not normalisable in a
        var = -alpha / (2 * q[2])
        unit, cov = noising_joint(eta, sigma0, 0.0, 0.0, 1.0, var)
        return cls(-q[4] / (2 * q[2]), -q[1] / (2 * q[2]), var, unit, cov)

    def means(self, states: np.ndarray) -> np.ndarray:
        """Joint means at each state, ``(len(states), N+1)``."""
        return (self.mean_c + self.mean_g * np.asarray(states, dtype=float))[:, None] * self.unit


def joint_kls(
    family: ChainFamily, theta: np.ndarray, target: Target, states: np.ndarray
) -> np.ndarray:
    """``KL(pi~_{0:N}(.|s) || ->pi_{0:N}(.|s))`` of Eq. 5.22 at each state (Section 5.4.1's joints).

    The generative joints come from :func:`~vslbook.bounds.dime_linear_chain.generative_joint`
    and the divergence from :func:`vslbook.dists.gaussian_kl`, not from :meth:`ChainFamily.maps`.
    """
    slope = family.split(theta)[0]
    joints = [
        generative_joint(family.eta, family.sigma0, slope, off)
        for off in family.offsets(theta, states)
    ]
    mean = np.stack([m for m, _ in joints])
    cov = np.stack([c for _, c in joints])
    return gaussian_kl_np(
        mean, cov, target.means(states), np.repeat(target.cov[None], len(joints), 0)
    )


def improve_exact(
    family: ChainFamily, target: Target, states: np.ndarray, theta_old: np.ndarray
) -> np.ndarray:
    """Minimise ``sum_s KL(pi~^theta_{0:N}(.|s) || ->pi_{0:N}(.|s))`` over ``theta`` (Eq. 5.22).

    For a fixed slope the KL is quadratic in the offsets (they move only the generative
    means), so they are solved for by weighted least squares; the slope, which sets the
    covariance, by :func:`scipy.optimize.minimize_scalar` on the profiled KL.
    """
    n, states = family.n, np.asarray(states, dtype=float)
    chol = np.linalg.cholesky(target.cov)
    log_det_q = 2 * np.log(np.diag(chol)).sum()
    prec = np.linalg.inv(target.cov)
    whiten = np.linalg.cholesky(prec).T  # ||whiten x||^2 = x^T prec x
    goal = (whiten @ target.means(states).T).T.ravel()

    def profile(slope: float) -> tuple[float, np.ndarray]:
        G, cov = family.maps(slope)
        wg = whiten @ G
        design = np.concatenate([np.hstack([wg, s * wg]) for s in states])
        offsets, *_ = np.linalg.lstsq(design, goal, rcond=None)
        residual = design @ offsets - goal
        log_det_p = np.linalg.slogdet(cov)[1]
        cov_part = np.trace(prec @ cov) - (n + 1) + log_det_q - log_det_p
        return 0.5 * (states.size * cov_part + residual @ residual), offsets

    slope0 = float(theta_old[0])
    best = minimize_scalar(lambda x: profile(x)[0], bracket=(slope0 - 0.5, slope0 + 0.5), tol=1e-12)
    return np.r_[best.x, profile(best.x)[1]]


def expected_q(q: np.ndarray, pi: Marginal, states: np.ndarray) -> np.ndarray:
    """``E_{a ~ pi_0(.|s)}[Q(s, a)]`` at each state."""
    s = np.asarray(states, dtype=float)
    m = pi.mean_c + pi.mean_g * s
    moments = np.stack([s * s, s * m, m * m + pi.var, s, m, np.ones_like(s)], -1)
    return moments @ q


def log_partition(q: np.ndarray, alpha: float, states: np.ndarray) -> np.ndarray:
    """``log Z(s) = log int exp(Q(s, a) / alpha) da`` (a Gaussian integral, ``q[2] < 0``)."""
    s = np.asarray(states, dtype=float)
    quad = q[2] / alpha
    lin = (q[1] * s + q[4]) / alpha
    const = (q[0] * s * s + q[3] * s + q[5]) / alpha
    return 0.5 * np.log(math.pi / -quad) + const - lin**2 / (4 * quad)


def lq_problem(rng: np.random.Generator, gamma: float, alpha: float) -> LinearQuadratic:
    """A random :class:`LinearQuadratic` problem with discount ``gamma`` and entropy weight
    ``alpha``, the start state drawn from ``N(0, 1)``."""
    return LinearQuadratic(
        A=rng.uniform(0.6, 0.95),
        B=rng.uniform(0.5, 1.0),
        W=rng.uniform(0.1, 0.4),
        k_s=rng.uniform(0.5, 1.5),
        k_a=rng.uniform(0.2, 0.6),
        goal=rng.normal(),
        gamma=gamma,
        alpha=alpha,
        start_mean=0.0,
        start_var=1.0,
    )

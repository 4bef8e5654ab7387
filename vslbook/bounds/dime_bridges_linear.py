"""Closed forms for general bridges with affine drifts (Section 5.6, Eqs. 5.29-5.38).

When ``f``, ``u`` and ``v`` are affine in the action, every kernel of Eqs. 5.35-5.36 is
linear-Gaussian, both joints of Eqs. 5.33-5.34 are Gaussians over ``(a^0, ..., a^N)`` and the
quantities of Section 5.6 have closed forms (:func:`linear_bridge_closed_form`): the joint KL of
Eq. 5.37 against a Gaussian target (Eq. 5.38 with a quadratic ``Q``), the entropy bound ``ℓ``
from the expected log-kernels, the entropy of the action marginal and the gap. The moments of
the continuous-time processes of Eqs. 5.29-5.30 come from their moment ODEs
(:func:`linear_sde_moments`), against which the Euler-Maruyama chains are checked.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp

from vslbook.bounds.dime_bridges import GeneralBridge
from vslbook.bounds.toy_numerics import to_numpy, to_tensor
from vslbook.dists import gaussian_kl

__all__ = [
    "LinearBridge",
    "affine_map",
    "linear_bridge_closed_form",
    "linear_sde_moments",
]


def affine_map(fn: Callable[[np.ndarray], np.ndarray], dim: int) -> tuple[np.ndarray, np.ndarray]:
    """``(A, b)`` with ``fn(a) = a A^T + b`` for a batch ``a`` ``(B, dim)``, read off at the
    origin and the unit vectors; raises ``ValueError`` if ``fn`` is not affine."""
    eye = np.eye(dim)
    b = np.asarray(fn(np.zeros((1, dim))), dtype=float)[0]
    A = (np.asarray(fn(eye), dtype=float) - b).T
    probe = np.random.default_rng(0).normal(size=(3, dim)) * 1.7
    expected = probe @ A.T + b
    got = np.asarray(fn(probe), dtype=float)
    if not np.allclose(got, expected, rtol=1e-9, atol=1e-9 * max(1.0, np.abs(expected).max())):
        raise ValueError("the bridge's drifts are not affine in the action; no closed form")
    return A, b


@dataclass(frozen=True)
class LinearBridge:
    """Closed forms of an affine :class:`~vslbook.bounds.dime_bridges.GeneralBridge`.

    Joints are over ``z = (a^0, ..., a^N)``, each block ``d`` wide (``traj[n] = a^n`` order).

    Attributes:
        backward_mean, backward_cov: ``pi~_{0:N}`` of Eq. 5.34.
        forward_mean, forward_cov: ``->pi_{0:N}`` of Eq. 5.33 started at the target.
        forward_marginals: ``(mean (N+1, d), cov (N+1, d, d))`` of ``->pi_n`` from the target.
        marginal_mean, marginal_cov: the action marginal ``pi~_0``.
        entropy: ``H(pi~_0)``.
        bound: ``ℓ`` of Eq. 5.15 with the bridge's kernels, from the expected log-kernels
            ``H(pi~_{0:N}) + sum_n E[log ->pi_{n+1|n}]`` (no KL formula involved).
        kl: Eq. 5.37, ``KL(pi~_{0:N} || ->pi_{0:N})`` with ``->pi_0`` the target (Eq. 5.38).
        gap_kl: ``KL(pi~_{0:N} || pi~_0 ->pi_{1:N|0})``, the forward chain started at the
            action marginal (Appendix C.1: equals ``H - ℓ``).
        marginal_kl: ``KL(pi~_0 || ->pi_0)``.
        expected_q: ``E_{pi~_0}[Q]`` for ``Q(a) = -(a - mu)^T Sigma^{-1} (a - mu) / 2``.
        log_z: ``log Z = log det(2 pi Sigma) / 2`` of that ``Q``.
    """

    backward_mean: np.ndarray
    backward_cov: np.ndarray
    forward_mean: np.ndarray
    forward_cov: np.ndarray
    forward_marginals: tuple[np.ndarray, np.ndarray]
    marginal_mean: np.ndarray
    marginal_cov: np.ndarray
    entropy: float
    bound: float
    kl: float
    gap_kl: float
    marginal_kl: float
    expected_q: float
    log_z: float


def _joint(
    links: dict[tuple[int, int], np.ndarray], offsets: list[np.ndarray], chols: list[np.ndarray]
) -> tuple[np.ndarray, np.ndarray]:
    """Mean and covariance of ``z_i = sum_j L_ij z_j + o_i + C_i e_i`` (an acyclic chain)."""
    d = offsets[0].size
    size = len(offsets) * d
    coupling, noise = np.zeros((size, size)), np.zeros((size, size))
    for (i, j), block in links.items():
        coupling[i * d : (i + 1) * d, j * d : (j + 1) * d] = block
    for i, chol in enumerate(chols):
        noise[i * d : (i + 1) * d, i * d : (i + 1) * d] = chol
    solve = np.linalg.inv(np.eye(size) - coupling)
    s = solve @ noise
    return solve @ np.concatenate(offsets), s @ s.T


def _kl(mean_p, cov_p, mean_q, cov_q) -> float:
    return float(
        to_numpy(
            gaussian_kl(to_tensor(mean_p), to_tensor(cov_p), to_tensor(mean_q), to_tensor(cov_q))
        )
    )


def _entropy(cov: np.ndarray) -> float:
    return 0.5 * float(np.linalg.slogdet(2 * math.pi * math.e * cov)[1])


def linear_bridge_closed_form(
    bridge: GeneralBridge, target_mean: np.ndarray, target_cov: np.ndarray
) -> LinearBridge:
    """Closed forms of Section 5.6 for an affine bridge and the target ``N(mu, Sigma)``.

    The target is the Boltzmann policy of ``Q(a) = -(a - mu)^T Sigma^{-1} (a - mu) / 2``
    (Eq. 5.38). Each kernel mean of Eqs. 5.35-5.36 is read off as an affine map
    (:func:`affine_map`), the joints follow from the chain structure, and the KLs use
    :func:`vslbook.dists.gaussian_kl`.
    """
    d, n_steps = bridge.dim, bridge.n_steps
    mu = np.asarray(target_mean, dtype=float).reshape(d)
    sigma = np.asarray(target_cov, dtype=float).reshape(d, d)
    fwd = [affine_map(lambda a, n=n: bridge.forward_mean(a, n), d) for n in range(n_steps)]
    bwd = [affine_map(lambda a, n=n: bridge.backward_mean(a, n), d) for n in range(1, n_steps + 1)]
    std = [np.diag(np.sqrt(bridge.kernel_var(n))) for n in range(1, n_steps + 1)]

    # backward: a^N ~ N(m_N, P_N), a^{n-1} = B_n a^n + b_n + noise (Eqs. 5.34, 5.36)
    b_links = {(n - 1, n): bwd[n - 1][0] for n in range(1, n_steps + 1)}
    b_offsets = [bwd[n][1] for n in range(n_steps)] + [bridge.prior_mean]
    b_chols = [*std, np.diag(np.sqrt(bridge.prior_var))]
    b_mean, b_cov = _joint(b_links, b_offsets, b_chols)

    def forward_joint(mean0: np.ndarray, cov0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        links = {(n + 1, n): fwd[n][0] for n in range(n_steps)}
        offsets = [mean0] + [fwd[n][1] for n in range(n_steps)]
        return _joint(links, offsets, [np.linalg.cholesky(cov0), *std])

    f_mean, f_cov = forward_joint(mu, sigma)
    m0, p0 = b_mean[:d], b_cov[:d, :d]
    g_mean, g_cov = forward_joint(m0, p0)

    # ℓ = H(pi~_{0:N}) + sum_n E[log ->pi_{n+1|n}(a^{n+1} | a^n)] under the backward joint
    bound = _entropy(b_cov)
    size = (n_steps + 1) * d
    for n in range(n_steps):
        rows = np.zeros((d, size))
        rows[:, (n + 1) * d : (n + 2) * d] = np.eye(d)
        rows[:, n * d : (n + 1) * d] = -fwd[n][0]
        r_mean = rows @ b_mean - fwd[n][1]
        r_sq = np.diag(rows @ b_cov @ rows.T) + r_mean**2
        var = bridge.kernel_var(n + 1)
        bound += float(np.sum(-0.5 * np.log(2 * math.pi * var) - r_sq / (2 * var)))

    prec = np.linalg.inv(sigma)
    diff = m0 - mu
    marg_mean = f_mean.reshape(n_steps + 1, d)
    marg_cov = np.stack(
        [f_cov[n * d : (n + 1) * d, n * d : (n + 1) * d] for n in range(n_steps + 1)]
    )
    return LinearBridge(
        backward_mean=b_mean,
        backward_cov=b_cov,
        forward_mean=f_mean,
        forward_cov=f_cov,
        forward_marginals=(marg_mean, marg_cov),
        marginal_mean=m0,
        marginal_cov=p0,
        entropy=_entropy(p0),
        bound=bound,
        kl=_kl(b_mean, b_cov, f_mean, f_cov),
        gap_kl=_kl(b_mean, b_cov, g_mean, g_cov),
        marginal_kl=_kl(m0, p0, mu, sigma),
        expected_q=-0.5 * float(np.trace(prec @ p0) + diff @ prec @ diff),
        log_z=0.5 * float(np.linalg.slogdet(2 * math.pi * sigma)[1]),
    )


def linear_sde_moments(
    drift: Callable[[float], tuple[np.ndarray, np.ndarray]],
    diffusion: np.ndarray,
    mean0: np.ndarray,
    cov0: np.ndarray,
    duration: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Mean and covariance at ``duration`` of ``dx = (A(t) x + b(t)) dt + sqrt(2 beta) dB``.

    Solves the moment ODEs ``m' = A m + b``, ``P' = A P + P A^T + 2 diag(beta)`` with an
    adaptive Runge-Kutta method (tolerance ``1e-11``): the continuous-time side of
    Eqs. 5.29-5.30 for affine drifts. ``drift(t)`` returns ``(A(t), b(t))``. For the backward
    process of Eq. 5.30 pass the drift in reversed time ``tau = T - t``,
    ``-(f - beta v)(x, T - tau)``.
    """
    d = np.asarray(mean0).size
    noise = 2 * np.diag(np.broadcast_to(np.asarray(diffusion, dtype=float), (d,)))

    def rhs(t: float, y: np.ndarray) -> np.ndarray:
        A, b = drift(t)
        m, P = y[:d], y[d:].reshape(d, d)
        return np.concatenate([A @ m + b, (A @ P + P @ A.T + noise).ravel()])

    y0 = np.concatenate([np.asarray(mean0, dtype=float), np.asarray(cov0, dtype=float).ravel()])
    sol = solve_ivp(rhs, (0.0, duration), y0, method="DOP853", rtol=1e-11, atol=1e-12)
    return sol.y[:d, -1], sol.y[d:, -1].reshape(d, d)

"""The linear-Gaussian diffusion chain of Section 5.4.1's checks (DIME), in closed form.

A :class:`~vslbook.srl.DiffusionPolicy` with an affine score network
(:func:`linear_gaussian_policy`) has a linear-Gaussian generative chain, and so does its
noising chain: their joint means and covariances, marginal entropies and KL
(:func:`linear_gaussian_chain`) are exact. The checks of the entropy lower bound
(:mod:`vslbook.bounds.dime_entropy`) and of policy iteration
(:mod:`vslbook.bounds.dime_policy_iteration`) are built on them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor, nn

from vslbook.bounds.toy_numerics import (
    check_count,
    check_positive,
    linear_gaussian_joint,
    to_numpy,
    to_tensor,
)
from vslbook.dists import gaussian_kl
from vslbook.srl.diffusion_policy import DiffusionPolicy, DiffusionPolicyConfig, cosine_schedule

__all__ = [
    "AffineScore",
    "LinearGaussianChain",
    "gaussian_entropy",
    "gaussian_kl_np",
    "generative_joint",
    "linear_gaussian_chain",
    "linear_gaussian_policy",
    "noising_joint",
]


class AffineScore(nn.Module):
    """A score network forced to the affine map ``f(x, n, s) = slope * x + offset``.

    Wraps a :class:`~vslbook.srl.ScoreNetwork` whose output layer has zero weights and bias
    ``offset``, so the network itself returns exactly ``offset`` for every input, and adds the
    linear drift ``slope * x``. With it the generative kernels of the diffusion policy (Eq. 5.12)
    are linear-Gaussian and the whole chain is a joint Gaussian.
    """

    def __init__(self, network: nn.Module, slope: Tensor) -> None:
        super().__init__()
        self.network = network
        self.register_buffer("slope", slope)

    def embed_steps(self, steps: Tensor) -> Tensor:
        """The wrapped network's step embedding."""
        return self.network.embed_steps(steps)

    def forward(self, x: Tensor, step_embedding: Tensor, obs: Tensor) -> Tensor:
        """``network(x, n, s) + slope * x`` (the network contributes its output bias)."""
        return self.network(x, step_embedding, obs) + self.slope * x


def linear_gaussian_policy(
    n_steps: int,
    sigma0: float,
    total_time: float,
    noise_var: Sequence[float] | np.ndarray,
    slope: Sequence[float] | np.ndarray,
    offset: Sequence[float] | np.ndarray,
    seed: int = 0,
) -> DiffusionPolicy:
    """A float64 :class:`~vslbook.srl.DiffusionPolicy` whose score network is affine.

    No tanh squashing, per-dimension noise scales ``sigma_d^2 = noise_var`` and
    ``f_theta(x) = slope * x + offset`` (see :class:`AffineScore`), so the generative chain

        x_N ~ N(0, sigma0^2),  x_{n-1} = x_n + eta_n (-x_n / sigma0^2 + slope x_n + offset)
                                          + sqrt(2 eta_n) eps_n

    is linear-Gaussian, with the step sizes of DIME's cosine schedule scaled so that
    ``sum_n dt_n = total_time``. ``seed`` seeds the (irrelevant) network initialisation without
    touching torch's global random state.
    """
    noise_var = np.asarray(noise_var, dtype=float)
    slope, offset = np.asarray(slope, dtype=float), np.asarray(offset, dtype=float)
    if noise_var.ndim != 1 or slope.shape != noise_var.shape or offset.shape != noise_var.shape:
        raise ValueError(
            f"noise_var, slope and offset must be 1-D of equal length, got shapes "
            f"{noise_var.shape}, {slope.shape}, {offset.shape}"
        )
    if not np.all(noise_var > 0):
        raise ValueError(f"noise_var must be positive, got {noise_var}")
    n_steps = check_count("n_steps", n_steps)
    # dt scale chosen so that the unnormalised cosine schedule sums to ``total_time``
    dt = check_positive("total_time", total_time) / float(cosine_schedule(n_steps).sum())
    config = DiffusionPolicyConfig(
        n_steps=n_steps,
        sigma0=check_positive("sigma0", sigma0),
        dt=dt,
        learn_beta=False,
        learn_dt=False,
        n_frequencies=8,
        hidden=16,
        n_layers=1,
        squash=False,
    )
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        policy = DiffusionPolicy(obs_dim=1, act_dim=noise_var.size, config=config).double()
    with torch.no_grad():
        # noise_var = 1 / softplus(raw)  <=>  raw = log(expm1(1 / noise_var))
        policy.raw_noise.copy_(to_tensor(np.log(np.expm1(1.0 / noise_var))))
        nn.init.zeros_(policy.score_net.out.weight)
        policy.score_net.out.bias.copy_(to_tensor(offset))
    policy.score_net = AffineScore(policy.score_net, to_tensor(slope))
    return policy


@dataclass(frozen=True)
class LinearGaussianChain:
    """Closed forms of a linear-Gaussian diffusion chain, one entry per action dimension.

    Variables are in sampling order, ``X_k = x^{N-k}`` for ``k = 0..N`` (``X_0 = x^N`` the
    prior draw, ``X_N = x^0`` the action); step ``k`` maps ``X_k`` to ``X_{k+1}``.

    Attributes:
        gen_mean, gen_cov: the generative joint ``pi_{0:N}`` of Eq. 5.14, shapes ``(d, N+1)``
            and ``(d, N+1, N+1)``.
        noising_mean, noising_cov: the noising joint of Eq. 5.13 started at the generative
            marginal, ``pi_0(x^0) prod_n ->pi_{n|n-1}(x^n|x^{n-1})``.
        marginal_mean, marginal_var: the generative marginal of ``x^0``, shape ``(d,)``.
        entropy: ``H(pi_0)`` per dimension, ``(d,)``.
        step_contributions: ``(d, N+1)``; column 0 is ``H(pi_N) = -E[log p_N(x^N)]`` and
            column ``k >= 1`` is ``E[log ->pi(X_{k-1}|X_k) - log pi(X_k|X_{k-1})]`` (noising
            minus generative log kernel of step ``k-1``). They sum to ``bound``.
        bound: ``ℓ`` of Eq. 5.15 per dimension, from the expected log kernels.
        kl: ``KL(generative joint || noising joint)`` per dimension (Eqs. 5.18, C.2).
    """

    gen_mean: np.ndarray
    gen_cov: np.ndarray
    noising_mean: np.ndarray
    noising_cov: np.ndarray
    marginal_mean: np.ndarray
    marginal_var: np.ndarray
    entropy: np.ndarray
    step_contributions: np.ndarray
    bound: np.ndarray
    kl: np.ndarray


def gaussian_entropy(var: np.ndarray) -> float:
    """Entropy ``sum_d 1/2 log(2 pi e var_d)`` of a Gaussian with diagonal covariance."""
    return float(np.sum(0.5 * np.log(2 * math.pi * math.e * np.asarray(var, dtype=float))))


def generative_joint(
    eta: np.ndarray, sigma0: float, slope: np.ndarray | float, offset: np.ndarray | float
) -> tuple[np.ndarray, np.ndarray]:
    """``X_0 = sigma0 e_0``, ``X_{k+1} = a_k X_k + eta_k offset_k + sqrt(2 eta_k) e_{k+1}``.

    ``a_k = 1 + eta_k (slope_k - 1 / sigma0^2)``; ``slope`` and ``offset`` are scalars or one
    value per step ``(N,)`` in sampling order.
    """
    n = eta.size
    coupling = np.zeros((n + 1, n + 1))
    coupling[np.arange(1, n + 1), np.arange(n)] = 1 + eta * (slope - 1 / sigma0**2)
    shift = np.r_[0.0, eta * offset]
    return linear_gaussian_joint(coupling, shift, np.r_[sigma0, np.sqrt(2 * eta)])


def noising_joint(
    eta: np.ndarray,
    sigma0: float,
    slope: np.ndarray | float,
    offset: np.ndarray | float,
    mean0: float,
    var0: float,
) -> tuple[np.ndarray, np.ndarray]:
    """``X_N ~ N(mean0, var0)``, ``X_k = c_k X_{k+1} + eta_k offset_k + sqrt(2 eta_k) e_k``.

    ``c_k = 1 + eta_k (slope_k - 1 / sigma0^2)``; scalars or one value per step ``(N,)``.
    """
    n = eta.size
    coupling = np.zeros((n + 1, n + 1))
    coupling[np.arange(n), np.arange(1, n + 1)] = 1 + eta * (slope - 1 / sigma0**2)
    shift = np.r_[eta * offset, mean0]
    return linear_gaussian_joint(coupling, shift, np.r_[np.sqrt(2 * eta), math.sqrt(var0)])


def gaussian_kl_np(
    mean_p: np.ndarray, cov_p: np.ndarray, mean_q: np.ndarray, cov_q: np.ndarray
) -> np.ndarray:
    """Gaussian ``KL(p || q)`` on NumPy arrays, by :func:`vslbook.dists.gaussian_kl`."""
    return to_numpy(
        gaussian_kl(to_tensor(mean_p), to_tensor(cov_p), to_tensor(mean_q), to_tensor(cov_q))
    )


def linear_gaussian_chain(
    etas: np.ndarray,
    sigma0: float,
    gen_slope: np.ndarray | float = 0.0,
    gen_offset: np.ndarray | float = 0.0,
    noise_slope: np.ndarray | float = 0.0,
    noise_offset: np.ndarray | float = 0.0,
) -> LinearGaussianChain:
    """Closed forms for the diffusion policy with affine drifts (Eqs. 5.12-5.15, 5.18, C.2).

    The kernels are those of :class:`~vslbook.srl.DiffusionPolicy` with
    ``f_theta(x) = gen_slope x + gen_offset`` and, for General Bridges, a learned noising drift
    ``g_psi(x) = noise_slope x + noise_offset`` (zero for DIME's fixed OU step):

        generative  X_{k+1} | X_k ~ N(X_k + eta_k (-X_k / sigma0^2 + f_k(X_k)), 2 eta_k)
        noising     X_k | X_{k+1} ~ N(X_{k+1} + eta_k (-X_{k+1} / sigma0^2 + g_k(X_{k+1})), 2 eta_k)

    Each coefficient may differ between steps (a score network that reads the step embedding),
    which the policy-iteration check uses; :func:`linear_gaussian_policy` shares them.

    The bound is computed from the expected log kernels, ``ℓ = H(pi_N) + sum_k (1/2 -
    E[u_k^2] / (4 eta_k))`` with ``u_k = X_k - E_noising[X_k | X_{k+1}]`` under the generative
    joint, independently of the KL, so ``H - ℓ = KL`` is a genuine identity to check.

    Args:
        etas: step sizes ``(N, d)`` in sampling order (``DiffusionPolicy.step_sizes``).
        sigma0: prior standard deviation.
        gen_slope, gen_offset, noise_slope, noise_offset: scalars, ``(d,)`` arrays (shared
            by the steps) or ``(N, d)`` arrays (one value per step, in sampling order).
    """
    etas = np.asarray(etas, dtype=float)
    if etas.ndim != 2 or not np.all(etas > 0):
        raise ValueError(f"etas must be a positive (N, d) array, got shape {etas.shape}")
    sigma0 = check_positive("sigma0", sigma0)
    n, d = etas.shape
    params = [
        np.broadcast_to(np.asarray(v, dtype=float), (n, d))
        for v in (gen_slope, gen_offset, noise_slope, noise_offset)
    ]
    fields: dict[str, list] = {k: [] for k in LinearGaussianChain.__dataclass_fields__}
    for j in range(d):
        eta = etas[:, j]
        g_slope, g_offset, n_slope, n_offset = (p[:, j] for p in params)
        mean_g, cov_g = generative_joint(eta, sigma0, g_slope, g_offset)
        m0, v0 = mean_g[-1], cov_g[-1, -1]
        mean_f, cov_f = noising_joint(eta, sigma0, n_slope, n_offset, m0, v0)
        # u_k = X_k - c_k X_{k+1} - eta_k noise_offset, linear in the generative joint
        c = 1 + eta * (n_slope - 1 / sigma0**2)
        rows = np.zeros((n, n + 1))
        rows[np.arange(n), np.arange(n)] = 1.0
        rows[np.arange(n), np.arange(1, n + 1)] = -c
        u_mean = rows @ mean_g - eta * n_offset
        u_sq = np.einsum("ki,ij,kj->k", rows, cov_g, rows) + u_mean**2
        steps = np.r_[0.5 * math.log(2 * math.pi * math.e * sigma0**2), 0.5 - u_sq / (4 * eta)]
        for key, value in (
            ("gen_mean", mean_g),
            ("gen_cov", cov_g),
            ("noising_mean", mean_f),
            ("noising_cov", cov_f),
            ("marginal_mean", m0),
            ("marginal_var", v0),
            ("entropy", gaussian_entropy(v0)),
            ("step_contributions", steps),
            ("bound", steps.sum()),
        ):
            fields[key].append(value)
    fields["kl"] = list(
        gaussian_kl_np(
            *(np.stack(fields[k]) for k in ("gen_mean", "gen_cov", "noising_mean", "noising_cov"))
        )
    )
    return LinearGaussianChain(**{k: np.array(v) for k, v in fields.items()})

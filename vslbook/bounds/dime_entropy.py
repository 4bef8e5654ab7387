"""Numerical checks of Section 5.4.1 (DIME): the entropy lower bound of a diffusion policy.

The bound ``ℓ`` of Eq. 5.15 (derived in Eq. C.2), its gap, the KL between the generative and the
noising chain (Eqs. 5.18-5.20) and the approximate inference form of Eq. C.11.
:func:`check_entropy_lower_bound` runs :class:`~vslbook.srl.DiffusionPolicy` itself with an
affine score network (:func:`linear_gaussian_policy`), so its chain is linear-Gaussian and every
quantity has a closed form (:func:`linear_gaussian_chain`). The closed forms are also the policy
family of :func:`~vslbook.bounds.dime_policy_iteration.check_diffusion_policy_iteration`.

Import from :mod:`vslbook.bounds.dime`, which re-exports everything public here.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor, nn

from vslbook.bounds import Check, CheckReport, relative_tol
from vslbook.bounds._helpers import _count, _linear_gaussian_joint, _np, _positive, _rng, _t, _worst
from vslbook.dists import gaussian_kl
from vslbook.srl.diffusion_policy import (
    DiffusionPolicy,
    DiffusionPolicyConfig,
    PolicySample,
    cosine_schedule,
)

__all__ = [
    "AffineScore",
    "LinearGaussianChain",
    "check_entropy_lower_bound",
    "gaussian_entropy",
    "linear_gaussian_chain",
    "linear_gaussian_policy",
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
    n_steps = _count("n_steps", n_steps)
    # dt scale chosen so that the unnormalised cosine schedule sums to ``total_time``
    dt = _positive("total_time", total_time) / float(cosine_schedule(n_steps).sum())
    config = DiffusionPolicyConfig(
        n_steps=n_steps,
        sigma0=_positive("sigma0", sigma0),
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
        policy.raw_noise.copy_(_t(np.log(np.expm1(1.0 / noise_var))))
        nn.init.zeros_(policy.score_net.out.weight)
        policy.score_net.out.bias.copy_(_t(offset))
    policy.score_net = AffineScore(policy.score_net, _t(slope))
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


def _generative_joint(
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
    return _linear_gaussian_joint(coupling, shift, np.r_[sigma0, np.sqrt(2 * eta)])


def _noising_joint(
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
    return _linear_gaussian_joint(coupling, shift, np.r_[np.sqrt(2 * eta), math.sqrt(var0)])


def _kl(mean_p: np.ndarray, cov_p: np.ndarray, mean_q: np.ndarray, cov_q: np.ndarray) -> np.ndarray:
    return _np(gaussian_kl(_t(mean_p), _t(cov_p), _t(mean_q), _t(cov_q)))


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
    sigma0 = _positive("sigma0", sigma0)
    n, d = etas.shape
    params = [
        np.broadcast_to(np.asarray(v, dtype=float), (n, d))
        for v in (gen_slope, gen_offset, noise_slope, noise_offset)
    ]
    fields: dict[str, list] = {k: [] for k in LinearGaussianChain.__dataclass_fields__}
    for j in range(d):
        eta = etas[:, j]
        g_slope, g_offset, n_slope, n_offset = (p[:, j] for p in params)
        mean_g, cov_g = _generative_joint(eta, sigma0, g_slope, g_offset)
        m0, v0 = mean_g[-1], cov_g[-1, -1]
        mean_f, cov_f = _noising_joint(eta, sigma0, n_slope, n_offset, m0, v0)
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
        _kl(*(np.stack(fields[k]) for k in ("gen_mean", "gen_cov", "noising_mean", "noising_cov")))
    )
    return LinearGaussianChain(**{k: np.array(v) for k, v in fields.items()})


def _log_normal(x: np.ndarray, mean: np.ndarray, var: np.ndarray) -> np.ndarray:
    return -0.5 * ((x - mean) ** 2 / var + np.log(2 * math.pi * var))


@contextmanager
def _single_thread() -> Iterator[None]:
    """Run torch on one thread, restoring the previous setting afterwards.

    The chains here are tiny; on a loaded machine torch's thread pool costs far more than the
    arithmetic, so the check pins itself to one thread (its results do not depend on it).
    """
    previous = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(previous)


def _sample_chain(
    policy: DiffusionPolicy,
    n_samples: int,
    seed: int,
    bound_estimator: Callable[[PolicySample], Tensor],
) -> tuple[np.ndarray, np.ndarray]:
    """The estimator's samples ``(n,)`` and the trajectories ``(N+1, n, d)`` (seeded)."""
    obs = torch.zeros(n_samples, 1, dtype=torch.float64)
    generator = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        out = policy.sample(obs, generator=generator, return_trajectory=True)
    return _np(bound_estimator(out)).astype(float), _np(out.trajectory)


def _log_ratio_terms(
    trajectory: np.ndarray, etas: np.ndarray, sigma0: float, slope: np.ndarray, offset: np.ndarray
) -> np.ndarray:
    """Per-sample terms ``(N+1, n)`` of the log ratio in Eq. 5.15 from the documented kernels.

    Row 0 is ``-log p_N(x^N)``; row ``k >= 1`` is ``log ->pi(X_{k-1}|X_k) - log pi(X_k|X_{k-1})``.
    """
    x = trajectory
    terms = [-_log_normal(x[0], 0.0, sigma0**2).sum(-1)]
    for k, eta in enumerate(etas):
        gen_mean = x[k] + eta * (-x[k] / sigma0**2 + slope * x[k] + offset)
        noising_mean = x[k + 1] - eta * x[k + 1] / sigma0**2
        log_noising = _log_normal(x[k], noising_mean, 2 * eta).sum(-1)
        log_generative = _log_normal(x[k + 1], gen_mean, 2 * eta).sum(-1)
        terms.append(log_noising - log_generative)
    return np.stack(terms)


def _mc(samples: np.ndarray) -> tuple[float, float]:
    return float(samples.mean()), float(samples.std(ddof=1) / math.sqrt(samples.size))


def check_entropy_lower_bound(
    seed: int = 0,
    n_steps: int = 4,
    sigma0: float = 1.5,
    act_dim: int = 2,
    n_samples: int = 20_000,
    total_time: float = 1.0,
    n_steps_series: Sequence[int] = (1, 2, 4, 8, 16),
    n_series_samples: int = 4000,
    marginal_entropy: Callable[[np.ndarray, np.ndarray], float] | None = None,
    bound_estimator: Callable[[PolicySample], Tensor] | None = None,
) -> CheckReport:
    """The diffusion policy's entropy bound ``ℓ <= H`` and its gap (Eqs. 5.15, 5.18-5.20, C.2).

    Runs :func:`linear_gaussian_policy`, the real :class:`~vslbook.srl.DiffusionPolicy` with
    ``f_theta(x) = slope x + offset`` (seeded ``slope``, ``offset`` and noise scales) and no
    tanh, so every quantity has a closed form (:func:`linear_gaussian_chain`). What the policy's
    ``entropy_bound`` estimates is the single-sample log ratio of Eq. 5.15,

        log ->pi_{1:N|0}(x^{1:N}|x^0) - log pi_{0:N}(x^{0:N})
          = sum_n [log ->pi_{n|n-1} - log pi_{n-1|n}] - log p_N(x^N),

    with ``x^{0:N}`` drawn from the generative chain (prior ``pi_N = p_N = N(0, sigma0^2)``).
    By Eq. C.2 its mean ``ℓ`` is ``H(pi_0) - KL(pi_{0:N} || pi_0 ->pi_{1:N|0})``: the gap is the
    KL between the generative joint and the noising joint started at the generative marginal.

    Checks: the policy's samples equal the log ratio recomputed from the documented kernels;
    the sample moments of ``x^0`` match the closed-form marginal; the Monte-Carlo mean of the
    estimator matches ``ℓ`` (5 standard errors), in total and step by step; ``ℓ <= H``;
    ``H - ℓ = KL`` in closed form and by Monte Carlo of ``-(estimate + log pi_0(x^0))``; for a
    Gaussian target ``exp Q / Z`` Eq. 5.20 (marginal KL <= joint KL) and Eq. C.11
    (joint KL = ``-E[Q] - ℓ + log Z``); and, for every ``n_steps`` in ``n_steps_series`` (same
    total time), ``ℓ <= H``, ``H - ℓ = KL`` and Monte Carlo = closed form.

    Args:
        marginal_entropy: candidate ``(mean, var) -> H`` for the ``x^0`` marginal (independent
            dimensions); defaults to :func:`gaussian_entropy`.
        bound_estimator: candidate ``PolicySample -> (n,)`` estimate of ``ℓ``; defaults to
            ``sample.entropy_bound``.

    Returns:
        Report with data ``etas`` (N, d), ``step_contributions`` (N+1,: prior term, then one
        per step in sampling order, summed over dimensions) and ``step_contributions_mc``,
        ``entropy``, ``bound``, ``gap`` (the closed-form KL), ``bound_mc``, ``bound_stderr``,
        ``gap_mc``, ``gap_stderr``, ``bound_samples`` (n_samples,), ``gap_samples``, ``latent``
        (the first 2000 actions x^0), ``marginal_mean``, ``marginal_var``, ``target_kl``
        (marginal, joint) and per ``series_steps``: ``series_entropy``, ``series_bound``,
        ``series_gap``, ``series_bound_mc``, ``series_bound_stderr``, ``series_gap_zero_drift``
        (the gap of the same chain with ``f_theta = 0``).
    """
    with _single_thread():
        return _entropy_lower_bound(
            seed,
            n_steps,
            sigma0,
            act_dim,
            n_samples,
            total_time,
            n_steps_series,
            n_series_samples,
            marginal_entropy,
            bound_estimator,
        )


def _entropy_lower_bound(
    seed: int,
    n_steps: int,
    sigma0: float,
    act_dim: int,
    n_samples: int,
    total_time: float,
    n_steps_series: Sequence[int],
    n_series_samples: int,
    marginal_entropy: Callable[[np.ndarray, np.ndarray], float] | None,
    bound_estimator: Callable[[PolicySample], Tensor] | None,
) -> CheckReport:
    """The body of :func:`check_entropy_lower_bound`."""
    d = _count("act_dim", act_dim)
    n_samples = _count("n_samples", n_samples, 2)
    n_series_samples = _count("n_series_samples", n_series_samples, 2)
    series = [_count("n_steps_series entry", n) for n in n_steps_series]
    entropy_of = marginal_entropy or (lambda mean, var: gaussian_entropy(var))
    estimator = bound_estimator or (lambda sample: sample.entropy_bound)
    rng = _rng(seed)
    noise_var = rng.uniform(0.5, 1.5, d)
    slope, offset = rng.uniform(-0.5, 0.0, d), rng.normal(scale=1.0, size=d)
    target_mean, target_std = rng.normal(size=d), rng.uniform(0.5, 1.5, d)

    def setup(n: int) -> tuple[DiffusionPolicy, np.ndarray, LinearGaussianChain]:
        policy = linear_gaussian_policy(n, sigma0, total_time, noise_var, slope, offset, seed)
        etas = _np(policy.step_sizes)
        return policy, etas, linear_gaussian_chain(etas, sigma0, slope, offset)

    policy, etas, chain = setup(_count("n_steps", n_steps))
    samples, trajectory = _sample_chain(policy, n_samples, seed, estimator)
    terms = _log_ratio_terms(trajectory, etas, sigma0, slope, offset)
    x0 = trajectory[-1]
    entropy = float(entropy_of(chain.marginal_mean, chain.marginal_var))
    bound, kl = float(chain.bound.sum()), float(chain.kl.sum())
    bound_mc, bound_se = _mc(samples)
    log_marginal = _log_normal(x0, chain.marginal_mean, chain.marginal_var).sum(-1)
    gap_samples = -(samples + log_marginal)
    gap_mc, gap_se = _mc(gap_samples)
    steps_cf = chain.step_contributions.sum(0)
    steps_mc, steps_se = terms.mean(1), terms.std(1, ddof=1) / math.sqrt(n_samples)
    mean_se = np.sqrt(chain.marginal_var / n_samples)
    var_se = chain.marginal_var * math.sqrt(2 / (n_samples - 1))

    # Eq. 5.20 and C.11 for a Gaussian target exp(Q)/Z, Q(a) = -sum_d (a_d - mu_d)^2 / (2 s_d^2).
    joint_target = []
    for j in range(d):
        mean_f, cov_f = _noising_joint(
            etas[:, j], sigma0, 0.0, 0.0, target_mean[j], target_std[j] ** 2
        )
        joint_target.append((mean_f, cov_f))
    kl_joint_target = float(
        _kl(
            chain.gen_mean,
            chain.gen_cov,
            np.stack([m for m, _ in joint_target]),
            np.stack([c for _, c in joint_target]),
        ).sum()
    )
    kl_marginal_target = float(
        _kl(
            chain.marginal_mean[:, None],
            chain.marginal_var[:, None, None],
            target_mean[:, None],
            (target_std**2)[:, None, None],
        ).sum()
    )
    expected_q = float(
        -np.sum(((chain.marginal_mean - target_mean) ** 2 + chain.marginal_var) / target_std**2) / 2
    )
    log_z = float(np.sum(0.5 * np.log(2 * math.pi * target_std**2)))

    s_entropy, s_bound, s_gap, s_mc, s_se, s_gap0 = ([] for _ in range(6))
    for i, n in enumerate(series):
        s_policy, s_etas, s_chain = setup(n)
        s_samples, _ = _sample_chain(s_policy, n_series_samples, seed + 1 + i, estimator)
        mc, se = _mc(s_samples)
        s_entropy.append(entropy_of(s_chain.marginal_mean, s_chain.marginal_var))
        s_bound.append(s_chain.bound.sum())
        s_gap.append(s_chain.kl.sum())
        s_mc.append(mc)
        s_se.append(se)
        s_gap0.append(linear_gaussian_chain(s_etas, sigma0).kl.sum())
    s_entropy, s_bound, s_gap, s_mc, s_se, s_gap0 = (
        np.array(v, dtype=float) for v in (s_entropy, s_bound, s_gap, s_mc, s_se, s_gap0)
    )

    tol = relative_tol(entropy, bound, kl)
    checks = (
        _worst(
            "entropy_bound sample = log ratio of Eq. 5.15 from the documented kernels",
            "Eqs. 5.12-5.15",
            samples,
            terms.sum(0),
            relative_tol(float(np.abs(samples).max())),
        ),
        _worst(
            "sample mean of x^0 = closed-form marginal mean (5 SE)",
            "Eq. 5.14",
            x0.mean(0),
            chain.marginal_mean,
            5 * mean_se,
        ),
        _worst(
            "sample var of x^0 = closed-form marginal var (5 SE)",
            "Eq. 5.14",
            x0.var(0, ddof=1),
            chain.marginal_var,
            5 * var_se,
        ),
        Check(
            "Monte Carlo E[entropy_bound] = closed-form ℓ (5 SE)",
            "Eq. 5.15",
            bound_mc,
            bound,
            5 * bound_se,
        ),
        _worst(
            "per-step Monte Carlo contributions to ℓ = closed form (5 SE)",
            "Eqs. 5.15, C.2",
            steps_mc,
            steps_cf,
            5 * steps_se,
        ),
        Check("ℓ <= H(pi_0)", "Eqs. 5.15, C.2", bound, entropy, tol, "<="),
        Check(
            "H(pi_0) - ℓ = KL(generative joint || noising joint from pi_0)",
            "Eqs. 5.18, C.2",
            entropy - bound,
            kl,
            tol,
        ),
        Check(
            "Monte Carlo of -(entropy_bound + log pi_0(x^0)) = KL (5 SE)",
            "Eqs. 5.18, C.2",
            gap_mc,
            kl,
            5 * gap_se,
        ),
        Check(
            "KL(pi_0 || exp Q / Z) <= KL(pi_{0:N} || ->pi_{0:N}) (data processing)",
            "Eq. 5.20",
            kl_marginal_target,
            kl_joint_target,
            relative_tol(kl_joint_target),
            "<=",
        ),
        Check(
            "KL(pi_{0:N} || ->pi_{0:N}) = -E[Q(x^0)] - ℓ + log Z",
            "Eqs. 5.18-5.19, C.11",
            kl_joint_target,
            -expected_q - bound + log_z,
            relative_tol(kl_joint_target, expected_q, bound, log_z),
        ),
        _worst(
            f"ℓ <= H for n_steps in {tuple(series)}",
            "Eqs. 5.15, C.2",
            s_bound,
            s_entropy,
            relative_tol(*s_entropy, *s_bound),
            "<=",
        ),
        _worst(
            f"H - ℓ = KL for n_steps in {tuple(series)}",
            "Eqs. 5.18, C.2",
            s_entropy - s_bound,
            s_gap,
            relative_tol(*s_entropy, *s_bound),
        ),
        _worst(
            f"Monte Carlo E[entropy_bound] = ℓ for n_steps in {tuple(series)} (5 SE)",
            "Eq. 5.15",
            s_mc,
            s_bound,
            5 * s_se,
        ),
    )
    data = {
        "etas": etas,
        "step_contributions": steps_cf,
        "step_contributions_mc": steps_mc,
        "entropy": np.array(entropy),
        "bound": np.array(bound),
        "gap": np.array(kl),
        "bound_mc": np.array(bound_mc),
        "bound_stderr": np.array(bound_se),
        "gap_mc": np.array(gap_mc),
        "gap_stderr": np.array(gap_se),
        "bound_samples": samples,
        "gap_samples": gap_samples,
        "latent": x0[:2000],
        "marginal_mean": chain.marginal_mean,
        "marginal_var": chain.marginal_var,
        "target_kl": np.array([kl_marginal_target, kl_joint_target]),
        "series_steps": np.array(series),
        "series_entropy": s_entropy,
        "series_bound": s_bound,
        "series_gap": s_gap,
        "series_bound_mc": s_mc,
        "series_bound_stderr": s_se,
        "series_gap_zero_drift": s_gap0,
    }
    return CheckReport("Entropy lower bound of the diffusion policy (Section 5.4.1)", checks, data)

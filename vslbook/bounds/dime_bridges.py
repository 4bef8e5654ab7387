"""General bridges (Section 5.6, Eqs. 5.29-5.38): DIME's objective for any pair of chains.

Section 5.6 replaces DIME's fixed Ornstein-Uhlenbeck noising process by a forward process with
a reference drift ``f`` and a control ``u``, and the denoising process by a backward process
with the same reference drift and a control ``v`` (Eqs. 5.29-5.30, after
:cite:p:`richter2024improved`). Discretised with Euler-Maruyama (Eqs. 5.31-5.32) both are
chains of Gaussian kernels (Eqs. 5.35-5.36) with joint densities (Eqs. 5.33-5.34), and the
objective is the same joint KL as DIME's (Eq. 5.37) against the forward chain started at the
Boltzmann policy (Eq. 5.38).

This module holds the bridge (:class:`GeneralBridge`), its two samplers, the log-densities of
its two joints and the single-sample estimators of the entropy bound ``ℓ`` (Eq. 5.15 with the
bridge's kernels) and of Eq. 5.37, with the two special cases:

* :func:`dime_bridge`: DIME in the thesis's notation, ``f = -beta a``, ``u = 0``,
  ``v = 2 grad log pi~`` (Eqs. 5.11b-5.12 as a bridge);
* :func:`policy_bridge`: the library's :class:`~vslbook.srl.DiffusionPolicy`, with or without
  ``general_bridges``, as a bridge.

Closed forms for bridges whose drifts are affine are in
:mod:`vslbook.bounds.dime_bridges_linear`, and the checks in
:mod:`vslbook.bounds.dime_bridges_checks`, :mod:`vslbook.bounds.dime_bridges_quadrature` and
:mod:`vslbook.bounds.dime_bridges_special`.

Conventions (the thesis is silent on them):

* The thesis writes ``beta`` without a step index in Eqs. 5.31-5.36. With a schedule, each
  transition between ``a^{n-1}`` and ``a^n`` gets one ``beta_n`` (``beta[n-1]`` here), used by
  both kernels of that transition, the library's convention (one step size per step); the
  thesis's Eqs. 5.11b-5.12 instead pair the forward step out of ``a^n`` and the backward step
  out of ``a^n`` with the same ``beta_n``. For a constant ``beta`` both readings agree.
* ``beta`` may differ between action dimensions (an array ``(N, d)``), as the library's
  learned per-dimension scales do; ``beta u`` is then elementwise.
* The state ``s`` is fixed and left out of the signatures: the drifts are ``f(a, n)``,
  ``u(a, n)``, ``v(a, n)`` for a batch ``a`` of shape ``(B, d)`` and an integer step ``n``
  (diffusion time ``t = n delta``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch

from vslbook.bounds.toy_numerics import check_count, check_positive, seeded_rng

__all__ = [
    "BoundEstimator",
    "Drift",
    "GeneralBridge",
    "KLEstimator",
    "bridge_kl_samples",
    "dime_bridge",
    "entropy_bound_samples",
    "log_backward_joint",
    "log_forward_conditional",
    "make_bridge",
    "policy_bridge",
    "sample_backward",
    "sample_forward",
]

Drift = Callable[[np.ndarray, int], np.ndarray]


def _zero(a: np.ndarray, n: int) -> np.ndarray:
    return np.zeros_like(a)


@dataclass(frozen=True)
class GeneralBridge:
    """A forward and a backward chain with shared reference drift (Eqs. 5.29-5.36).

    Attributes:
        f: reference drift ``f(a, n)``.
        u: forward control ``u(a, n)`` (Eq. 5.29); DIME fixes it.
        v: backward control ``v(a, n)`` (Eq. 5.30); DIME learns it.
        beta: diffusion coefficients ``(N, d)``; row ``n - 1`` belongs to the transition
            between ``a^{n-1}`` and ``a^n``.
        delta: step size ``delta = T / N``.
        prior_var: ``(d,)`` variances of the backward chain's start ``pi~_N =
            N(prior_mean, diag(prior_var))`` (Eq. 5.30 has ``N(0, I)``; DIME's Eq. 5.8
            ``N(0, eta^2 I)``).
        prior_mean: ``(d,)`` its mean, zero in the thesis; the checks move it only to show
            which controls make the two chains each other's time reversal.
    """

    f: Drift
    u: Drift
    v: Drift
    beta: np.ndarray
    delta: float
    prior_var: np.ndarray
    prior_mean: np.ndarray

    @property
    def n_steps(self) -> int:
        """``N``."""
        return self.beta.shape[0]

    @property
    def dim(self) -> int:
        """The action dimension ``d``."""
        return self.beta.shape[1]

    def kernel_var(self, n: int) -> np.ndarray:
        """``2 beta delta`` of the transition between ``a^{n-1}`` and ``a^n``, ``(d,)``."""
        return 2 * self.beta[n - 1] * self.delta

    def forward_mean(self, a: np.ndarray, n: int) -> np.ndarray:
        """Mean of ``->pi_{n+1|n}(. | a)``: ``a + [f(a, n) + beta u(a, n)] delta`` (Eq. 5.35)."""
        return a + (self.f(a, n) + self.beta[n] * self.u(a, n)) * self.delta

    def backward_mean(self, a: np.ndarray, n: int) -> np.ndarray:
        """Mean of ``pi~_{n-1|n}(. | a)``: ``a - [f(a, n) - beta v(a, n)] delta`` (Eq. 5.36)."""
        return a - (self.f(a, n) - self.beta[n - 1] * self.v(a, n)) * self.delta


def make_bridge(
    f: Drift | None,
    u: Drift | None,
    v: Drift | None,
    beta: float | np.ndarray,
    delta: float,
    n_steps: int,
    dim: int,
    prior_var: float | np.ndarray = 1.0,
    prior_mean: float | np.ndarray = 0.0,
) -> GeneralBridge:
    """A :class:`GeneralBridge` with validated, broadcast coefficients.

    ``None`` for a drift means zero. ``beta`` is a scalar (the thesis's constant ``beta``),
    ``(N,)`` (a schedule), ``(1, d)`` (one constant per dimension) or ``(N, d)``;
    ``prior_var`` and ``prior_mean`` are scalars or ``(d,)``.
    """
    n_steps, dim = check_count("n_steps", n_steps), check_count("dim", dim)
    beta_arr = np.asarray(beta, dtype=float)
    if beta_arr.ndim == 1:
        beta_arr = beta_arr[:, None]
    try:
        beta_arr = np.broadcast_to(beta_arr, (n_steps, dim)).copy()
    except ValueError:
        raise ValueError(
            f"beta must be a scalar, (N,), (1, d) or (N, d) = ({n_steps}, {dim}), "
            f"got shape {np.shape(beta)}"
        ) from None
    if not np.all(beta_arr > 0):
        raise ValueError(f"beta must be positive, got {beta}")
    prior = np.broadcast_to(np.asarray(prior_var, dtype=float), (dim,)).copy()
    if not np.all(prior > 0):
        raise ValueError(f"prior_var must be positive, got {prior_var}")
    mean = np.broadcast_to(np.asarray(prior_mean, dtype=float), (dim,)).copy()
    return GeneralBridge(
        f or _zero, u or _zero, v or _zero, beta_arr, check_positive("delta", delta), prior, mean
    )


def dime_bridge(
    beta: float,
    delta: float,
    n_steps: int,
    dim: int,
    score: Drift,
    eta: float = 1.0,
) -> GeneralBridge:
    """DIME's chains (Eqs. 5.11b-5.12) as a general bridge, in the thesis's notation.

    The OU noising step ``a^{n+1} = a^n - beta a^n delta + N(0, 2 eta^2 beta delta)`` and the
    denoising step ``a^{n-1} = a^n + (beta a^n + 2 eta^2 beta score(a^n, n)) delta +
    N(0, 2 eta^2 beta delta)`` are Eqs. 5.35-5.36 with

        beta_GB = eta^2 beta,   f(a, n) = -beta a,   u = 0,   v = 2 score,
        pi~_N = N(0, eta^2 I)

    (for ``eta = 1`` the thesis's ``f = -beta a``, ``u = 0``, ``v = 2 grad log pi~_n`` and
    ``N(0, I)`` of Eq. 5.30 exactly). ``beta`` is the constant of Eqs. 5.31-5.36.
    """
    beta, eta = check_positive("beta", beta), check_positive("eta", eta)

    def f(a: np.ndarray, n: int) -> np.ndarray:
        return -beta * a

    def v(a: np.ndarray, n: int) -> np.ndarray:
        return 2 * score(a, n)

    return make_bridge(f, None, v, eta**2 * beta, delta, n_steps, dim, eta**2)


def policy_bridge(policy: torch.nn.Module, obs: np.ndarray) -> GeneralBridge:
    """The library's :class:`~vslbook.srl.DiffusionPolicy` at state ``obs`` as a bridge.

    The policy's generative step ``x_{n-1} = x_n + eta_n (grad log p_N + f_theta)(x_n)`` and
    its noising kernel ``N(x_n; x_{n-1} + eta_n (grad log p_N + g_psi)(x_{n-1}), 2 eta_n)``
    (``g_psi = 0`` unless ``general_bridges``) are Eqs. 5.35-5.36 with

        delta = 1,  beta_n = eta_n,  f = 0,  u = grad log p_N + g_psi,  v = grad log p_N + f_theta,
        pi~_N = p_N = N(0, sigma0^2 I),

    where ``eta_n`` is the policy's step size of the transition between ``x_{n-1}`` and
    ``x_n`` (``policy.step_sizes[N - n]``, per dimension), ``f_theta`` reads the step
    embedding of ``n`` and ``g_psi`` that of ``n - 1``. The tanh squashing of the action
    (Eq. C.30) is not part of the bridge: use a policy with ``squash=False``.
    """
    config = policy.config
    param = next(policy.parameters())
    with torch.no_grad():
        etas = policy.step_sizes.detach().cpu().double().numpy()  # (N, d), sampling order
    n_steps = etas.shape[0]
    obs_t = torch.as_tensor(np.asarray(obs, dtype=float), dtype=param.dtype).reshape(1, -1)

    def network(net: torch.nn.Module, a: np.ndarray, step: int) -> np.ndarray:
        x = torch.as_tensor(a, dtype=param.dtype)
        with torch.no_grad():
            emb = net.embed_steps(torch.tensor([float(step)], dtype=param.dtype))[0]
            out = net(x, emb, obs_t.expand(x.shape[0], -1))
        return out.double().numpy()

    def prior_score(a: np.ndarray) -> np.ndarray:
        return -a / config.sigma0**2

    def u(a: np.ndarray, n: int) -> np.ndarray:
        out = prior_score(a)
        if getattr(policy, "noising_net", None) is not None:
            out = out + network(policy.noising_net, a, n)
        return out

    def v(a: np.ndarray, n: int) -> np.ndarray:
        return prior_score(a) + network(policy.score_net, a, n)

    beta = etas[::-1].copy()  # row n - 1 <-> transition (n-1, n) <-> sampling step N - n
    return make_bridge(None, u, v, beta, 1.0, n_steps, etas.shape[1], config.sigma0**2)


#: An estimator of the bridge KL of Eq. 5.37 per backward trajectory:
#: ``(bridge, traj, Q, log Z) -> samples`` (default :func:`bridge_kl_samples`).
KLEstimator = Callable[
    [GeneralBridge, np.ndarray, Callable[[np.ndarray], np.ndarray], float], np.ndarray
]
#: An estimator of the entropy bound ``ℓ`` per backward trajectory: ``(bridge, traj) ->
#: samples`` (default :func:`entropy_bound_samples`).
BoundEstimator = Callable[[GeneralBridge, np.ndarray], np.ndarray]


def _log_normal(x: np.ndarray, mean: np.ndarray, var: np.ndarray) -> np.ndarray:
    """``log N(x; mean, diag(var))`` summed over the last axis."""
    return -0.5 * ((x - mean) ** 2 / var + np.log(2 * math.pi * var)).sum(-1)


def _check_trajectory(bridge: GeneralBridge, traj: np.ndarray) -> np.ndarray:
    traj = np.asarray(traj, dtype=float)
    if traj.ndim != 3 or traj.shape[0] != bridge.n_steps + 1 or traj.shape[2] != bridge.dim:
        raise ValueError(
            f"trajectory must have shape (N + 1, batch, d) = ({bridge.n_steps + 1}, batch, "
            f"{bridge.dim}) with traj[n] = a^n, got {traj.shape}"
        )
    return traj


def sample_backward(bridge: GeneralBridge, n_samples: int, seed: int = 0) -> np.ndarray:
    """Chains of the backward process, Eq. 5.32 from ``a^N ~ pi~_N`` (Eq. 5.34).

    Returns ``(N + 1, n_samples, d)`` with ``traj[n] = a^n`` (``traj[0]`` the action).
    """
    rng = seeded_rng(seed, 29)
    n, d = check_count("n_samples", n_samples), bridge.dim
    traj = np.empty((bridge.n_steps + 1, n, d))
    traj[-1] = bridge.prior_mean + np.sqrt(bridge.prior_var) * rng.standard_normal((n, d))
    for step in range(bridge.n_steps, 0, -1):
        noise = np.sqrt(bridge.kernel_var(step)) * rng.standard_normal((n, d))
        traj[step - 1] = bridge.backward_mean(traj[step], step) + noise
    return traj


def sample_forward(bridge: GeneralBridge, a0: np.ndarray, seed: int = 0) -> np.ndarray:
    """Chains of the forward process, Eq. 5.31 from the given ``a^0`` ``(B, d)`` (Eq. 5.33).

    Returns ``(N + 1, B, d)`` with ``traj[n] = a^n``.
    """
    a0 = np.asarray(a0, dtype=float)
    if a0.ndim != 2 or a0.shape[1] != bridge.dim:
        raise ValueError(f"a0 must have shape (batch, {bridge.dim}), got {a0.shape}")
    rng = seeded_rng(seed, 31)
    traj = np.empty((bridge.n_steps + 1, *a0.shape))
    traj[0] = a0
    for step in range(bridge.n_steps):
        noise = np.sqrt(bridge.kernel_var(step + 1)) * rng.standard_normal(a0.shape)
        traj[step + 1] = bridge.forward_mean(traj[step], step) + noise
    return traj


def log_backward_joint(bridge: GeneralBridge, traj: np.ndarray) -> np.ndarray:
    """``log pi~_{0:N}(a^{0:N})`` of Eq. 5.34 with the kernels of Eq. 5.36, per chain."""
    traj = _check_trajectory(bridge, traj)
    out = _log_normal(traj[-1], bridge.prior_mean, bridge.prior_var)
    for n in range(1, bridge.n_steps + 1):
        out = out + _log_normal(traj[n - 1], bridge.backward_mean(traj[n], n), bridge.kernel_var(n))
    return out


def log_forward_conditional(bridge: GeneralBridge, traj: np.ndarray) -> np.ndarray:
    """``log ->pi_{1:N|0}(a^{1:N} | a^0) = sum_n log ->pi_{n+1|n}`` (Eq. 5.33 with 5.35)."""
    traj = _check_trajectory(bridge, traj)
    out = np.zeros(traj.shape[1])
    for n in range(bridge.n_steps):
        out = out + _log_normal(
            traj[n + 1], bridge.forward_mean(traj[n], n), bridge.kernel_var(n + 1)
        )
    return out


def entropy_bound_samples(bridge: GeneralBridge, traj: np.ndarray) -> np.ndarray:
    """Single-chain estimates of ``ℓ`` (Eq. 5.15) with the bridge's kernels.

    ``log ->pi_{1:N|0}(a^{1:N} | a^0) - log pi~_{0:N}(a^{0:N})`` on backward chains; its mean
    is ``ℓ <= H(pi~_0)``, whatever the forward kernels are (Appendix C.1 never uses their form).
    """
    return log_forward_conditional(bridge, traj) - log_backward_joint(bridge, traj)


def bridge_kl_samples(
    bridge: GeneralBridge,
    traj: np.ndarray,
    q: Callable[[np.ndarray], np.ndarray],
    log_z: float = 0.0,
) -> np.ndarray:
    """Single-chain estimates of Eq. 5.37 with the target of Eq. 5.38.

    ``log pi~_{0:N} - log ->pi_{0:N}`` on backward chains, where the forward chain starts at
    ``pi_0 = exp Q / Z``: ``log pi~_{0:N} - Q(a^0) + log Z - log ->pi_{1:N|0}``, i.e.
    ``-ℓ^ - Q(a^0) + log Z``. Without ``log_z`` it is Eq. 5.27's bracket, the practical loss.
    """
    traj = _check_trajectory(bridge, traj)
    return -entropy_bound_samples(bridge, traj) - np.asarray(q(traj[0]), dtype=float) + log_z

"""The contextual mixture of linear-Gaussian experts shared by the mixture baselines.

HiREPS (:mod:`vslbook.erl.hireps`) and LaDiPS (:mod:`vslbook.erl.ladips`), the Chapter 3
baselines of Sections 3.2 and 3.4.2 (hyper-parameters Tables A.2 and A.3), learn the same
policy over the task's FIXED context distribution p(c) (no curriculum), with all N experts
present from the start:

    π(θ|c) = Σ_o π(o|c) π(θ|c,o),   π(θ|c,o) = N(θ | K_o c + k_o, Σ_o),
    π(o|c) = π(o) N(c|μ_o, S_o) / Σ_o' π(o') N(c|μ_o', S_o'),

the generative ("Bayes") gating that SVSL also uses (π(o|c) = π(c|o)π(o)/π(c), Eq. 3.1), so
the methods compare directly. They differ only in how the weights of the samples are found;
this module holds what they share:

* densities, responsibilities p̃(o|c,θ) ∝ π(o|c) π(θ|c,o) and sampling (:class:`MixtureState`,
  :func:`gating_log_probs`, :func:`expert_log_density`, :func:`log_responsibilities`,
  :func:`sample_mixture`);
* the quadratic context features φ(c) of V(c) and Q(c, o) (:func:`context_features`);
* weighted maximum likelihood of gating and experts from per-sample, per-expert weights
  (:func:`fit_gating`, :func:`fit_linear_gaussian`, :func:`mixture_update`): ridge on the
  gain K (not on the offset k), cov_reg·I added to every covariance; an expert (and its
  gating component) whose weights have an effective sample size below ``min_ess`` keeps its
  old parameters while its prior π(o) still takes the new mass; prior masses floored at 1e-20;
* the initial mixture (:func:`init_mixture`): expert offsets k_o = init_mean +
  init_mean_std·N(0, I) (random, to break the symmetry), K_o = 0, Σ_o = diag(init_cov);
  gating means uniform in the context box, S_o the box's uniform covariance, π(o) = 1/N;
* the algorithm shell (:class:`MixtureAlgorithm`): sampling, the buffer of the last
  ``reuse_iterations`` batches, and the state round trip.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from scipy.special import logsumexp

__all__ = [
    "MixtureAlgorithm",
    "MixtureState",
    "context_features",
    "effective_sample_size",
    "expert_log_density",
    "fit_gating",
    "fit_linear_gaussian",
    "gating_log_probs",
    "gaussian_log_pdf",
    "init_mixture",
    "log_responsibilities",
    "mixture_update",
    "sample_mixture",
]

_LOG_P_MIN = np.log(1e-20)


# --------------------------------------------------------------------------------------
# the mixture: densities and sampling
# --------------------------------------------------------------------------------------
def gaussian_log_pdf(x: np.ndarray, mean: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """log N(x_i | mean_o, cov_o) for every sample i and component o: ``(n, N)``.

    Args:
        x: (n, d) or (n, N, d) (a separate point per component); mean: (N, d) or (n, N, d);
        cov: (N, d, d).
    """
    x = np.asarray(x, dtype=np.float64)
    chol = np.linalg.cholesky(cov)  # (N, d, d)
    diff = (x[:, None, :] if x.ndim == 2 else x) - mean  # (n, N, d)
    d = diff.shape[-1]
    d_inv = np.linalg.inv(chol)  # (N, d, d) lower-triangular L⁻¹
    z = np.einsum("oij,noj->noi", d_inv, diff)  # z = L⁻¹ (x − mean) for every (i, o)
    log_det = 2 * np.log(np.diagonal(chol, axis1=-2, axis2=-1)).sum(-1)
    return -0.5 * (np.einsum("ijk,ijk->ij", z, z) + log_det + d * np.log(2 * np.pi))


@dataclass
class MixtureState:
    """Parameters of the mixture of linear-Gaussian experts with a Bayes gating.

    Attributes:
        log_prior: (N,) log π(o); ctx_mean: (N, dc) μ_o; ctx_cov: (N, dc, dc) S_o;
        K: (N, dθ, dc); k: (N, dθ); cov: (N, dθ, dθ) — expert o is N(K_o c + k_o, Σ_o).
    """

    log_prior: np.ndarray
    ctx_mean: np.ndarray
    ctx_cov: np.ndarray
    K: np.ndarray
    k: np.ndarray
    cov: np.ndarray
    arrays: ClassVar[tuple[str, ...]] = ("log_prior", "ctx_mean", "ctx_cov", "K", "k", "cov")

    def copy(self) -> MixtureState:
        return MixtureState(*(getattr(self, a).copy() for a in self.arrays))


def gating_log_probs(contexts: np.ndarray, mix: MixtureState) -> np.ndarray:
    """log π(o|c) = log π(o) + log N(c|μ_o, S_o) − log Σ_o' (…), shape ``(n, N)``."""
    joint = mix.log_prior + gaussian_log_pdf(contexts, mix.ctx_mean, mix.ctx_cov)
    return joint - logsumexp(joint, axis=1, keepdims=True)


def expert_log_density(contexts: np.ndarray, theta: np.ndarray, mix: MixtureState) -> np.ndarray:
    """log π(θ_i | c_i, o) for every sample i and expert o: ``(n, N)``."""
    means = np.einsum("ojc,nc->noj", mix.K, contexts) + mix.k  # (n, N, dθ)
    th = np.broadcast_to(theta[:, None, :], means.shape)
    return gaussian_log_pdf(th, means, mix.cov)


def log_responsibilities(contexts: np.ndarray, theta: np.ndarray, mix: MixtureState) -> np.ndarray:
    """log p̃(o|c,θ) ∝ log π(o|c) + log π(θ|c,o), normalised over o: ``(n, N)``."""
    joint = gating_log_probs(contexts, mix) + expert_log_density(contexts, theta, mix)
    return joint - logsumexp(joint, axis=1, keepdims=True)


def sample_mixture(
    mix: MixtureState, contexts: np.ndarray, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """o ~ π(o|c) (gating), then θ ~ π(θ|c,o): returns ``(theta (n, dθ), experts (n,))``."""
    logp = gating_log_probs(contexts, mix)
    u = rng.random(len(contexts))
    cdf = np.cumsum(np.exp(logp), axis=1)
    experts = np.minimum((u[:, None] > cdf).sum(axis=1), mix.K.shape[0] - 1)
    means = np.einsum("njc,nc->nj", mix.K[experts], contexts) + mix.k[experts]
    chol = np.linalg.cholesky(mix.cov[experts])
    noise = rng.standard_normal(means.shape)
    return means + np.einsum("njk,nk->nj", chol, noise), experts


# --------------------------------------------------------------------------------------
# context features and the weighted ML fits
# --------------------------------------------------------------------------------------
def context_features(contexts: np.ndarray, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """φ(c): the context scaled to [−1, 1] on the box and its quadratic monomials (i ≤ j)."""
    c = 2 * (np.asarray(contexts, dtype=np.float64) - low) / (high - low) - 1
    iu = np.triu_indices(c.shape[1])
    return np.concatenate([c, (c[:, :, None] * c[:, None, :])[:, iu[0], iu[1]]], axis=1)


def fit_gating(
    contexts: np.ndarray, weights: np.ndarray, *, cov_reg: float = 0.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Weighted ML of the Bayes gating π(o) N(c|μ_o, S_o) from weights w_io.

    Returns ``(log_prior (N,), mean (N, dc), cov (N, dc, dc))``: π(o) ∝ Σ_i w_io (floored at
    1e-20), μ_o and S_o the w_·o-weighted mean and (biased) covariance, plus cov_reg·I.
    Components with zero total weight get NaN means (the caller keeps the old ones).
    """
    c = np.asarray(contexts, dtype=np.float64)
    w = np.asarray(weights, dtype=np.float64)
    mass = w.sum(axis=0)
    wn = w / np.where(mass > 0, mass, np.nan)
    mean = wn.T @ c
    diff = c[:, None, :] - mean[None]
    cov = np.einsum("no,noi,noj->oij", wn, diff, diff) + cov_reg * np.eye(c.shape[1])
    log_prior = np.maximum(np.log(np.maximum(mass / mass.sum(), 1e-300)), _LOG_P_MIN)
    return log_prior - logsumexp(log_prior), mean, cov


def fit_linear_gaussian(
    contexts: np.ndarray,
    theta: np.ndarray,
    weights: np.ndarray,
    *,
    ridge: float = 0.0,
    cov_reg: float = 0.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Weighted ML (weighted ridge) of every expert N(θ | K_o c + k_o, Σ_o).

    [K_o k_o] = argmin Σ_i w_io ‖θ_i − K c_i − k‖² + ridge ‖K‖²_F, i.e. with X = [c, 1]
    and W_o = diag(w_·o): (Xᵀ W_o X + ridge·diag(1, …, 1, 0))⁻¹ Xᵀ W_o Θ; Σ_o the weighted
    (biased) residual covariance Σ_i w_io r_i r_iᵀ / Σ_i w_io, plus cov_reg·I.

    Returns ``(K (N, dθ, dc), k (N, dθ), cov (N, dθ, dθ))``.
    """
    c = np.asarray(contexts, dtype=np.float64)
    th = np.asarray(theta, dtype=np.float64)
    w = np.asarray(weights, dtype=np.float64)
    n, dc = c.shape
    x = np.concatenate([c, np.ones((n, 1))], axis=1)
    reg = ridge * np.diag(np.r_[np.ones(dc), 0.0])
    mass = w.sum(axis=0)
    empty = ~(mass > 0)  # experts without weight: solved on I, returned as NaN
    xtwx = np.einsum("no,ni,nj->oij", w, x, x) + reg
    xtwx[empty] = np.eye(dc + 1)
    xtwy = np.einsum("no,ni,nj->oij", w, x, th)
    beta = np.linalg.solve(xtwx, xtwy)  # (N, dc+1, dθ)
    beta[empty] = np.nan
    K = np.swapaxes(beta[:, :dc, :], 1, 2)
    k = beta[:, dc, :]
    resid = th[:, None, :] - (np.einsum("ni,oij->noj", x, beta))  # (n, N, dθ)
    wn = w / np.where(empty, 1.0, mass)
    cov = np.einsum("no,noi,noj->oij", wn, resid, resid) + cov_reg * np.eye(th.shape[1])
    return K, k, cov


def effective_sample_size(weights: np.ndarray) -> np.ndarray:
    """(Σ_i w_io)² / Σ_i w_io² per component (0 where all weights are 0)."""
    w = np.asarray(weights, dtype=np.float64)
    s2 = (w**2).sum(axis=0)
    return np.where(s2 > 0, w.sum(axis=0) ** 2 / np.where(s2 > 0, s2, 1.0), 0.0)


def mixture_update(
    mix: MixtureState,
    contexts: np.ndarray,
    theta: np.ndarray,
    weights: np.ndarray,
    *,
    ridge: float,
    cov_reg: float,
    min_ess: float,
) -> MixtureState:
    """Weighted ML of gating and experts; components with ESS < min_ess keep their old
    Gaussians (their prior still takes the new mass)."""
    new = mix.copy()
    log_prior, mu, s = fit_gating(contexts, weights, cov_reg=cov_reg)
    K, k, cov = fit_linear_gaussian(contexts, theta, weights, ridge=ridge, cov_reg=cov_reg)
    ok = effective_sample_size(weights) >= max(min_ess, 1e-12)
    new.log_prior = log_prior
    new.ctx_mean[ok], new.ctx_cov[ok] = mu[ok], s[ok]
    new.K[ok], new.k[ok], new.cov[ok] = K[ok], k[ok], cov[ok]
    return new


# --------------------------------------------------------------------------------------
# the initial mixture and the algorithm shell
# --------------------------------------------------------------------------------------
def init_mixture(
    task: Any,
    n_experts: int,
    init_mean: tuple,
    init_cov: Any,
    init_mean_std: float,
    rng: np.random.Generator,
) -> MixtureState:
    """The initial mixture (module docstring)."""
    d, dc = int(task.n_params), int(task.context_dim)
    mean0 = np.zeros(d) if len(init_mean) == 0 else np.asarray(init_mean, dtype=np.float64)
    cov0 = (
        np.broadcast_to(np.asarray(init_cov, dtype=np.float64), (d,))
        if np.ndim(init_cov) == 0 or len(np.atleast_1d(init_cov)) == 1
        else np.asarray(init_cov, dtype=np.float64)
    )
    if mean0.shape != (d,) or cov0.shape != (d,):
        raise ValueError(
            f"init_mean / init_cov must have length n_params = {d}, "
            f"got {mean0.shape} and {np.shape(init_cov)}"
        )
    lo, hi = np.asarray(task.context_low, float), np.asarray(task.context_high, float)
    return MixtureState(
        log_prior=np.full(n_experts, -np.log(n_experts)),
        ctx_mean=rng.uniform(lo, hi, (n_experts, dc)),
        ctx_cov=np.tile(np.diag((hi - lo) ** 2 / 12), (n_experts, 1, 1)),
        K=np.zeros((n_experts, d, dc)),
        k=mean0 + init_mean_std * rng.standard_normal((n_experts, d)),
        cov=np.tile(np.diag(cov0), (n_experts, 1, 1)),
    )


class MixtureAlgorithm:
    """Shared shell of the mixture baselines: sampling, sample buffer, state round trip."""

    config: Any

    def __init__(self, task: Any, config: Any, seed: int, workers: int | None = 0) -> None:
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
            raise ValueError(f"seed must be an integer, got {seed!r}")
        self.task = task
        self.config = config
        self.workers = workers
        self.rng = np.random.default_rng(int(seed))
        self.mix = init_mixture(
            task, config.n_experts, config.init_mean, config.init_cov,
            config.init_mean_std, self.rng,
        )  # fmt: skip
        self.iterations_done = 0
        self.total_samples = 0
        self.buffer: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []

    # -- policy -----------------------------------------------------------------------
    def _check_contexts(self, contexts: Any) -> np.ndarray:
        c = np.asarray(contexts, dtype=np.float64)
        if c.ndim != 2 or c.shape[1] != self.task.context_dim or not np.all(np.isfinite(c)):
            raise ValueError(
                f"contexts must be a finite array of shape (n, {self.task.context_dim}), "
                f"got shape {c.shape}"
            )
        return c

    def sample(self, contexts: Any, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """Gating o ~ π(o|c), then θ ~ π(θ|c,o): ``(theta (n, n_params), experts (n,))``."""
        return sample_mixture(self.mix, self._check_contexts(contexts), rng)

    def mean_action(self, contexts: Any, rng: np.random.Generator) -> np.ndarray:
        """Sample the expert from the gating and return its mean K_o c + k_o."""
        c = self._check_contexts(contexts)
        _, o = sample_mixture(self.mix, c, rng)
        return np.einsum("njc,nc->nj", self.mix.K[o], c) + self.mix.k[o]

    def gating(self, contexts: Any) -> np.ndarray:
        """π(o|c), ``(n, N)``."""
        return np.exp(gating_log_probs(self._check_contexts(contexts), self.mix))

    # -- one batch of episodes ---------------------------------------------------------
    def _collect(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
        cfg = self.config
        c = self.task.sample_contexts(cfg.samples_per_iteration, self.rng)
        theta, _ = sample_mixture(self.mix, c, self.rng)
        roll = self.task.evaluate(theta, c, workers=self.workers, out_of_range="penalise")
        self.buffer.append((c, theta, np.asarray(roll.returns, dtype=np.float64)))
        self.buffer = self.buffer[-cfg.reuse_iterations :]
        n_exec = int(roll.n_executed)
        self.total_samples += n_exec
        return c, theta, np.asarray(roll.returns, dtype=np.float64), n_exec

    def _buffer_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return tuple(np.concatenate([b[j] for b in self.buffer]) for j in range(3))  # type: ignore[return-value]

    # -- state round trip --------------------------------------------------------------
    def state_dict(self) -> dict[str, Any]:
        """Numpy arrays and the generator state; :meth:`load_state_dict` restores them."""
        d: dict[str, Any] = {f"mix.{a}": getattr(self.mix, a).copy() for a in self.mix.arrays}
        d["buffer"] = [tuple(x.copy() for x in b) for b in self.buffer]
        d["rng"] = self.rng.bit_generator.state
        d["iterations_done"] = self.iterations_done
        d["total_samples"] = self.total_samples
        return d

    def load_state_dict(self, d: dict[str, Any]) -> None:
        """Restore :meth:`state_dict`'s output (the object then continues identically)."""
        for a in self.mix.arrays:
            arr = np.asarray(d[f"mix.{a}"], dtype=np.float64)
            if arr.shape != getattr(self.mix, a).shape:
                raise ValueError(
                    f"state {a!r} has shape {arr.shape}, expected {getattr(self.mix, a).shape}"
                )
            setattr(self.mix, a, arr.copy())
        self.buffer = [tuple(np.array(x) for x in b) for b in d["buffer"]]  # type: ignore[misc]
        self.rng.bit_generator.state = d["rng"]
        self.iterations_done = int(d["iterations_done"])
        self.total_samples = int(d["total_samples"])


def run_iterations(
    algo: MixtureAlgorithm,
    iterations: int,
    callback: Callable[[int, dict[str, float]], None] | None = None,
) -> MixtureAlgorithm:
    """Call ``algo.iteration()`` ``iterations`` times; ``callback(i, metrics)`` after each."""
    if (
        isinstance(iterations, bool)
        or not isinstance(iterations, (int, np.integer))
        or iterations < 0
    ):
        raise ValueError(f"iterations must be an integer >= 0, got {iterations!r}")
    for i in range(int(iterations)):
        metrics = algo.iteration()
        if callback is not None:
            callback(i, metrics)
    return algo

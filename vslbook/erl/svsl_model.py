"""SVSL's policy: a mixture of linear-Gaussian experts with per-expert context Gaussians (Eq. 3.1).

    π(θ | c) = Σ_o π(c | o) π(o) / π(c) · π(θ | c, o),    π(c) = Σ_o π(c | o) π(o),

with π(c | o) = N(μ_o, Σ_c,o) (the expert's curriculum), π(θ | c, o) = N(K_o c + k_o, Σ_o)
and categorical weights π(o). The gating π(o | c) is Bayes' rule on the first two factors.
The model is the one of :class:`vslbook.dists.LinearGaussianMoE` (Eqs. 2.47–2.49), which
:attr:`MixtureModel.moe` builds from the current parameters; this module adds what SVSL
needs on top: a model that grows by one expert at a time, sampling from each expert's own
curriculum, the log responsibilities log π(o | c, θ) and log π(o | c) of the augmented
rewards (Eq. 3.4), and the mixture's expected entropy (Figs. A.1, A.2). Everything is numpy
float64; the experts are the leading axis E. The densities of every sample under every
expert, which the responsibilities need (n × E Gaussians: 18 k × 70 when all beer-pong
experts are updated), are computed here with the inverse Cholesky factors and one batched
product per expert and block of samples; the general broadcasting triangular solve of
``dists`` took about ten times longer at that size.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch

from vslbook.dists import LinearGaussianMoE

__all__ = ["MixtureModel"]


def _chol(cov: np.ndarray) -> np.ndarray:
    return np.linalg.cholesky(cov)


@dataclass
class MixtureModel:
    """The parameters of Eq. 3.1 for E experts (all arrays float64, leading axis E).

    Attributes:
        log_w: (E,) log π(o).
        ctx_mean: (E, dc), ctx_cov: (E, dc, dc) — π(c | o).
        gain: (E, dθ, dc) K_o, offset: (E, dθ) k_o, cov: (E, dθ, dθ) Σ_o — π(θ | c, o).
    """

    log_w: np.ndarray
    ctx_mean: np.ndarray
    ctx_cov: np.ndarray
    gain: np.ndarray
    offset: np.ndarray
    cov: np.ndarray
    _moe: LinearGaussianMoE | None = field(default=None, repr=False, compare=False)
    _cache: dict[str, np.ndarray] | None = field(default=None, repr=False, compare=False)

    @classmethod
    def empty(cls, context_dim: int, param_dim: int) -> MixtureModel:
        dc, dt = context_dim, param_dim
        return cls(
            np.zeros(0), np.zeros((0, dc)), np.zeros((0, dc, dc)),
            np.zeros((0, dt, dc)), np.zeros((0, dt)), np.zeros((0, dt, dt)),
        )  # fmt: skip

    # -- shape ------------------------------------------------------------------------
    @property
    def n_experts(self) -> int:
        return len(self.log_w)

    @property
    def context_dim(self) -> int:
        return self.ctx_mean.shape[1]

    @property
    def param_dim(self) -> int:
        return self.offset.shape[1]

    def changed(self) -> None:
        """Forget cached densities; call after changing any parameter in place."""
        self._moe = None
        self._cache = None

    def add_expert(
        self,
        ctx_mean: np.ndarray,
        ctx_cov: np.ndarray,
        gain: np.ndarray,
        offset: np.ndarray,
        cov: np.ndarray,
    ) -> None:
        """Append one expert and set the weights uniform, π(o) = 1/k (Algorithm 1, lines 2–3)."""
        self.ctx_mean = np.concatenate([self.ctx_mean, np.asarray(ctx_mean, float)[None]])
        self.ctx_cov = np.concatenate([self.ctx_cov, np.asarray(ctx_cov, float)[None]])
        self.gain = np.concatenate([self.gain, np.asarray(gain, float)[None]])
        self.offset = np.concatenate([self.offset, np.asarray(offset, float)[None]])
        self.cov = np.concatenate([self.cov, np.asarray(cov, float)[None]])
        e = len(self.ctx_mean)
        self.log_w = np.full(e, -np.log(e))
        self.changed()

    def keep(self, mask: np.ndarray) -> None:
        """Keep only the experts where ``mask`` is True and renormalise π(o) (line 18)."""
        mask = np.asarray(mask, bool)
        if not mask.any():
            raise ValueError("cannot delete every expert")
        for name in ("ctx_mean", "ctx_cov", "gain", "offset", "cov"):
            setattr(self, name, getattr(self, name)[mask])
        lw = self.log_w[mask]
        self.log_w = lw - np.logaddexp.reduce(lw)
        self.changed()

    def arrays(self) -> dict[str, np.ndarray]:
        return {
            k: getattr(self, k).copy()
            for k in ("log_w", "ctx_mean", "ctx_cov", "gain", "offset", "cov")
        }

    @classmethod
    def from_arrays(cls, d: dict[str, np.ndarray]) -> MixtureModel:
        return cls(**{k: np.array(v, dtype=np.float64) for k, v in d.items()})

    # -- densities --------------------------------------------------------------------
    @property
    def moe(self) -> LinearGaussianMoE:
        """The same mixture as a :class:`vslbook.dists.LinearGaussianMoE` (torch)."""
        if self._moe is None:
            t = torch.from_numpy
            self._moe = LinearGaussianMoE(
                t(np.exp(self.log_w - np.logaddexp.reduce(self.log_w))),
                t(self.ctx_mean), t(self.ctx_cov), t(self.gain), t(self.offset), t(self.cov),
            )  # fmt: skip
        return self._moe

    def _factors(self) -> dict[str, np.ndarray]:
        """Inverse Cholesky factors and normalising constants of every Gaussian (cached)."""
        if self._cache is None:
            ctx_inv = np.linalg.inv(np.linalg.cholesky(self.ctx_cov))
            inv = np.linalg.inv(np.linalg.cholesky(self.cov))
            self._cache = {
                "ctx_inv": ctx_inv,
                "ctx_const": np.log(np.abs(np.diagonal(ctx_inv, axis1=1, axis2=2))).sum(1)
                - 0.5 * self.context_dim * np.log(2 * np.pi),
                "inv": inv,
                "const": np.log(np.abs(np.diagonal(inv, axis1=1, axis2=2))).sum(1)
                - 0.5 * self.param_dim * np.log(2 * np.pi),
            }
        return self._cache

    def _log_densities(
        self, contexts: np.ndarray, theta: np.ndarray | None, block: int = 2048
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """log π(c | o) and (if θ given) log π(θ | c, o) for every sample and expert, (n, E)."""
        f = self._factors()
        c = np.asarray(contexts, dtype=np.float64)
        log_c = np.empty((len(c), self.n_experts))
        log_t = None if theta is None else np.empty((len(c), self.n_experts))
        th = None if theta is None else np.asarray(theta, dtype=np.float64)
        ctx_inv_t = f["ctx_inv"].transpose(0, 2, 1)
        inv_t = f["inv"].transpose(0, 2, 1)
        gain_t = self.gain.transpose(0, 2, 1)
        for s in range(0, len(c), block):  # expert-major (E, n, d): one matmul per expert
            cb = c[s : s + block]
            z = (cb[None] - self.ctx_mean[:, None, :]) @ ctx_inv_t
            log_c[s : s + block] = (f["ctx_const"][:, None] - 0.5 * np.sum(z * z, -1)).T
            if log_t is not None:
                mean = cb @ gain_t + self.offset[:, None, :]
                z = (th[None, s : s + block] - mean) @ inv_t
                log_t[s : s + block] = (f["const"][:, None] - 0.5 * np.sum(z * z, -1)).T
        return log_c, log_t

    def _log_gate(self, log_c: np.ndarray) -> np.ndarray:
        joint = log_c + (self.log_w - np.logaddexp.reduce(self.log_w))
        return joint - np.logaddexp.reduce(joint, axis=1, keepdims=True)

    def log_gating(self, contexts: np.ndarray) -> np.ndarray:
        """log π(o | c) for every expert, (n, E)."""
        return self._log_gate(self._log_densities(contexts, None)[0])

    def log_responsibilities(
        self, contexts: np.ndarray, theta: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """(log π(o | c, θ), log π(o | c)), each (n, E) (the terms of Eq. 3.4).

        log π(o | c, θ) = log π(θ | c, o) + log π(o | c) − log Σ_o' π(θ | c, o') π(o' | c).
        """
        log_c, log_t = self._log_densities(contexts, theta)
        log_gate = self._log_gate(log_c)
        joint = log_t + log_gate
        return joint - np.logaddexp.reduce(joint, axis=1, keepdims=True), log_gate

    def log_prob(self, contexts: np.ndarray, theta: np.ndarray) -> np.ndarray:
        """log π(θ | c) of the mixture (Eq. 3.1), (n,)."""
        log_c, log_t = self._log_densities(contexts, theta)
        return np.logaddexp.reduce(log_t + self._log_gate(log_c), axis=1)

    def expert_entropy(self) -> np.ndarray:
        """H[π(θ | c, o)] for every expert, (E,) (independent of c)."""
        d = self.param_dim
        return 0.5 * (d * np.log(2 * np.pi * np.e) + np.linalg.slogdet(self.cov)[1])

    def context_entropy(self) -> np.ndarray:
        """H[π(c | o)] for every expert, (E,)."""
        d = self.context_dim
        return 0.5 * (d * np.log(2 * np.pi * np.e) + np.linalg.slogdet(self.ctx_cov)[1])

    # -- sampling ---------------------------------------------------------------------
    def expert_means(self, contexts: np.ndarray, experts: np.ndarray) -> np.ndarray:
        """K_o c + k_o for each (c, o) pair, (n, dθ)."""
        c = np.asarray(contexts, float)
        o = np.asarray(experts, int)
        return np.einsum("nij,nj->ni", self.gain[o], c) + self.offset[o]

    def sample_experts(self, contexts: np.ndarray, experts: np.ndarray, rng) -> np.ndarray:
        """θ ~ π(θ | c, o) for each (c, o) pair, (n, dθ)."""
        o = np.asarray(experts, int)
        noise = rng.standard_normal((len(o), self.param_dim))
        return self.expert_means(contexts, o) + np.einsum("nij,nj->ni", _chol(self.cov)[o], noise)

    def sample_curriculum(self, expert: int, n: int, rng) -> tuple[np.ndarray, np.ndarray]:
        """n pairs c ~ π(c | o), θ ~ π(θ | c, o) from one expert (how SVSL explores)."""
        noise = rng.standard_normal((n, self.context_dim))
        c = self.ctx_mean[expert] + noise @ _chol(self.ctx_cov[expert]).T
        return c, self.sample_experts(c, np.full(n, expert), rng)

    def choose_experts(
        self, contexts: np.ndarray, rng, *, exclude: np.ndarray | None = None
    ) -> np.ndarray:
        """o ~ π(o | c) for each context (optionally never choosing the experts in ``exclude``)."""
        log_gate = self.log_gating(contexts)
        if exclude is not None and len(exclude) and len(exclude) < self.n_experts:
            log_gate[:, np.asarray(exclude, int)] = -np.inf
            log_gate -= np.logaddexp.reduce(log_gate, axis=1, keepdims=True)
        p = np.exp(log_gate)
        u = rng.random(len(p))[:, None]
        return np.minimum((np.cumsum(p, axis=1) < u).sum(axis=1), self.n_experts - 1)

    def sample(
        self, contexts: np.ndarray, rng, *, exclude: np.ndarray | None = None, mean: bool = False
    ) -> tuple[np.ndarray, np.ndarray]:
        """θ ~ π(θ | c) (Eq. 3.1): o ~ π(o | c), then θ ~ π(θ | c, o) or its mean.

        Returns (θ (n, dθ), o (n,)).
        """
        o = self.choose_experts(contexts, rng, exclude=exclude)
        th = self.expert_means(contexts, o) if mean else self.sample_experts(contexts, o, rng)
        return th, o

    def expected_entropy(self, contexts: np.ndarray, n_samples: int, rng) -> np.ndarray:
        """Monte-Carlo H[π(θ | c)] of the mixture per context, (n,) (Figs. A.1, A.2).

        ``n_samples`` draws θ ~ π(θ | c) per context; H ≈ −mean log π(θ | c).
        """
        c = np.asarray(contexts, float)
        rep = np.repeat(c, n_samples, axis=0)
        th, _ = self.sample(rep, rng)
        return -self.log_prob(rep, th).reshape(len(c), n_samples).mean(axis=1)

"""Gaussian mixtures and contextual mixtures of linear-Gaussian experts (thesis Section 2.6.2).

A mixture writes ``p(x) = sum_o p(o) p(x | o)`` (Eq. 2.47). Its contextual version, the
mixture of experts (MoE) of Eq. 2.48, reads ``pi(theta | c) = sum_o pi(o | c) pi(theta | c, o)``
with Gaussian experts (Eq. 2.49). The MoE used in Chapter 3 gives every expert its own context
distribution ``p(c | o)``; the gating then follows from Bayes' rule,
``pi(o | c) = p(c | o) p(o) / sum_o' p(c | o') p(o')``, the same posterior as the E-step of
Eq. 2.64. All densities are combined in log space with log-sum-exp.

Shapes: ``K`` components, ``d`` data dimensions. ``log_weights`` has shape ``(..., K)``,
``means`` ``(..., K, d)`` and ``covs`` ``(..., K, d, d)``.
"""

from __future__ import annotations

import math

import torch

from vslbook.dists.gaussian import (
    Tensor,
    TensorLike,
    as_floats,
    check_mean_cov,
    cholesky,
    dtype_tolerance,
    gaussian_log_prob,
)


def _check_mixture(x: Tensor, log_weights: Tensor, means: Tensor, covs: Tensor) -> None:
    if log_weights.ndim < 1:
        raise ValueError("log_weights must have shape (..., K), got a scalar")
    k = log_weights.shape[-1]
    if means.ndim < 2 or means.shape[-2] != k:
        raise ValueError(
            f"means must have shape (..., {k}, d) to match log_weights of shape "
            f"{tuple(log_weights.shape)}, got {tuple(means.shape)}"
        )
    d = check_mean_cov(means, covs, "means", "covs")
    if x.ndim < 1 or x.shape[-1] != d:
        raise ValueError(f"x must have shape (..., {d}) to match means, got {tuple(x.shape)}")
    _check_log_normalised(log_weights, "log_weights")


def _check_log_normalised(log_probs: Tensor, name: str) -> None:
    total = torch.logsumexp(log_probs, dim=-1)
    worst = total.abs().amax() if total.numel() else total.new_tensor(0.0)
    tol = dtype_tolerance(log_probs.dtype)
    if not bool(worst <= tol) or bool((log_probs > tol).any()):
        raise ValueError(
            f"{name} must be normalised log-probabilities (logsumexp over the last dimension "
            f"= 0, i.e. weights summing to 1); got logsumexp off by {float(worst):.3g}"
        )


def _check_probabilities(probs: Tensor, name: str) -> None:
    if probs.ndim < 1:
        raise ValueError(f"{name} must have shape (..., K), got a scalar")
    if bool((probs < 0).any()):
        raise ValueError(f"{name} must be non-negative, got minimum {float(probs.min()):.3g}")
    total = probs.sum(-1)
    worst = (total - 1).abs().amax() if total.numel() else total.new_tensor(0.0)
    if not bool(worst <= dtype_tolerance(probs.dtype)):
        raise ValueError(
            f"{name} must sum to 1 over the last dimension; the sums are off by up to "
            f"{float(worst):.3g}"
        )


def component_log_probs(
    x: TensorLike, log_weights: TensorLike, means: TensorLike, covs: TensorLike
) -> Tensor:
    """Joint log densities ``log p(o) + log N(x | mu_o, Sigma_o)``, shape ``(..., K)``."""
    x, log_weights, means, covs = as_floats(x=x, log_weights=log_weights, means=means, covs=covs)
    _check_mixture(x, log_weights, means, covs)
    return log_weights + gaussian_log_prob(x.unsqueeze(-2), means, covs)


def moe_log_prob(
    x: TensorLike, log_weights: TensorLike, means: TensorLike, covs: TensorLike
) -> Tensor:
    """Log density of a Gaussian mixture, ``log sum_o p(o) N(x | mu_o, Sigma_o)`` (Eq. 2.47).

    Args:
        x: points, shape ``(..., d)``.
        log_weights: ``log p(o)``, shape ``(..., K)``; must be normalised.
        means: component means, shape ``(..., K, d)``.
        covs: component covariances, shape ``(..., K, d, d)``.

    Returns:
        ``log p(x)`` of the broadcast batch shape.
    """
    return torch.logsumexp(component_log_probs(x, log_weights, means, covs), dim=-1)


def log_responsibilities(
    x: TensorLike, log_weights: TensorLike, means: TensorLike, covs: TensorLike
) -> Tensor:
    """``log p(o | x)`` by Bayes' rule (Eq. 2.64), shape ``(..., K)``."""
    joint = component_log_probs(x, log_weights, means, covs)
    return joint - torch.logsumexp(joint, dim=-1, keepdim=True)


def responsibilities(
    x: TensorLike, log_weights: TensorLike, means: TensorLike, covs: TensorLike
) -> Tensor:
    """Posterior ``p(o | x) = p(x | o) p(o) / sum_o' p(x | o') p(o')`` (Eq. 2.64).

    Returns:
        Probabilities of shape ``(..., K)`` summing to 1 over the last dimension.
    """
    return log_responsibilities(x, log_weights, means, covs).exp()


def categorical_entropy(probs: TensorLike) -> Tensor:
    """Entropy ``-sum_o p(o) log p(o)`` of categorical distributions (with ``0 log 0 = 0``).

    Args:
        probs: probabilities, shape ``(..., K)``, non-negative and summing to 1.

    Returns:
        Entropies in nats, shape ``(...)``.
    """
    (probs,) = as_floats(probs=probs)
    _check_probabilities(probs, "probs")
    return -torch.special.xlogy(probs, probs).sum(-1)


class LinearGaussianMoE:
    """Mixture of linear-Gaussian experts with per-expert context Gaussians (Eqs. 2.48-2.49).

    The generative model over contexts ``c`` (dimension ``dc``) and parameters ``theta``
    (dimension ``dt``) is

    * ``o ~ p(o)`` with weights ``weights``,
    * ``c | o ~ N(context_means[o], context_covs[o])``,
    * ``theta | c, o ~ N(gains[o] @ c + offsets[o], covs[o])``.

    The gating ``pi(o | c)`` is the Bayes posterior of the first two factors.

    Args:
        weights: ``p(o)``, shape ``(K,)``, non-negative and summing to 1.
        context_means: shape ``(K, dc)``.
        context_covs: shape ``(K, dc, dc)``, positive definite.
        gains: ``K_o``, shape ``(K, dt, dc)``.
        offsets: ``k_o``, shape ``(K, dt)``.
        covs: expert covariances ``Sigma_o``, shape ``(K, dt, dt)``, positive definite.
    """

    def __init__(
        self,
        weights: TensorLike,
        context_means: TensorLike,
        context_covs: TensorLike,
        gains: TensorLike,
        offsets: TensorLike,
        covs: TensorLike,
    ) -> None:
        weights, context_means, context_covs, gains, offsets, covs = as_floats(
            weights=weights,
            context_means=context_means,
            context_covs=context_covs,
            gains=gains,
            offsets=offsets,
            covs=covs,
        )
        if weights.ndim != 1:
            raise ValueError(f"weights must have shape (K,), got {tuple(weights.shape)}")
        _check_probabilities(weights, "weights")
        k = weights.shape[0]
        if context_means.ndim != 2 or context_means.shape[0] != k:
            raise ValueError(
                f"context_means must have shape ({k}, dc), got {tuple(context_means.shape)}"
            )
        dc = context_means.shape[1]
        if context_covs.shape != (k, dc, dc):
            raise ValueError(
                f"context_covs must have shape ({k}, {dc}, {dc}), got {tuple(context_covs.shape)}"
            )
        if offsets.ndim != 2 or offsets.shape[0] != k:
            raise ValueError(f"offsets must have shape ({k}, dt), got {tuple(offsets.shape)}")
        dt = offsets.shape[1]
        if gains.shape != (k, dt, dc):
            raise ValueError(f"gains must have shape ({k}, {dt}, {dc}), got {tuple(gains.shape)}")
        if covs.shape != (k, dt, dt):
            raise ValueError(f"covs must have shape ({k}, {dt}, {dt}), got {tuple(covs.shape)}")
        self.weights = weights
        self.log_weights = torch.log(weights)
        self.context_means = context_means
        self.context_covs = context_covs
        self.gains = gains
        self.offsets = offsets
        self.covs = covs
        self._context_chol = cholesky(context_covs, "context_covs")
        self._chol = cholesky(covs, "covs")

    @classmethod
    def random(
        cls,
        n_components: int,
        context_dim: int,
        param_dim: int,
        seed: int = 0,
        dtype: torch.dtype = torch.float64,
    ) -> LinearGaussianMoE:
        """A well-conditioned random model, reproducible from ``seed`` (for demos and tests)."""
        for name, value in (
            ("n_components", n_components),
            ("context_dim", context_dim),
            ("param_dim", param_dim),
        ):
            if not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} must be a positive integer, got {value!r}")
        g = torch.Generator().manual_seed(seed)
        k, dc, dt = n_components, context_dim, param_dim

        def spd(dim: int, scale: float) -> Tensor:
            a = torch.randn(k, dim, dim, generator=g, dtype=dtype) / math.sqrt(dim)
            return scale * (a @ a.mT + 0.3 * torch.eye(dim, dtype=dtype))

        weights = torch.softmax(torch.randn(k, generator=g, dtype=dtype), dim=0)
        return cls(
            weights=weights,
            context_means=2.0 * torch.randn(k, dc, generator=g, dtype=dtype),
            context_covs=spd(dc, 0.5),
            gains=torch.randn(k, dt, dc, generator=g, dtype=dtype),
            offsets=torch.randn(k, dt, generator=g, dtype=dtype),
            covs=spd(dt, 0.3),
        )

    @property
    def n_components(self) -> int:
        return self.weights.shape[0]

    @property
    def context_dim(self) -> int:
        return self.context_means.shape[1]

    @property
    def param_dim(self) -> int:
        return self.offsets.shape[1]

    @property
    def dtype(self) -> torch.dtype:
        return self.weights.dtype

    def _as_input(self, value: TensorLike, dim: int, name: str) -> Tensor:
        value = torch.as_tensor(value, dtype=self.dtype)
        if value.ndim < 1 or value.shape[-1] != dim:
            raise ValueError(f"{name} must have shape (..., {dim}), got {tuple(value.shape)}")
        return value

    def context_component_log_prob(self, c: TensorLike) -> Tensor:
        """``log p(c | o)`` for every expert, shape ``(..., K)``."""
        c = self._as_input(c, self.context_dim, "c")
        return gaussian_log_prob(c.unsqueeze(-2), self.context_means, self.context_covs)

    def context_log_prob(self, c: TensorLike) -> Tensor:
        """Log of the context marginal ``p(c) = sum_o p(o) p(c | o)``, shape ``(...)``."""
        return torch.logsumexp(self.context_component_log_prob(c) + self.log_weights, dim=-1)

    def log_gating(self, c: TensorLike) -> Tensor:
        """``log pi(o | c) = log p(c | o) + log p(o) - log p(c)`` (Bayes), shape ``(..., K)``."""
        joint = self.context_component_log_prob(c) + self.log_weights
        return joint - torch.logsumexp(joint, dim=-1, keepdim=True)

    def gating(self, c: TensorLike) -> Tensor:
        """Gating ``pi(o | c) ∝ p(c | o) p(o)`` of Eq. 2.48, shape ``(..., K)``."""
        return self.log_gating(c).exp()

    def expert_means(self, c: TensorLike) -> Tensor:
        """Expert means ``K_o c + k_o``, shape ``(..., K, dt)``."""
        c = self._as_input(c, self.context_dim, "c")
        return (self.gains @ c.unsqueeze(-2).unsqueeze(-1)).squeeze(-1) + self.offsets

    def expert_log_prob(self, theta: TensorLike, c: TensorLike) -> Tensor:
        """``log pi(theta | c, o)`` for every expert (Eq. 2.49), shape ``(..., K)``."""
        theta = self._as_input(theta, self.param_dim, "theta")
        return gaussian_log_prob(theta.unsqueeze(-2), self.expert_means(c), self.covs)

    def log_prob(self, theta: TensorLike, c: TensorLike) -> Tensor:
        """``log pi(theta | c) = log sum_o pi(o | c) pi(theta | c, o)`` (Eq. 2.48)."""
        return torch.logsumexp(self.log_gating(c) + self.expert_log_prob(theta, c), dim=-1)

    def joint_log_prob(self, theta: TensorLike, c: TensorLike) -> Tensor:
        """``log p(theta, c) = log sum_o p(o) p(c | o) pi(theta | c, o)``.

        Equals ``log_prob(theta, c) + context_log_prob(c)``.
        """
        joint = self.log_weights + self.context_component_log_prob(c)
        return torch.logsumexp(joint + self.expert_log_prob(theta, c), dim=-1)

    def sample(
        self, c: TensorLike, generator: torch.Generator | None = None
    ) -> tuple[Tensor, Tensor]:
        """Draw ``o ~ pi(o | c)`` and then ``theta ~ pi(theta | c, o)``, one per context.

        Args:
            c: contexts, shape ``(..., dc)``.
            generator: torch random generator for reproducible draws.

        Returns:
            ``(theta, o)``: parameters of shape ``(..., dt)`` and the chosen experts (int64)
            of shape ``(...)``.
        """
        c = self._as_input(c, self.context_dim, "c")
        batch = c.shape[:-1]
        probs = self.gating(c).reshape(-1, self.n_components)
        o = torch.multinomial(probs, 1, generator=generator).reshape(batch)
        means = self.expert_means(c)
        mean = torch.gather(
            means, -2, o[..., None, None].expand(*batch, 1, self.param_dim)
        ).squeeze(-2)
        eps = torch.randn(*batch, self.param_dim, generator=generator, dtype=self.dtype)
        theta = mean + (self._chol[o] @ eps.unsqueeze(-1)).squeeze(-1)
        return theta, o

    def sample_contexts(
        self, n: int, generator: torch.Generator | None = None
    ) -> tuple[Tensor, Tensor]:
        """Draw ``n`` contexts from ``p(c) = sum_o p(o) p(c | o)``.

        Returns:
            ``(c, o)``: contexts of shape ``(n, dc)`` and the components they came from.
        """
        if not isinstance(n, int) or n < 1:
            raise ValueError(f"n must be a positive integer, got {n!r}")
        o = torch.multinomial(self.weights, n, replacement=True, generator=generator)
        eps = torch.randn(n, self.context_dim, generator=generator, dtype=self.dtype)
        c = self.context_means[o] + (self._context_chol[o] @ eps.unsqueeze(-1)).squeeze(-1)
        return c, o

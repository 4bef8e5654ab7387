"""Tanh-Gaussian policy (SAC / CrossQ style) for the "Gaussian vs diffusion" ablation (Fig. 5.4).

x = μ(s) + σ(s) ε, a = tanh(x), with the exact log-density

    log π(a|s) = log N(x; μ(s), σ(s)²) - Σ_d log(1 - tanh² x_d).

``sample`` returns the same ``PolicySample`` as ``DiffusionPolicy`` with
``running_cost = log π(a|s)`` and ``terminal_cost = 0``, so ``entropy_bound = -log π(a|s)``
(here an unbiased single-sample entropy estimate, not only a bound) and the actor update
mean(-Q + α (running_cost + terminal_cost)) is SAC's.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor, nn

from vslbook.srl.diffusion_policy import PolicySample, tanh_log_det_jacobian


class GaussianPolicy(nn.Module):
    """MLP trunk (``n_layers`` x [Linear, ReLU]) with mean and log-std heads.

    The log-std is clipped to ``log_std_bounds``; Table C.3 uses 3 layers of 256 units.
    """

    def __init__(
        self,
        obs_dim: int,
        act_dim: int,
        hidden: int = 256,
        n_layers: int = 3,
        log_std_bounds: tuple[float, float] = (-20.0, 2.0),
    ) -> None:
        super().__init__()
        if obs_dim < 1 or act_dim < 1:
            raise ValueError(f"obs_dim and act_dim must be >= 1, got {obs_dim}, {act_dim}")
        if hidden < 1 or n_layers < 1:
            raise ValueError(f"hidden and n_layers must be >= 1, got {hidden}, {n_layers}")
        if not log_std_bounds[0] < log_std_bounds[1]:
            raise ValueError(f"log_std_bounds must be (low, high) with low < high, "
                             f"got {log_std_bounds}")
        self.act_dim = act_dim
        self.log_std_bounds = log_std_bounds
        layers: list[nn.Module] = []
        width = obs_dim
        for _ in range(n_layers):
            layers += [nn.Linear(width, hidden), nn.ReLU()]
            width = hidden
        self.trunk = nn.Sequential(*layers)
        self.mean = nn.Linear(width, act_dim)
        self.log_std = nn.Linear(width, act_dim)

    def distribution(self, obs: Tensor) -> tuple[Tensor, Tensor]:
        """Mean and log-std of the pre-tanh Gaussian, each (B, act_dim)."""
        h = self.trunk(obs)
        return self.mean(h), self.log_std(h).clamp(*self.log_std_bounds)

    def forward(
        self, obs: Tensor, deterministic: bool = False, noise: Tensor | None = None
    ) -> PolicySample:
        return self.sample(obs, deterministic, noise=noise)

    def noise_shape(self, batch: int) -> tuple[int, int]:
        """Shape of the ``noise`` (ε) :meth:`sample` takes."""
        return (batch, self.act_dim)

    def sample(
        self,
        obs: Tensor,
        deterministic: bool = False,
        generator: torch.Generator | None = None,
        noise: Tensor | None = None,
    ) -> PolicySample:
        """Reparameterised a = tanh(μ + σ ε); ``deterministic`` uses ε = 0 (a = tanh μ).

        ``generator`` seeds ε, or ``noise`` (:meth:`noise_shape`) is ε itself."""
        obs_dim = self.trunk[0].in_features
        if obs.ndim != 2 or obs.shape[1] != obs_dim:  # shapes only: no host sync
            raise ValueError(
                f"obs must have shape (batch, obs_dim) = (batch, {obs_dim}), "
                f"got {tuple(obs.shape)}"
            )
        mean, log_std = self.distribution(obs)
        if deterministic:
            eps = torch.zeros_like(mean)
        elif noise is not None:
            if tuple(noise.shape) != tuple(mean.shape):
                raise ValueError(
                    f"noise must have shape {tuple(mean.shape)}, got {tuple(noise.shape)}"
                )
            eps = noise
        else:
            eps = torch.randn(mean.shape, generator=generator, device=mean.device,
                              dtype=mean.dtype)
        x = mean + log_std.exp() * eps
        log_prob = (-0.5 * eps**2 - log_std - 0.5 * math.log(2.0 * math.pi)).sum(dim=-1)
        log_prob = log_prob - tanh_log_det_jacobian(x)
        return PolicySample(torch.tanh(x), log_prob, torch.zeros_like(log_prob), x)

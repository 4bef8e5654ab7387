"""Batch Renormalization (Ioffe, 2017), the normalisation layer of the CrossQ critic.

During training, a batch x with statistics μ_B, σ_B = sqrt(var_B + ε) is normalised as

    x̂ = (x - μ_B) / σ_B · r + d,   r = clip(σ_B / σ, 1/r_max, r_max),
                                   d = clip((μ_B - μ) / σ, -d_max, d_max),

with σ = sqrt(running_var + ε), μ = running_mean and no gradient through r and d. With r = 1,
d = 0 this is plain batch norm, which is what the layer does for its first ``warmup_steps``
training passes while the running statistics settle (DIME / CrossQ: 100k critic updates).
In eval mode it normalises with the running statistics only.
"""

from __future__ import annotations

import torch
from torch import Tensor, nn


class BatchRenorm1d(nn.Module):
    """Batch Renormalization over the feature dimension of a ``(batch, num_features)`` input.

    Args:
        num_features: size of the feature dimension.
        momentum: decay of the running statistics, *Flax / CrossQ convention*:
            ``running = momentum * running + (1 - momentum) * batch``. This is
            ``torch.nn.BatchNorm1d(momentum=1 - momentum)`` in PyTorch's convention.
        eps: added to the variance before the square root.
        r_max, d_max: clipping bounds of the renormalisation factors r and d.
        warmup_steps: number of training-mode forward passes that use plain batch norm
            (r = 1, d = 0) before renormalisation starts. The count is the buffer ``steps``,
            so it survives ``state_dict`` round trips.

    As in ``torch.nn.BatchNorm1d``, the output uses the biased batch variance and the running
    variance is updated with the unbiased one; during warm-up the layer therefore matches
    ``BatchNorm1d`` exactly, in train and in eval mode.
    """

    def __init__(
        self,
        num_features: int,
        momentum: float = 0.99,
        eps: float = 1e-3,
        r_max: float = 3.0,
        d_max: float = 5.0,
        warmup_steps: int = 100_000,
    ) -> None:
        super().__init__()
        if num_features < 1:
            raise ValueError(f"num_features must be >= 1, got {num_features}")
        if not 0.0 <= momentum < 1.0:
            raise ValueError(f"momentum must be in [0, 1), got {momentum}")
        if eps <= 0:
            raise ValueError(f"eps must be > 0, got {eps}")
        if r_max < 1.0 or d_max < 0.0:
            raise ValueError(f"need r_max >= 1 and d_max >= 0, got r_max={r_max}, d_max={d_max}")
        if warmup_steps < 0:
            raise ValueError(f"warmup_steps must be >= 0, got {warmup_steps}")
        self.num_features = num_features
        self.momentum = momentum
        self.eps = eps
        self.r_max = r_max
        self.d_max = d_max
        self.warmup_steps = warmup_steps
        self.weight = nn.Parameter(torch.ones(num_features))
        self.bias = nn.Parameter(torch.zeros(num_features))
        self.register_buffer("running_mean", torch.zeros(num_features))
        self.register_buffer("running_var", torch.ones(num_features))
        self.register_buffer("steps", torch.zeros((), dtype=torch.long))

    @property
    def renormalizing(self) -> bool:
        """True once the warm-up is over, i.e. the next training pass uses r and d."""
        return int(self.steps) >= self.warmup_steps

    def forward(self, x: Tensor) -> Tensor:
        """Normalise ``x`` (batch, num_features); in training mode update the statistics.

        Written as one affine map per feature, x ↦ x · a + c, so that only a single
        operation touches the (batch, features) tensor in each direction (the updates of
        small critics are dominated by such per-element passes): in training
        a = γ r / σ_B and c = β + γ (d - μ_B r / σ_B), which is γ((x - μ_B)/σ_B · r + d) + β
        with the gradient flowing through μ_B and σ_B (not r, d); in eval mode a = γ / σ and
        c = β - μ a.
        """
        if x.dim() != 2 or x.shape[1] != self.num_features:
            raise ValueError(f"expected input (batch, {self.num_features}), got {tuple(x.shape)}")
        if not self.training:
            scale = self.weight * torch.rsqrt(self.running_var + self.eps)
            return torch.addcmul(self.bias - self.running_mean * scale, x, scale)

        var, mean = torch.var_mean(x, dim=0, unbiased=False)
        inv_std = torch.rsqrt(var + self.eps)
        with torch.no_grad():  # stop-gradient through r and d (Ioffe 2017, Alg. 1)
            inv_running_std = torch.rsqrt(self.running_var + self.eps)
            r = (inv_std.detach().reciprocal() * inv_running_std).clamp(
                1.0 / self.r_max, self.r_max
            )
            d = ((mean.detach() - self.running_mean) * inv_running_std).clamp(
                -self.d_max, self.d_max
            )
            # r = 1, d = 0 during warm-up; a tensor test, so no host sync on accelerators
            warm = self.steps >= self.warmup_steps
            r = torch.where(warm, r, torch.ones_like(r))
            d = torch.where(warm, d, torch.zeros_like(d))
            n = x.shape[0]
            m = self.momentum  # (lerp_ would do, but has no vmap batching rule)
            self.running_mean.mul_(m).add_(mean.detach(), alpha=1.0 - m)
            self.running_var.mul_(m).add_(var.detach(), alpha=(1.0 - m) * n / max(n - 1, 1))
            self.steps.add_(1)
        scale = self.weight * r * inv_std
        shift = self.bias + self.weight * (d - mean * r * inv_std)
        return torch.addcmul(shift, x, scale)

    def extra_repr(self) -> str:
        return (
            f"{self.num_features}, momentum={self.momentum}, eps={self.eps}, "
            f"r_max={self.r_max}, d_max={self.d_max}, warmup_steps={self.warmup_steps}"
        )

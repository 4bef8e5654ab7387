"""CrossQ-style critics for DIME (Section 5.4.4, Appendix C.4).

Each critic is an MLP on concat(s, a):

    [BatchRenorm] -> ([Linear, ReLU, BatchRenorm] x n_layers) -> Linear(out)

with ``out = n_atoms`` logits (distributional, C51) or ``out = 1`` (scalar Q for the
Bellman-residual ablation, Eq. 5.24). CrossQ keeps no target network: the current and next
state-actions go through each critic as *one* batch (``DoubleCritic.joint_forward``) so the
batch statistics are shared, and the caller stops gradients on the next-state half. With
``use_batchrenorm=False`` the critic is a plain MLP meant to be paired with a Polyak-averaged
target network (``polyak_update``), as in the point-mass experiment of Fig. 5.7.
"""

from __future__ import annotations

from collections.abc import Mapping

import torch
from torch import Tensor, nn

from vslbook.srl.batchrenorm import BatchRenorm1d


def critic_mlp(
    in_dim: int,
    out_dim: int,
    hidden: int = 2048,
    n_layers: int = 2,
    use_batchrenorm: bool = True,
    normalize_input: bool = True,
    renorm_kwargs: Mapping[str, float] | None = None,
) -> nn.Sequential:
    """The critic trunk and head; ``normalize_input`` adds a BatchRenorm on concat(s, a).

    ``renorm_kwargs`` go to every ``BatchRenorm1d`` (momentum, eps, r_max, d_max,
    warmup_steps); the input normalisation is only used together with ``use_batchrenorm``.
    """
    if in_dim < 1 or out_dim < 1:
        raise ValueError(f"in_dim and out_dim must be >= 1, got {in_dim}, {out_dim}")
    if hidden < 1 or n_layers < 1:
        raise ValueError(f"hidden and n_layers must be >= 1, got {hidden}, {n_layers}")
    kwargs = dict(renorm_kwargs or {})
    layers: list[nn.Module] = []
    if use_batchrenorm and normalize_input:
        layers.append(BatchRenorm1d(in_dim, **kwargs))
    width = in_dim
    for _ in range(n_layers):
        layers += [nn.Linear(width, hidden), nn.ReLU()]
        if use_batchrenorm:
            layers.append(BatchRenorm1d(hidden, **kwargs))
        width = hidden
    layers.append(nn.Linear(width, out_dim))
    return nn.Sequential(*layers)


class DistributionalCritic(nn.Module):
    """Q(s, a) as logits over ``n_atoms`` return atoms (softmax gives the C51 probabilities)."""

    def __init__(
        self,
        obs_dim: int,
        act_dim: int,
        hidden: int = 2048,
        n_atoms: int = 101,
        use_batchrenorm: bool = True,
        n_layers: int = 2,
        normalize_input: bool = True,
        renorm_kwargs: Mapping[str, float] | None = None,
    ) -> None:
        super().__init__()
        if n_atoms < 2:
            raise ValueError(f"n_atoms must be >= 2, got {n_atoms}")
        self.n_atoms = n_atoms
        self.net = critic_mlp(
            obs_dim + act_dim, n_atoms, hidden, n_layers, use_batchrenorm, normalize_input,
            renorm_kwargs,
        )

    def forward(self, obs: Tensor, act: Tensor) -> Tensor:
        """Logits of shape (B, n_atoms)."""
        return self.net(torch.cat([obs, act], dim=-1))


class ScalarCritic(nn.Module):
    """Q(s, a) as a single number, same trunk (Bellman-residual ablation, Eq. 5.24)."""

    def __init__(
        self,
        obs_dim: int,
        act_dim: int,
        hidden: int = 2048,
        use_batchrenorm: bool = True,
        n_layers: int = 2,
        normalize_input: bool = True,
        renorm_kwargs: Mapping[str, float] | None = None,
    ) -> None:
        super().__init__()
        self.net = critic_mlp(
            obs_dim + act_dim, 1, hidden, n_layers, use_batchrenorm, normalize_input,
            renorm_kwargs,
        )

    def forward(self, obs: Tensor, act: Tensor) -> Tensor:
        """Q-values of shape (B,)."""
        return self.net(torch.cat([obs, act], dim=-1)).squeeze(-1)


class DoubleCritic(nn.Module):
    """Two independent critics; outputs are stacked along a leading dimension of size 2.

    ``distributional=True`` gives logits (2, B, n_atoms), otherwise Q-values (2, B). Other
    keyword arguments go to ``DistributionalCritic`` / ``ScalarCritic``. DIME combines the two
    with the *mean* (not the min) in the target and in the actor loss (Appendix C.4).
    """

    def __init__(
        self,
        obs_dim: int,
        act_dim: int,
        hidden: int = 2048,
        n_atoms: int = 101,
        use_batchrenorm: bool = True,
        distributional: bool = True,
        **critic_kwargs,
    ) -> None:
        super().__init__()
        self.distributional = distributional
        critic_cls = DistributionalCritic if distributional else ScalarCritic
        if distributional:
            critic_kwargs["n_atoms"] = n_atoms
        self.critics = nn.ModuleList(
            critic_cls(obs_dim, act_dim, hidden=hidden, use_batchrenorm=use_batchrenorm,
                       **critic_kwargs)
            for _ in range(2)
        )

    def forward(self, obs: Tensor, act: Tensor) -> Tensor:
        return torch.stack([critic(obs, act) for critic in self.critics])

    def joint_forward(
        self, obs: Tensor, act: Tensor, next_obs: Tensor, next_act: Tensor
    ) -> tuple[Tensor, Tensor]:
        """CrossQ's joint batch: one pass on concat([(s, a), (s', a')]), split back.

        Returns ``(current, next)`` with batch sizes B and B'. In training mode the
        normalisation layers see one batch of B + B' rows and update their running statistics
        once. Detach ``next`` before building the Bellman target.
        """
        out = self(torch.cat([obs, next_obs]), torch.cat([act, next_act]))
        return out[:, : obs.shape[0]], out[:, obs.shape[0] :]


@torch.no_grad()
def polyak_update(target: nn.Module, online: nn.Module, tau: float) -> None:
    """target <- (1 - tau) target + tau online, for parameters and floating-point buffers."""
    if not 0.0 < tau <= 1.0:
        raise ValueError(f"tau must be in (0, 1], got {tau}")
    pairs = list(zip(target.parameters(), online.parameters(), strict=True))
    pairs += [
        (t, o) for t, o in zip(target.buffers(), online.buffers(), strict=True)
        if t.is_floating_point()
    ]
    for t, o in pairs:
        t.lerp_(o, tau)

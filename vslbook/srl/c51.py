"""Categorical (C51) return distributions: fixed support, projection and loss.

DIME's critic outputs a distribution over ``n_atoms`` fixed return values
z_i = v_min + i Δz, Δz = (v_max - v_min) / (n_atoms - 1) (Bellemare et al., 2017; Appendix C.4).
The distributional Bellman target (Eq. 5.21) moves every atom of the next-state distribution to

    Tz_i = r + γ (1 - done) (z_i + α ℓ(s')),     ℓ(s') = entropy bound of the policy at s',

which no longer lies on the support; ``CategoricalSupport.project`` splits each moved atom's
mass linearly between its two neighbouring atoms. ``categorical_loss`` is the cross-entropy
to the projected target with a small entropy term on the prediction.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor, nn


class CategoricalSupport(nn.Module):
    """The atoms z = linspace(v_min, v_max, n_atoms) (a buffer, so it follows ``.to(device)``).

    Table C.3 ranges: ±200 (DMC), ±1600 (gymnasium locomotion), ±3600 (MyoSuite).
    """

    def __init__(self, v_min: float, v_max: float, n_atoms: int = 101) -> None:
        super().__init__()
        if not v_min < v_max:
            raise ValueError(f"need v_min < v_max, got v_min={v_min}, v_max={v_max}")
        if n_atoms < 2:
            raise ValueError(f"n_atoms must be >= 2, got {n_atoms}")
        self.v_min = float(v_min)
        self.v_max = float(v_max)
        self.n_atoms = int(n_atoms)
        self.delta = (self.v_max - self.v_min) / (self.n_atoms - 1)
        self.register_buffer("atoms", torch.linspace(self.v_min, self.v_max, self.n_atoms))

    def mean(self, probs: Tensor) -> Tensor:
        """Expected value Σ_i p_i z_i of distributions ``(..., n_atoms)`` -> ``(...)``."""
        return (probs * self.atoms.to(probs)).sum(dim=-1)

    def bellman_atoms(
        self, reward: Tensor, done: Tensor, gamma: float, entropy_bonus: Tensor | None = None
    ) -> Tensor:
        """Target atom positions Tz = r + γ(1 - done)(z + bonus), shape ``(B, n_atoms)``.

        ``entropy_bonus`` (B,) is α times the policy's entropy bound at s', i.e.
        ``alpha * sample.entropy_bound = -alpha * (running_cost + terminal_cost)`` (Eq. 5.21).
        """
        atoms = self.atoms.to(reward)
        soft_atoms = atoms if entropy_bonus is None else atoms + entropy_bonus[:, None]
        return reward[:, None] + gamma * (1.0 - done.to(reward))[:, None] * soft_atoms

    def project(self, values: Tensor, probs: Tensor) -> Tensor:
        """Project mass ``probs`` (B, n_atoms) sitting at ``values`` (B, n_atoms) onto the support.

        Values are clipped to [v_min, v_max]; an atom at fractional index b = (Tz - v_min)/Δz
        gives (u - b) of its mass to atom l = floor(b) and (b - l) to atom u = ceil(b). Writing
        the lower weight as 1 - (b - l) also covers the exact hit l == u (all mass to l).
        Returns distributions on the support, shape (B, n_atoms); rows keep their total mass.
        A row with a NaN value (a diverged target) comes back as NaNs, so the loss shows the
        divergence instead of the scatter failing on an invalid index.
        """
        if values.shape != probs.shape or values.shape[-1] != self.n_atoms:
            raise ValueError(
                f"values and probs must both be (B, {self.n_atoms}), "
                f"got {tuple(values.shape)} and {tuple(probs.shape)}"
            )
        b = (values.clamp(self.v_min, self.v_max) - self.v_min) / self.delta
        b = b.clamp(0.0, self.n_atoms - 1)  # guard against rounding just past the ends
        nan = b.isnan()  # clamp keeps NaN (±inf go to the ends)
        b = b.masked_fill(nan, 0.0)
        lower = b.floor()
        upper = b.ceil()
        upper_weight = b - lower
        projected = torch.zeros_like(probs)
        projected.scatter_add_(-1, lower.long(), probs * (1.0 - upper_weight))
        projected.scatter_add_(-1, upper.long(), probs * upper_weight)
        return projected.masked_fill(nan.any(dim=-1, keepdim=True), float("nan"))


def categorical_loss(logits: Tensor, target_probs: Tensor, entropy_coef: float = 0.005) -> Tensor:
    """Cross-entropy to the projected target minus ``entropy_coef`` times the prediction entropy.

    Per row: -Σ_i q_i log p_i - c · H(p), H(p) = -Σ_i p_i log p_i, p = softmax(logits); the
    result is averaged over the batch dimension (the second-to-last one) and summed over any
    leading ensemble dimensions, so logits (2, B, n) against targets (B, n) give
    loss(Q1) + loss(Q2). A positive ``entropy_coef`` rewards spread-out predictions; this is
    the sign of the authors' released training code. Appendix C.4 prints the term as
    -0.005 Σ p log p = +0.005 H(p); pass a negative ``entropy_coef`` to get that form.
    """
    if logits.dim() < 2:
        raise ValueError(f"logits must be (..., batch, n_atoms), got {tuple(logits.shape)}")
    log_p = F.log_softmax(logits, dim=-1)
    cross_entropy = -(target_probs * log_p).sum(dim=-1)
    entropy = -(log_p.exp() * log_p).sum(dim=-1)
    return (cross_entropy - entropy_coef * entropy).mean(dim=-1).sum()

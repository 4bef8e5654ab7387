"""Fig. 5.1: a diffusion policy fitted to exp(Q/α)/Z for several α, without an environment.

With one fixed state, DIME's actor objective (Eq. 5.26–5.27) reduces to fitting the
diffusion sampler to the Boltzmann target of a known energy:

    min_θ  E[ -Q(a) + α (running_cost + terminal_cost) ]  ≥  α KL(π_θ ‖ exp(Q/α)/Z) − α log Z,

so the loss is an upper bound on α·KL up to the constant α log Z. Small α gives a
concentrated target and nearly noise-free final denoising steps; large α a smooth target
and noisy samples — the exploration knob the thesis describes for Fig. 5.1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from vslbook.srl.diffusion_policy import DiffusionPolicy, DiffusionPolicyConfig


def double_well(a: torch.Tensor, depth: float = 4.0) -> torch.Tensor:
    """A bimodal 1-D "Q-function" Q(a) = -depth (a² - 1)², maxima at a = ±1."""
    return -depth * (a[..., 0] ** 2 - 1.0) ** 2


@dataclass
class ToyFit:
    """A fitted policy and what the notebook plots.

    Attributes:
        alpha: the temperature.
        losses: the actor loss per iteration (Eq. 5.27 with one state).
        trajectories: (N+1, n, 1) sampled chains x_N → x_0.
        grid, target: the Boltzmann target density exp(Q/α)/Z on a grid.
        kl_upper: final loss/α + log Z, an estimate of an upper bound on KL(π_θ ‖ target).
        log_z: log Z of the target (numerical quadrature).
    """

    alpha: float
    losses: np.ndarray
    trajectories: np.ndarray
    grid: np.ndarray
    target: np.ndarray
    kl_upper: float
    log_z: float


def fit_boltzmann(
    alpha: float,
    iterations: int = 300,
    batch: int = 256,
    n_steps: int = 16,
    hidden: int = 64,
    lr: float = 3e-3,
    seed: int = 0,
    n_show: int = 200,
) -> ToyFit:
    """Fit a state-less diffusion policy (no tanh) to exp(Q/α)/Z of :func:`double_well`."""
    if not alpha > 0:
        raise ValueError(f"alpha must be > 0, got {alpha}")
    if iterations < 1 or batch < 1:
        raise ValueError(f"iterations and batch must be >= 1, got {iterations}, {batch}")
    torch.manual_seed(seed)
    gen = torch.Generator().manual_seed(seed)
    cfg = DiffusionPolicyConfig(n_steps=n_steps, sigma0=1.0, hidden=hidden, n_frequencies=32,
                                squash=False)
    policy = DiffusionPolicy(obs_dim=1, act_dim=1, config=cfg)
    opt = torch.optim.Adam(policy.parameters(), lr=lr)
    obs = torch.zeros(batch, 1)
    losses = []
    for _ in range(iterations):
        s = policy.sample(obs, generator=gen)
        loss = (-double_well(s.action) + alpha * s.cost).mean()  # Eq. 5.27, one state
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(loss.item())

    grid = np.linspace(-2.5, 2.5, 2001)
    log_unnorm = double_well(torch.from_numpy(grid)[:, None]).numpy() / alpha
    shift = log_unnorm.max()
    log_z = float(shift + math.log(np.trapezoid(np.exp(log_unnorm - shift), grid)))
    with torch.no_grad():
        show = policy.sample(torch.zeros(n_show, 1), generator=gen, return_trajectory=True)
        final = policy.sample(torch.zeros(4096, 1), generator=gen)
        final_loss = (-double_well(final.action) + alpha * final.cost).mean().item()
    return ToyFit(
        alpha=alpha,
        losses=np.asarray(losses),
        trajectories=show.trajectory.numpy(),
        grid=grid,
        target=np.exp(log_unnorm - log_z),
        kl_upper=final_loss / alpha + log_z,
        log_z=log_z,
    )

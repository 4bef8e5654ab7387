"""DIME's agent and its three updates (Algorithm 4, l. 7-10), as pure functions.

Critic (CrossQ, Section 5.4.4 and Appendix C.4). Two critics, no target network; (s, a) and
(s', a') go through each critic as one joint batch in train mode so the BatchRenorm
statistics are shared, and the s' half is detached. With a' ~ π(·|s') and its cost
c(s') = running_cost + terminal_cost = -ℓ(a', s') (the negative entropy bound, Eq. 5.15),

    distributional   Tz_i = r + γ (1 - terminated) (z_i - α c(s'))           (Eq. 5.21)
                     target = ½ Σ_k Proj_z(Tz, p_k(s', a')), loss = CE(target, p(s, a)) - 0.005 H
    scalar (Eq. 5.24) y = r + γ (1 - terminated) (Q̄(s', a') - α c(s')),     loss = ½ (Q - y)²

with Q̄ the mean (DIME, Appendix C.4) or the min (CrossQ) of the two critics.

Actor (Eq. 5.27): minimise mean[α (running_cost + terminal_cost) - ½ (Q1 + Q2)(s, a)] with
a reparameterised through the chain; the critics are in eval mode and their weights are
frozen, so only the gradient with respect to the action flows through them.

Temperature (Eq. 5.28): J(α) = α (H_target - mean running_cost), in log space. H_target is
a target for the *running* cost, the log ratio of the denoising to the noising kernels plus
the tanh correction, i.e. minus the entropy bound without the prior's term. Table C.2's
H_target = 4·|A| therefore holds the running part of the bound at -4|A|; the full bound
adds the prior's entropy |A| ½ log(2πe σ0²) ≈ 2.33|A| (σ0 = 2.5), so DIME aims at an
entropy bound near -1.67|A|. For the Gaussian policy the running cost is log π(a|s) and
``h_target_per_dim = 1`` is SAC's usual entropy target H = -|A|. A running cost above the
target (too little entropy) makes α grow, one below it makes α shrink.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from vslbook.srl.c51 import CategoricalSupport, categorical_loss
from vslbook.srl.critic import DoubleCritic, polyak_update
from vslbook.srl.diffusion_policy import DiffusionPolicy, DiffusionPolicyConfig
from vslbook.srl.dime_config import DIMEConfig
from vslbook.srl.gaussian_policy import GaussianPolicy
from vslbook.srl.replay import Batch

# --------------------------------------------------------------------------- the agent


@dataclass
class Agent:
    """Everything the updates change: networks, temperature and their optimisers."""

    cfg: DIMEConfig
    policy: nn.Module
    critic: DoubleCritic
    critic_target: DoubleCritic | None
    support: CategoricalSupport | None
    log_alpha: Tensor
    actor_opt: torch.optim.Optimizer
    critic_opt: torch.optim.Optimizer
    alpha_opt: torch.optim.Optimizer | None
    h_target: float

    @property
    def alpha(self) -> Tensor:
        """The current temperature α (no gradient)."""
        if self.cfg.fixed_alpha is not None:
            return torch.full_like(self.log_alpha, self.cfg.fixed_alpha)
        return self.log_alpha.detach().exp()

    def state_dict(self) -> dict[str, Any]:
        return {
            "policy": self.policy.state_dict(),
            "critic": self.critic.state_dict(),
            "critic_target": None
            if self.critic_target is None
            else self.critic_target.state_dict(),
            "log_alpha": self.log_alpha.detach().cpu().clone(),
            "actor_opt": self.actor_opt.state_dict(),
            "critic_opt": self.critic_opt.state_dict(),
            "alpha_opt": None if self.alpha_opt is None else self.alpha_opt.state_dict(),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.policy.load_state_dict(state["policy"])
        self.critic.load_state_dict(state["critic"])
        if self.critic_target is not None:
            self.critic_target.load_state_dict(state["critic_target"])
        with torch.no_grad():
            self.log_alpha.copy_(state["log_alpha"])
        self.actor_opt.load_state_dict(state["actor_opt"])
        self.critic_opt.load_state_dict(state["critic_opt"])
        if self.alpha_opt is not None:
            self.alpha_opt.load_state_dict(state["alpha_opt"])


def resolve_device(name: str) -> torch.device:
    """``"auto"`` is cuda when available, else cpu; anything else is passed to torch."""
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    return torch.device(name)


def _adam(params, lr: float, beta1: float, device: torch.device) -> torch.optim.Adam:
    # fused Adam (one kernel for all tensors) where torch has it for this device; its step
    # counter lives on the device, so a step never reads a tensor on the host
    fused = device.type in ("cuda", "cpu")
    return torch.optim.Adam(params, lr=lr, betas=(beta1, 0.999), fused=fused)


def make_agent(
    obs_dim: int,
    act_dim: int,
    cfg: DIMEConfig,
    *,
    v_min: float | None = None,
    v_max: float | None = None,
    device: str | torch.device = "cpu",
) -> Agent:
    """Build the policy, the two critics, α and the optimisers on ``device``."""
    device = torch.device(device)
    if cfg.policy == "diffusion":
        policy_cfg = DiffusionPolicyConfig(
            n_steps=cfg.n_diffusion_steps,
            sigma0=cfg.sigma0,
            dt=cfg.diffusion_dt,
            learn_beta=cfg.learn_beta,
            hidden=cfg.actor_hidden,
            n_layers=cfg.actor_layers,
            general_bridges=cfg.general_bridges,
        )
        policy: nn.Module = DiffusionPolicy(obs_dim, act_dim, policy_cfg)
    else:
        policy = GaussianPolicy(obs_dim, act_dim, cfg.actor_hidden, cfg.actor_layers)
    distributional = cfg.critic == "distributional"

    def new_critic() -> DoubleCritic:
        return DoubleCritic(
            obs_dim,
            act_dim,
            hidden=cfg.critic_hidden,
            n_atoms=cfg.n_atoms,
            use_batchrenorm=cfg.critic_batchrenorm,
            distributional=distributional,
            n_layers=cfg.critic_layers,
            renorm_kwargs={"warmup_steps": cfg.renorm_warmup},
        )

    critic = new_critic()
    critic_target = None
    if cfg.use_target_network:
        critic_target = new_critic()
        critic_target.load_state_dict(critic.state_dict())
        critic_target.requires_grad_(False).eval()  # s' values use its running statistics
    support = None
    if distributional:
        if v_min is None or v_max is None:
            raise ValueError("the distributional critic needs v_min and v_max")
        support = CategoricalSupport(v_min, v_max, cfg.n_atoms)
    policy, critic, support = (m if m is None else m.to(device) for m in (policy, critic, support))
    if critic_target is not None:
        critic_target = critic_target.to(device)
    log_alpha = torch.tensor(float(cfg.init_log_alpha), device=device)
    alpha_opt = None
    if cfg.fixed_alpha is None:
        log_alpha.requires_grad_(True)
        alpha_opt = _adam([log_alpha], cfg.alpha_lr, 0.9, device)  # torch's default betas
    return Agent(
        cfg=cfg,
        policy=policy,
        critic=critic,
        critic_target=critic_target,
        support=support,
        log_alpha=log_alpha,
        actor_opt=_adam(
            [p for p in policy.parameters() if p.requires_grad],
            cfg.actor_lr,
            cfg.adam_beta1,
            device,
        ),
        critic_opt=_adam(critic.parameters(), cfg.critic_lr, cfg.adam_beta1, device),
        alpha_opt=alpha_opt,
        h_target=cfg.h_target_per_dim * act_dim,
    )


# --------------------------------------------------------------------------- the updates


def combine_q(agent: Agent, q: Tensor) -> Tensor:
    """(2, B) -> (B): ½(Q1 + Q2) (DIME) or min(Q1, Q2) (``q_reduce="min"``)."""
    return q.mean(dim=0) if agent.cfg.q_reduce == "mean" else q.min(dim=0).values


def q_values(agent: Agent, critic_out: Tensor) -> Tensor:
    """Expected Q (2, B) from the critics' output: Σ_i p_i z_i for C51 logits (Appendix C.4)."""
    if agent.support is None:
        return critic_out
    return agent.support.mean(F.softmax(critic_out, dim=-1))


def policy_noise(
    policy: nn.Module, batch: int, generator: torch.Generator | None, device: torch.device
) -> Tensor:
    """The standard normals ``policy.sample`` would draw for ``batch`` states, drawn now.

    Drawn from ``generator`` (None: the device's default generator) in the chunks the policy
    draws them (the diffusion policy one (batch, act_dim) draw per step, x_N's first; the
    Gaussian policy one), so passing the result as ``noise`` gives the very sample the eager
    call ``policy.sample(obs, generator=generator)`` would have drawn.
    """
    shape = policy.noise_shape(batch)
    if len(shape) == 3:
        chunk = shape[1:]
        return torch.stack(
            [torch.randn(chunk, generator=generator, device=device) for _ in range(shape[0])]
        )
    return torch.randn(shape, generator=generator, device=device)


class UpdateStats(NamedTuple):
    """Diagnostics of one update (0-d tensors, detached)."""

    loss: Tensor
    value: Tensor  # critic: mean predicted Q; actor: mean entropy bound -cost
    running_cost: Tensor | None = None


def critic_loss(agent: Any, batch: Batch, noise: Tensor | None = None) -> tuple[Tensor, Tensor]:
    """The critic loss of one batch (Eq. 5.21 / 5.24, CrossQ joint batch) and the mean Q.

    ``agent`` is an :class:`Agent` or anything with its ``cfg``, ``policy``, ``critic``,
    ``critic_target``, ``support`` and ``alpha`` (:mod:`vslbook.srl.seed_axis` passes one
    seed's networks); ``noise`` is the policy's draws for a' ~ π(·|s') (default: fresh).
    """
    cfg = agent.cfg
    with torch.no_grad():
        next_sample = agent.policy.sample(batch.next_obs, noise=noise)  # a' ~ π(·|s'), costs
        soft_bonus = -agent.alpha * next_sample.cost  # α ℓ(a', s'), ℓ the entropy bound
    if agent.critic_target is None:  # CrossQ: one pass on [(s, a); (s', a')], s' half detached
        out, out_next = agent.critic.joint_forward(
            batch.obs, batch.action, batch.next_obs, next_sample.action
        )
        out_next = out_next.detach()
    else:
        out = agent.critic(batch.obs, batch.action)
        with torch.no_grad():
            out_next = agent.critic_target(batch.next_obs, next_sample.action)

    if agent.support is not None:  # distributional (C51) target, Eq. 5.21
        with torch.no_grad():
            next_probs = F.softmax(out_next, dim=-1)  # (2, B, n_atoms)
            moved = agent.support.bellman_atoms(
                batch.reward, batch.terminated, cfg.gamma, soft_bonus
            )  # Tz (B, n_atoms)
            target = agent.support.project(moved.expand_as(next_probs), next_probs).mean(dim=0)
        loss = categorical_loss(out, target, cfg.critic_entropy_coef)  # summed over 2 critics
    else:  # Bellman residual, Eq. 5.24
        with torch.no_grad():
            not_done = 1.0 - batch.terminated
            target = batch.reward + cfg.gamma * not_done * (combine_q(agent, out_next) + soft_bonus)
        loss = 0.5 * ((out - target) ** 2).mean(dim=-1).sum()
    with torch.no_grad():
        q_mean = q_values(agent, out.detach()).mean()
    return loss, q_mean


def critic_update(agent: Agent, batch: Batch, noise: Tensor | None = None) -> UpdateStats:
    """One step on the critic loss (Algorithm 4, l. 7; Eq. 5.21 / 5.24, CrossQ joint batch);
    ``noise``: the policy's draws for a' (default: fresh, from torch's global stream)."""
    loss, q_mean = critic_loss(agent, batch, noise)
    agent.critic_opt.zero_grad(set_to_none=True)
    loss.backward()
    agent.critic_opt.step()
    if agent.critic_target is not None:
        polyak_update(agent.critic_target, agent.critic, agent.cfg.tau)
    return UpdateStats(loss.detach(), q_mean)


def actor_loss(agent: Any, obs: Tensor, noise: Tensor | None = None) -> tuple[Tensor, Any]:
    """Eq. 5.27, mean[α (running + terminal cost) - ½(Q1 + Q2)(s, a)], and the sample.

    The caller puts the critics in eval mode and keeps gradients from their weights."""
    sample = agent.policy.sample(obs, noise=noise)  # reparameterised through the chain
    q = combine_q(agent, q_values(agent, agent.critic(obs, sample.action)))
    return (agent.alpha * sample.cost - q).mean(), sample  # log Z does not depend on θ


def clean_actor_grads(params: list[Tensor], clip: float) -> None:
    """Drop NaN gradient entries, then clip each element to ±``clip`` (if > 0)."""
    for p in params:
        torch.nan_to_num_(p.grad, nan=0.0, posinf=math.inf, neginf=-math.inf)
    if clip > 0:
        nn.utils.clip_grad_value_(params, clip)


def actor_update(agent: Agent, obs: Tensor, noise: Tensor | None = None) -> UpdateStats:
    """One step on Eq. 5.27, mean[α (running + terminal cost) - ½(Q1 + Q2)(s, a)] (l. 9).

    ``noise``: the policy's draws for a ~ π(·|s) (default: fresh). The critics run in eval
    mode with ``requires_grad`` switched off, so no gradient is computed for (or written
    into) their weights; only ∂Q/∂a reaches the policy.
    """
    critic, cfg = agent.critic, agent.cfg
    critic.eval()
    critic.requires_grad_(False)
    try:
        loss, sample = actor_loss(agent, obs, noise)
        agent.actor_opt.zero_grad(set_to_none=True)
        loss.backward()
    finally:
        critic.requires_grad_(True)
        critic.train()
    params = [p for p in agent.policy.parameters() if p.grad is not None]
    clean_actor_grads(params, cfg.actor_grad_clip)  # NaN entries dropped, each element ±1
    agent.actor_opt.step()
    return UpdateStats(
        loss.detach(), sample.entropy_bound.detach().mean(), sample.running_cost.detach()
    )


def alpha_update(agent: Agent, running_cost: Tensor) -> Tensor:
    """One step on Eq. 5.28, J(α) = α (H_target - mean running cost), in log α (l. 10).

    Returns the loss; a fixed α (``fixed_alpha``) is left alone.
    """
    if agent.alpha_opt is None:
        return torch.zeros((), device=running_cost.device)
    loss = agent.log_alpha.exp() * (agent.h_target - running_cost.detach().mean())
    agent.alpha_opt.zero_grad(set_to_none=True)
    loss.backward()
    agent.alpha_opt.step()
    return loss.detach()

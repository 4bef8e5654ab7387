"""DIME: diffusion-based maximum entropy RL (Chapter 5, Algorithm 4), plus CrossQ.

Read :func:`train` next to Algorithm 4. Per environment step t:

    l. 3-5   a_t ~ π_θ(·|s_t) through the whole denoising chain (uniform random actions for
             the first ``learning_starts`` steps), s_{t+1} ~ p(·|s_t, a_t), D ← D ∪ {transition}
    l. 7     ``utd`` critic updates ϕ ← ϕ - λ_ϕ ∇J_Q  (Eq. 5.24 / distributional Eq. 5.21)
    l. 8-10  after every ``policy_delay``-th critic update: one actor step on Eq. 5.27 and one
             temperature step on Eq. 5.28

(Algorithm 4 writes the same schedule as one loop over critic updates k that collects a
transition when k hits the UTD ratio.)

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

Episodes and resume. Time-limit truncations bootstrap, terminations do not. The training
environment is reset with a seed derived from (run seed, episode index) and the evaluation
environment from (run seed, evaluation index, episode), so no simulator state is pickled:
checkpoints are written at episode boundaries only, and a run resumed from one logs exactly
the numbers an uninterrupted run logs on CPU (all metrics except the wall-clock rates
``critic_updates_per_s`` and ``env_steps_per_s``).
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass
from functools import partial
from typing import Any, NamedTuple

import gymnasium as gym
import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor, nn
from tqdm.auto import tqdm

from vslbook.budget import Budget
from vslbook.registry import config_from_record, register_algorithm
from vslbook.results import RunDir, restore_rng_state, rng_state
from vslbook.seeding import seed_everything
from vslbook.srl.c51 import CategoricalSupport, categorical_loss
from vslbook.srl.critic import DoubleCritic, polyak_update
from vslbook.srl.diffusion_policy import DiffusionPolicy, DiffusionPolicyConfig
from vslbook.srl.gaussian_policy import GaussianPolicy
from vslbook.srl.replay import Batch, ReplayBuffer

POLICIES = ("diffusion", "gaussian")
CRITICS = ("distributional", "scalar")
Q_REDUCTIONS = ("mean", "min")
#: Table C.3's gymnasium-locomotion range, used when no per-suite range is known.
FALLBACK_VALUE_RANGE = (-1600.0, 1600.0)


@dataclass(frozen=True)
class DIMEConfig:
    """DIME's hyper-parameters; defaults are Table C.2 / C.3 (DIME column) and Appendix C.4.

    Counts marked *scaled* are full-budget values that a :class:`~vslbook.budget.Budget`
    shrinks (``budget.scale``, never below ``min(value, 1000)``); everything else is the
    algorithm and is never changed by a budget.

    Attributes:
        total_steps: environment steps (*scaled*; 1M in the thesis, 3M for two DMC tasks).
        learning_starts: uniform-random exploration steps before updates begin (*scaled*;
            Table C.2 "Exploration Steps" 5000).
        eval_every: environment steps between evaluations (*scaled*; the published learning
            curves are evaluated every 24k steps).
        eval_episodes: episodes per evaluation with the stochastic policy; 0 takes the
            budget's ``eval_episodes``.
        checkpoint_every: environment steps between checkpoints (*scaled*), each written at
            the first episode end at or after the multiple.
        batch_size, utd, policy_delay, gamma, buffer_size: Table C.2 / C.3 (256, 2, 3,
            0.99, 1e6); ``utd`` critic updates per environment step, one actor and α update
            every ``policy_delay`` critic updates.
        actor_lr, critic_lr, alpha_lr: Adam learning rates (Table C.2: 3e-4, 3e-4, 1e-3).
        adam_beta1: β1 of the actor and critic Adam (0.5, CrossQ's value that DIME adopts);
            the temperature uses Adam's default betas.
        actor_grad_clip: actor gradients are cleared of NaNs and clipped elementwise to
            ±this value (0 disables the clipping).
        init_log_alpha: initial log α (0, i.e. α = 1).
        h_target_per_dim: H_target / |A| of Eq. 5.28, a target for the mean running cost
            (Table C.2: 4·dim(A)); see the module docstring for its entropy meaning.
        fixed_alpha: a constant α instead of the autotuning (the α sweep of Fig. 5.4a-b).
        policy: ``"diffusion"`` (DIME) or ``"gaussian"`` (tanh-Gaussian, Fig. 5.4c-d).
        actor_hidden, actor_layers: score network / Gaussian trunk size (256, 3).
        n_diffusion_steps: N, the denoising steps (Table C.2: 16).
        sigma0: standard deviation of the prior N(0, σ0² I) (Table C.2: 2.5).
        diffusion_total_time: initial total time T = Σ_n dt_n of the cosine schedule (0.1).
        learn_beta: learn the per-dimension diffusion coefficient β (Appendix C.4, Fig. C.2).
        general_bridges: also learn the noising drift (Section 5.6, Fig. 5.8a-b).
        critic: ``"distributional"`` (C51, DIME) or ``"scalar"`` (Bellman residual, Eq. 5.24,
            the ablation of Fig. 5.5c-d / 5.6).
        critic_hidden, critic_layers: critic width and depth (Table C.2: 2048, 2).
        n_atoms: atoms of the categorical return distribution (101 on [v_min, v_max]).
        v_min, v_max: support of the return distribution; None picks the suite's range
            (Table C.3 text: ±200 DMC, ±1600 gymnasium, ±3600 MyoSuite) through
            ``vslbook.envs.step_based.value_range``, else ±1600 with a warning.
        critic_entropy_coef: c in the critic loss CE - c H(p) (Appendix C.4: 0.005).
        q_reduce: how the two critics combine in the target and the actor loss: ``"mean"``
            (DIME, Appendix C.4) or ``"min"`` (clipped double Q; scalar critic only).
        critic_batchrenorm: BatchRenorm layers in the critic (CrossQ).
        renorm_warmup: critic training passes with plain batch norm before renormalising.
        use_target_network: Polyak-averaged target critics for s' (the point-mass study of
            Fig. 5.7) instead of CrossQ's joint batch; ``tau`` is the averaging rate.
        device: ``"auto"`` (cuda if available, else cpu) or a torch device string.
        compile: wrap the update functions in ``torch.compile``.
        num_threads: torch CPU threads (0 leaves torch's default).
    """

    total_steps: int = 1_000_000
    learning_starts: int = 5000
    eval_every: int = 24_000
    eval_episodes: int = 0
    checkpoint_every: int = 100_000
    batch_size: int = 256
    utd: int = 2
    policy_delay: int = 3
    gamma: float = 0.99
    buffer_size: int = 1_000_000
    actor_lr: float = 3e-4
    critic_lr: float = 3e-4
    alpha_lr: float = 1e-3
    adam_beta1: float = 0.5
    actor_grad_clip: float = 1.0
    init_log_alpha: float = 0.0
    h_target_per_dim: float = 4.0
    fixed_alpha: float | None = None
    policy: str = "diffusion"
    actor_hidden: int = 256
    actor_layers: int = 3
    n_diffusion_steps: int = 16
    sigma0: float = 2.5
    diffusion_total_time: float = 0.1
    learn_beta: bool = True
    general_bridges: bool = False
    critic: str = "distributional"
    critic_hidden: int = 2048
    critic_layers: int = 2
    n_atoms: int = 101
    v_min: float | None = None
    v_max: float | None = None
    critic_entropy_coef: float = 0.005
    q_reduce: str = "mean"
    critic_batchrenorm: bool = True
    renorm_warmup: int = 100_000
    use_target_network: bool = False
    tau: float = 0.005
    device: str = "auto"
    compile: bool = False
    num_threads: int = 0

    def __post_init__(self) -> None:
        for name in (
            "total_steps", "eval_every", "checkpoint_every", "batch_size", "utd",
            "policy_delay", "buffer_size", "actor_hidden", "actor_layers",
            "n_diffusion_steps", "critic_hidden", "critic_layers",
        ):  # fmt: skip
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
        for name in ("learning_starts", "eval_episodes", "renorm_warmup", "num_threads"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ValueError(f"{name} must be an integer >= 0, got {value!r}")
        for name in ("actor_lr", "critic_lr", "alpha_lr", "sigma0", "diffusion_total_time"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)!r}")
        if not 0.0 <= self.gamma <= 1.0:
            raise ValueError(f"gamma must be in [0, 1], got {self.gamma!r}")
        if not 0.0 <= self.adam_beta1 < 1.0:
            raise ValueError(f"adam_beta1 must be in [0, 1), got {self.adam_beta1!r}")
        if self.actor_grad_clip < 0:
            raise ValueError(f"actor_grad_clip must be >= 0 (0: off), got {self.actor_grad_clip!r}")
        if self.fixed_alpha is not None and not self.fixed_alpha > 0:
            raise ValueError(f"fixed_alpha must be > 0 or None, got {self.fixed_alpha!r}")
        if not 0.0 < self.tau <= 1.0:
            raise ValueError(f"tau must be in (0, 1], got {self.tau!r}")
        if self.n_atoms < 2:
            raise ValueError(f"n_atoms must be >= 2, got {self.n_atoms!r}")
        for name, value, allowed in (
            ("policy", self.policy, POLICIES),
            ("critic", self.critic, CRITICS),
            ("q_reduce", self.q_reduce, Q_REDUCTIONS),
        ):
            if value not in allowed:
                raise ValueError(f"unknown {name} {value!r}; expected one of {', '.join(allowed)}")
        if (self.v_min is None) != (self.v_max is None):
            raise ValueError(
                f"set both v_min and v_max or neither, got v_min={self.v_min!r}, "
                f"v_max={self.v_max!r}"
            )
        if self.v_min is not None and not self.v_min < self.v_max:
            raise ValueError(f"need v_min < v_max, got v_min={self.v_min!r}, v_max={self.v_max!r}")
        if self.critic == "distributional" and self.q_reduce == "min":
            raise ValueError(
                "q_reduce='min' is defined for the scalar critic only; the distributional "
                "critic averages the two projected distributions (expected q_reduce='mean')"
            )
        if self.general_bridges and self.policy != "diffusion":
            raise ValueError(
                f"general_bridges=True needs policy='diffusion', got policy={self.policy!r}"
            )
        if self.device != "auto":
            try:
                torch.device(self.device)
            except RuntimeError as err:
                raise ValueError(
                    f"unknown device {self.device!r}; expected 'auto', 'cpu', 'cuda', ..."
                ) from err


@dataclass(frozen=True)
class DIMEGaussianConfig(DIMEConfig):
    """DIME with a tanh-Gaussian policy: identical critic and updates (Fig. 5.4c-d).

    Only the policy and its entropy target change; ``h_target_per_dim = 1`` puts the target on
    log π(a|s) at |A|, i.e. SAC's entropy target -|A|.
    """

    policy: str = "gaussian"
    h_target_per_dim: float = 1.0


@dataclass(frozen=True)
class CrossQConfig(DIMEConfig):
    """CrossQ (Bhatt et al., 2024) as the thesis runs it (Table C.3, CrossQ column).

    Tanh-Gaussian actor (3 x 256), scalar critics trained on the Bellman residual (Eq. 5.24)
    with BatchRenorm and no target network, clipped double Q (min), learning rate 7e-4,
    temperature learning rate 3e-4, H_target = dim(A) on log π (entropy -|A|), no actor
    gradient clipping.
    """

    policy: str = "gaussian"
    critic: str = "scalar"
    q_reduce: str = "min"
    actor_lr: float = 7e-4
    critic_lr: float = 7e-4
    alpha_lr: float = 3e-4
    h_target_per_dim: float = 1.0
    actor_grad_clip: float = 0.0


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
    # fused Adam (one kernel for all tensors) where torch has it for this device
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
            total_time=cfg.diffusion_total_time,
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
        alpha_opt = torch.optim.Adam([log_alpha], lr=cfg.alpha_lr)
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


class UpdateStats(NamedTuple):
    """Diagnostics of one update (0-d tensors, detached)."""

    loss: Tensor
    value: Tensor  # critic: mean predicted Q; actor: mean entropy bound -cost
    running_cost: Tensor | None = None


def critic_update(agent: Agent, batch: Batch) -> UpdateStats:
    """One step on the critic loss (Algorithm 4, l. 7; Eq. 5.21 / 5.24, CrossQ joint batch)."""
    cfg = agent.cfg
    with torch.no_grad():
        next_sample = agent.policy.sample(batch.next_obs)  # a' ~ π(·|s') and its costs
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

    agent.critic_opt.zero_grad(set_to_none=True)
    loss.backward()
    agent.critic_opt.step()
    if agent.critic_target is not None:
        polyak_update(agent.critic_target, agent.critic, cfg.tau)
    with torch.no_grad():
        q_mean = q_values(agent, out.detach()).mean()
    return UpdateStats(loss.detach(), q_mean)


def actor_update(agent: Agent, obs: Tensor) -> UpdateStats:
    """One step on Eq. 5.27, mean[α (running + terminal cost) - ½(Q1 + Q2)(s, a)] (l. 9).

    The critics run in eval mode with ``requires_grad`` switched off, so no gradient is
    computed for (or written into) their weights; only ∂Q/∂a reaches the policy.
    """
    critic, cfg = agent.critic, agent.cfg
    critic.eval()
    critic.requires_grad_(False)
    try:
        sample = agent.policy.sample(obs)  # reparameterised through the chain
        q = combine_q(agent, q_values(agent, critic(obs, sample.action)))
        loss = (agent.alpha * sample.cost - q).mean()  # Eq. 5.27 (log Z does not depend on θ)
        agent.actor_opt.zero_grad(set_to_none=True)
        loss.backward()
    finally:
        critic.requires_grad_(True)
        critic.train()
    params = [p for p in agent.policy.parameters() if p.grad is not None]
    for p in params:  # drop NaN gradient entries
        torch.nan_to_num_(p.grad, nan=0.0, posinf=math.inf, neginf=-math.inf)
    if cfg.actor_grad_clip > 0:  # then clip each element to ±actor_grad_clip (±1)
        nn.utils.clip_grad_value_(params, cfg.actor_grad_clip)
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


# --------------------------------------------------------------------------- environments


def make_env(env_id: str) -> gym.Env:
    """The environment through ``vslbook.envs.make`` (vslbook's own ids and the Chapter 5
    tasks with their wrappers; any other gymnasium id as ``gymnasium.make``); it must have a
    flat Box observation space and a bounded Box action space."""
    from vslbook.envs import make

    env = make(env_id)
    obs_space, act_space = env.observation_space, env.action_space
    if not (isinstance(obs_space, gym.spaces.Box) and len(obs_space.shape) == 1):
        raise ValueError(f"{env_id}: expected a flat Box observation space, got {obs_space}")
    if not (
        isinstance(act_space, gym.spaces.Box)
        and len(act_space.shape) == 1
        and np.all(np.isfinite(act_space.low))
        and np.all(np.isfinite(act_space.high))
    ):
        raise ValueError(f"{env_id}: expected a bounded flat Box action space, got {act_space}")
    return env


def default_value_range(env_id: str) -> tuple[float, float]:
    """The C51 support for ``env_id``'s suite (``vslbook.envs.step_based.value_range``).

    Ids outside vslbook (e.g. gymnasium's ``Pendulum-v1``), or a missing ``step_based``
    module, fall back to ±1600 (Table C.3's gymnasium range) with a warning.
    """
    try:
        from vslbook.envs.step_based import value_range
    except ImportError as err:
        reason = f"vslbook.envs.step_based is not importable ({err})"
    else:
        try:
            v_min, v_max = value_range(env_id)
            return float(v_min), float(v_max)
        except (KeyError, ValueError) as err:
            if env_id.startswith("vslbook/"):
                raise
            reason = f"no suite range for {env_id!r} ({err})"
    warnings.warn(
        f"{reason}; using v_min, v_max = {FALLBACK_VALUE_RANGE} (Table C.3's gymnasium range). "
        "Set v_min and v_max in the config to choose the support.",
        stacklevel=2,
    )
    return FALLBACK_VALUE_RANGE


def _stream_seed(seed: int, stream: int, *index: int) -> int:
    """A reset seed for (run seed, stream, index...), well mixed by numpy's SeedSequence."""
    return int(np.random.SeedSequence([seed, stream, *index]).generate_state(1)[0])


TRAIN_RESETS, EVAL_RESETS, EVAL_NOISE = 0, 1, 2


def _to_env_action(action: np.ndarray, space: gym.spaces.Box) -> np.ndarray:
    """Map a ∈ [-1, 1] to the Box [low, high]."""
    scaled = space.low + 0.5 * (action + 1.0) * (space.high - space.low)
    return scaled.astype(space.dtype)


@torch.no_grad()
def act(
    policy: nn.Module,
    obs: np.ndarray,
    device: torch.device,
    generator: torch.Generator | None = None,
) -> np.ndarray:
    """One stochastic action in [-1, 1] for one observation (l. 3: the whole chain)."""
    obs_t = torch.as_tensor(obs, dtype=torch.float32, device=device).unsqueeze(0)
    return policy.sample(obs_t, generator=generator).action[0].cpu().numpy()


def evaluate(
    policy: nn.Module,
    env: gym.Env,
    *,
    seed: int,
    index: int,
    episodes: int,
    device: torch.device,
) -> tuple[float, float | None]:
    """Mean return of ``episodes`` episodes with the stochastic policy, and the mean final
    ``info["success"]`` when the environment reports one (else None).

    Resets and the policy noise are seeded from (seed, index), so an evaluation does not
    touch the training random streams.
    """
    generator = torch.Generator(device=device)
    generator.manual_seed(_stream_seed(seed, EVAL_NOISE, index))
    returns, successes = [], []
    for episode in range(episodes):
        obs, info = env.reset(seed=_stream_seed(seed, EVAL_RESETS, index, episode))
        total, done = 0.0, False
        while not done:
            action = act(policy, obs, device, generator)
            obs, reward, terminated, truncated, info = env.step(
                _to_env_action(action, env.action_space)
            )
            total += float(reward)
            done = terminated or truncated
        returns.append(total)
        if "success" in info:
            successes.append(float(info["success"]))
    return float(np.mean(returns)), (float(np.mean(successes)) if successes else None)


# --------------------------------------------------------------------------- diagnostics


class _Means:
    """Running sums of diagnostics between two log rows (on the device, no host sync)."""

    def __init__(self, device: torch.device) -> None:
        self.device = device
        self.sums: dict[str, Tensor] = {}
        self.counts: dict[str, int] = {}

    def add(self, name: str, value: Tensor | float) -> None:
        value = torch.as_tensor(value, dtype=torch.float64, device=self.device)
        if name in self.sums:
            self.sums[name] += value
        else:
            self.sums[name] = value.clone()
        self.counts[name] = self.counts.get(name, 0) + 1

    def pop(self) -> dict[str, float]:
        means = {k: float(self.sums[k].item()) / self.counts[k] for k in self.sums}
        self.sums, self.counts = {}, {}
        return means

    def state_dict(self) -> dict[str, Any]:
        return {"sums": {k: float(v.item()) for k, v in self.sums.items()}, "counts": self.counts}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.sums = {
            k: torch.tensor(v, dtype=torch.float64, device=self.device)
            for k, v in state["sums"].items()
        }
        self.counts = dict(state["counts"])


def _scaled(budget: Budget, full: int) -> int:
    """``budget``'s share of a full-budget count, at least ``min(full, 1000)``."""
    return budget.scale(full, minimum=min(full, 1000))


# --------------------------------------------------------------------------- Algorithm 4


def train(
    run: RunDir,
    config: dict,
    budget: Budget,
    *,
    progress: bool = True,
    stop_after: int | None = None,
    config_cls: type[DIMEConfig] = DIMEConfig,
) -> dict | None:
    """Train DIME (or a variant) in ``run``, resuming from its checkpoint if there is one.

    ``config`` holds ``env``, ``seed`` and the fields of ``config_cls``. ``stop_after``
    counts environment steps of this call: the run stops (checkpointed, not finished) at the
    first episode end after that many steps. Returns a summary when finished, None when
    stopped early.
    """
    cfg = config_from_record(config_cls, config)
    env_id, seed = config["env"], int(config["seed"])
    if cfg.num_threads:
        torch.set_num_threads(cfg.num_threads)
    device = resolve_device(cfg.device)
    total_steps = budget.scale(cfg.total_steps)
    learning_starts = min(_scaled(budget, cfg.learning_starts), total_steps)
    eval_every = _scaled(budget, cfg.eval_every)
    checkpoint_every = _scaled(budget, cfg.checkpoint_every)
    eval_episodes = cfg.eval_episodes or budget.eval_episodes

    seed_everything(seed, deterministic_torch=False)
    rng = np.random.default_rng(seed)  # exploration actions and replay indices
    env, eval_env = make_env(env_id), make_env(env_id)
    obs_dim, act_dim = env.observation_space.shape[0], env.action_space.shape[0]
    v_min, v_max = cfg.v_min, cfg.v_max
    if cfg.critic == "distributional" and v_min is None:
        v_min, v_max = default_value_range(env_id)
    agent = make_agent(obs_dim, act_dim, cfg, v_min=v_min, v_max=v_max, device=device)
    buffer = ReplayBuffer(min(cfg.buffer_size, total_steps), obs_dim, act_dim, device)
    critic_step, actor_step = critic_update, actor_update
    if cfg.compile:
        critic_step, actor_step = torch.compile(critic_update), torch.compile(actor_update)
    diag = _Means(device)

    step = episode = n_updates = n_evals = 0
    last_eval: dict[str, Any] = {}
    state = run.load_checkpoint()
    if state is not None:
        agent.load_state_dict(state["agent"])
        if state["replay"] is not None:
            buffer.load_state_dict(state["replay"])
        diag.load_state_dict(state["diagnostics"])
        step, episode, n_updates, n_evals = (
            state[k] for k in ("step", "episode", "updates", "evals")
        )
        last_eval = state["last_eval"]
        restore_rng_state(state["rng"], rng)

    def checkpoint(final: bool = False) -> None:
        run.save_checkpoint(
            {
                "agent": agent.state_dict(),
                "replay": None if final else buffer.state_dict(),
                "diagnostics": diag.state_dict(),
                "step": step,
                "episode": episode,
                "updates": n_updates,
                "evals": n_evals,
                "last_eval": last_eval,
                "rng": rng_state(rng),
            }
        )

    bar = tqdm(
        total=total_steps,
        initial=step,
        disable=not progress,
        desc=f"{config.get('algo', 'dime')} {env_id} s{seed}",
    )
    clock, steps_at_clock, updates_at_clock = time.perf_counter(), step, n_updates
    steps_this_call = 0
    next_checkpoint = (step // checkpoint_every + 1) * checkpoint_every
    obs, _ = env.reset(seed=_stream_seed(seed, TRAIN_RESETS, episode))
    episode_return = 0.0
    while step < total_steps:
        # l. 3-5: a ~ π(·|s) (uniform at first), s' ~ p(·|s, a), D ← D ∪ {(s, a, r, s', term)}
        if step < learning_starts:
            action = rng.uniform(-1.0, 1.0, size=act_dim).astype(np.float32)
        else:
            action = act(agent.policy, obs, device)
        next_obs, reward, terminated, truncated, info = env.step(
            _to_env_action(action, env.action_space)
        )
        buffer.add(obs, action, reward, next_obs, terminated)
        obs, episode_return = next_obs, episode_return + float(reward)
        step += 1
        steps_this_call += 1

        if step >= learning_starts:
            for _ in range(cfg.utd):  # l. 7: UTD critic updates per environment step
                batch = buffer.sample(cfg.batch_size, rng)
                critic_stats = critic_step(agent, batch)
                diag.add("critic_loss", critic_stats.loss)
                diag.add("q_mean", critic_stats.value)
                n_updates += 1
                if n_updates % cfg.policy_delay == 0:  # l. 8-10: actor (5.27) and α (5.28)
                    actor_stats = actor_step(agent, batch.obs)
                    alpha_update(agent, actor_stats.running_cost)
                    diag.add("actor_loss", actor_stats.loss)
                    diag.add("entropy_bound", actor_stats.value)
                    diag.add("running_cost", actor_stats.running_cost.mean())

        if step % eval_every == 0 or step == total_steps:
            eval_return, eval_success = evaluate(
                agent.policy, eval_env, seed=seed, index=n_evals, episodes=eval_episodes,
                device=device,
            )  # fmt: skip
            n_evals += 1
            now = time.perf_counter()
            elapsed = max(now - clock, 1e-9)
            row: dict[str, Any] = {"eval_return": eval_return}
            if eval_success is not None:
                row["eval_success"] = eval_success
            row.update(diag.pop())
            row.update(
                alpha=float(agent.alpha.item()),
                critic_updates=n_updates,
                episodes=episode,
                critic_updates_per_s=(n_updates - updates_at_clock) / elapsed,
                env_steps_per_s=(step - steps_at_clock) / elapsed,
            )
            run.log(step, **row)
            last_eval = {"eval_return": eval_return, "eval_success": eval_success}
            bar.set_postfix(ret=f"{eval_return:.1f}", alpha=f"{row['alpha']:.3g}")
            clock, steps_at_clock, updates_at_clock = time.perf_counter(), step, n_updates
        bar.update(1)

        if terminated or truncated:  # episode boundary: reset, maybe checkpoint or stop
            diag.add("train_return", episode_return)
            episode += 1
            obs, _ = env.reset(seed=_stream_seed(seed, TRAIN_RESETS, episode))
            episode_return = 0.0
            stopping = stop_after is not None and steps_this_call >= stop_after
            if step < total_steps and (step >= next_checkpoint or stopping):
                checkpoint()
                next_checkpoint = (step // checkpoint_every + 1) * checkpoint_every
            if stopping and step < total_steps:
                bar.close()
                return None
    bar.close()
    checkpoint(final=True)  # networks for later analysis; the replay buffer is dropped
    return {
        "env_steps": total_steps,
        "critic_updates": n_updates,
        "episodes": episode,
        **last_eval,
        "v_min": v_min,
        "v_max": v_max,
    }


register_algorithm(
    "dime",
    train=train,
    config=DIMEConfig,
    doc="DIME (Algorithm 4): diffusion policy, distributional CrossQ critics, autotuned α",
)
register_algorithm(
    "dime-gaussian",
    train=partial(train, config_cls=DIMEGaussianConfig),
    config=DIMEGaussianConfig,
    doc="DIME's critic and updates with a tanh-Gaussian policy (Fig. 5.4c-d ablation)",
)
register_algorithm(
    "crossq",
    train=partial(train, config_cls=CrossQConfig),
    config=CrossQConfig,
    doc="CrossQ: tanh-Gaussian policy, BatchRenorm scalar critics, no target network",
)

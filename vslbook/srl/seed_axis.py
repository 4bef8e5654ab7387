"""S independent DIME agents updated as one: every tensor with a leading seed axis.

One process trains several seeds at once (DIME, its Gaussian variant and CrossQ). Each
seed keeps everything it would have alone:

* **networks and BatchRenorm statistics**: the S agents' parameters and buffers are
  stacked (``torch.func.stack_module_state``) and the losses of :mod:`vslbook.srl.dime_updates`
  run under ``torch.func.vmap`` over the agents' functional form, so a seed's batch is
  normalised with its own batch statistics and updates its own running statistics; seeds
  are never folded into the batch dimension;
* **optimiser state**: Adam is elementwise, so one fused Adam over the stacked tensors takes
  exactly each seed's own step (its moments are the stacked moments); the actor's gradient
  cleaning (NaN entries to 0, each element clipped to ±1) is elementwise too; log α has
  shape (S,), one temperature per seed;
* **random numbers**: seed s draws its policy noise from its own ``torch.Generator``
  (:meth:`SeedStack.noise`) in the chunks its single-seed run draws them, so both consume
  identical random numbers.

Per seed the updates are those of Algorithm 4 (l. 7-10) exactly; :meth:`SeedStack.agent_state`
gives seed s's state in :class:`~vslbook.srl.dime_updates.Agent`'s own ``state_dict``
format, so S ordinary run directories can be written and resumed. Configurations with a
target network (an ablation, ``use_target_network``) are trained one seed per process.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any

import torch
from torch import Tensor, nn
from torch.func import functional_call, stack_module_state, vmap

from vslbook.srl.dime_updates import (
    Agent,
    UpdateStats,
    actor_loss,
    clean_actor_grads,
    critic_loss,
    policy_noise,
)
from vslbook.srl.replay import Batch

__all__ = ["SeedStack"]


class _Nets(nn.Module):
    """A policy and a critic under one module, so one functional call swaps both."""

    def __init__(self, policy: nn.Module, critic: nn.Module) -> None:
        super().__init__()
        self.policy = policy
        self.critic = critic

    def forward(self, fn: Any, *args: Any) -> Any:
        return fn(self.policy, self.critic, *args)


@dataclass
class _View:
    """One seed's agent as the loss functions see it (inside ``vmap``)."""

    cfg: Any
    policy: nn.Module
    critic: nn.Module
    support: Any
    alpha: Tensor
    critic_target: None = None


def _stack_adam_state(opts: list[torch.optim.Optimizer], params: list[Tensor]) -> dict:
    """The state of one Adam over stacked ``params`` from S per-seed Adams' states."""
    states = [o.state_dict() for o in opts]
    if any(not s["state"] for s in states):
        if not all(not s["state"] for s in states):
            raise ValueError("some seeds' optimisers have taken steps and others have not")
        return {}
    out = {}
    for i in range(len(params)):
        per = [s["state"][i] for s in states]
        steps = {float(p["step"]) for p in per}
        if len(steps) != 1:
            raise ValueError(f"seeds' optimisers are at different steps {sorted(steps)}")
        out[i] = {
            "step": per[0]["step"].clone(),
            "exp_avg": torch.stack([p["exp_avg"] for p in per]),
            "exp_avg_sq": torch.stack([p["exp_avg_sq"] for p in per]),
        }
    return out


def _adam(params: list[Tensor], lr: float, beta1: float) -> torch.optim.Adam:
    """Adam as :func:`~vslbook.srl.dime_updates.make_agent` builds it (fused on cpu / cuda)."""
    fused = params[0].device.type in ("cuda", "cpu")
    return torch.optim.Adam(params, lr=lr, betas=(beta1, 0.999), fused=fused)


def _load_adam(opt: torch.optim.Optimizer, params: list[Tensor], state: dict) -> None:
    for i, p in enumerate(params):
        if i in state:
            opt.state[p] = {k: v.to(p.device) for k, v in state[i].items()}


def _seed_adam_state(opt: torch.optim.Optimizer, params: list[Tensor], s: int, like: dict) -> dict:
    """Seed ``s``'s slice of a stacked Adam, in the format of its own Adam's state_dict."""
    state = {}
    for i, p in enumerate(params):
        st = opt.state.get(p)
        if st:
            state[i] = {
                "step": st["step"].clone(),
                "exp_avg": st["exp_avg"][s].clone(),
                "exp_avg_sq": st["exp_avg_sq"][s].clone(),
            }
    return {"state": state, "param_groups": copy.deepcopy(like["param_groups"])}


class SeedStack:
    """S agents made by :func:`~vslbook.srl.dime_updates.make_agent` (one per seed), as one.

    Args:
        agents: the seeds' agents, in seed order, built with the same configuration and
            sizes (each may have loaded a checkpoint; their optimisers must be at the same
            step).
    """

    def __init__(self, agents: list[Agent]) -> None:
        if not agents:
            raise ValueError("need at least one agent")
        cfg = agents[0].cfg
        if any(a.cfg != cfg for a in agents):
            raise ValueError("every seed's agent must have the same configuration")
        if any(a.critic_target is not None for a in agents):
            raise ValueError(
                "a seed axis needs a configuration without a target network "
                "(use_target_network=False); train the target-network ablation one seed at a time"
            )
        self.cfg, self.n_seeds = cfg, len(agents)
        self.support, self.h_target = agents[0].support, agents[0].h_target
        self._template = agents[0]
        self._nets = _Nets(copy.deepcopy(agents[0].policy), copy.deepcopy(agents[0].critic))
        self._nets = self._nets.to("meta")
        self.params, self.buffers = stack_module_state([_Nets(a.policy, a.critic) for a in agents])
        self._critic_names = [f"critic.{n}" for n, _ in agents[0].critic.named_parameters()]
        self._actor_names = [
            f"policy.{n}" for n, p in agents[0].policy.named_parameters() if p.requires_grad
        ]
        for name, p in self.params.items():  # frozen policy parameters (learn_dt=False)
            if name.startswith("policy.") and name not in self._actor_names:
                p.requires_grad_(False)
        critic_params = [self.params[n] for n in self._critic_names]
        actor_params = [self.params[n] for n in self._actor_names]
        self.critic_opt = _adam(critic_params, cfg.critic_lr, cfg.adam_beta1)
        self.actor_opt = _adam(actor_params, cfg.actor_lr, cfg.adam_beta1)
        _load_adam(self.critic_opt, critic_params,
                   _stack_adam_state([a.critic_opt for a in agents], critic_params))  # fmt: skip
        _load_adam(self.actor_opt, actor_params,
                   _stack_adam_state([a.actor_opt for a in agents], actor_params))  # fmt: skip
        self.log_alpha = torch.stack([a.log_alpha.detach().clone() for a in agents])
        self.alpha_opt = None
        if cfg.fixed_alpha is None:
            self.log_alpha.requires_grad_(True)
            self.alpha_opt = _adam([self.log_alpha], cfg.alpha_lr, 0.9)
            alpha_state = _stack_adam_state([a.alpha_opt for a in agents], [self.log_alpha])
            _load_adam(self.alpha_opt, [self.log_alpha], alpha_state)

    # ------------------------------------------------------------------ helpers
    @property
    def alpha(self) -> Tensor:
        """(S,) the seeds' temperatures (no gradient)."""
        if self.cfg.fixed_alpha is not None:
            return torch.full_like(self.log_alpha, self.cfg.fixed_alpha).detach()
        return self.log_alpha.detach().exp()

    def noise(self, generators: list[torch.Generator], batch: int) -> Tensor:
        """(S, *noise_shape) policy noise, seed s's from ``generators[s]`` as its own run draws it.

        The diffusion policy draws its n_steps + 1 normals one (batch, act_dim) chunk at a
        time (chunk sizes change the numbers torch returns); the Gaussian policy one chunk.
        """
        if len(generators) != self.n_seeds:
            raise ValueError(f"need {self.n_seeds} generators, got {len(generators)}")
        device = self.log_alpha.device
        policy = self._template.policy
        return torch.stack([policy_noise(policy, batch, g, device) for g in generators])

    def _call(self, fn: Any, params: dict, *args: Any) -> Any:
        """``fn(policy, critic, *args)`` for every seed, each with its own state."""

        def one(p: dict, b: dict, *a: Any) -> Any:
            return functional_call(self._nets, (p, b), (fn, *a))

        return vmap(one)(params, self.buffers, *args)

    # ------------------------------------------------------------------ the updates
    def critic_update(self, batch: Batch, noise: Tensor) -> UpdateStats:
        """One critic step per seed (Algorithm 4, l. 7). ``batch``'s tensors and ``noise``
        carry the seed axis first; returns (S,) losses and mean Q."""
        cfg, support = self.cfg, self.support

        def loss(policy: nn.Module, critic: nn.Module, alpha: Tensor, *b: Tensor) -> Any:
            view = _View(cfg, policy, critic, support, alpha)
            return critic_loss(view, Batch(*b[:5]), b[5])

        losses, q_mean = self._call(loss, self.params, self.alpha, *batch, noise)
        self.critic_opt.zero_grad(set_to_none=True)
        losses.sum().backward()  # seeds share no parameter: each gets its own gradient
        self.critic_opt.step()
        return UpdateStats(losses.detach(), q_mean.detach())

    def actor_update(self, obs: Tensor, noise: Tensor) -> UpdateStats:
        """One actor step per seed on Eq. 5.27 (l. 9), the critics frozen and in eval mode."""
        cfg, support = self.cfg, self.support
        params = {
            k: (v.detach() if k.startswith("critic.") else v) for k, v in self.params.items()
        }

        def loss(policy: nn.Module, critic: nn.Module, alpha: Tensor, o: Tensor, n: Tensor):
            value, sample = actor_loss(_View(cfg, policy, critic, support, alpha), o, n)
            return value, sample.entropy_bound.mean(), sample.running_cost

        self._nets.critic.eval()
        try:
            losses, bound, running_cost = self._call(loss, params, self.alpha, obs, noise)
        finally:
            self._nets.critic.train()
        self.actor_opt.zero_grad(set_to_none=True)
        losses.sum().backward()
        grads = [self.params[n] for n in self._actor_names if self.params[n].grad is not None]
        clean_actor_grads(grads, cfg.actor_grad_clip)
        self.actor_opt.step()
        return UpdateStats(losses.detach(), bound.detach(), running_cost.detach())

    def alpha_update(self, running_cost: Tensor) -> Tensor:
        """One temperature step per seed on Eq. 5.28 (l. 10); (S,) losses."""
        if self.alpha_opt is None:
            return torch.zeros(self.n_seeds, device=running_cost.device)
        losses = self.log_alpha.exp() * (self.h_target - running_cost.detach().mean(dim=-1))
        self.alpha_opt.zero_grad(set_to_none=True)
        losses.sum().backward()
        self.alpha_opt.step()
        return losses.detach()

    @torch.no_grad()
    def act(self, obs: Tensor, noise: Tensor) -> Tensor:
        """(S, act_dim) actions a ~ π(·|s) for one state per seed: obs (S, obs_dim), noise
        :meth:`noise` with batch 1."""

        def sample(policy: nn.Module, critic: nn.Module, o: Tensor, n: Tensor) -> Tensor:
            return policy.sample(o[None], noise=n).action[0]

        return self._call(sample, self.params, obs, noise)

    # ------------------------------------------------------------------ one seed
    def agent_state(self, s: int) -> dict[str, Any]:
        """Seed ``s``'s state in :meth:`Agent.state_dict`'s format (an ordinary checkpoint)."""
        if not 0 <= s < self.n_seeds:
            raise ValueError(f"seed index must be in [0, {self.n_seeds}), got {s}")
        t = self._template
        state: dict[str, Any] = {}
        for part in ("policy", "critic"):
            own = getattr(t, part).state_dict()
            state[part] = {
                k: (self.params.get(f"{part}.{k}", self.buffers.get(f"{part}.{k}"))[s])
                .detach()
                .clone()
                for k in own
            }
        state["critic_target"] = None
        state["log_alpha"] = self.log_alpha.detach()[s].cpu().clone()
        critic_params = [self.params[n] for n in self._critic_names]
        actor_params = [self.params[n] for n in self._actor_names]
        state["critic_opt"] = _seed_adam_state(
            self.critic_opt, critic_params, s, t.critic_opt.state_dict()
        )
        state["actor_opt"] = _seed_adam_state(
            self.actor_opt, actor_params, s, t.actor_opt.state_dict()
        )
        state["alpha_opt"] = None
        if self.alpha_opt is not None:
            alpha = _seed_adam_state(
                self.alpha_opt, [self.log_alpha], s, t.alpha_opt.state_dict()
            )
            for st in alpha["state"].values():  # 0-d tensors, as a lone seed's log α has
                st["exp_avg"] = st["exp_avg"].reshape(())
                st["exp_avg_sq"] = st["exp_avg_sq"].reshape(())
            state["alpha_opt"] = alpha
        return state

"""What a DIME run holds, and how it is created, resumed and checkpointed.

Algorithm 4's input is "initialized parameters θ, ϕ, α, learning rates λ"; a run adds the
replay buffer D, the environments, the random streams and the counters. :class:`SeedState`
is one seed's share of all that, :class:`Schedule` the run's counts at its budget, and
:class:`Means` the diagnostics between two rows of ``metrics.jsonl``.

Checkpoints are written in one format whether a seed trained alone
(:func:`vslbook.srl.dime_loop.train`) or on a seed axis (:mod:`vslbook.srl.dime_seeds`):
networks, optimisers and α (:meth:`~vslbook.srl.dime_updates.Agent.state_dict`), the replay
buffer, the diagnostics, the counters, the random streams, and the actions of the episode
under way. On resume the environment is reset with that episode's seed and the actions are
replayed (the simulators are deterministic), so no simulator state is pickled.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from torch import Tensor

from vslbook.budget import Budget
from vslbook.results import DivergenceError, RunDir
from vslbook.rng_state import restore_rng_state, rng_state
from vslbook.seeding import seed_everything
from vslbook.srl.dime_config import DIMEConfig
from vslbook.srl.dime_env import (
    REPLAY_INDICES,
    TRAIN_RESETS,
    default_value_range,
    make_env,
    stream_seed,
    to_env_action,
)
from vslbook.srl.dime_updates import Agent, make_agent
from vslbook.srl.replay import Batch, ReplayBuffer, replay_generator

__all__ = [
    "Means",
    "Schedule",
    "SeedState",
    "eval_row",
    "global_rng_state",
    "require_finite_parameters",
    "set_global_rng_state",
]


@dataclass(frozen=True)
class Schedule:
    """Algorithm 4's counts for a run at its budget (``DIMEConfig`` holds full-budget ones).

    ``total_steps``, ``eval_every`` and ``checkpoint_every`` are scaled by the budget (the
    last two never below ``min(full, 1000)``); ``learning_starts`` is not (Table C.2's
    exploration steps are the algorithm), only capped at the run's length.
    """

    total_steps: int
    learning_starts: int
    eval_every: int
    checkpoint_every: int
    eval_episodes: int

    @classmethod
    def of(cls, cfg: DIMEConfig, budget: Budget) -> Schedule:
        total = budget.scale(cfg.total_steps)
        return cls(
            total_steps=total,
            learning_starts=min(cfg.learning_starts, total),
            eval_every=budget.scale(cfg.eval_every, minimum=min(cfg.eval_every, 1000)),
            checkpoint_every=budget.scale(
                cfg.checkpoint_every, minimum=min(cfg.checkpoint_every, 1000)
            ),
            eval_episodes=cfg.eval_episodes or budget.eval_episodes,
        )

    def evaluating(self, step: int) -> bool:
        """Whether the policy is evaluated after environment step ``step``."""
        return step % self.eval_every == 0 or step == self.total_steps

    def next_checkpoint(self, step: int) -> int:
        """The first multiple of ``checkpoint_every`` after ``step``."""
        return (step // self.checkpoint_every + 1) * self.checkpoint_every


class Means:
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


def global_rng_state(device: torch.device) -> Tensor:
    """The state of torch's global stream that a single-seed run on ``device`` draws its
    policy noise from (the CPU generator, or the device's default CUDA generator)."""
    if device.type == "cuda":
        return torch.cuda.get_rng_state(device)
    return torch.get_rng_state()


def set_global_rng_state(device: torch.device, state: Tensor) -> None:
    """Set the stream :func:`global_rng_state` reads."""
    if device.type == "cuda":
        torch.cuda.set_rng_state(state, device)
    else:
        torch.set_rng_state(state)


@dataclass(eq=False)
class SeedState:
    """One seed's share of a DIME run: Algorithm 4's θ, ϕ, α (``agent``), D (``buffer``),
    its environments, random streams and counters.

    Attributes:
        rng: the numpy stream of the uniform exploration actions and the replay indices.
        indices: a torch stream on the device for the replay indices (``replay_sampler``),
            or None (numpy's).
        noise: this seed's own policy-noise stream (the seed axis), or None: torch's global
            stream, which a single-seed run draws from.
        step, episode, updates, evals: environment steps, finished episodes, critic updates
            (l. 7) and evaluations so far.
        actions, episode_return, obs: the episode under way: its actions so far (replayed
            on resume), its return and the current observation.
    """

    run: RunDir
    seed: int
    env: gym.Env
    eval_env: gym.Env
    agent: Agent
    buffer: ReplayBuffer
    rng: np.random.Generator
    indices: torch.Generator | None
    noise: torch.Generator | None
    v_range: tuple[float | None, float | None]
    diag: Means
    step: int = 0
    episode: int = 0
    updates: int = 0
    evals: int = 0
    last_eval: dict[str, Any] = field(default_factory=dict)
    actions: list[np.ndarray] = field(default_factory=list)
    episode_return: float = 0.0
    obs: np.ndarray | None = None

    @classmethod
    def create(
        cls, run: RunDir, record: dict, cfg: DIMEConfig, budget: Budget, device: torch.device,
        *, own_noise: bool = False,
    ) -> SeedState:  # fmt: skip
        """Algorithm 4's input for ``record``'s seed, resumed from ``run``'s checkpoint if
        it has one. ``own_noise``: draw the policy noise from a generator of its own, started
        where torch's global stream stands after the initialisation (the seed axis)."""
        seed, env_id = int(record["seed"]), record["env"]
        seed_everything(seed, deterministic_torch=False)
        rng = np.random.default_rng(seed)
        env, eval_env = make_env(env_id), make_env(env_id)
        obs_dim, act_dim = env.observation_space.shape[0], env.action_space.shape[0]
        v_min, v_max = cfg.v_min, cfg.v_max
        if cfg.critic == "distributional" and v_min is None:
            v_min, v_max = default_value_range(env_id)
        agent = make_agent(obs_dim, act_dim, cfg, v_min=v_min, v_max=v_max, device=device)
        total = budget.scale(cfg.total_steps)
        state = cls(
            run=run, seed=seed, env=env, eval_env=eval_env, agent=agent,
            buffer=ReplayBuffer(min(cfg.buffer_size, total), obs_dim, act_dim, device),
            rng=rng,
            indices=replay_generator(
                cfg.replay_sampler, device, stream_seed(seed, REPLAY_INDICES)
            ),
            noise=torch.Generator(device=device) if own_noise else None,
            v_range=(v_min, v_max), diag=Means(device),
        )  # fmt: skip
        state.load(run.load_checkpoint())
        return state

    def load(self, checkpoint: dict | None) -> None:
        """Continue from ``checkpoint`` (None: from the start) and replay the cut episode."""
        if checkpoint is not None:
            self.agent.load_state_dict(checkpoint["agent"])
            if checkpoint["replay"] is not None:
                self.buffer.load_state_dict(checkpoint["replay"])
            self.diag.load_state_dict(checkpoint["diagnostics"])
            self.step, self.episode, self.updates, self.evals = (
                checkpoint[k] for k in ("step", "episode", "updates", "evals")
            )
            self.last_eval = checkpoint["last_eval"]
            restore_rng_state(checkpoint["rng"], self.rng)
            if self.indices is not None:
                self.indices.set_state(checkpoint["replay_indices"])
            self.actions = [
                np.asarray(a, np.float32) for a in checkpoint.get("episode_actions", [])
            ]
            self.episode_return = float(checkpoint.get("episode_return", 0.0))
        if self.noise is not None:  # the global stream as the single-seed run would use it
            self.noise.set_state(global_rng_state(self.noise.device))
        self.obs = self.replay_episode()

    def replay_episode(self) -> np.ndarray:
        """Reset to this episode's start (its seeded reset) and replay its actions so far."""
        obs, _ = self.env.reset(seed=stream_seed(self.seed, TRAIN_RESETS, self.episode))
        for a in self.actions:
            obs, *_ = self.env.step(to_env_action(a, self.env.action_space))
        return obs

    # ------------------------------------------------------------------ Algorithm 4
    def exploration_action(self) -> np.ndarray:
        """A uniform action in [-1, 1]^|A| (the first ``learning_starts`` steps)."""
        act_dim = self.env.action_space.shape[0]
        return self.rng.uniform(-1.0, 1.0, size=act_dim).astype(np.float32)

    def step_env(self, action: np.ndarray) -> bool:
        """l. 4-5: s' ~ p(·|s, a), D ← D ∪ {(s, a, r, s', terminated)}; whether the episode
        ended (terminated or truncated; only a termination stops the bootstrap)."""
        next_obs, reward, terminated, truncated, _ = self.env.step(
            to_env_action(action, self.env.action_space)
        )
        self.buffer.add(self.obs, action, reward, next_obs, terminated)
        self.obs, self.episode_return = next_obs, self.episode_return + float(reward)
        self.actions.append(np.asarray(action))
        self.step += 1
        return bool(terminated or truncated)

    def sample(self, batch_size: int) -> Batch:
        """A minibatch from D (indices from :attr:`indices`, else :attr:`rng`)."""
        return self.buffer.sample(batch_size, self.rng if self.indices is None else self.indices)

    def end_episode(self) -> None:
        """Log the episode's return and reset the environment for the next episode."""
        self.diag.add("train_return", self.episode_return)
        self.episode += 1
        self.actions, self.episode_return = [], 0.0
        self.obs, _ = self.env.reset(seed=stream_seed(self.seed, TRAIN_RESETS, self.episode))

    # ------------------------------------------------------------------ saving
    def checkpoint(
        self, agent_state: dict[str, Any], *, final: bool = False, keep_previous: bool = False
    ) -> None:
        """Save this seed into its run directory: ``agent_state`` (the learner's current
        θ, ϕ, α), D (not when ``final``: the finished run keeps its networks only), the
        diagnostics, counters, streams and the episode's actions so far."""
        self.run.save_checkpoint(
            {
                "agent": agent_state,
                "replay": None if final else self.buffer.state_dict(),
                "diagnostics": self.diag.state_dict(),
                "step": self.step,
                "episode": self.episode,
                "updates": self.updates,
                "evals": self.evals,
                "last_eval": self.last_eval,
                "rng": self._rng_state(),
                "replay_indices": None if self.indices is None else self.indices.get_state(),
                "episode_actions": [a.tolist() for a in self.actions],
                "episode_return": self.episode_return,
            },
            keep_previous=keep_previous,
        )

    def _rng_state(self) -> dict[str, Any]:
        """The streams in the single-seed format: an own noise stream in torch's global slot."""
        if self.noise is None:
            return rng_state(self.rng)
        device = self.noise.device
        torch_state = global_rng_state(device)
        set_global_rng_state(device, self.noise.get_state())
        try:
            return rng_state(self.rng)
        finally:
            set_global_rng_state(device, torch_state)

    def summary(self, total_steps: int) -> dict[str, Any]:
        """What ``DONE`` records for the finished run."""
        return {
            "env_steps": total_steps, "critic_updates": self.updates, "episodes": self.episode,
            **self.last_eval, "v_min": self.v_range[0], "v_max": self.v_range[1],
        }  # fmt: skip


def eval_row(
    agent: Agent, diag: Means, eval_return: float, eval_success: float | None, *,
    updates: int, episodes: int, updates_per_s: float, steps_per_s: float,
) -> dict[str, Any]:  # fmt: skip
    """One evaluation's row of ``metrics.jsonl``: return (and success), the diagnostics'
    means since the last row, the learned β per dimension (Fig. C.2), α, counts and rates."""
    row: dict[str, Any] = {"eval_return": eval_return}
    if eval_success is not None:
        row["eval_success"] = eval_success
    row.update(diag.pop())
    if hasattr(agent.policy, "noise_var"):  # Fig. C.2: the learned β_k = σ_k² per dim
        betas = agent.policy.noise_var.detach().cpu().tolist()
        row.update({f"beta_{k}": value for k, value in enumerate(betas)})
    row.update(
        alpha=float(agent.alpha.item()), critic_updates=updates, episodes=episodes,
        critic_updates_per_s=updates_per_s, env_steps_per_s=steps_per_s,
    )  # fmt: skip
    return row


def require_finite_parameters(step: int, agent: Agent) -> None:
    """Raise :class:`DivergenceError` if any network parameter or log α is not finite."""
    named = [("log_alpha", agent.log_alpha)]
    for prefix, module in (("policy", agent.policy), ("critic", agent.critic)):
        named += [(f"{prefix}.{n}", p) for n, p in module.named_parameters()]
    for name, p in named:
        if not bool(torch.isfinite(p).all()):
            raise DivergenceError(step, f"parameter {name}")

"""DIME: diffusion-based maximum entropy RL (Chapter 5, Algorithm 4), plus CrossQ.

Read :func:`train` next to Algorithm 4. Per environment step t:

    l. 3-5   a_t ~ π_θ(·|s_t) through the whole denoising chain (uniform random actions for
             the first ``learning_starts`` steps), s_{t+1} ~ p(·|s_t, a_t), D ← D ∪ {transition}
    l. 7     ``utd`` critic updates ϕ ← ϕ - λ_ϕ ∇J_Q  (Eq. 5.24 / distributional Eq. 5.21)
    l. 8-10  after every ``policy_delay``-th critic update: one actor step on Eq. 5.27 and one
             temperature step on Eq. 5.28

(Algorithm 4 writes the same schedule as one loop over critic updates k that collects a
transition when k hits the UTD ratio.)

The configuration lives in :mod:`vslbook.srl.dime_config`, the agent and its updates
(critic Eq. 5.21 / 5.24, actor Eq. 5.27, temperature Eq. 5.28) in
:mod:`vslbook.srl.dime_updates`; this module is the loop that calls them.

Episodes and resume. Time-limit truncations bootstrap, terminations do not. The training
environment is reset with a seed derived from (run seed, episode index) and the evaluation
environment from (run seed, evaluation index, episode), so no simulator state is pickled:
checkpoints are written at episode boundaries only, and a run resumed from one logs exactly
the numbers an uninterrupted run logs on CPU (all metrics except the wall-clock rates
``critic_updates_per_s`` and ``env_steps_per_s``).

Divergence. Every update's losses, the critic's mean Q and the entropy bound are watched
for finiteness on the device (:class:`vslbook.srl.divergence.FiniteWatch`, no host sync per
update) and checked at every evaluation and episode end, the parameters and log α at every
evaluation; the first non-finite one raises :class:`vslbook.results.DivergenceError` naming
the step of the update that produced it and the quantity, and
:func:`vslbook.training.run` marks the run FAILED instead of DONE.
"""

from __future__ import annotations

import time
import warnings
from functools import partial
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from torch import Tensor, nn
from tqdm.auto import tqdm

from vslbook.budget import Budget
from vslbook.registry import config_from_record, register_algorithm
from vslbook.results import DivergenceError, RunDir
from vslbook.rng_state import restore_rng_state, rng_state
from vslbook.seeding import seed_everything
from vslbook.srl.cuda_graphs import GraphedUpdates, graphs_wanted
from vslbook.srl.dime_config import CrossQConfig, DIMEConfig, DIMEGaussianConfig
from vslbook.srl.dime_updates import (
    Agent,
    UpdateStats,
    actor_update,
    alpha_update,
    combine_q,
    critic_update,
    make_agent,
    policy_noise,
    q_values,
    resolve_device,
)
from vslbook.srl.divergence import WATCHED, FiniteWatch
from vslbook.srl.replay import ReplayBuffer, replay_generator

__all__ = [
    "Agent",
    "CrossQConfig",
    "DIMEConfig",
    "DIMEGaussianConfig",
    "UpdateStats",
    "act",
    "actor_update",
    "alpha_update",
    "combine_q",
    "critic_update",
    "default_value_range",
    "evaluate",
    "make_agent",
    "make_env",
    "q_values",
    "resolve_device",
    "train",
]

#: Table C.3's gymnasium-locomotion range, used when no per-suite range is known.
FALLBACK_VALUE_RANGE = (-1600.0, 1600.0)


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


def _validate_env(env_id: str) -> None:
    """Build ``env_id`` once to check its spaces (:func:`make_env`) before a run is made."""
    make_env(env_id).close()


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


TRAIN_RESETS, EVAL_RESETS, EVAL_NOISE, REPLAY_INDICES = 0, 1, 2, 3


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
    graphs: GraphedUpdates | None = None,
) -> np.ndarray:
    """One stochastic action in [-1, 1] for one observation (l. 3: the whole chain);
    with ``graphs``, the chain is replayed as a CUDA graph (the same draws)."""
    obs_t = torch.as_tensor(obs, dtype=torch.float32, device=device).unsqueeze(0)
    if graphs is not None:
        noise = policy_noise(policy, 1, generator, device)
        return graphs.act(obs_t, noise)[0].cpu().numpy()
    return policy.sample(obs_t, generator=generator).action[0].cpu().numpy()


def evaluate(
    policy: nn.Module,
    env: gym.Env,
    *,
    seed: int,
    index: int,
    episodes: int,
    device: torch.device,
    graphs: GraphedUpdates | None = None,
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
            action = act(policy, obs, device, generator, graphs)
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


def eval_row(
    agent: Agent, diag: _Means, eval_return: float, eval_success: float | None, *,
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


def _require_finite_parameters(step: int, agent: Agent) -> None:
    """Raise :class:`DivergenceError` if any network parameter or log α is not finite."""
    named = [("log_alpha", agent.log_alpha)]
    for prefix, module in (("policy", agent.policy), ("critic", agent.critic)):
        named += [(f"{prefix}.{n}", p) for n, p in module.named_parameters()]
    for name, p in named:
        if not bool(torch.isfinite(p).all()):
            raise DivergenceError(step, f"parameter {name}")


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
    learning_starts = min(cfg.learning_starts, total_steps)  # Table C.2: never scaled
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
    indices = replay_generator(cfg.replay_sampler, device, _stream_seed(seed, REPLAY_INDICES))
    critic_step, actor_step = critic_update, actor_update
    graphs = GraphedUpdates(agent) if graphs_wanted(cfg, device) else None
    if cfg.compile and graphs is None:
        critic_step, actor_step = torch.compile(critic_update), torch.compile(actor_update)
    diag = _Means(device)
    watch = FiniteWatch(WATCHED, device)

    step = episode = n_updates = n_evals = 0
    last_eval: dict[str, Any] = {}
    episode_actions: list = []  # a checkpoint of vslbook.srl.dime_seeds may cut an episode
    episode_return = 0.0
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
        if indices is not None:
            indices.set_state(state["replay_indices"])
        episode_actions = state.get("episode_actions", [])
        episode_return = float(state.get("episode_return", 0.0))

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
                "replay_indices": None if indices is None else indices.get_state(),
            }
        )

    def update_step() -> None:
        """l. 7-10: ``utd`` critic updates; the actor and α after every ``policy_delay``-th."""
        nonlocal n_updates
        for _ in range(cfg.utd):
            batch = buffer.sample(cfg.batch_size, rng if indices is None else indices)
            if graphs is None:
                critic_stats = critic_step(agent, batch)
            else:  # the draws the eager step would make, from the same (global) stream
                noise = policy_noise(agent.policy, cfg.batch_size, None, device)
                critic_stats = graphs.critic_update(batch, noise)
            watch.add(step, critic_loss=critic_stats.loss, q_mean=critic_stats.value)
            diag.add("critic_loss", critic_stats.loss)
            diag.add("q_mean", critic_stats.value)
            n_updates += 1
            if n_updates % cfg.policy_delay == 0:  # l. 8-10: actor (5.27) and α (5.28)
                if graphs is None:
                    actor_stats = actor_step(agent, batch.obs)
                    alpha_loss = alpha_update(agent, actor_stats.running_cost)
                else:
                    noise = policy_noise(agent.policy, cfg.batch_size, None, device)
                    actor_stats, alpha_loss = graphs.actor_alpha_update(batch.obs, noise)
                watch.add(
                    step, actor_loss=actor_stats.loss, entropy_bound=actor_stats.value,
                    alpha_loss=alpha_loss,
                )  # fmt: skip
                diag.add("actor_loss", actor_stats.loss)
                diag.add("entropy_bound", actor_stats.value)
                diag.add("running_cost", actor_stats.running_cost.mean())

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
    for action in episode_actions:  # replay the cut episode (deterministic simulators)
        obs, *_ = env.step(_to_env_action(np.asarray(action, np.float32), env.action_space))
    while step < total_steps:
        # l. 3-5: a ~ π(·|s) (uniform at first), s' ~ p(·|s, a), D ← D ∪ {(s, a, r, s', term)}
        if step < learning_starts:
            action = rng.uniform(-1.0, 1.0, size=act_dim).astype(np.float32)
        else:
            action = act(agent.policy, obs, device, graphs=graphs)  # the step's one host sync
            if not np.isfinite(action).all():  # a diverged update shows here first
                watch.check()
                raise DivergenceError(step + 1, "action", float(action[~np.isfinite(action)][0]))
        next_obs, reward, terminated, truncated, info = env.step(
            _to_env_action(action, env.action_space)
        )
        buffer.add(obs, action, reward, next_obs, terminated)
        obs, episode_return = next_obs, episode_return + float(reward)
        step += 1
        steps_this_call += 1

        if step >= learning_starts:
            try:
                update_step()
            except Exception as err:  # an update failing on an earlier update's non-finite
                if not isinstance(err, DivergenceError):  # output says so; else its own error
                    watch.check()
                raise

        if step % eval_every == 0 or step == total_steps:
            watch.check()
            _require_finite_parameters(step, agent)
            eval_return, eval_success = evaluate(
                agent.policy, eval_env, seed=seed, index=n_evals, episodes=eval_episodes,
                device=device, graphs=graphs,
            )  # fmt: skip
            n_evals += 1
            now = time.perf_counter()
            elapsed = max(now - clock, 1e-9)
            row = eval_row(
                agent, diag, eval_return, eval_success, updates=n_updates, episodes=episode,
                updates_per_s=(n_updates - updates_at_clock) / elapsed,
                steps_per_s=(step - steps_at_clock) / elapsed,
            )  # fmt: skip
            run.log(step, **row)
            last_eval = {"eval_return": eval_return, "eval_success": eval_success}
            bar.set_postfix(ret=f"{eval_return:.1f}", alpha=f"{row['alpha']:.3g}")
            clock, steps_at_clock, updates_at_clock = time.perf_counter(), step, n_updates
        bar.update(1)

        if terminated or truncated:  # episode boundary: reset, maybe checkpoint or stop
            watch.check()
            diag.add("train_return", episode_return)
            episode += 1
            obs, _ = env.reset(seed=_stream_seed(seed, TRAIN_RESETS, episode))
            episode_return = 0.0
            stopping = stop_after is not None and steps_this_call >= stop_after
            due = step >= next_checkpoint or run.checkpoint_due()
            if step < total_steps and (due or stopping):
                checkpoint()
                next_checkpoint = (step // checkpoint_every + 1) * checkpoint_every
            if stopping and step < total_steps:
                bar.close()
                return None
    bar.close()
    watch.check()
    checkpoint(final=True)  # networks for later analysis; the replay buffer is dropped
    return {
        "env_steps": total_steps,
        "critic_updates": n_updates,
        "episodes": episode,
        **last_eval,
        "v_min": v_min,
        "v_max": v_max,
    }


# Chapter 5's runs never import the episodic (Chapters 2-4) code.
_NOT_SRL = ("erl/", "envs/robot/")


def _train_seeds(*args: Any, config_cls: type[DIMEConfig] = DIMEConfig, **kwargs: Any) -> list:
    """:func:`vslbook.srl.dime_seeds.train_seeds` (several seeds in one process)."""
    from vslbook.srl.dime_seeds import train_seeds

    return train_seeds(*args, config_cls=config_cls, **kwargs)


register_algorithm(
    "dime",
    train=train,
    config=DIMEConfig,
    doc="DIME (Algorithm 4): diffusion policy, distributional CrossQ critics, autotuned α",
    independent_of=_NOT_SRL,
    train_seeds=_train_seeds,
    validate_env=_validate_env,
)
register_algorithm(
    "dime-gaussian",
    train=partial(train, config_cls=DIMEGaussianConfig),
    config=DIMEGaussianConfig,
    doc="DIME's critic and updates with a tanh-Gaussian policy (Fig. 5.4c-d ablation)",
    independent_of=_NOT_SRL,
    train_seeds=partial(_train_seeds, config_cls=DIMEGaussianConfig),
    validate_env=_validate_env,
)
register_algorithm(
    "crossq",
    train=partial(train, config_cls=CrossQConfig),
    config=CrossQConfig,
    doc="CrossQ: tanh-Gaussian policy, BatchRenorm scalar critics, no target network",
    independent_of=_NOT_SRL,
    train_seeds=partial(_train_seeds, config_cls=CrossQConfig),
    validate_env=_validate_env,
)

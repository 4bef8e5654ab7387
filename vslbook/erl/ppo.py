"""PPO baseline of Chapter 3 (Section 3.4.3, Fig. 3.5, Table A.5) with stable-baselines3.

The thesis compares SVSL with PPO (Schulman et al. 2017) in the implementation of Raffin
et al. (2019), i.e. stable-baselines3, on the step-based 5-link reacher
(:class:`vslbook.envs.robot.reacher5_step.Reacher5Ch3StepEnv`) with the rewards of
Eqs. 3.8, 3.9 and 3.10. Table A.5 gives one set of hyper-parameters for all three rewards;
what it leaves open is filled in here and marked as our choice in :class:`PPOConfig`.

Read :func:`train_ppo` as the loop

    repeat until ``total_steps`` environment steps:
        evaluate the deterministic policy on fixed goals (every ``eval_every`` steps)
        collect N = 16384 steps from ``n_envs`` reacher copies (observations and rewards
            normalised by running statistics, VecNormalize)
        n_epochs passes of minibatch-K clipped-surrogate updates with GAE(λ) advantages

where the inner two lines are ``PPO.learn`` of stable-baselines3, unchanged.

Evaluation. :func:`evaluate` runs the mean action of the policy (observations normalised
with the current statistics, which it does not update) on a fixed set of goals drawn from
p(c) with :data:`EVAL_GOAL_SEED` (:func:`evaluation_goals`), the same for every reward and
every training seed, and reports the thesis's own (un-normalised) return and the final tip
distance, so PPO and SVSL are on one scale. The x-axis is reported both as environment
steps and as completed training episodes (200 steps each), because Fig. 3.5 compares with
an episode-based method.

Checkpoints and exact resume. With ``run_dir`` a checkpoint is written at every
evaluation (one file, written then renamed): the SB3 model zip (policy and Adam state),
the VecNormalize statistics, the metrics so far, the RNG states (python, numpy, torch) and
the state of the training environments. Stable-baselines3's own save/load does not
resume a run exactly, for three reasons that the checkpoint covers:

* ``VecNormalize`` drops its running discounted return (``returns``, used to scale the
  rewards) when pickled, and ``VecNormalize.load`` starts it from zero;
* ``PPO.load`` re-seeds python, numpy and torch with the construction seed and forgets the
  last observation, so the environments are reset and the random streams restart;
* evaluations fall on rollout boundaries, which are not episode boundaries (1024 steps per
  environment are 5.12 episodes), so the simulators are mid-episode: we store each
  environment's MuJoCo integration state, goal, step counter and ``np_random`` state.

A run interrupted after any checkpoint and resumed logs the numbers of an uninterrupted run
on CPU (except the wall-clock rate ``env_steps_per_s``).

The pieces that do not depend on the reacher (the checks of the shared hyper-parameters,
:func:`build_ppo`, :func:`mean_actions`, the MuJoCo and training-state snapshots and the
checkpointed loop :func:`train_with_checkpoints`) are reused by Chapter 4's PPO baselines
(:mod:`vslbook.erl.ppo_ch4`).
"""

from __future__ import annotations

import copy
import io
import math
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Protocol

import gymnasium as gym
import mujoco
import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize
from tqdm.auto import tqdm

from vslbook.envs.robot.reacher5 import N_STEPS, Reacher5Ch3, check_ch3_reward
from vslbook.envs.robot.reacher5_step import Reacher5Ch3StepEnv
from vslbook.results import restore_rng_state, rng_state

__all__ = [
    "CHECKPOINT_FILE",
    "EVAL_GOAL_SEED",
    "PPOConfig",
    "evaluate",
    "evaluation_goals",
    "make_ppo",
    "train_ppo",
]

#: Seed of the fixed evaluation goals (the same for every reward, run and method).
EVAL_GOAL_SEED = 343
#: Name of the checkpoint file inside ``run_dir``.
CHECKPOINT_FILE = "ppo_checkpoint.pt"
#: Training statistics of ``PPO.train`` copied into the metrics (SB3 logger key → ours).
_TRAIN_STATS = {
    "train/policy_gradient_loss": "policy_loss",
    "train/value_loss": "value_loss",
    "train/entropy_loss": "entropy_loss",
    "train/approx_kl": "approx_kl",
    "train/clip_fraction": "clip_fraction",
    "train/explained_variance": "explained_variance",
    "train/std": "action_std",
}
_MJ_STATE = mujoco.mjtState.mjSTATE_INTEGRATION


def is_positive_int(value: Any) -> bool:
    """Whether ``value`` is an integer >= 1 (``bool`` is not an integer here)."""
    return not isinstance(value, bool) and isinstance(value, (int, np.integer)) and value >= 1


def check_seed(seed: Any) -> int:
    """``seed`` as an ``int``; raises ValueError unless it is a non-negative integer."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    return int(seed)


def check_ppo_fields(config: Any) -> None:
    """Check the hyper-parameters every PPO configuration here has (raises ValueError).

    ``config`` is a frozen dataclass with ``learning_rate``, ``n_rollout_steps``,
    ``gae_lambda``, ``gamma``, ``batch_size``, ``clip_range``, ``net_arch``, ``n_epochs``,
    ``n_envs`` and ``total_steps``; its ``net_arch`` is stored as a tuple.
    """
    for name in ("n_rollout_steps", "batch_size", "n_epochs", "n_envs", "total_steps"):
        value = getattr(config, name)
        if not is_positive_int(value):
            raise ValueError(f"{name} must be a positive integer, got {value!r}")
    for name, low, high in (
        ("learning_rate", 0.0, math.inf),
        ("gae_lambda", 0.0, 1.0),
        ("gamma", 0.0, 1.0),
        ("clip_range", 0.0, math.inf),
    ):
        value = getattr(config, name)
        if (
            isinstance(value, bool)
            or not isinstance(value, (int, float))
            or not (low < value <= high)
        ):
            raise ValueError(f"{name} must be a number in ({low}, {high}], got {value!r}")
    arch = tuple(config.net_arch)
    if not arch or not all(isinstance(w, int) and w > 0 for w in arch):
        raise ValueError(f"net_arch must be positive layer widths, got {config.net_arch!r}")
    object.__setattr__(config, "net_arch", arch)
    if config.n_rollout_steps % config.n_envs:
        raise ValueError(
            f"n_rollout_steps ({config.n_rollout_steps}) must be a multiple of n_envs "
            f"({config.n_envs}): every environment contributes N / n_envs steps"
        )
    if config.n_rollout_steps < 2 * config.n_envs:
        raise ValueError(
            f"n_rollout_steps ({config.n_rollout_steps}) must be at least 2 steps per "
            f"environment ({2 * config.n_envs})"
        )
    if config.total_steps % config.n_rollout_steps:
        raise ValueError(
            f"total_steps ({config.total_steps}) must be a multiple of n_rollout_steps "
            f"({config.n_rollout_steps}): PPO trains on whole rollouts"
        )


@dataclass(frozen=True)
class PPOConfig:
    """PPO for the 5-link reacher, Table A.5 (the same for Eqs. 3.8, 3.9 and 3.10).

    ======================  ======  ==========================================
    Table A.5               value   field
    ======================  ======  ==========================================
    α (learning rate)       1e-4    ``learning_rate``
    N (steps per rollout)   16384   ``n_rollout_steps`` (over all environments)
    GAE λ                   0.95    ``gae_lambda``
    γ                       0.99    ``gamma``
    K (minibatch size)      64      ``batch_size``
    ϵ (ratio clip)          0.2     ``clip_range``
    network structure       64, 64  ``net_arch`` (policy and value network each)
    obs./reward normalised  yes     ``normalize`` (VecNormalize, clip 10, γ above)
    ======================  ======  ==========================================

    Not in the thesis (our choices): ``n_epochs`` = 10, SB3's default; ``n_envs`` = 16
    parallel environments, so N = 16 × 1024 steps; ``total_steps`` = 300 updates
    (4,915,200 steps, 24,576 episodes); every other PPO setting is SB3's default (tanh
    units, orthogonal initialisation, state-independent log std starting at 0, advantages
    normalised per minibatch, entropy coefficient 0, value coefficient 0.5, gradient norm
    clip 0.5, no value clipping), as the thesis names no others.
    """

    learning_rate: float = 1e-4
    n_rollout_steps: int = 16384
    gae_lambda: float = 0.95
    gamma: float = 0.99
    batch_size: int = 64
    clip_range: float = 0.2
    net_arch: tuple[int, ...] = (64, 64)
    n_epochs: int = 10
    n_envs: int = 16
    normalize: bool = True
    total_steps: int = 300 * 16384

    def __post_init__(self) -> None:
        check_ppo_fields(self)


def evaluation_goals(n: int, seed: int = EVAL_GOAL_SEED) -> np.ndarray:
    """``n`` goals from p(c) (the right half disk of radius 0.5, Section 3.4.3), ``(n, 2)``."""
    return Reacher5Ch3().sample_contexts(n, np.random.default_rng(seed))


def make_ppo(reward: str, config: PPOConfig, seed: int) -> PPO:
    """The stable-baselines3 PPO of Table A.5 on ``config.n_envs`` step-based reachers.

    The environments are wrapped in ``VecNormalize`` when ``config.normalize`` (get it back
    with ``model.get_vec_normalize_env()``). Seeds python, numpy and torch with ``seed``
    and the environments with ``seed + i``.
    """
    reward = check_ch3_reward(reward)
    if not isinstance(config, PPOConfig):
        raise TypeError(f"config must be a PPOConfig, got {type(config).__name__}")
    seed = check_seed(seed)
    return build_ppo(
        [lambda: Reacher5Ch3StepEnv(reward=reward) for _ in range(config.n_envs)], config, seed
    )


def build_ppo(
    env_fns: Sequence[Callable[[], gym.Env]],
    config: Any,
    seed: int,
    *,
    ppo_class: type[PPO] = PPO,
    **overrides: Any,
) -> PPO:
    """Stable-baselines3's PPO on ``DummyVecEnv(env_fns)`` with ``config``'s hyper-parameters.

    ``config`` has the fields that :func:`check_ppo_fields` checks and ``normalize``: with
    it, the environments are wrapped in ``VecNormalize`` (observations and rewards, both
    clipped at 10, the reward scale from the discounted return with ``config.gamma``). The
    policy and the value function are separate MLPs of ``config.net_arch``; ``overrides``
    are further (or replacing) keyword arguments of ``ppo_class``. Seeds python, numpy and
    torch with ``seed`` and environment i with ``seed + i``.
    """
    venv: Any = DummyVecEnv(list(env_fns))
    if config.normalize:
        venv = VecNormalize(
            venv, norm_obs=True, norm_reward=True, clip_obs=10.0, clip_reward=10.0,
            gamma=config.gamma,
        )  # fmt: skip
    layers = list(config.net_arch)
    kwargs: dict[str, Any] = {
        "learning_rate": config.learning_rate,
        "n_steps": config.n_rollout_steps // config.n_envs,
        "batch_size": config.batch_size,
        "n_epochs": config.n_epochs,
        "gamma": config.gamma,
        "gae_lambda": config.gae_lambda,
        "clip_range": config.clip_range,
        "policy_kwargs": {"net_arch": {"pi": layers, "vf": list(layers)}},
        "seed": seed,
        "device": "cpu",
        "verbose": 0,
    }
    kwargs.update(overrides)
    return ppo_class("MlpPolicy", venv, **kwargs)


def mean_actions(model: PPO, obs: np.ndarray) -> np.ndarray:
    """The policy's mean action for a batch of raw observations ``obs``.

    The observations are normalised with the model's VecNormalize statistics (if any),
    which are read, not updated; the actions come clipped to the action space.
    """
    normalizer = model.get_vec_normalize_env()
    policy_obs = normalizer.normalize_obs(obs) if normalizer is not None else obs
    actions, _ = model.predict(policy_obs, deterministic=True)
    return actions


def evaluate(model: PPO, envs: list[Reacher5Ch3StepEnv], goals: np.ndarray) -> dict[str, float]:
    """Mean return (Eq. 3.8/3.9/3.10, un-normalised) and final tip distance on ``goals``.

    One episode per goal, all ``len(goals)`` episodes stepped together with the mean
    action; ``envs`` holds one environment per goal. The policy sees observations
    normalised with the model's VecNormalize statistics (not updated). Uses no randomness.
    """
    goals = np.asarray(goals, dtype=np.float64)
    if goals.ndim != 2 or goals.shape[1] != 2 or len(goals) != len(envs) or len(goals) == 0:
        raise ValueError(
            f"goals must have shape (n, 2) with n = len(envs) = {len(envs)} > 0, "
            f"got shape {goals.shape}"
        )
    obs = np.stack([env.reset(options={"goal": g})[0] for env, g in zip(envs, goals, strict=True)])
    returns = np.zeros(len(envs))
    distance = np.zeros(len(envs))
    for _ in range(N_STEPS):
        actions = mean_actions(model, obs)
        for i, env in enumerate(envs):
            obs[i], r, _, _, info = env.step(actions[i])
            returns[i] += r
            distance[i] = info["tip_distance"]
    return {
        "eval_return": float(returns.mean()),
        "eval_return_std": float(returns.std()),
        "eval_tip_distance": float(distance.mean()),
    }


# -- checkpoint state that SB3 does not save (see the module doc) ------------------------


def physics_state(model: mujoco.MjModel, data: mujoco.MjData) -> np.ndarray:
    """MuJoCo's integration state of ``data`` (time, q, q̇, controls, warm start, mocap, ...)."""
    physics = np.empty(mujoco.mj_stateSize(model, _MJ_STATE))
    mujoco.mj_getState(model, data, physics, _MJ_STATE)
    return physics


def set_physics_state(model: mujoco.MjModel, data: mujoco.MjData, physics: np.ndarray) -> None:
    """Write a :func:`physics_state` back into ``data`` (derived quantities are not recomputed)."""
    mujoco.mj_setState(model, data, np.asarray(physics, dtype=np.float64), _MJ_STATE)


def generator_from_state(state: dict[str, Any]) -> np.random.Generator:
    """A numpy PCG64 generator in the bit-generator state ``state``."""
    generator = np.random.Generator(np.random.PCG64())
    generator.bit_generator.state = state
    return generator


def reacher_state(env: gym.Env) -> dict[str, Any]:
    """Mid-episode state of a step-based reacher (simulator, goal, step, ``np_random``)."""
    sim = env.sim
    return {
        "physics": physics_state(sim.model, sim.data),
        "physics_steps": sim.physics_steps,
        "goal": env._goal.copy(),
        "t": env._t,
        "np_random": env.np_random.bit_generator.state,
    }


def set_reacher_state(env: gym.Env, state: dict[str, Any]) -> None:
    """Put a step-based reacher back into a :func:`reacher_state`."""
    sim = env.sim
    set_physics_state(sim.model, sim.data, state["physics"])
    sim.physics_steps = state["physics_steps"]
    env._goal = np.array(state["goal"], dtype=np.float64)
    env._t = int(state["t"])
    env.np_random = generator_from_state(state["np_random"])


class StatefulCallback(Protocol):
    """A stable-baselines3 callback whose state goes into the checkpoint."""

    def state_dict(self) -> dict[str, Any]: ...

    def load_state_dict(self, state: dict[str, Any]) -> None: ...


def _normalizer_state(normalizer: VecNormalize) -> dict[str, Any]:
    """Running statistics and the running discounted return (which SB3's pickling drops)."""
    names = ("obs_rms", "ret_rms", "returns", "old_obs", "old_reward")
    # old_obs exists only after the first reset
    return {k: copy.deepcopy(vars(normalizer)[k]) for k in names if k in vars(normalizer)}


def _training_state(
    model: PPO,
    env_state: Callable[[gym.Env], dict[str, Any]],
    callback: StatefulCallback | None,
) -> dict[str, Any]:
    buffer = io.BytesIO()
    model.save(buffer)  # policy, value function and Adam state
    normalizer = model.get_vec_normalize_env()
    base = model.get_env()
    started = model._last_obs is not None
    return {
        "model_zip": buffer.getvalue(),
        "num_timesteps": model.num_timesteps,
        "n_updates": model._n_updates,
        "last_obs": model._last_obs,
        "last_original_obs": model._last_original_obs,
        "last_episode_starts": model._last_episode_starts,
        "vec_normalize": None if normalizer is None else _normalizer_state(normalizer),
        # before the first rollout the environments have not been reset yet
        "envs": [env_state(e) for e in base.unwrapped.envs] if started else None,
        "callback": None if callback is None else callback.state_dict(),
    }


def _restore_training_state(
    model: PPO,
    state: dict[str, Any],
    set_env_state: Callable[[gym.Env, dict[str, Any]], None],
    callback: StatefulCallback | None,
) -> None:
    model.set_parameters(io.BytesIO(state["model_zip"]), exact_match=True, device="cpu")
    model.num_timesteps = int(state["num_timesteps"])
    model._n_updates = int(state["n_updates"])
    model._last_obs = state["last_obs"]
    model._last_original_obs = state["last_original_obs"]
    model._last_episode_starts = state["last_episode_starts"]
    normalizer = model.get_vec_normalize_env()
    if (normalizer is None) != (state["vec_normalize"] is None):
        raise ValueError("the checkpoint and the config disagree on observation normalisation")
    if normalizer is not None:
        for name, value in copy.deepcopy(state["vec_normalize"]).items():
            setattr(normalizer, name, value)
    if state["envs"] is not None:
        for env, env_state in zip(model.get_env().unwrapped.envs, state["envs"], strict=True):
            set_env_state(env, env_state)
    if callback is not None:
        callback.load_state_dict(state["callback"])


def _save_checkpoint(path: Path, payload: dict[str, Any]) -> None:
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as fh:
        torch.save(payload, fh)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


def _check_resumable(saved: dict[str, Any], current: dict[str, Any], path: Path) -> None:
    """Everything but ``total_steps`` must match (a finished run may be extended)."""
    keys = set(saved) | set(current)
    diff = sorted(k for k in keys if k != "total_steps" and saved.get(k) != current.get(k))
    if diff:
        changes = ", ".join(f"{k}: {saved.get(k)!r} → {current.get(k)!r}" for k in diff)
        raise ValueError(f"{path} belongs to another run ({changes}); use a new run_dir")


def train_ppo(
    reward: str,
    config: PPOConfig,
    seed: int,
    run_dir: Path | None = None,
    eval_every: int = 5 * 16384,
    eval_episodes: int = 20,
    progress: bool = False,
    stop_after_evals: int | None = None,
) -> list[dict[str, Any]]:
    """Train PPO (Table A.5) on the reacher with reward Eq. ``reward``; return the metrics.

    Args:
        reward: "3.8", "3.9" or "3.10" (Eqs. 3.8–3.10).
        config: the hyper-parameters, :class:`PPOConfig`.
        seed: a non-negative integer (python, numpy, torch; environment i gets seed + i).
        run_dir: if given, a checkpoint is written there at every evaluation and the run
            resumes from it (raises ValueError if it belongs to another run).
        eval_every: environment steps between evaluations, a multiple of
            ``config.n_rollout_steps``; the policy is evaluated at step 0, every
            ``eval_every`` steps and at ``config.total_steps``.
        eval_episodes: number of fixed evaluation goals (:func:`evaluation_goals`).
        progress: show a progress bar.
        stop_after_evals: return (checkpointed) after this many evaluations in this call,
            as if interrupted; None runs to ``config.total_steps``.

    Returns:
        One dict per evaluation: ``env_steps``, ``episodes`` (completed training episodes
        of 200 steps), ``updates`` (PPO iterations), ``eval_return``, ``eval_return_std``,
        ``eval_tip_distance`` (see :func:`evaluate`), the last update's training
        statistics (``policy_loss``, ``value_loss``, ``entropy_loss``, ``approx_kl``,
        ``clip_fraction``, ``explained_variance``, ``action_std``; absent at step 0) and
        ``env_steps_per_s`` (wall clock, training only).
    """
    reward = check_ch3_reward(reward)
    if not isinstance(config, PPOConfig):
        raise TypeError(f"config must be a PPOConfig, got {type(config).__name__}")
    seed = check_seed(seed)
    check_run_arguments(config, eval_every, eval_episodes, stop_after_evals)

    model = make_ppo(reward, config, seed)
    goals = evaluation_goals(eval_episodes)
    eval_envs = [Reacher5Ch3StepEnv(reward=reward) for _ in range(eval_episodes)]
    run_info = {
        "reward": reward, "seed": seed, "eval_every": int(eval_every),
        "eval_episodes": int(eval_episodes), **asdict(config),
    }  # fmt: skip
    return train_with_checkpoints(
        model,
        total_steps=config.total_steps,
        eval_every=eval_every,
        run_info=run_info,
        run_dir=run_dir,
        evaluate=lambda: evaluate(model, eval_envs, goals),
        episodes=lambda steps: config.n_envs * ((steps // config.n_envs) // N_STEPS),
        env_state=reacher_state,
        set_env_state=set_reacher_state,
        desc=f"PPO Eq. {reward} s{seed}",
        postfix=lambda row: {
            "ret": f"{row['eval_return']:.1f}",
            "dist": f"{row['eval_tip_distance']:.3f}",
        },
        progress=progress,
        stop_after_evals=stop_after_evals,
    )


def check_run_arguments(
    config: Any, eval_every: Any, eval_episodes: Any, stop_after_evals: Any
) -> None:
    """Check the evaluation and stopping arguments of a PPO run (raises ValueError)."""
    if not is_positive_int(eval_every) or eval_every % config.n_rollout_steps:
        raise ValueError(
            f"eval_every must be a positive multiple of n_rollout_steps "
            f"({config.n_rollout_steps}), got {eval_every!r}"
        )
    if not is_positive_int(eval_episodes):
        raise ValueError(f"eval_episodes must be a positive integer, got {eval_episodes!r}")
    if stop_after_evals is not None and not is_positive_int(stop_after_evals):
        raise ValueError(f"stop_after_evals must be None or >= 1, got {stop_after_evals!r}")


def train_with_checkpoints(
    model: PPO,
    *,
    total_steps: int,
    eval_every: int,
    run_info: dict[str, Any],
    run_dir: Path | str | None,
    evaluate: Callable[[], dict[str, float]],
    episodes: Callable[[int], int],
    env_state: Callable[[gym.Env], dict[str, Any]],
    set_env_state: Callable[[gym.Env, dict[str, Any]], None],
    desc: str,
    postfix: Callable[[dict[str, Any]], dict[str, str]],
    progress: bool = False,
    stop_after_evals: int | None = None,
    callback: StatefulCallback | None = None,
) -> list[dict[str, Any]]:
    """Run ``model.learn`` in chunks of ``eval_every`` steps with an evaluation after each.

    The loop of :func:`train_ppo`, independent of the task: ``evaluate()`` gives the
    evaluation numbers of the current policy, ``episodes(env_steps)`` the completed training
    episodes, ``env_state`` / ``set_env_state`` snapshot one training environment
    mid-episode, ``callback`` (passed to ``learn``) may carry state of its own. With
    ``run_dir`` the run checkpoints at every evaluation and resumes from the checkpoint
    (``run_info`` identifies the run: everything in it but ``total_steps`` must match).
    Returns the rows of all evaluations (see :func:`train_ppo`).
    """
    n_rollout_steps = model.n_steps * model.n_envs
    metrics: list[dict[str, Any]] = []
    path = None if run_dir is None else Path(run_dir) / CHECKPOINT_FILE
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        if path.exists():
            saved = torch.load(path, map_location="cpu", weights_only=False)
            _check_resumable(saved["run"], run_info, path)
            _restore_training_state(model, saved["training"], set_env_state, callback)
            restore_rng_state(saved["rng"])  # after building the model, which re-seeded
            metrics = saved["metrics"]

    def log_evaluation(row: dict[str, Any]) -> None:
        row.update(evaluate())
        metrics.append(row)
        if path is not None:
            _save_checkpoint(
                path,
                {
                    "run": run_info,
                    "training": _training_state(model, env_state, callback),
                    "rng": rng_state(),
                    "metrics": metrics,
                },
            )

    evals_this_call = 0
    bar = tqdm(total=total_steps, initial=model.num_timesteps, disable=not progress, desc=desc)
    if not metrics:  # the initial policy
        log_evaluation({"env_steps": 0, "episodes": 0, "updates": 0})
        evals_this_call += 1
    while model.num_timesteps < total_steps and (
        stop_after_evals is None or evals_this_call < stop_after_evals
    ):
        chunk = min(eval_every, total_steps - model.num_timesteps)
        clock = time.perf_counter()
        # N steps from the n_envs environments, then n_epochs of minibatch-K updates
        # (clipped surrogate, GAE(λ)), chunk / N times; episodes continue across calls
        model.learn(chunk, callback=callback, reset_num_timesteps=False, log_interval=None)
        elapsed = max(time.perf_counter() - clock, 1e-9)
        steps = model.num_timesteps
        train_stats = model.logger.name_to_value
        row: dict[str, Any] = {
            "env_steps": steps,
            "episodes": episodes(steps),
            "updates": steps // n_rollout_steps,
            **{ours: float(train_stats[key]) for key, ours in _TRAIN_STATS.items()
               if key in train_stats},
            "env_steps_per_s": chunk / elapsed,
        }  # fmt: skip
        log_evaluation(row)
        evals_this_call += 1
        bar.update(chunk)
        bar.set_postfix(postfix(row))
    bar.close()
    return [dict(m) for m in metrics]

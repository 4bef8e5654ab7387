"""The task-independent parts of the PPO baselines (Chapters 3 and 4) on stable-baselines3.

:mod:`vslbook.erl.ppo` (Fig. 3.5, Table A.5) and :mod:`vslbook.erl.ppo_ch4` (Figs. 4.3c and
4.4b, Tables B.3 and B.6) differ in the task, the hyper-parameters and the evaluation; what
they share lives here:

* the checks of the hyper-parameters every PPO configuration has (:func:`check_ppo_fields`,
  :func:`check_seed`, :func:`check_run_arguments`);
* :func:`build_ppo`, stable-baselines3's PPO on a ``DummyVecEnv`` (optionally
  ``VecNormalize``), and :func:`mean_actions`, the deterministic policy on raw observations;
* the snapshots that stable-baselines3's own save/load leaves out (the MuJoCo integration
  state and ``np_random`` of every training environment mid-episode, VecNormalize's
  running discounted return, the last observation; see :mod:`vslbook.erl.ppo`);
* :func:`train_with_checkpoints`, the loop "learn ``eval_every`` steps, evaluate,
  checkpoint" that resumes a killed run exactly.
"""

from __future__ import annotations

import copy
import io
import math
import os
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, Protocol

import gymnasium as gym
import mujoco
import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.logger import Logger
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

from vslbook.progress import progress_bar
from vslbook.rng_state import restore_rng_state, rng_state

__all__ = [
    "CHECKPOINT_FILE",
    "StatefulCallback",
    "build_ppo",
    "check_ppo_fields",
    "check_run_arguments",
    "check_seed",
    "mean_actions",
    "train_with_checkpoints",
]

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
    bar = progress_bar(total=total_steps, initial=model.num_timesteps, disable=not progress,
                       desc=desc, unit="steps")  # fmt: skip
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
        # a fresh logger per call, as SB3 makes itself, but one that writes nowhere: SB3's
        # own makes an empty folder tempdir/SB3-<time> on every call
        model.set_logger(Logger(folder=None, output_formats=[]))
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

"""PPO baselines of Chapter 4 (Fig. 4.3c: 5LR, Fig. 4.4b: BPO; Tables B.3 and B.6) with SB3.

Chapter 4 runs PPO (Schulman et al. 2017) where the task is Markov once the step index is
part of the state: on the 5-link reacher with the time-sparse reward of Appendix B.4.3
(:class:`vslbook.envs.robot.reacher5_sparse_step.Reacher5SparseStepEnv`, ``"reacher5"``)
and on Box Pushing with Obstacle (:class:`vslbook.envs.robot.box_pushing_step.
BoxPushingObstacleStepEnv`, ``"box-pushing-obstacle"``). In both the reward that matters
arrives at the last step, which is the point of the comparison: exploring with
independent noise at every step has little chance of finding it.

The thesis's PPO is built on the code of Otto et al. (2021, "Differentiable trust region
layers for deep reinforcement learning", ICLR) with "all code-level optimisations" of
Engstrom et al. (2020). We use stable-baselines3 (Raffin et al. 2019), as Chapter 3 does
(:mod:`vslbook.erl.ppo`, its shared loop in :mod:`vslbook.erl.ppo_loop`), with the
settings of Tables B.3 and B.6 and those optimisations (:class:`PPOCh4Config` lists where
each comes from). Engstrom et al. name nine: value
clipping, reward scaling, reward clipping, observation normalisation, observation
clipping, orthogonal initialisation with layer scaling, Adam step-size annealing, tanh
units and a global gradient-norm clip. Stable-baselines3 has seven of them by default (with
``VecNormalize``); value clipping (``clip_range_vf``) and the annealing (``anneal_lr``) are
switched on here. Among the differences to Otto et al.'s code that remain: the policy and
value losses share one Adam optimiser (the tables give both the same step size), and the
clipped value loss is the squared error of the clipped prediction (SB3), not the larger of
the clipped and unclipped errors.

Read :func:`train_ppo_ch4` as the loop

    repeat until ``total_steps`` environment steps:
        evaluate the mean action on fixed contexts (every ``eval_every`` steps)
        collect N = 16384 steps from ``n_envs`` environments (observations and rewards
            normalised by running statistics)
        n_epochs passes over minibatches of the clipped surrogate with GAE(λ) advantages,
            step size α (1 − k / U) for update k of U

where the inner two lines are ``PPO.learn`` of stable-baselines3. The episodes end at the
horizon with ``terminated`` (the horizon belongs to the task: γ = 1 and the goal term is
paid at t = T), so the last state is never bootstrapped.

Evaluation. :func:`evaluate` runs the policy's mean action (observations normalised with
the current statistics, not updated) on ``eval_episodes`` contexts drawn once from the
episodic task's p(c) (``sample_contexts``) with :data:`EVAL_CONTEXT_SEED`, the same for every
training seed; it reports the task's own, un-normalised return (the sum of the step
rewards is the episodic return of the same commands) and, for box pushing, the task's
success rule (position error < 0.05 m and rotation error < 0.5 rad after the last step).
The x-axis is kept in environment steps and in completed training episodes, counted as
they end (a box-pushing episode whose simulation becomes unstable ends early), to compare
with the episode-based Di-SkilL.

Budget. The tables do not say how long PPO ran. At the full budget it gets as many
episodes as Di-SkilL's run on the task (:func:`matched_total_steps`: iterations × experts ×
samples per expert of :func:`vslbook.erl.diskill_config.diskill_config`, times the episode
length, rounded up to whole rollouts): 5LR 3000 × 10 × 25 episodes of 200 steps = 9156
rollouts (150,011,904 steps); BPO 4500 × 10 × 50 episodes of 100 steps = 13733 rollouts
(225,001,472 steps).

Checkpoints and exact resume work as in :mod:`vslbook.erl.ppo` (its
:func:`~vslbook.erl.ppo_loop.train_with_checkpoints`); the box-pushing snapshot also keeps the
bias forces of the last physics step, which the torque law of the next step reads before
MuJoCo recomputes them. A resumed run logs the numbers of an uninterrupted one on CPU
(except ``env_steps_per_s``).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.utils import LinearSchedule

from vslbook.envs.robot.box_pushing import HORIZON as BPO_HORIZON
from vslbook.envs.robot.box_pushing_step import BoxPushingObstacleStepEnv
from vslbook.envs.robot.reacher5 import N_STEPS as REACHER_HORIZON
from vslbook.envs.robot.reacher5_sparse_step import Reacher5SparseStepEnv
from vslbook.erl.diskill_config import diskill_config
from vslbook.erl.ppo import EVAL_GOAL_SEED
from vslbook.erl.ppo_loop import (
    build_ppo,
    check_ppo_fields,
    check_run_arguments,
    check_seed,
    generator_from_state,
    is_positive_int,
    mean_actions,
    physics_state,
    reacher_state,
    set_physics_state,
    set_reacher_state,
    train_with_checkpoints,
)

__all__ = [
    "EVAL_CONTEXT_SEED",
    "N_ROLLOUT_STEPS",
    "TASKS",
    "PPOCh4Config",
    "evaluate",
    "evaluation_contexts",
    "make_ppo_ch4",
    "matched_total_steps",
    "ppo_ch4_config",
    "train_ppo_ch4",
]

#: Seed of the fixed evaluation contexts (the same for every run; Chapter 3's goal seed).
EVAL_CONTEXT_SEED = EVAL_GOAL_SEED
#: N, environment steps per PPO update (Tables B.3 and B.6: 16384 samples).
N_ROLLOUT_STEPS = 16384


@dataclass(frozen=True)
class _Task:
    """What differs between the two tasks."""

    make_env: Callable[[], gym.Env]
    option: str  # the reset option that sets the context
    horizon: int  # control steps of one episode
    table: dict[str, Any]  # the task's column of Table B.3 / B.6
    env_state: Callable[[gym.Env], dict[str, Any]]
    set_env_state: Callable[[gym.Env, dict[str, Any]], None]


def _sparse_reacher_state(env: Reacher5SparseStepEnv) -> dict[str, Any]:
    return {**reacher_state(env), "done": env._done}


def _set_sparse_reacher_state(env: Reacher5SparseStepEnv, state: dict[str, Any]) -> None:
    set_reacher_state(env, state)
    env._done = bool(state["done"])


def _box_pushing_state(env: BoxPushingObstacleStepEnv) -> dict[str, Any]:
    task = env.task
    # A training environment is never mid-episode after an unstable step (that step ends
    # the episode and the reset clears MuJoCo's warnings), so the warning counters that
    # `unstable` reads are zero and need no snapshot.
    return {
        "physics": physics_state(task.model, task.data),
        "qfrc_bias": task.data.qfrc_bias.copy(),  # read by the next step's torque law
        "physics_steps": task.physics_steps,
        "context": env._context.copy(),
        "goal_pos": env._goal_pos.copy(),
        "goal_quat": env._goal_quat.copy(),
        "t": env._t,
        "done": env._done,
        "np_random": env.np_random.bit_generator.state,
    }


def _set_box_pushing_state(env: BoxPushingObstacleStepEnv, state: dict[str, Any]) -> None:
    task = env.task
    set_physics_state(task.model, task.data, state["physics"])
    task.data.qfrc_bias[:] = state["qfrc_bias"]
    task.physics_steps = int(state["physics_steps"])
    env._context = np.array(state["context"], dtype=np.float64)
    env._goal_pos = np.array(state["goal_pos"], dtype=np.float64)
    env._goal_quat = np.array(state["goal_quat"], dtype=np.float64)
    env._t = int(state["t"])
    env._done = bool(state["done"])
    env.np_random = generator_from_state(state["np_random"])


_TASKS: dict[str, _Task] = {
    "reacher5": _Task(
        make_env=Reacher5SparseStepEnv,
        option="goal",
        horizon=REACHER_HORIZON,
        table={"learning_rate": 3e-4, "batch_size": 512, "net_arch": (32, 32)},
        env_state=_sparse_reacher_state,
        set_env_state=_set_sparse_reacher_state,
    ),
    "box-pushing-obstacle": _Task(
        make_env=BoxPushingObstacleStepEnv,
        option="context",
        horizon=BPO_HORIZON,
        table={"learning_rate": 1e-4, "batch_size": 410, "net_arch": (256, 256)},
        env_state=_box_pushing_state,
        set_env_state=_set_box_pushing_state,
    ),
}
#: The tasks with a PPO baseline in Chapter 4 (names of :func:`vslbook.envs.robot.make_task`).
TASKS = tuple(_TASKS)


def _task(task: Any) -> _Task:
    if not isinstance(task, str) or task not in _TASKS:
        raise ValueError(f"task must be one of {TASKS}, got {task!r}")
    return _TASKS[task]


@dataclass(frozen=True)
class PPOCh4Config:
    """PPO on the step-based 5LR and BPO tasks, Tables B.3 and B.6 (PPO columns).

    ===========================  ==========  ===========  ==============================
    Table B.3 (5LR) / B.6 (BPO)  5LR         BPO          field
    ===========================  ==========  ===========  ==============================
    hidden sizes policy, critic  [32, 32]    [256, 256]   ``net_arch`` (each network)
    activation, initialisation   tanh, orth. tanh, orth.  SB3's MlpPolicy
    lr policy = lr critic        3e-4        1e-4         ``learning_rate`` (one Adam)
    epochs (policy and critic)   10          10           ``n_epochs``
    samples per update           16384       16384        ``n_rollout_steps``
    minibatch size               512         410          ``batch_size``
    nr. of minibatches           32          40           :attr:`n_minibatches`
    normalise advantages         True        True         SB3 (per minibatch)
    covariance                   diagonal    diagonal     SB3 (state-independent log σ)
    discount factor γ            1           1            ``gamma``
    ===========================  ==========  ===========  ==============================

    16384 / 410 is not whole: stable-baselines3 makes 39 minibatches of 410 and one of 394,
    40 in all, as the table says.

    "All code-level optimisations" (Engstrom et al. 2020), as in the tables' captions:
    ``clip_range_vf`` = 0.2 clips the value prediction around the old one; ``anneal_lr``
    decays the step size linearly over the ``total_steps`` / N = U updates (α (1 − k / U)
    for update k = 0..U−1); ``normalize`` (observations and
    rewards by running statistics, both clipped at 10, VecNormalize with γ above);
    orthogonal initialisation, tanh and the gradient-norm clip 0.5 are SB3's defaults.

    Not in the thesis (our choices, as stable-baselines3's defaults and Chapter 3's
    :class:`vslbook.erl.ppo.PPOConfig`): ``gae_lambda`` = 0.95; ``clip_range`` = 0.2; the
    value-clip range equal to it; ``n_envs`` = 16 environments (N = 16 × 1024 steps);
    entropy coefficient 0; value-loss coefficient 0.5; initial σ = 1.
    ``total_steps``: as many episodes as Di-SkilL gets at the full budget
    (:func:`matched_total_steps`), set by :func:`ppo_ch4_config`.
    """

    learning_rate: float
    batch_size: int
    net_arch: tuple[int, ...]
    total_steps: int
    n_rollout_steps: int = N_ROLLOUT_STEPS
    n_epochs: int = 10
    gamma: float = 1.0
    gae_lambda: float = 0.95
    clip_range: float = 0.2
    clip_range_vf: float | None = 0.2
    anneal_lr: bool = True
    n_envs: int = 16
    normalize: bool = True

    def __post_init__(self) -> None:
        check_ppo_fields(self)
        if self.batch_size < 2 or self.batch_size > self.n_rollout_steps:
            raise ValueError(
                f"batch_size must be in [2, n_rollout_steps = {self.n_rollout_steps}], "
                f"got {self.batch_size}"
            )
        vf = self.clip_range_vf
        if vf is not None and (
            isinstance(vf, bool) or not isinstance(vf, (int, float)) or not (0.0 < vf < math.inf)
        ):
            raise ValueError(f"clip_range_vf must be None or a positive number, got {vf!r}")
        for name in ("anneal_lr", "normalize"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name} must be True or False, got {getattr(self, name)!r}")

    @property
    def n_minibatches(self) -> int:
        """Minibatches per epoch (the last one holds the remainder of N / batch_size)."""
        return -(-self.n_rollout_steps // self.batch_size)


def matched_total_steps(task: str, n_rollout_steps: int = N_ROLLOUT_STEPS) -> int:
    """Environment steps of as many episodes as Di-SkilL's full-budget run on ``task``.

    iterations × experts × samples per expert (:func:`vslbook.erl.diskill_config.diskill_config`)
    episodes of the task's length, rounded up to a multiple of ``n_rollout_steps``.
    """
    spec = _task(task)
    if not is_positive_int(n_rollout_steps):
        raise ValueError(f"n_rollout_steps must be a positive integer, got {n_rollout_steps!r}")
    d = diskill_config(task)
    steps = d.iterations * d.episodes_per_iteration * spec.horizon
    return -(-steps // n_rollout_steps) * n_rollout_steps


def ppo_ch4_config(task: str, **overrides: Any) -> PPOCh4Config:
    """The PPO configuration of Table B.3 (``"reacher5"``) or B.6 (``"box-pushing-obstacle"``).

    ``overrides`` replace any :class:`PPOCh4Config` field. Without ``total_steps``, the
    run is :func:`matched_total_steps` long (for the given ``n_rollout_steps``).
    """
    spec = _task(task)
    names = {f.name for f in fields(PPOCh4Config)}
    unknown = sorted(set(overrides) - names)
    if unknown:
        raise ValueError(f"unknown PPOCh4Config fields {unknown}; expected some of {sorted(names)}")
    kwargs = {**spec.table, **overrides}
    if "total_steps" not in kwargs:
        kwargs["total_steps"] = matched_total_steps(
            task, kwargs.get("n_rollout_steps", N_ROLLOUT_STEPS)
        )
    return PPOCh4Config(**kwargs)


def evaluation_contexts(task: str, n: int, seed: int = EVAL_CONTEXT_SEED) -> np.ndarray:
    """``n`` contexts from the episodic task's p(c) with a fixed seed, ``(n, context_dim)``."""
    spec = _task(task)
    if not is_positive_int(n):
        raise ValueError(f"n must be a positive integer, got {n!r}")
    return spec.make_env().task.sample_contexts(n, np.random.default_rng(check_seed(seed)))


class _WholeRunPPO(PPO):
    """SB3's PPO whose schedules run over the whole run of ``run_steps`` environment steps.

    :func:`~vslbook.erl.ppo_loop.train_with_checkpoints` calls ``learn`` once per evaluation,
    and SB3 would measure a schedule's progress against the end of the current call. Here
    the progress of an update is 1 − t₀ / ``run_steps`` with t₀ the steps taken before the
    rollout it learns from, so with U = ``run_steps`` / N updates the step size of update
    k = 0..U−1 is α (1 − k / U): α for the first, α / U for the last (the annealing of
    Engstrom et al. 2020).
    """

    run_steps: int = 0

    def _update_current_progress_remaining(self, num_timesteps: int, total_timesteps: int) -> None:
        started = num_timesteps - self.n_steps * self.n_envs
        super()._update_current_progress_remaining(started, self.run_steps or total_timesteps)


class _EpisodeCounter(BaseCallback):
    """Counts the training episodes that ended (its count goes into the checkpoint)."""

    def __init__(self) -> None:
        super().__init__()
        self.episodes = 0

    def _on_step(self) -> bool:
        self.episodes += int(np.sum(self.locals["dones"]))
        return True

    def state_dict(self) -> dict[str, Any]:
        return {"episodes": self.episodes}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.episodes = int(state["episodes"])


def make_ppo_ch4(task: str, config: PPOCh4Config, seed: int) -> PPO:
    """Stable-baselines3's PPO of :class:`PPOCh4Config` on ``config.n_envs`` copies of the task.

    The environments are wrapped in ``VecNormalize`` when ``config.normalize``. Seeds
    python, numpy and torch with ``seed`` and environment i with ``seed + i``.
    """
    spec = _task(task)
    if not isinstance(config, PPOCh4Config):
        raise ValueError(f"config must be a PPOCh4Config, got {type(config).__name__}")
    seed = check_seed(seed)
    lr = (
        LinearSchedule(config.learning_rate, 0.0, 1.0) if config.anneal_lr else config.learning_rate
    )
    with warnings.catch_warnings():
        # the truncated last minibatch of Table B.6 (16384 = 39 × 410 + 394) is intended
        warnings.filterwarnings("ignore", message="You have specified a mini-batch size")
        model = build_ppo(
            [spec.make_env for _ in range(config.n_envs)], config, seed,
            ppo_class=_WholeRunPPO, learning_rate=lr, clip_range_vf=config.clip_range_vf,
        )  # fmt: skip
    model.run_steps = config.total_steps
    return model


def evaluate(model: PPO, task: str, envs: list[gym.Env], contexts: np.ndarray) -> dict[str, float]:
    """The policy's mean action on ``contexts``, one episode each (see the module doc).

    ``envs`` holds one step-based environment of ``task`` per context; all episodes are
    stepped together. Returns ``test_return`` (mean task return) and ``test_return_std``;
    for 5LR ``test_tip_distance`` (mean final distance to the goal), for box pushing
    ``test_success`` (share of successful episodes). Uses no randomness.
    """
    spec = _task(task)
    contexts = np.asarray(contexts, dtype=np.float64)
    n = len(envs)
    dim = envs[0].task.context_dim if n else 0
    if n == 0 or contexts.shape != (n, dim) or not np.all(np.isfinite(contexts)):
        raise ValueError(
            f"contexts must be finite with shape (n, context_dim) = ({n}, {dim}), n = "
            f"len(envs) > 0; got shape {contexts.shape}"
        )
    obs = np.stack(
        [env.reset(options={spec.option: c})[0] for env, c in zip(envs, contexts, strict=True)]
    )
    returns = np.zeros(n)
    running = np.ones(n, dtype=bool)
    last: list[dict[str, Any]] = [{} for _ in range(n)]
    while running.any():
        actions = mean_actions(model, obs)
        for i in np.flatnonzero(running):
            obs[i], r, terminated, truncated, last[i] = envs[i].step(actions[i])
            returns[i] += r
            running[i] = not (terminated or truncated)
    out = {"test_return": float(returns.mean()), "test_return_std": float(returns.std())}
    if "success" in last[0]:
        out["test_success"] = float(np.mean([info["success"] for info in last]))
    else:
        out["test_tip_distance"] = float(np.mean([info["tip_distance"] for info in last]))
    return out


def train_ppo_ch4(
    task: str,
    config: PPOCh4Config,
    seed: int,
    *,
    run_dir: Path | str | None = None,
    eval_every: int = 10 * N_ROLLOUT_STEPS,
    eval_episodes: int = 75,
    progress: bool = False,
    stop_after_evals: int | None = None,
) -> list[dict[str, Any]]:
    """Train PPO (Table B.3 or B.6) on the step-based ``task``; return the metrics.

    Args:
        task: ``"reacher5"`` or ``"box-pushing-obstacle"``.
        config: the hyper-parameters, :class:`PPOCh4Config` (:func:`ppo_ch4_config`).
        seed: a non-negative integer (python, numpy, torch; environment i gets seed + i).
        run_dir: if given, a checkpoint is written there at every evaluation and the run
            resumes from it (raises ValueError if it belongs to another run; with
            ``anneal_lr`` the run's length is part of it).
        eval_every: environment steps between evaluations, a multiple of
            ``config.n_rollout_steps``; the policy is evaluated at step 0, every
            ``eval_every`` steps and at ``config.total_steps``.
        eval_episodes: number of fixed evaluation contexts (:func:`evaluation_contexts`;
            75, Di-SkilL's number of test contexts, by default).
        progress: show a progress bar.
        stop_after_evals: return (checkpointed) after this many evaluations in this call,
            as if interrupted; None runs to ``config.total_steps``.

    Returns:
        One dict per evaluation: ``env_steps``, ``episodes`` (training episodes that
        ended), ``updates``, the numbers of :func:`evaluate` (``test_return``,
        ``test_return_std``, and ``test_success`` or ``test_tip_distance``), the last
        update's training statistics (as :func:`vslbook.erl.ppo.train_ppo`; absent at step
        0) and ``env_steps_per_s`` (wall clock, training only).
    """
    spec = _task(task)
    if not isinstance(config, PPOCh4Config):
        raise ValueError(f"config must be a PPOCh4Config, got {type(config).__name__}")
    seed = check_seed(seed)
    check_run_arguments(config, eval_every, eval_episodes, stop_after_evals)

    model = make_ppo_ch4(task, config, seed)
    contexts = evaluation_contexts(task, eval_episodes)
    eval_envs = [spec.make_env() for _ in range(eval_episodes)]
    counter = _EpisodeCounter()
    run_info = {
        "task": task, "seed": seed, "eval_every": int(eval_every),
        "eval_episodes": int(eval_episodes), **asdict(config),
        "lr_schedule_steps": config.total_steps if config.anneal_lr else None,
    }  # fmt: skip
    key = "test_success" if task == "box-pushing-obstacle" else "test_tip_distance"
    return train_with_checkpoints(
        model,
        total_steps=config.total_steps,
        eval_every=eval_every,
        run_info=run_info,
        run_dir=run_dir,
        evaluate=lambda: evaluate(model, task, eval_envs, contexts),
        episodes=lambda _steps: counter.episodes,
        env_state=spec.env_state,
        set_env_state=spec.set_env_state,
        desc=f"PPO {task} s{seed}",
        postfix=lambda row: {"ret": f"{row['test_return']:.1f}", key: f"{row[key]:.3f}"},
        progress=progress,
        stop_after_evals=stop_after_evals,
        callback=counter,
    )

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

The pieces that Chapter 4's PPO baselines (:mod:`vslbook.erl.ppo_ch4`) share with this one
(the checks of the shared hyper-parameters, :func:`~vslbook.erl.ppo_loop.build_ppo`,
:func:`~vslbook.erl.ppo_loop.mean_actions`, the MuJoCo and training-state snapshots and
the checkpointed loop :func:`~vslbook.erl.ppo_loop.train_with_checkpoints`) live in
:mod:`vslbook.erl.ppo_loop`.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3 import PPO

from vslbook.envs.robot.reacher5 import N_STEPS, Reacher5Ch3, check_ch3_reward
from vslbook.envs.robot.reacher5_step import Reacher5Ch3StepEnv
from vslbook.erl.ppo_loop import (
    CHECKPOINT_FILE,
    build_ppo,
    check_ppo_fields,
    check_run_arguments,
    check_seed,
    mean_actions,
    reacher_state,
    set_reacher_state,
    train_with_checkpoints,
)

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

"""DIME's environment side: the tasks, the seeded resets, acting and evaluating.

Algorithm 4's l. 3-4 take an action through the whole denoising chain, a ~ π_θ(·|s), and
step the environment, s' ~ p(·|s, a). The policy acts in [-1, 1]^|A|
(:func:`to_env_action` maps that to the task's Box). Every reset is seeded from the run's
seed and an index (:func:`stream_seed`): the training environment from (seed, episode),
the evaluation environment from (seed, evaluation, episode), so no simulator state is ever
pickled and a resumed run meets the same episodes.
"""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import torch
from torch import nn

from vslbook.srl.cuda_graphs import GraphedUpdates
from vslbook.srl.dime_updates import policy_noise

__all__ = [
    "EVAL_NOISE",
    "EVAL_RESETS",
    "FALLBACK_VALUE_RANGE",
    "REPLAY_INDICES",
    "TRAIN_RESETS",
    "act",
    "default_value_range",
    "evaluate",
    "make_env",
    "stream_seed",
    "to_env_action",
    "validate_env",
]

#: Table C.3's gymnasium-locomotion range, used when no per-suite range is known.
FALLBACK_VALUE_RANGE = (-1600.0, 1600.0)

#: The streams a run's seed is split into (:func:`stream_seed`): training resets, evaluation
#: resets, evaluation policy noise and device-drawn replay indices.
TRAIN_RESETS, EVAL_RESETS, EVAL_NOISE, REPLAY_INDICES = 0, 1, 2, 3


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


def validate_env(env_id: str) -> None:
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


def stream_seed(seed: int, stream: int, *index: int) -> int:
    """A reset seed for (run seed, stream, index...), well mixed by numpy's SeedSequence."""
    return int(np.random.SeedSequence([seed, stream, *index]).generate_state(1)[0])


def to_env_action(action: np.ndarray, space: gym.spaces.Box) -> np.ndarray:
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
    generator.manual_seed(stream_seed(seed, EVAL_NOISE, index))
    returns, successes = [], []
    for episode in range(episodes):
        obs, info = env.reset(seed=stream_seed(seed, EVAL_RESETS, index, episode))
        total, done = 0.0, False
        while not done:
            action = act(policy, obs, device, generator, graphs)
            obs, reward, terminated, truncated, info = env.step(
                to_env_action(action, env.action_space)
            )
            total += float(reward)
            done = terminated or truncated
        returns.append(total)
        if "success" in info:
            successes.append(float(info["success"]))
    return float(np.mean(returns)), (float(np.mean(successes)) if successes else None)

"""The gymnasium faces of an :class:`~vslbook.envs.robot.task.EpisodicTask`.

:class:`EpisodicEnv` wraps a task as a one-step gymnasium environment (observation = c,
action = θ), the form used by ``gym.make``; :func:`context_from_options` and
:func:`check_action` are the ``reset`` and ``step`` input helpers of the step-based
environments of Chapter 4. The task interface itself is in :mod:`vslbook.envs.robot.task`,
which re-exports these names.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import gymnasium as gym
import numpy as np

if TYPE_CHECKING:
    from vslbook.envs.robot.task import EpisodicTask

__all__ = ["EpisodicEnv", "check_action", "context_from_options"]


def context_from_options(
    task: EpisodicTask, options: dict[str, Any] | None, key: str, rng: np.random.Generator
) -> np.ndarray:
    """A step-based env's context at ``reset``: ``options[key]`` (checked against the task's
    context space) or a draw from the task's p(c) with ``rng``; any other option is a clear
    error."""
    options = dict(options or {})
    unknown = set(options) - {key}
    if unknown:
        raise ValueError(f"unknown reset options {sorted(unknown)}; expected only {key!r}")
    if key in options:
        return task.one_context(options[key])
    return task.sample_contexts(1, rng)[0]


def check_action(action: Any, n: int) -> np.ndarray:
    """A step-based env's ``action`` as ``n`` finite floats clipped to [-1, 1], or a clear
    ``ValueError`` naming what is wrong."""
    try:
        a = np.asarray(action, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise ValueError(f"action must be {n} numbers, got {action!r}") from err
    if a.shape != (n,):
        raise ValueError(f"action must have shape ({n},), got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"action must be finite, got {a.tolist()}")
    return np.clip(a, -1.0, 1.0)


class EpisodicEnv(gym.Env):
    """A task as a one-step gymnasium environment: observation = context, action = θ.

    ``reset`` draws c ~ p(c) (or takes ``options={"context": c}``); ``step(θ)`` runs the
    episode in this process and returns (c, R, terminated=True, truncated=False, info) with
    ``info`` holding ``success``, ``executed`` and the task's per-episode numbers (those that
    apply: NaN entries are left out, so gymnasium's checker can compare infos).
    """

    metadata: dict[str, Any] = {"render_modes": []}

    def __init__(self, task: type[EpisodicTask] | EpisodicTask, **kwargs: Any) -> None:
        self.task = task(**kwargs) if isinstance(task, type) else task
        t = self.task
        self.observation_space = gym.spaces.Box(
            t.context_low.astype(np.float64), t.context_high.astype(np.float64), dtype=np.float64
        )
        self.action_space = gym.spaces.Box(-np.inf, np.inf, (t.n_params,), dtype=np.float64)
        self._context = np.asarray(t.context_low, dtype=np.float64).copy()

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        if options and "context" in options:
            self._context = self.task.check_contexts(options["context"])[0]
        else:
            self._context = self.task.sample_contexts(1, self.np_random)[0]
        return self._context.copy(), {}

    def step(self, action: Any):
        th = self.task.check_theta(action, n=1)
        ep = self.task.episodes(th, self._context[None])[0]
        # A number that does not apply to this episode (NaN) is left out of the info.
        extra = {k: v for k, v in ep.info.items() if not (isinstance(v, float) and math.isnan(v))}
        info = {"success": bool(ep.success), "executed": bool(ep.executed), **extra}
        return self._context.copy(), float(ep.ret), True, False, info

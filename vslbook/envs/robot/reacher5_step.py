"""Step-based 5-link reacher of Chapter 3 (Section 3.4.3): the PPO side of Fig. 3.5.

The same simulator, start state (arm horizontal pointing left, q̇0 = 0), goal distribution
(right half disk of radius 0.5) and rewards (Eqs. 3.8, 3.9, 3.10, ``reward=...``) as the
episodic :class:`vslbook.envs.robot.reacher5.Reacher5Ch3`, but the agent sends the five
motor commands itself at every control step (dt = 0.02 s, 200 steps, then ``truncated``).

* action: the 5 motor commands, ``Box(-1, 1, (5,))``; values outside are clipped, and the
  rewards' Σa² uses the clipped command.
* observation (gymnasium's Reacher-v5 layout for 5 links, Brockman et al. 2016):
  ``[cos q (5), sin q (5), goal (2), q̇ (5), tip − goal (2)]``, 19 numbers; for Eqs. 3.9 and
  3.10 the thesis adds the time step: we append t / 200 (the normalised index of the next
  control step, 0 at reset), 20 numbers. The v5 layout drops the always-zero z of
  tip − goal (v4 had 3 numbers).
* reward r_t of the chosen equation with t = 0..199 the index of the action and the state
  after it (see the reward note in :mod:`vslbook.envs.robot.reacher5`).
* ``reset(seed=...)`` draws the goal from p(c) with ``self.np_random``; ``options={"goal":
  (x, y)}`` sets it (checked against the context space).

Registered as ``vslbook/Reacher5Ch3Step-v0`` (``gym.make(..., reward="3.10")``).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from vslbook.envs.robot.reacher5 import (
    N_LINKS,
    N_STEPS,
    Q0_LEFT,
    Reacher5Ch3,
    ReacherSim,
    check_ch3_reward,
    rewards_ch3,
    tip_position,
)


class Reacher5Ch3StepEnv(gym.Env):
    """Chapter 3's 5-link reacher as a step-based gymnasium environment (see module doc).

    Args:
        reward: "3.8", "3.9" or "3.10".
        render_mode: only None (no rendering).
    """

    metadata: dict[str, Any] = {"render_modes": []}

    def __init__(self, reward: str = "3.8", render_mode: str | None = None) -> None:
        if render_mode is not None:
            raise ValueError(f"render_mode must be None (no rendering), got {render_mode!r}")
        self.reward = check_ch3_reward(reward)
        self.timed = self.reward != "3.8"
        self.task = Reacher5Ch3(reward=self.reward)
        self.sim = ReacherSim()
        n_obs = 4 * N_LINKS - 1 + int(self.timed)
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (n_obs,), dtype=np.float64)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (N_LINKS,), dtype=np.float32)
        self._goal = np.array([0.25, 0.0])
        self._t = 0

    def _obs(self) -> np.ndarray:
        q, dq = self.sim.q, self.sim.dq
        parts = [np.cos(q), np.sin(q), self._goal, dq, tip_position(q) - self._goal]
        if self.timed:
            parts.append([self._t / N_STEPS])
        return np.concatenate(parts).astype(np.float64)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        if options and "goal" in options:
            self._goal = self.task.check_contexts(options["goal"])[0]
        else:
            self._goal = self.task.sample_contexts(1, self.np_random)[0]
        self.sim.reset(Q0_LEFT, self._goal)
        self._t = 0
        return self._obs(), {"goal": self._goal.copy()}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if self._t >= N_STEPS:
            raise RuntimeError("episode is over (200 steps): call reset()")
        a = np.asarray(action, dtype=np.float64).reshape(-1)
        if a.shape != (N_LINKS,):
            raise ValueError(f"action must have shape ({N_LINKS},), got {np.shape(action)}")
        if not np.all(np.isfinite(a)):
            raise ValueError("action must be finite")
        a = np.clip(a, -1.0, 1.0)
        self.sim.step(a)
        q, dq = self.sim.q, self.sim.dq
        tip = tip_position(q)
        r = rewards_ch3(self.reward, np.array([self._t]), a[None], tip[None], dq[None], self._goal)
        self._t += 1
        info = {"tip_distance": float(np.linalg.norm(tip - self._goal)), "step": self._t}
        return self._obs(), float(r[0]), False, self._t >= N_STEPS, info

"""Step-based 5-link reacher of Chapter 4 (5LR, sparse in time): the PPO side of Fig. 4.3c.

The simulator, start state (all joints 0: the arm straight to the right, q̇0 = 0), goal
distribution (the whole disk of radius 0.5) and time-sparse reward (Appendix B.4.3) of the
episodic :class:`vslbook.envs.robot.reacher5.Reacher5`, but the agent sends the five motor
commands itself at each of the T = 200 control steps (dt = 0.02 s, 2 physics steps).

* **action**: the 5 motor commands (torques, gear 200), ``Box(-1, 1, (5,))``; values outside
  are clipped, and the cost Σa² uses the clipped command.
* **observation** (ours; the thesis does not list one), 20 numbers: gymnasium's Reacher-v5
  layout for 5 links (Brockman et al. 2016), ``[cos q (5), sin q (5), goal (2), q̇ (5), tip −
  goal (2)]``, as the Chapter 3 step-based reacher
  (:mod:`vslbook.envs.robot.reacher5_step`), plus t / 200 (0 at reset, 1 after the last
  step): the task reward arrives only at t = T, so the step index is part of the state.
* **reward** (B.4.3), t = 0..199 the action's index, scored on the state after the action:
  r_t = −Σa_t² for t < 199; the last step adds −200‖p_tip − p_goal‖ − 10Σq̇_T²
  (:func:`vslbook.envs.robot.reacher5.rewards_5lr`). The episodic return of the same
  commands is the sum of the r_t.
* **end of the episode**: ``terminated`` after the 200th step (the horizon is part of the
  task: the goal term is paid at t = T, discount factor 1 in Table B.3), ``truncated``
  stays False.
* **context**: ``reset(seed=...)`` draws the goal from p(c) (uniform on the disk, rejection
  from [−0.5, 0.5]²) with ``self.np_random``; ``options={"goal": (x, y)}`` sets it (checked
  against the disk).
* The thesis defines no success for 5LR, so ``info`` has no ``success``; it reports
  ``tip_distance`` (‖tip − goal‖ after the step), ``goal`` (at reset) and ``step``.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from vslbook.envs.robot.gym_env import check_action, context_from_options
from vslbook.envs.robot.reacher5 import (
    N_LINKS,
    N_STEPS,
    Q0_RIGHT,
    Reacher5,
    ReacherSim,
    rewards_5lr,
    tip_position,
)

#: [cos q (5), sin q (5), goal (2), q̇ (5), tip − goal (2), t / T (1)]
OBS_DIM = 3 * N_LINKS + 2 + 2 + 1


class Reacher5SparseStepEnv(gym.Env):
    """Chapter 4's sparse 5-link reacher as a step-based gymnasium environment (module doc).

    Args:
        render_mode: only None (no rendering).
    """

    metadata: dict[str, Any] = {"render_modes": []}

    def __init__(self, render_mode: str | None = None) -> None:
        if render_mode is not None:
            raise ValueError(f"render_mode must be None (no rendering), got {render_mode!r}")
        self.task = Reacher5()
        self.sim = ReacherSim()
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (OBS_DIM,), dtype=np.float64)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (N_LINKS,), dtype=np.float32)
        self._goal = np.array([0.25, 0.0])
        self._t = 0
        self._done = True

    @property
    def goal(self) -> np.ndarray:
        """The current episode's goal (x, y)."""
        return self._goal.copy()

    def _obs(self) -> np.ndarray:
        q, dq = self.sim.q, self.sim.dq
        parts = [np.cos(q), np.sin(q), self._goal, dq, tip_position(q) - self._goal]
        return np.concatenate([*parts, [self._t / N_STEPS]]).astype(np.float64)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start an episode: arm straight to the right at rest, goal from p(c) or options."""
        super().reset(seed=seed)
        self._goal = context_from_options(self.task, options, "goal", self.np_random)
        self.sim.reset(Q0_RIGHT, self._goal)
        self._t = 0
        self._done = False
        return self._obs(), {"goal": self._goal.copy()}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Hold the (clipped) command for one control step and score the state after it."""
        if self._done:
            raise RuntimeError("episode is over (or reset() was never called): call reset()")
        a = check_action(action, N_LINKS)
        self.sim.step(a)
        self._t += 1
        tip = tip_position(self.sim.q)
        if self._t >= N_STEPS:
            r = float(rewards_5lr(a[None], tip, self.sim.dq, self._goal)[0])
        else:
            r = -float(np.sum(np.square(a)))
        self._done = self._t >= N_STEPS
        info = {"tip_distance": float(np.linalg.norm(tip - self._goal)), "step": self._t}
        return self._obs(), r, self._done, False, info

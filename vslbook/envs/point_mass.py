"""A 2-D point mass with four goals: the multimodality study of DIME (Section 5.5.3, Fig. 5.7).

What the thesis fixes: the state is the (x, y) position of the point mass, it starts at
the origin (the middle of the state space), the action is a change of that position, and
the task is to reach any one of four goals. Everything else is a choice made here:

- workspace [-1, 1]², positions are clipped to it;
- goals at (±0.5, ±0.5), indexed counter-clockwise from the first quadrant
  (0: (+, +), 1: (-, +), 2: (-, -), 3: (+, -)); a goal is reached within radius 0.1;
- the action a ∈ [-1, 1]² moves the point by ``step_size`` · a (at most 0.1 per axis and
  step), so a goal is at least 5 steps away from the start;
- reward r_t = -distance_cost · d(p_{t+1}) + goal_reward · [goal reached], with d the
  distance to the nearest goal (defaults 10 and 50): the dense term makes every goal a
  mode of the value function, the bonus makes reaching one worth more than the entropy
  a wandering policy collects at the α values of Fig. 5.7 (up to 5);
- the episode terminates when a goal is reached and is truncated after 50 steps.

``info["goal"]`` is the index of the goal reached at this step, or -1; counting the
distinct indices over many rollouts gives the number of modes a policy covers.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

GOALS = np.array([[0.5, 0.5], [-0.5, 0.5], [-0.5, -0.5], [0.5, -0.5]], dtype=np.float32)
WORKSPACE = 1.0


def goal_index(positions: np.ndarray, radius: float = 0.1) -> np.ndarray:
    """Index of the goal within ``radius`` of each position (..., 2), or -1 where none."""
    positions = np.asarray(positions, dtype=np.float64)
    if positions.shape[-1] != 2:
        raise ValueError(f"positions must have last dimension 2, got shape {positions.shape}")
    dist = np.linalg.norm(positions[..., None, :] - GOALS, axis=-1)
    nearest = np.argmin(dist, axis=-1)
    inside = np.take_along_axis(dist, nearest[..., None], axis=-1)[..., 0] <= radius
    return np.where(inside, nearest, -1)


def distance_to_nearest_goal(positions: np.ndarray) -> np.ndarray:
    """Euclidean distance from each position (..., 2) to its nearest goal."""
    positions = np.asarray(positions, dtype=np.float64)
    return np.min(np.linalg.norm(positions[..., None, :] - GOALS, axis=-1), axis=-1)


class PointMassFourGoalsEnv(gym.Env):
    """Point mass on [-1, 1]² that has to reach one of four goals (see module docstring)."""

    metadata: dict[str, Any] = {"render_modes": []}

    def __init__(
        self,
        horizon: int = 50,
        step_size: float = 0.1,
        goal_radius: float = 0.1,
        distance_cost: float = 10.0,
        goal_reward: float = 50.0,
    ):
        if horizon < 1:
            raise ValueError(f"horizon must be >= 1, got {horizon}")
        if step_size <= 0 or goal_radius <= 0:
            raise ValueError(
                f"step_size and goal_radius must be > 0, got {step_size} and {goal_radius}"
            )
        self.horizon = int(horizon)
        self.step_size = float(step_size)
        self.goal_radius = float(goal_radius)
        self.distance_cost = float(distance_cost)
        self.goal_reward = float(goal_reward)
        self.goals = GOALS.copy()
        self.observation_space = gym.spaces.Box(-WORKSPACE, WORKSPACE, (2,), dtype=np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)
        self._position = np.zeros(2, dtype=np.float32)
        self._t = 0

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start at the origin, or at ``options["start"]`` (e.g. to probe a value grid)."""
        super().reset(seed=seed)
        start = np.zeros(2) if not options or "start" not in options else options["start"]
        start = np.asarray(start, dtype=np.float64)
        if start.shape != (2,):
            raise ValueError(f"options['start'] must have shape (2,), got {start.shape}")
        self._position = np.clip(start, -WORKSPACE, WORKSPACE).astype(np.float32)
        self._t = 0
        return self._position.copy(), {"goal": -1, "success": False}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Move by ``step_size`` · a; reward and termination as in the module docstring."""
        a = np.clip(np.asarray(action, dtype=np.float64).reshape(2), -1.0, 1.0)
        self._position = np.clip(self._position + self.step_size * a, -WORKSPACE, WORKSPACE)
        self._position = self._position.astype(np.float32)
        self._t += 1
        goal = int(goal_index(self._position, self.goal_radius))
        reached = goal >= 0
        reward = -self.distance_cost * float(distance_to_nearest_goal(self._position))
        reward += self.goal_reward * reached
        truncated = self._t >= self.horizon and not reached
        info = {"goal": goal, "success": reached}
        return self._position.copy(), reward, reached, truncated, info

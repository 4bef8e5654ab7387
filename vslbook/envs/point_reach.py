"""A contextual episodic reaching task for a 2-D point, driven by a ProMP (Section 2.3).

The context c ∈ [-1, 1]² is a goal. The parameters θ are the ProMP weights of a planar
trajectory that starts at the origin (ProMPs cannot start anywhere else without an
offset, Section 2.6.1). The return is the non-Markovian episode score

    R(θ, c) = -10 ||y_T(θ) - c||² - λ · mean_t ||ÿ_t(θ)||²,

final-position error plus a smoothness penalty. The final position is linear in θ, so
a linear-Gaussian search distribution π(θ|c) = N(Kc + k, Σ) can solve every context:
it is the smallest task on which the episode-based objective (Eq. 2.27) and its policy
gradient (Eq. 2.33) can be watched converging.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from vslbook.movement import ProMP


class PointReachEnv(gym.Env):
    """One episode per ``step``: observation = context, action = ProMP weights θ."""

    metadata: dict[str, Any] = {"render_modes": []}

    def __init__(
        self,
        n_basis: int = 5,
        duration: float = 1.0,
        dt: float = 0.02,
        smoothness: float = 1e-4,
        success_radius: float = 0.05,
        weight_bound: float = 10.0,
    ):
        if n_basis < 1:
            raise ValueError(f"n_basis must be >= 1, got {n_basis}")
        self.promp = ProMP(n_basis=n_basis, n_dof=2, duration=duration, dt=dt)
        self.n_params = 2 * n_basis
        self.smoothness = float(smoothness)
        self.success_radius = float(success_radius)
        self.dt = float(dt)
        self.context_low = np.array([-1.0, -1.0])
        self.context_high = np.array([1.0, 1.0])
        self.observation_space = gym.spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float64)
        self.action_space = gym.spaces.Box(
            -weight_bound, weight_bound, shape=(self.n_params,), dtype=np.float64
        )
        self._context = np.zeros(2)

    def sample_contexts(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """n contexts from the environment's context distribution p(c) (uniform)."""
        return rng.uniform(self.context_low, self.context_high, size=(n, 2))

    def trajectories(self, theta: np.ndarray) -> np.ndarray:
        """Desired positions (..., T, 2) of parameter vectors ``theta`` (..., n_params)."""
        theta = np.asarray(theta, dtype=np.float64)
        if theta.shape[-1] != self.n_params:
            raise ValueError(
                f"theta must have last dimension {self.n_params}, got shape {theta.shape}"
            )
        return self.promp.trajectory(theta).numpy()

    def evaluate(self, theta: np.ndarray, context: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Batched returns R(θ, c) and success flags for (..., n_params) and (..., 2)."""
        context = np.asarray(context, dtype=np.float64)
        if context.shape[-1] != 2:
            raise ValueError(f"context must have last dimension 2, got shape {context.shape}")
        y = self.trajectories(theta)
        err = np.linalg.norm(y[..., -1, :] - context, axis=-1)
        acc = np.diff(y, n=2, axis=-2) / self.dt**2
        ret = -10.0 * err**2 - self.smoothness * np.mean(np.sum(acc**2, axis=-1), axis=-1)
        return ret, err < self.success_radius

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        if options and "context" in options:
            self._context = np.asarray(options["context"], dtype=np.float64).reshape(2)
        else:
            self._context = self.sample_contexts(1, self.np_random)[0]
        return self._context.copy(), {}

    def step(self, action: np.ndarray):
        action = np.asarray(action, dtype=np.float64)
        if action.shape != (self.n_params,):
            raise ValueError(f"action must have shape ({self.n_params},), got {action.shape}")
        ret, success = self.evaluate(action, self._context)
        info = {"success": bool(success)}
        return self._context.copy(), float(ret), True, False, info

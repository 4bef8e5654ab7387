"""Step-based Box Pushing with Obstacle: the PPO side of Fig. 4.4b (thesis Section 4.5.1).

The simulator, start state, context distribution p(c), torque law and rewards are those of
the episodic :class:`vslbook.envs.robot.box_pushing.BoxPushingObstacle` (Appendix B.4.2.1;
see that module for every number and for where the thesis and the authors' code differ),
but the agent chooses the normalised action a_t itself at each of the T = 100 control steps
(dt = 0.02 s, 10 physics steps of 0.002 s) instead of a ProDMP and PD tracking. The
task's ``settings`` (``"code"``, the default: the authors' ``BoxPushingObstacleTemporalSparse``
reward and y-distance rule; ``"thesis"``: B.4.2.1's), ``reward``, ``distance_rule`` and
``obstacle`` are options of this environment too (an explicit option wins over the
settings); ``obstacle=False`` is the scene without the obstacle that the physics check
against fancy-gym 0.3.0 steps through (``tests/test_box_pushing_reference.py``).

* **action**: ``Box(-1, 1, (7,))``, the normalised joint torques; values outside [−1, 1] are
  clipped. The motor command is the episodic task's ``clip(10 a + qfrc_bias, ±[90, 90, 90,
  90, 12, 12, 12])`` (gravity/Coriolis compensation from the state at the start of the step,
  held for the 10 physics steps); MuJoCo clips the first four joints further to ±87 N m.
* **observation** (ours; the thesis does not list one), 30 numbers:
  ``[q (7), q̇ (7), box position (3), box quaternion (4, w x y z), goal (x, y) (2), goal
  quaternion (4), obstacle (x, y) (2), t / 100 (1)]``. Joint state, box pose and goal pose
  are what the step-based box pushing of Otto et al. (2023) observes; the obstacle position
  (the context's x_o, y_o, where the obstacle is placed) is the rest of the context, and the
  normalised step index t/100 (0 at reset, 1 after the last step) makes the state Markov for
  a reward that arrives only at t = T. The rod tip is a function of q and is left out. The
  box pose is read from the free joint's ``qpos`` (the state after the step).
* **reward** r_t (t = 0..99 the action's index): the episodic task's per-step reward of the
  state after the action (:meth:`BoxPushingObstacle.state_reward`,
  :func:`~vslbook.envs.robot.box_pushing.step_reward`), with the goal terms at the last
  step: by default the code's ``−err − 2 clip(‖p − h_pos‖, 0.05, 100) − 0.02 Σ(10 a_t)² −
  [tilt > π/4] tilt/π``, at the last step also ``−350 ‖p − p_goal‖ − 100 d_rot/π −
  50 ‖q̇‖``; ``reward="thesis"``: B.4.2.1's ``−R_rod − R_rod_rotation − 0.02 Σ(10 a_t)² −
  err(q, q̇)``, at the last step also ``−350 R_goal − 200 R_rotation``. The episodic
  return of the same action sequence is the sum of the r_t.
* **end of the episode**: ``terminated`` after the 100th step. The horizon is part of the
  task (the goal terms are paid at t = T, discount factor 1 in Table B.6), so the last
  state is terminal and must not be bootstrapped; ``truncated`` stays False.
* **unstable simulation** (:func:`~vslbook.envs.robot.box_pushing.unstable`): as in the
  episodic task, every remaining step costs −50; the step that detects it returns
  −50 (T − t) at once and ``terminated`` (``info["unstable"]`` True).
* **context**: ``reset(seed=...)`` draws c = (x_g, y_g, φ_g, x_o, y_o) from the task's p(c)
  (uniform with the task's rejection rules) with ``self.np_random``;
  ``options={"context": c}`` sets it (checked against the context space).
* **info**: ``context`` (at reset), ``pos_error`` (‖p − p_goal‖, m), ``rot_error`` (rotation
  angle to the goal, rad), ``success`` (bool: both errors below 0.05 m / 0.5 rad for the
  current state; after the last step this is the task's success of B.4.2.1), ``unstable``
  and ``step``.

There is no validity check (it belongs to θ of the episodic task; here every action is
applied).
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np

from vslbook.envs.robot.box_pushing import (
    FRAME_SKIP,
    HORIZON,
    UNSTABLE_STEP,
    BoxPushingObstacle,
    apply_torque,
    is_success,
    unstable,
)
from vslbook.envs.robot.gym_env import check_action, context_from_options

N_JOINTS = 7
OBS_DIM = 2 * N_JOINTS + 3 + 4 + 2 + 4 + 2 + 1


class BoxPushingObstacleStepEnv(gym.Env):
    """Box Pushing with Obstacle as a step-based gymnasium environment (see module doc).

    Args:
        render_mode: only None (no rendering).
        settings: ``"code"`` (default) or ``"thesis"``, the task's (reward and context rule).
        reward, distance_rule: the task's options; None: the settings'.
        obstacle: False: the scene without the obstacle (the physics check against
            fancy-gym 0.3.0); the observation still holds the context's x_o, y_o.
    """

    metadata: dict[str, Any] = {"render_modes": []}

    def __init__(
        self, render_mode: str | None = None, settings: str = "code", reward: str | None = None,
        distance_rule: str | None = None, obstacle: bool = True,
    ) -> None:  # fmt: skip
        if render_mode is not None:
            raise ValueError(f"render_mode must be None (no rendering), got {render_mode!r}")
        # every action is applied: no θ, no validity check
        self.task = BoxPushingObstacle(
            settings=settings, reward=reward, distance_rule=distance_rule,
            joint_limit_check=False, obstacle=obstacle,
        )  # fmt: skip
        m = self.task.model
        adr = int(m.jnt_qposadr[m.joint("box_joint").id])
        self._box_qpos = slice(adr, adr + 7)
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (OBS_DIM,), dtype=np.float64)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (N_JOINTS,), dtype=np.float32)
        self._context = np.zeros(self.task.context_dim)
        self._goal_pos = np.zeros(3)
        self._goal_quat = np.array([1.0, 0.0, 0.0, 0.0])
        self._t = 0
        self._done = True

    @property
    def context(self) -> np.ndarray:
        """The current episode's context (x_g, y_g, φ_g, x_o, y_o)."""
        return self._context.copy()

    def _obs(self) -> np.ndarray:
        d = self.task.data
        return np.concatenate([
            d.qpos[:N_JOINTS], d.qvel[:N_JOINTS], d.qpos[self._box_qpos],
            self._goal_pos[:2], self._goal_quat, self._context[3:5],
            [self._t / HORIZON],
        ]).astype(np.float64)  # fmt: skip

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start an episode: robot at q0, box at its start, goal and obstacle from c."""
        super().reset(seed=seed)
        self._context = context_from_options(self.task, options, "context", self.np_random)
        self._goal_pos, self._goal_quat = self.task.reset(self._context)
        self._t = 0
        self._done = False
        return self._obs(), {"context": self._context.copy(), "success": False}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Apply the torque law to ``action`` for one control step (10 physics steps)."""
        if self._done:
            raise RuntimeError("episode is over (or reset() was never called): call reset()")
        a = check_action(action, N_JOINTS)
        task, m, d = self.task, self.task.model, self.task.data
        torque = apply_torque(m, d, a)
        task.physics_steps += FRAME_SKIP
        t = self._t
        self._t += 1
        broken = unstable(d)
        if broken:
            r, pos_err, rot_err = UNSTABLE_STEP * (HORIZON - t), math.nan, math.nan
            obs = np.nan_to_num(self._obs(), nan=0.0, posinf=0.0, neginf=0.0)
        else:
            r, pos_err, rot_err = task.state_reward(
                self._goal_pos, self._goal_quat, torque, final=t == HORIZON - 1
            )
            obs = self._obs()
        terminated = broken or self._t >= HORIZON
        self._done = terminated
        info = {
            "pos_error": pos_err,
            "rot_error": rot_err,
            "success": (not broken) and is_success(pos_err, rot_err),
            "unstable": broken,
            "step": self._t,
        }
        return obs, float(r), bool(terminated), False, info

"""The staged return of robot table tennis (Appendix A.3.3, = B.4.1.1's f2..f5).

:func:`staged_reward` scores one strike from the ball and bat centres over the episode, the
goal, whether the ball touched the bat and where it landed; the rules and their reading are
in the docstring of :mod:`vslbook.envs.robot.table_tennis`, which holds the task and
re-exports this function.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["staged_reward"]


def staged_reward(
    ball: np.ndarray, racket: np.ndarray, goal: np.ndarray, hit: bool, landing: np.ndarray | None
) -> float:
    """The staged return of the module docstring (A.3.3).

    Args:
        ball, racket: ``(T, 3)`` ball centre and bat centre at every simulated sub-step.
        goal: ``(2,)`` desired landing point.
        hit: whether the ball touched the bat.
        landing: ``(≥2,)`` position of the landing that counts (None: no landing).
    """
    ball = np.asarray(ball, dtype=np.float64).reshape(-1, 3)
    racket = np.asarray(racket, dtype=np.float64).reshape(-1, 3)
    if len(ball) == 0 or ball.shape != racket.shape:
        raise ValueError(
            f"ball and racket must be equal (T>0, 3) arrays: {ball.shape}, {racket.shape}"
        )
    goal = np.asarray(goal, dtype=np.float64)[:2]
    diff = ball - racket
    near = 1.0 - math.tanh(float(np.min(np.einsum("ij,ij->i", diff, diff))))
    if not hit:
        return 0.2 * near
    if landing is None:
        off = ball[:, :2] - goal
        closest = float(np.min(np.einsum("ij,ij->i", off, off)))
        return 2.0 * near + (1.0 - math.tanh(closest))
    land = np.asarray(landing, dtype=np.float64)[:2]
    err = float(np.sum((land - goal) ** 2))
    return 2.0 * near + 4.0 * (1.0 - math.tanh(err)) + float(land[0] < 0.0)

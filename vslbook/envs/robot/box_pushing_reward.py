"""The reward of Box Pushing with Obstacle (Appendix B.4.2.1), in the authors' code's
version (``"code"``, Di-SkilL's ``BoxPushingObstacleTemporalSparse._get_reward`` in
``fancy_gym/envs/mujoco/box_pushing/box_pushing_obstacle_env.py``) and the thesis's
(``"thesis"``, B.4.2.1's R_tot).

Every step: the Franka joint-limit excess err = Σ(q − q_max)₊ + Σ(q_min − q)₊ +
Σ(|q̇| − q̇_max)₊ and the action cost 0.02‖10 a‖²; the rod's distance to the box
(code: 2·clip(d, 0.05, 100); thesis: clip(d, 0.05, 10)) and its tilt from pointing down
(code: tilt/π when the tilt exceeds π/4; thesis: clip((2/π) arccos|⟨q_rod, (0,1,0,0)⟩|,
0.25, 2), the same above π/4 and a flat 0.25 below it). At the last step: −350‖p_box −
p_goal‖ − 100 d(r, r_goal)/π (= 200 R_rotation), and in the code −50‖q̇_T‖ as well.
:func:`step_reward` is the plain reading of the formulas, one step at a time (the
step-based environment's reward); :func:`step_rewards` the same for a whole episode at
once (what the episodes use).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "ACTION_COST", "CODE_FINAL_VEL_WEIGHT", "CODE_ROD_CLIP", "CODE_ROD_WEIGHT",
    "CODE_TILT_THRESHOLD", "GOAL_POS_WEIGHT", "QD_MAX", "Q_MAX", "Q_MIN", "REWARDS",
    "ROD_QUAT_DESIRED", "rotation_distance", "step_reward", "step_rewards",
]  # fmt: skip

Q_MAX = np.array([2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973])
Q_MIN = np.array([-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973])
QD_MAX = np.array([2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61])
ROD_QUAT_DESIRED = np.array([0.0, 1.0, 0.0, 0.0])
#: The reward variants (module docstring): BoxPushingObstacleTemporalSparse's, B.4.2.1's.
REWARDS = ("code", "thesis")
# The code's reward (BoxPushingObstacleTemporalSparse): rod–box weight and clip, the rod's
# tilt threshold, the final joint-velocity weight; the goal weights are shared (350, and
# 100 on d(r, r_goal)/π = B.4.2.1's 200 R_rotation).
CODE_ROD_WEIGHT, CODE_ROD_CLIP = 2.0, 100.0
CODE_TILT_THRESHOLD = math.pi / 4
CODE_FINAL_VEL_WEIGHT = 50.0
GOAL_POS_WEIGHT = 350.0
ACTION_COST = 0.02



def rotation_distance(p: np.ndarray, q: np.ndarray) -> float:
    """Angle (rad, in [0, π]) of the rotation between unit quaternions ``p`` and ``q``."""
    return 2.0 * math.acos(min(abs(float(np.dot(p, q))), 1.0))


def _check_variant(variant: str) -> None:
    if variant not in REWARDS:
        raise ValueError(f"variant must be one of {REWARDS}, got {variant!r}")


def step_reward(
    box_pos: np.ndarray, box_quat: np.ndarray, goal_pos: np.ndarray, goal_quat: np.ndarray,
    rod_tip: np.ndarray, rod_quat: np.ndarray, q: np.ndarray, dq: np.ndarray,
    torque: np.ndarray, final: bool, variant: str = "code",
) -> float:  # fmt: skip
    """One step's reward (see the module docstring); ``final`` adds the goal terms.

    ``variant`` ``"code"``: Di-SkilL's ``BoxPushingObstacleTemporalSparse._get_reward``
    (``fancy_gym/envs/mujoco/box_pushing/box_pushing_obstacle_env.py``); ``"thesis"``:
    B.4.2.1's R_tot. ``torque`` is the commanded torque 10 a (without the bias
    compensation). The plain reading of the formulas: the step-based environment's reward,
    and the reference the tests hold :func:`step_rewards` (what the episodes use) to.
    """
    _check_variant(variant)
    err = float(
        np.sum(np.maximum(q - Q_MAX, 0.0))
        + np.sum(np.maximum(Q_MIN - q, 0.0))
        + np.sum(np.maximum(np.abs(dq) - QD_MAX, 0.0))
    )
    cost = ACTION_COST * float(np.sum(np.square(torque)))
    rod_dist = float(np.linalg.norm(box_pos - rod_tip))
    tilt = rotation_distance(rod_quat, ROD_QUAT_DESIRED)
    if variant == "code":
        r = -err - CODE_ROD_WEIGHT * float(np.clip(rod_dist, 0.05, CODE_ROD_CLIP)) - cost
        if tilt > CODE_TILT_THRESHOLD:
            r -= tilt / math.pi
    else:  # B.4.2.1: R_rod = clip(‖p − h_pos‖, 0.05, 10), R_rod_rotation clipped to [0.25, 2]
        cos_rod = min(abs(float(np.dot(rod_quat, ROD_QUAT_DESIRED))), 1.0)
        r_rod_rot = float(np.clip(2.0 / math.pi * math.acos(cos_rod), 0.25, 2.0))
        r = -float(np.clip(rod_dist, 0.05, 10.0)) - r_rod_rot - cost - err
    if final:
        r_goal = float(np.linalg.norm(box_pos - goal_pos))
        r_rot = math.acos(min(abs(float(np.dot(box_quat, goal_quat))), 1.0)) / math.pi
        r += -GOAL_POS_WEIGHT * r_goal - 200.0 * r_rot
        if variant == "code":
            r -= CODE_FINAL_VEL_WEIGHT * float(np.linalg.norm(dq))
    return r


def step_rewards(
    box_pos: np.ndarray, box_quat: np.ndarray, goal_pos: np.ndarray, goal_quat: np.ndarray,
    rod_tip: np.ndarray, rod_quat: np.ndarray, q: np.ndarray, dq: np.ndarray,
    torque: np.ndarray, final: bool, variant: str = "code",
) -> np.ndarray:  # fmt: skip
    """:func:`step_reward` of T steps at once: row t of every ``(T, ·)`` argument is step t's
    state (positions ``(T, 3)``, quaternions ``(T, 4)``, ``q``, ``dq``, ``torque`` ``(T, 7)``);
    ``goal_pos`` (3,) and ``goal_quat`` (4,) are the context's. ``final`` adds the goal terms
    to the last row. Returns the T rewards; the same numbers as :func:`step_reward` row by
    row, up to rounding (one numpy expression per term instead of one call per step).
    """
    _check_variant(variant)
    n = len(torque)
    for name, a, width in (
        ("box_pos", box_pos, 3), ("box_quat", box_quat, 4), ("rod_tip", rod_tip, 3),
        ("rod_quat", rod_quat, 4), ("q", q, 7), ("dq", dq, 7), ("torque", torque, 7),
    ):  # fmt: skip
        if a.shape != (n, width):
            raise ValueError(f"{name} must have shape ({n}, {width}) (T steps), got {a.shape}")
    if np.shape(goal_pos) != (3,) or np.shape(goal_quat) != (4,):
        raise ValueError(
            f"goal_pos and goal_quat must have shapes (3,) and (4,), got "
            f"{np.shape(goal_pos)} and {np.shape(goal_quat)}"
        )
    # err = Σ(q − q_max)₊ + Σ(q_min − q)₊ + Σ(|q̇| − q̇_max)₊, cost = 0.02 Σ (10 a)²
    err = (
        np.sum(np.maximum(q - Q_MAX, 0.0), axis=1)
        + np.sum(np.maximum(Q_MIN - q, 0.0), axis=1)
        + np.sum(np.maximum(np.abs(dq) - QD_MAX, 0.0), axis=1)
    )
    cost = ACTION_COST * np.sum(np.square(torque), axis=1)
    rod_dist = np.linalg.norm(box_pos - rod_tip, axis=1)
    cos_rod = np.minimum(np.abs(rod_quat @ ROD_QUAT_DESIRED), 1.0)
    if variant == "code":
        # −err − 2 clip(‖p − h_pos‖, 0.05, 100) − cost − [tilt > π/4] tilt/π, tilt = 2 arccos
        tilt = 2.0 * np.arccos(cos_rod)
        tilt_cost = np.where(tilt > CODE_TILT_THRESHOLD, tilt / math.pi, 0.0)
        r = -err - CODE_ROD_WEIGHT * np.clip(rod_dist, 0.05, CODE_ROD_CLIP) - cost - tilt_cost
    else:
        # −R_rod − R_rod_rotation − cost − err, R_rod = clip(‖p − h_pos‖, 0.05, 10),
        # R_rod_rotation = clip((2/π) arccos|h_rot · (0,1,0,0)|, 0.25, 2)
        r_rod_rot = np.clip(2.0 / math.pi * np.arccos(cos_rod), 0.25, 2.0)
        r = -np.clip(rod_dist, 0.05, 10.0) - r_rod_rot - cost - err
    if final and n > 0:  # −350 R_goal − 200 R_rotation (= 100 d/π) at t = T
        r_goal = float(np.linalg.norm(box_pos[-1] - goal_pos))
        r_rot = math.acos(min(abs(float(np.dot(box_quat[-1], goal_quat))), 1.0)) / math.pi
        r[-1] += -GOAL_POS_WEIGHT * r_goal - 200.0 * r_rot
        if variant == "code":  # and −50 ‖q̇_T‖
            r[-1] -= CODE_FINAL_VEL_WEIGHT * float(np.linalg.norm(dq[-1]))
    return r

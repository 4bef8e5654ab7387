"""Probes of task objects for the audit rows of :mod:`vslbook.experiments.audit_tasks`.

A probe runs the task object :func:`vslbook.envs.robot.make_task` built on a made-up input
and names the formula its answer matches, so the audit's ``ours`` column is read from
what the task does, never typed. Here: the three punishments of the Chapter 3 table tennis
(thesis Appendix A.3.3; :mod:`vslbook.envs.robot.table_tennis_ch3`), each told apart from
the authors' SVSL code's by a value both formulas are written out for.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = [
    "TT3_CONTEXT",
    "TT3_DURATION",
    "TT3_JOINTS",
    "tt3_context_punishment",
    "tt3_duration_punishment",
    "tt3_joint_punishment",
]

#: The names of the two versions of each punishment: (A.3.3's, the authors' code's).
TT3_CONTEXT = ("-20 d²", "-20 Σ|violation|")
TT3_DURATION = ("-3|l - b|", "-3|l - b| - 1")
TT3_JOINTS = ("-(1/T) Σ_t d_qpos,t", "-(mean excess above high + mean excess below low)")


def _name(value: float, thesis: float, code: float, names: tuple[str, str], at: str) -> str:
    for want, name in zip((thesis, code), names, strict=True):
        if math.isclose(value, want, rel_tol=1e-9):
            return name
    return f"{value:.6g} at {at}"


def _centre(task: Any) -> np.ndarray:
    return (np.asarray(task.valid_low) + np.asarray(task.valid_high)) / 2


def tt3_context_punishment(task: Any) -> str:
    """task.context_penalty 0.1 below the valid box in one coordinate"""
    c = np.array(task.valid_low, dtype=float)
    c[0] -= 0.1
    p = float(np.asarray(task.context_penalty(c[None]))[0])
    return _name(p, -20 * 0.1**2, -20 * 0.1, TT3_CONTEXT, "d = 0.1")


def tt3_duration_punishment(task: Any) -> str:
    """task.episode(θ, c).ret for a duration l = 5.5 s, 0.5 s above its bound b = 5"""
    theta = np.zeros(task.n_params)
    theta[0] = 5.5
    ret = float(task.episode(theta, _centre(task)).ret)  # punished, not simulated
    return _name(ret, -3 * 0.5, -3 * 0.5 - 1, TT3_DURATION, "l = 5.5")


def tt3_joint_punishment(task: Any) -> str:
    """task.episode(θ, c).ret for a plan that leaves the joint box above and below"""
    from vslbook.envs.robot.table_tennis import JOINT_HIGH, JOINT_LOW
    from vslbook.envs.robot.table_tennis_ch3 import planned_trajectory

    theta = np.zeros(task.n_params)
    theta[0] = 1.2
    theta[6], theta[15] = 6.0, -12.0  # joint 2 past 2.0, joint 5 below -4.8
    q, _ = planned_trajectory(theta)
    above, below = q - JOINT_HIGH, JOINT_LOW - q
    code = -(np.mean(above[above > 0]) + np.mean(below[below > 0]))
    thesis = -np.mean(np.linalg.norm(np.maximum(above, 0) + np.maximum(below, 0), axis=1))
    ret = float(task.episode(theta, _centre(task)).ret)  # punished, not simulated
    return _name(ret, float(thesis), float(code), TT3_JOINTS, "this plan")

"""Environments, registered with gymnasium under the ``vslbook/`` namespace.

Episodic (black-box) tasks of Chapters 2–4 use a one-step gymnasium interface: the
observation is the context c, the action is the whole parameter vector θ of a movement
primitive, and ``step(θ)`` runs the episode and returns the return R(θ, c) (Eq. 2.27).
They also expose ``evaluate(theta, context)`` for batched evaluation and
``sample_contexts(n, rng)`` for the environment's context distribution p(c).
"""

from __future__ import annotations

import difflib
from typing import Any

import gymnasium as gym

from vslbook.envs.step_based import STEP_TASKS, make_step_env

VSLBOOK_ENVS = {
    "vslbook/PointReach-v0": "vslbook.envs.point_reach:PointReachEnv",
    # Step-based (Chapter 5); make() builds it through make_step_env like the other STEP_TASKS.
    "vslbook/PointMassFourGoals-v0": "vslbook.envs.point_mass:PointMassFourGoalsEnv",
}

for _id, _entry in VSLBOOK_ENVS.items():
    if _id not in gym.registry:
        gym.register(id=_id, entry_point=_entry)


def check_env_id(env_id: str) -> None:
    """Raise a clear ValueError unless :func:`make` knows ``env_id``; builds no simulator.

    Known are the step-based tasks (:data:`STEP_TASKS`: dm_control, gymnasium MuJoCo,
    MyoSuite and the point mass), the robot tasks of Chapters 3-4
    (:mod:`vslbook.envs.robot`, one-step and step-based ids) and every id in gymnasium's
    registry. The message names
    the id, suggests close matches and lists the ids vslbook provides.
    """
    if isinstance(env_id, str) and (env_id in STEP_TASKS or env_id in gym.registry):
        return
    # The robot tasks of Chapters 3-4 register on first use: a run that never asks for one
    # never imports them (DIME's runs are independent of vslbook/envs/robot/).
    import vslbook.envs.robot  # noqa: F401

    if isinstance(env_id, str) and env_id in gym.registry:
        return
    known = sorted({k for k in gym.registry if k.startswith("vslbook/")} | set(STEP_TASKS))
    close = difflib.get_close_matches(str(env_id), sorted(set(gym.registry) | set(known)), n=3)
    hint = f"did you mean {', '.join(close)}? " if close else ""
    raise ValueError(f"unknown environment {env_id!r}; {hint}vslbook provides {', '.join(known)}")


def make(env_id: str, **kwargs: Any) -> gym.Env:
    """Create a registered environment; an unknown id is a clear error listing the known ones."""
    if env_id in STEP_TASKS:
        return make_step_env(env_id, **kwargs)
    check_env_id(env_id)
    return gym.make(env_id, **kwargs)

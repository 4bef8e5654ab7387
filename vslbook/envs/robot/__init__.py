"""Robot tasks of Chapters 3 and 4 on MuJoCo 3 and gymnasium 1 (and the planar reacher).

Every task is an :class:`~vslbook.envs.robot.task.EpisodicTask`: ``sample_contexts(n, rng)``
draws from p(c) with the task's rejection rules, ``evaluate(theta, contexts)`` runs a batch
and returns a :class:`~vslbook.envs.robot.task.Rollouts` (returns, success, executed flags,
per-episode info). :func:`make_task` builds one by name; importing this package registers
each task as a one-step gymnasium id ``vslbook/<Name>-v0`` (observation = context, action =
θ) and the step-based ids the PPO baselines use.

These are re-implementations from the thesis's descriptions (Sections 3.4, 4.5.1,
Appendices A.3, B.4) on today's simulators, with the model files of fancy-gym 0.3.0 (MIT)
read from its installed wheel (:mod:`vslbook.envs.robot.assets`): absolute rewards compare
with the thesis's in shape only.
"""

from __future__ import annotations

import difflib
import importlib
from typing import Any

import gymnasium as gym

from vslbook.envs.robot.gym_env import EpisodicEnv
from vslbook.envs.robot.task import Episode, EpisodicTask, Rollouts

_R = "vslbook.envs.robot."

#: name → (module:class, one-step gymnasium id); the name is the class's ``name``.
TASKS: dict[str, tuple[str, str]] = {
    "planar-reacher": (_R + "planar_reacher:PlanarReacherTask", "vslbook/PlanarReacher-v0"),
    "reacher5": (_R + "reacher5:Reacher5", "vslbook/Reacher5-v0"),
    "reacher5-ch3": (_R + "reacher5:Reacher5Ch3", "vslbook/Reacher5Ch3-v0"),
    "table-tennis-4d": (_R + "table_tennis:TableTennis4D", "vslbook/TableTennis4D-v0"),
    "table-tennis-hard": (_R + "table_tennis:TableTennisHard", "vslbook/TableTennisHard-v0"),
    "table-tennis-ch3": (_R + "table_tennis_ch3:TableTennisCh3", "vslbook/TableTennisCh3-v0"),
    "beer-pong": (_R + "beer_pong:BeerPong", "vslbook/BeerPong-v0"),
    "hopper-jump": (_R + "hopper_jump:HopperJump", "vslbook/HopperJump-v0"),
    "mini-golf": (_R + "mini_golf:MiniGolf", "vslbook/MiniGolf-v0"),
    "box-pushing-obstacle": (
        _R + "box_pushing:BoxPushingObstacle",
        "vslbook/BoxPushingObstacle-v0",
    ),
}

#: Step-based gymnasium ids (PPO baselines): id → module:class.
STEP_IDS: dict[str, str] = {
    "vslbook/Reacher5Ch3Step-v0": _R + "reacher5_step:Reacher5Ch3StepEnv",
    "vslbook/Reacher5SparseStep-v0": _R + "reacher5_sparse_step:Reacher5SparseStepEnv",
    "vslbook/BoxPushingObstacleStep-v0": _R + "box_pushing_step:BoxPushingObstacleStepEnv",
}


def task_class(name: str) -> type[EpisodicTask]:
    """The class of a task by name, or a clear error listing the known names."""
    if name not in TASKS:
        close = difflib.get_close_matches(str(name), list(TASKS), n=3)
        hint = f"did you mean {', '.join(close)}? " if close else ""
        raise ValueError(f"unknown task {name!r}; {hint}known tasks: {', '.join(sorted(TASKS))}")
    module, cls = TASKS[name][0].split(":")
    return getattr(importlib.import_module(module), cls)


def make_task(name: str, **kwargs: Any) -> EpisodicTask:
    """Build the task ``name`` (see :data:`TASKS`) with its keyword arguments."""
    return task_class(name)(**kwargs)


def _make_episodic(task: str, **kwargs: Any) -> EpisodicEnv:
    return EpisodicEnv(task_class(task), **kwargs)


def register_envs() -> None:
    """Register every task's one-step id and every step-based id with gymnasium."""
    for name, (_, env_id) in TASKS.items():
        if env_id not in gym.registry:
            gym.register(id=env_id, entry_point=_make_episodic, kwargs={"task": name})
    for env_id, entry in STEP_IDS.items():
        if env_id not in gym.registry:
            gym.register(id=env_id, entry_point=entry)


register_envs()

__all__ = [
    "Episode", "EpisodicEnv", "EpisodicTask", "Rollouts", "STEP_IDS", "TASKS",
    "make_task", "register_envs", "task_class",
]  # fmt: skip

"""Step-based tasks of Chapter 5 (DIME) behind one factory, :func:`make_step_env`.

Every task comes out with the same contract, whatever its simulator:

- a flat ``Box`` observation of dtype float32 and a float reward;
- a ``Box`` action space with bounds [-1, 1] (the learner squashes with tanh, Eq. C.29);
  where the simulator's bounds differ (Humanoid-v5: ±0.4, dm_control quadruped: up to
  1.1), ``gymnasium.wrappers.RescaleAction`` maps [-1, 1] onto them;
- ``truncated`` is True when an episode ends at its time limit and ``terminated`` only when
  it really ends, so a learner bootstraps through time limits;
- MyoSuite tasks put their success flag (MyoSuite's ``info["solved"]``) in
  ``info["success"]``, also after ``reset`` (False).

Suites and the recipes used (Appendix C.3, Table C.1):

``dmc``
    DeepMind Control through shimmy: ``gymnasium.make("dm_control/<domain>-<task>-v0")``,
    then ``FlattenObservation`` (the observation is a Dict) and the float32 cast. dm_control
    ends every episode itself after 1000 control steps (the registered ``max_episode_steps``
    is None); shimmy reports that last step with discount 1 as ``truncated=True``. The
    thesis runs dog and humanoid; the published learning curves add eight more tasks, whose
    dm_control task names are those of the DMC-15 benchmark of BRO (Nauman et al., 2024),
    the baseline DIME's curves are compared with: ``dmc_acrobot`` is acrobot-swingup and
    ``dmc_finger_turn`` is finger-turn_hard. Table C.1 gives the DMC humanoid 24 action
    dimensions; dm_control's humanoid has 21 actuators, and 21 is what it gets here.
``gym``
    gymnasium MuJoCo Ant-v5 and Humanoid-v5 (time limit 1000 steps). The thesis used Ant-v3
    and Humanoid-v3, which need mujoco-py and cannot be built on this stack. v5 drops the
    entries that are always zero from the observation (the world body's contact forces;
    for Humanoid also its inertia and velocity and the free joint's actuator forces):
    105 instead of 111 dimensions for Ant and 348 instead of 376 for Humanoid (Table C.1).
    Models, reward terms (contact cost included, as in v3) and termination are v3's; v5
    pays the healthy reward only while healthy, which changes the terminal step alone.
    Returns are comparable with the ``gym_*_v3`` paper data in scale, not to the digit.
``myo``
    MyoSuite 3.0.0 hand tasks with random targets (Table C.1 names), imported only when one
    is made. MyoSuite's own registration sets the time limits (key turn 200, object hold
    75, pen twirl 50, reach 100 steps) and the early termination (a dropped pen or object,
    fingertips too far from the key or from their reach targets).
``toy``
    :mod:`vslbook.envs.point_mass`, the four-goal point mass of Fig. 5.7.
"""

from __future__ import annotations

import logging
import warnings
from dataclasses import dataclass
from typing import Any, Literal

import gymnasium as gym
import numpy as np
from gymnasium.wrappers import FlattenObservation, RescaleAction

Suite = Literal["dmc", "gym", "myo", "toy"]


@dataclass(frozen=True)
class StepTask:
    """One row of the task table.

    ``env_id`` is what :func:`make_step_env` takes (the simulator's own gymnasium id),
    ``thesis_name`` how the thesis names the task (empty where only the published data
    has it), ``paper_id`` the id in ``data/paper/dime_learning_curves.csv`` (empty for
    the toy task, which has no published curve).
    """

    env_id: str
    suite: Suite
    thesis_name: str
    paper_id: str


def _dmc(domain_task: str, thesis_name: str, paper_id: str) -> StepTask:
    return StepTask(f"dm_control/{domain_task}-v0", "dmc", thesis_name, paper_id)


TASK_TABLE: tuple[StepTask, ...] = (
    _dmc("dog-stand", "dog-stand", "dmc_dog_stand"),
    _dmc("dog-walk", "dog-walk", "dmc_dog_walk"),
    _dmc("dog-trot", "dog-trot", "dmc_dog_trot"),
    _dmc("dog-run", "dog-run", "dmc_dog_run"),
    _dmc("humanoid-stand", "humanoid-stand", "dmc_humanoid_stand"),
    _dmc("humanoid-walk", "humanoid-walk", "dmc_humanoid_walk"),
    _dmc("humanoid-run", "humanoid-run", "dmc_humanoid_run"),
    _dmc("acrobot-swingup", "", "dmc_acrobot"),
    _dmc("cheetah-run", "", "dmc_cheetah_run"),
    _dmc("finger-turn_hard", "", "dmc_finger_turn"),
    _dmc("fish-swim", "", "dmc_fish_swim"),
    _dmc("hopper-hop", "", "dmc_hopper_hop"),
    _dmc("pendulum-swingup", "", "dmc_pendulum_swingup"),
    _dmc("quadruped-run", "", "dmc_quadruped_run"),
    _dmc("walker-run", "", "dmc_walker_run"),
    StepTask("Ant-v5", "gym", "Ant-v3", "gym_ant_v3"),
    StepTask("Humanoid-v5", "gym", "Humanoid-v3", "gym_humanoid_v3"),
    StepTask("myoHandKeyTurnRandom-v0", "myo", "myoHandKeyTurnRandom-v0", "myo_hand_key_turn_rndm"),
    StepTask("myoHandObjHoldRandom-v0", "myo", "myoHandObjHoldRandom-v0", "myo_hand_obj_hold_rndm"),
    StepTask(
        "myoHandPenTwirlRandom-v0", "myo", "myoHandPenTwirlRandom-v0", "myo_hand_pen_twirl_rndm"
    ),
    StepTask("myoHandReachRandom-v0", "myo", "myoHandReachRandom-v0", "myo_hand_reach_rndm"),
    StepTask("vslbook/PointMassFourGoals-v0", "toy", "point mass (Fig. 5.7)", ""),
)

TASKS: dict[str, StepTask] = {t.env_id: t for t in TASK_TABLE}
STEP_TASKS: list[str] = [t.env_id for t in TASK_TABLE]
_BY_PAPER_ID: dict[str, StepTask] = {t.paper_id: t for t in TASK_TABLE if t.paper_id}

# C51 support of DIME's distributional critic per suite (Appendix C.5). The thesis gives no
# per-task exception. The toy range is a choice: it holds the point mass's returns
# (between about -355 and +50) up to the wandering start of training.
VALUE_RANGES: dict[str, tuple[float, float]] = {
    "dmc": (-200.0, 200.0),
    "gym": (-1600.0, 1600.0),
    "myo": (-3600.0, 3600.0),
    "toy": (-200.0, 200.0),
}

# MyoSuite's name for the success flag, exposed as info["success"].
MYO_SUCCESS_KEY = "solved"


def _task(env_id: str) -> StepTask:
    if env_id not in TASKS:
        raise ValueError(
            f"unknown step-based task {env_id!r}; valid ids are {', '.join(STEP_TASKS)}"
        )
    return TASKS[env_id]


def suite_of(env_id: str) -> Suite:
    """The benchmark suite of a task: "dmc", "gym", "myo" or "toy"."""
    return _task(env_id).suite


def value_range(env_id: str) -> tuple[float, float]:
    """(v_min, v_max) of the distributional critic's support for this task (Appendix C.5)."""
    return VALUE_RANGES[suite_of(env_id)]


def paper_id(env_id: str) -> str:
    """The task's id in the published learning curves, e.g. ``dmc_dog_run``."""
    task = _task(env_id)
    if not task.paper_id:
        valid = ", ".join(t.env_id for t in _BY_PAPER_ID.values())
        raise ValueError(f"{env_id!r} has no published curve; tasks with one are {valid}")
    return task.paper_id


def env_id_from_paper(paper_task: str) -> str:
    """The inverse of :func:`paper_id`: ``dmc_dog_run`` → ``dm_control/dog-run-v0``."""
    if paper_task not in _BY_PAPER_ID:
        raise ValueError(
            f"unknown paper task id {paper_task!r}; valid ids are {', '.join(_BY_PAPER_ID)}"
        )
    return _BY_PAPER_ID[paper_task].env_id


class Float32Observation(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Cast observations to float32 and rewards to Python floats (shimmy may return int 0)."""

    def __init__(self, env: gym.Env):
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.Wrapper.__init__(self, env)
        space = env.observation_space
        if not isinstance(space, gym.spaces.Box):
            raise ValueError(f"Float32Observation needs a Box observation space, got {space}")
        self.observation_space = gym.spaces.Box(
            space.low.astype(np.float32), space.high.astype(np.float32), dtype=np.float32
        )

    def reset(self, **kwargs: Any) -> tuple[np.ndarray, dict[str, Any]]:
        obs, info = self.env.reset(**kwargs)
        return np.asarray(obs, dtype=np.float32), info

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        return np.asarray(obs, dtype=np.float32), float(reward), terminated, truncated, info


class SuccessInfo(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Copy a simulator's own success flag ``info[key]`` to ``info["success"]`` as a bool."""

    def __init__(self, env: gym.Env, key: str):
        gym.utils.RecordConstructorArgs.__init__(self, key=key)
        gym.Wrapper.__init__(self, env)
        self.key = key

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(**kwargs)
        return obs, {**info, "success": bool(info.get(self.key, False))}

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        if self.key not in info:
            raise KeyError(f"expected the success flag info[{self.key!r}], got {sorted(info)}")
        return obs, reward, terminated, truncated, {**info, "success": bool(info[self.key])}


class _DeprecatedMjcfAttributes(logging.Filter):
    """Drops dm_control's warning that an MJCF attribute of its own models is deprecated
    (``compiler attribute 'settotalmass' is deprecated``), logged once per environment
    made: a page of them would stand in every notebook output that builds a DMC task."""

    def filter(self, record: logging.LogRecord) -> bool:
        return "is deprecated and will be removed" not in record.getMessage()


_MJCF_FILTER = _DeprecatedMjcfAttributes()


def _import_suite(suite: Suite) -> None:
    """Import the package that registers a suite's gymnasium ids, only when it is needed."""
    if suite == "dmc":
        import shimmy  # noqa: F401  (registers dm_control/<domain>-<task>-v0)

        logging.getLogger("absl").addFilter(_MJCF_FILTER)  # once: the same filter object
    elif suite == "myo":
        try:
            import myosuite  # noqa: F401  (registers the myo* ids)
        except ImportError as err:
            raise ImportError(
                "the MyoSuite tasks need the myosuite package; install it with `make myo`"
            ) from err


def _unit_actions(env: gym.Env) -> gym.Env:
    """Rescale a Box action space to [-1, 1] when its bounds are anything else."""
    space = env.action_space
    if np.all(space.low == -1.0) and np.all(space.high == 1.0):
        return env
    one = np.ones(space.shape, dtype=space.dtype)
    return RescaleAction(env, -one, one)


def make_step_env(env_id: str, seed: int | None = None, **kwargs: Any) -> gym.Env:
    """Create a step-based task with the contract of the module docstring.

    ``kwargs`` go to ``gymnasium.make`` (e.g. ``render_mode``). With a ``seed`` the
    environment is reset once with it and its action space is seeded, so the next
    ``reset()`` without a seed continues a reproducible stream.
    """
    task = _task(env_id)
    _import_suite(task.suite)
    with warnings.catch_warnings():
        # MyoSuite's model builder warns about its own spec prefixes; nothing to act on.
        warnings.filterwarnings("ignore", message="Attaching a spec with an empty prefix")
        env = gym.make(env_id, **kwargs)
    if isinstance(env.observation_space, gym.spaces.Dict):
        env = FlattenObservation(env)
    if task.suite == "myo":
        env = SuccessInfo(env, MYO_SUCCESS_KEY)
    env = _unit_actions(Float32Observation(env))
    if seed is not None:
        env.reset(seed=seed)
        env.action_space.seed(seed)
        env.observation_space.seed(seed)
    return env

"""The step-based tasks of Chapter 5: one factory, one contract for every suite."""

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from vslbook.envs import make
from vslbook.envs.point_mass import GOALS, PointMassFourGoalsEnv, goal_index
from vslbook.envs.step_based import (
    STEP_TASKS,
    TASKS,
    env_id_from_paper,
    make_step_env,
    paper_id,
    suite_of,
    value_range,
)

# Creating these takes most of a second each (dog models, MyoSuite's model builder).
COSTLY = {t for t in STEP_TASKS if "dog-" in t or suite_of(t) == "myo"}
TASK_PARAMS = [pytest.param(t, marks=pytest.mark.slow) if t in COSTLY else t for t in STEP_TASKS]

# Table C.1 (gym rows: the v5 observations, see vslbook.envs.step_based).
DIMS = {
    "dm_control/dog-run-v0": (223, 38),
    "dm_control/humanoid-run-v0": (67, 21),
    "Ant-v5": (105, 8),
    "Humanoid-v5": (348, 17),
    "myoHandKeyTurnRandom-v0": (93, 39),
    "myoHandObjHoldRandom-v0": (91, 39),
    "myoHandPenTwirlRandom-v0": (83, 39),
    "myoHandReachRandom-v0": (115, 39),
    "vslbook/PointMassFourGoals-v0": (2, 2),
}


@pytest.mark.parametrize("env_id", TASK_PARAMS)
def test_task_passes_env_checker_with_the_common_contract(env_id):
    env = make(env_id, seed=0)
    with warnings.catch_warnings():
        # The checker advises checking env.unwrapped; the wrapped env is the contract here.
        warnings.filterwarnings("ignore", message=".*is different from the unwrapped version")
        warnings.filterwarnings("ignore", message=".*Box observation space m.*infinity")
        check_env(env, skip_render_check=True)
    obs_space, act_space = env.observation_space, env.action_space
    assert isinstance(obs_space, gym.spaces.Box) and obs_space.dtype == np.float32
    assert len(obs_space.shape) == 1
    assert isinstance(act_space, gym.spaces.Box) and len(act_space.shape) == 1
    assert np.all(act_space.low == -1.0) and np.all(act_space.high == 1.0)
    obs, _ = env.reset(seed=1)
    assert obs.dtype == np.float32 and obs.shape == obs_space.shape
    obs, reward, terminated, truncated, info = env.step(act_space.sample())
    assert obs.dtype == np.float32 and isinstance(reward, float)
    if env_id in DIMS:
        assert (obs_space.shape[0], act_space.shape[0]) == DIMS[env_id]
    v_min, v_max = value_range(env_id)
    assert v_min < 0 < v_max
    env.close()


def test_dmc_time_limit_is_a_truncation_at_step_1000():
    env = make_step_env("dm_control/pendulum-swingup-v0", seed=0)
    env.reset()
    steps, truncated = 0, False
    while not truncated and steps < 1001:
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        assert not terminated
        steps += 1
    assert truncated and steps == 1000


def test_actions_are_rescaled_onto_the_simulator_bounds():
    env = make_step_env("Humanoid-v5")
    assert np.allclose(env.unwrapped.action_space.high, 0.4)
    assert np.allclose(env.action(np.ones(17, dtype=np.float32)), 0.4)
    quadruped = make_step_env("dm_control/quadruped-run-v0")
    inner = quadruped.unwrapped.action_space
    assert np.allclose(quadruped.action(-np.ones(12)), inner.low)
    assert np.allclose(quadruped.action(np.ones(12)), inner.high)


def test_seed_makes_the_following_resets_reproducible():
    first = [make_step_env("dm_control/cheetah-run-v0", seed=3).reset()[0] for _ in range(2)]
    np.testing.assert_array_equal(*first)


@pytest.mark.slow
def test_myo_success_is_reported_as_info_success():
    env = make_step_env("myoHandPenTwirlRandom-v0", seed=0)
    _, info = env.reset()
    assert info["success"] is False
    _, _, _, _, info = env.step(env.action_space.sample())
    assert "solved" in info and info["success"] is bool(info["solved"])


def test_paper_ids_round_trip_and_cover_the_published_data():
    published = {
        "dmc_acrobot", "dmc_cheetah_run", "dmc_dog_run", "dmc_dog_stand", "dmc_dog_trot",
        "dmc_dog_walk", "dmc_finger_turn", "dmc_fish_swim", "dmc_hopper_hop",
        "dmc_humanoid_run", "dmc_humanoid_stand", "dmc_humanoid_walk", "dmc_pendulum_swingup",
        "dmc_quadruped_run", "dmc_walker_run", "gym_ant_v3", "gym_humanoid_v3",
        "myo_hand_key_turn_rndm", "myo_hand_obj_hold_rndm", "myo_hand_pen_twirl_rndm",
        "myo_hand_reach_rndm",
    }  # fmt: skip
    with_curves = [t for t in STEP_TASKS if suite_of(t) != "toy"]
    assert {paper_id(t) for t in with_curves} == published
    for t in with_curves:
        assert env_id_from_paper(paper_id(t)) == t
    assert env_id_from_paper("dmc_finger_turn") == "dm_control/finger-turn_hard-v0"
    assert TASKS["Humanoid-v5"].thesis_name == "Humanoid-v3"


def test_value_ranges_follow_appendix_c5():
    assert value_range("dm_control/dog-run-v0") == (-200.0, 200.0)
    assert value_range("Ant-v5") == (-1600.0, 1600.0)
    assert value_range("myoHandReachRandom-v0") == (-3600.0, 3600.0)


def _drive_to(env, target, max_steps=50):
    obs, info = env.reset()
    for _ in range(max_steps):
        obs, reward, terminated, truncated, info = env.step(np.clip(10 * (target - obs), -1, 1))
        if terminated or truncated:
            break
    return obs, reward, terminated, info


def test_point_mass_four_goals_are_reachable_and_identified():
    env = make("vslbook/PointMassFourGoals-v0", seed=0)
    obs, info = env.reset()
    np.testing.assert_array_equal(obs, np.zeros(2, dtype=np.float32))
    assert info["goal"] == -1
    for k, goal in enumerate(GOALS):
        obs, reward, terminated, info = _drive_to(env, goal)
        assert terminated and info["goal"] == k and info["success"]
        assert reward > 0
    assert goal_index(GOALS).tolist() == [0, 1, 2, 3]
    assert goal_index(np.zeros(2)) == -1


def test_point_mass_truncates_at_its_horizon_without_a_goal():
    env = PointMassFourGoalsEnv(horizon=7)
    env.reset(seed=0)
    ends = []
    for _ in range(7):
        _, reward, terminated, truncated, info = env.step(np.array([1.0, 0.0], np.float32))
        assert not terminated and info["goal"] == -1 and reward < 0
        ends.append(truncated)
    assert ends == [False] * 6 + [True]


@pytest.mark.parametrize("bad", ["dm_control/dog-fly-v0", "vslbook/PointMass-v0", "nope"])
def test_unknown_ids_are_clear_errors(bad):
    with pytest.raises(ValueError, match="dm_control/dog-run-v0") as err:
        make(bad)
    assert bad in str(err.value) and "vslbook/PointReach-v0" in str(err.value)
    for fn in (make_step_env, suite_of, value_range, paper_id):
        with pytest.raises(ValueError, match="myoHandReachRandom-v0"):
            fn(bad)
    with pytest.raises(ValueError, match="dmc_dog_run"):
        env_id_from_paper(bad)


def test_the_thesis_gym_versions_are_not_step_tasks():
    # Ant-v3/Humanoid-v3 need mujoco-py; the v5 tasks stand in for them.
    with pytest.raises(ValueError, match="'Ant-v3'.*Ant-v5"):
        make_step_env("Ant-v3")
    with pytest.raises(ValueError, match="no published curve"):
        paper_id("vslbook/PointMassFourGoals-v0")


def test_dm_control_model_deprecations_stay_out_of_the_output(caplog):
    import logging

    make_step_env("dm_control/cheetah-run-v0", seed=0)  # dm_control warns while compiling
    logging.getLogger("absl").warning("compiler attribute 'x' is deprecated and will be "
                                      "removed in a future release")  # fmt: skip
    logging.getLogger("absl").warning("another warning")
    said = [r.getMessage() for r in caplog.records if r.name == "absl"]
    assert said == ["another warning"]

"""Beer Pong (thesis Section 3.4, Appendix A.3.2): layout, determinism, reward cases from
placed ball states, validity checks before simulation, contexts, and a throw into the cup."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from vslbook.envs.robot.beer_pong import (
    J_MAX,
    J_MIN,
    Q0,
    BeerPong,
    beer_pong_reward,
    desired_trajectory,
)
from vslbook.envs.robot.task import EpisodicEnv

CONTEXT = np.array([0.0, -1.7])
# Found by a cross-entropy search on the context (0, −1.7): population 25, elite 5, start
# mean [l = 0.6, joint 2 weights −6, joint 4 weights −4.5, others 0] (a throw over the
# shoulder read off a coarse grid of 40 episodes), std 1 (0.05 for l), seed 0; the first
# population already held this θ (≈65 episodes in all).
SUCCESS_THETA = np.array([
    6.42637424e-01, -6.67687292e-01, 1.63244006e-01, -6.83075196e00, -3.65419193e00,
    -7.04139562e-01, -4.53074444e-01, -5.56583802e00, -4.84612128e00, -5.87602670e-03,
    7.67789135e-01, -6.10486646e-01, -1.85773959e-01, -1.41648937e00, -8.27402227e-01,
])  # fmt: skip


@pytest.fixture(scope="module")
def task() -> BeerPong:
    t = BeerPong()
    yield t
    t.close()


def test_layout_and_trajectory(task: BeerPong) -> None:
    assert task.n_params == 15 and task.context_dim == 2
    np.testing.assert_allclose(task.model.jnt_range[:7, 0], J_MIN)
    np.testing.assert_allclose(task.model.jnt_range[:7, 1], J_MAX)
    theta = np.r_[0.5, np.linspace(-3, 3, 14)]
    q, dq = desired_trajectory(theta)
    assert q.shape == dq.shape == (101, 7)  # 0.5 s / 0.005 s steps + 1
    np.testing.assert_allclose(q[0], Q0, atol=1e-8)  # starts at the start posture
    np.testing.assert_allclose(dq[0], 0.0, atol=1e-6)
    # q̇_d is the time derivative of q_d (central differences).
    np.testing.assert_allclose(dq[1:-1], (q[2:] - q[:-2]) / 0.01, rtol=0.02, atol=0.05)
    # The end position is mostly the second learned weight of each joint (× √0.02).
    np.testing.assert_allclose(q[-1] - Q0, theta[2::2] * math.sqrt(0.02), atol=0.02)


@pytest.mark.slow  # starting two worker processes takes ~15 s on a loaded machine
def test_determinism_and_workers() -> None:
    t = BeerPong(extra_steps=40)
    rng = np.random.default_rng(3)
    theta = np.c_[rng.uniform(0.3, 0.9, 4), rng.normal(0, 1, (4, 14))]
    contexts = t.sample_contexts(4, rng)
    a = t.evaluate(theta, contexts, workers=0)
    b = t.evaluate(theta, contexts, workers=0)
    try:
        c = t.evaluate(theta, contexts, workers=2)
    finally:
        t.close()
    assert a.executed.all()
    for other in (b, c):
        np.testing.assert_array_equal(a.returns, other.returns)
        np.testing.assert_array_equal(a.success, other.success)
        for k in t.info_keys:
            np.testing.assert_array_equal(a.info[k], other.info[k])


def _place_ball(task: BeerPong, pos: np.ndarray) -> tuple[bool, bool]:
    task.reset(CONTEXT)
    task.data.qpos[7:10] = pos
    task.data.qvel[:] = 0.0
    mujoco.mj_forward(task.model, task.data)
    return task.ball_contacts()


def test_contacts_from_placed_ball_states(task: BeerPong) -> None:
    task.reset(CONTEXT)
    top, bottom = task.cup_sites()
    # Cup placed at the context: its axis is 0.134 m along −y of the body origin.
    np.testing.assert_allclose(top[:2], bottom[:2])
    np.testing.assert_allclose(bottom, [0.0, -1.7 - 0.1337249, 0.865], atol=1e-6)
    assert top[2] > bottom[2]
    r = 0.025
    # Resting on the cup floor: in the cup, no table contact.
    assert _place_ball(task, bottom + [0, 0, r - 1e-3]) == (True, False)
    # On the table, away from the cup.
    table_top = 0.4025 + 0.31 + 0.1
    assert _place_ball(task, np.array([0.3, -1.4, table_top + r - 1e-3])) == (False, True)
    # In the air above the cup: neither.
    assert _place_ball(task, top + [0, 0, 0.2]) == (False, False)


def test_reward_cases() -> None:
    d_top, d_bot, tau = 0.3, 0.5, 1234.0
    miss = -4 - d_top**2 - 0.5 * d_bot**2 - 1e-4 * tau  # cond. 1
    bounce = -2 - d_top**2 - 0.5 * d_bot**2 - 1e-4 * tau  # cond. 2
    cup = -(0.04**2) - 1.5e-4 * tau  # cond. 3, with the minus sign
    assert beer_pong_reward(False, False, d_top, d_bot, tau) == pytest.approx(miss)
    assert beer_pong_reward(False, True, d_top, d_bot, tau) == pytest.approx(bounce)
    assert beer_pong_reward(True, False, d_top, 0.04, tau) == pytest.approx(cup)
    assert beer_pong_reward(True, True, d_top, 0.04, tau) == pytest.approx(cup)
    assert cup > bounce > miss
    # More torque or a farther ball always costs.
    assert beer_pong_reward(True, False, 0, 0.04, 2 * tau) < cup
    assert beer_pong_reward(False, False, 0.4, d_bot, tau) < miss


@pytest.mark.parametrize(
    ("duration", "penalty"),
    [(0.05, -30 - 10 * 0.05**2), (-1.0, -30 - 10 * 1.1**2), (1.5, -30 - 10 * 0.2**2)],
)
def test_invalid_duration_not_simulated(task: BeerPong, duration: float, penalty: float) -> None:
    before = task.n_physics_steps
    r = task.evaluate(np.r_[duration, np.zeros(14)], CONTEXT, workers=0)
    assert r.returns[0] == pytest.approx(penalty)
    assert not r.executed[0] and not r.success[0] and r.n_executed == 0
    assert r.info["duration"][0] == duration and np.isnan(r.info["in_cup"][0])
    assert task.n_physics_steps == before


def test_joint_limit_violation_not_simulated(task: BeerPong) -> None:
    theta = np.r_[0.5, np.zeros(14)]
    theta[1 + 2 * 3 + 1] = -20.0  # elbow ends at 1.18 − 20·√0.02 < −0.9
    q, _ = desired_trajectory(theta)
    assert q[:, 3].min() < J_MIN[3]
    before = task.n_physics_steps
    r = task.evaluate(theta, CONTEXT, workers=0)
    assert r.returns[0] == -30.0 and not r.executed[0]
    assert task.n_physics_steps == before
    ok = task.evaluate(np.r_[0.5, np.zeros(14)], CONTEXT, workers=0)
    assert ok.executed[0] and task.n_physics_steps > before


def test_contexts(task: BeerPong) -> None:
    theta = np.r_[0.5, np.zeros(14)]
    with pytest.raises(ValueError, match="outside the task's context space"):
        task.evaluate(theta, [0.0, -1.0], workers=0)
    with pytest.raises(ValueError, match=r"shape \(n, 2\)"):
        task.evaluate(theta, [0.0, -1.5, 0.84], workers=0)
    with pytest.raises(ValueError, match="theta must have shape"):
        task.evaluate(np.zeros(14), CONTEXT, workers=0)
    r = task.evaluate(theta, [[0.5, -1.0]], workers=0, out_of_range="penalise")
    assert r.returns[0] == pytest.approx(-30 - (0.18**2 + 0.2**2)) and not r.executed[0]
    c = task.sample_contexts(500, np.random.default_rng(0))
    assert c.shape == (500, 2)
    assert np.all(c >= [-0.32, -2.2]) and np.all(c <= [0.32, -1.2])
    assert c[:, 0].min() < -0.25 and c[:, 1].max() > -1.3  # the whole box is used


def test_found_throw_lands_in_cup_random_theta_does_not(task: BeerPong) -> None:
    ep = task.episode(SUCCESS_THETA, CONTEXT)
    assert ep.executed and ep.success and ep.info["in_cup"] == 1.0
    assert ep.info["final_dist_bottom"] < 0.06 and ep.ret > -2.0
    assert ep.info["release_time"] == pytest.approx(0.645)
    rng = np.random.default_rng(1)
    theta = np.c_[rng.uniform(0.2, 1.2, 6), rng.normal(0, 1, (6, 14))]
    r = task.evaluate(theta, CONTEXT, workers=0)
    assert r.executed.all() and not r.success.any()
    assert np.all(r.returns < -2.0) and np.all(r.returns < ep.ret)


def test_one_step_env() -> None:
    from gymnasium.utils.env_checker import check_env

    env = EpisodicEnv(BeerPong, extra_steps=20)
    obs, _ = env.reset(seed=0, options={"context": CONTEXT})
    np.testing.assert_array_equal(obs, CONTEXT)
    _, ret, terminated, _, info = env.step(np.r_[0.5, np.zeros(14)])
    assert terminated and info["executed"] and np.isfinite(ret)
    check_env(env, skip_render_check=True)

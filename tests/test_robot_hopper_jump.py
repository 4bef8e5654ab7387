"""Hopper Jump (HJ, thesis 4.5.1 / B.4.2): layout, start state, reward, input checks and a
θ that jumps."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from vslbook.envs.robot.hopper_jump import (
    HopperJump,
    JumpRecord,
    first_recontact,
    is_healthy,
    jump_reward,
)
from vslbook.envs.robot.task import EpisodicEnv

CONTEXT = np.array([-0.25, -0.1, 0.4, 0.8])  # [q_thigh, q_leg, q_foot, goal_x]

# θ in mp_pytorch's layout (per joint [w_1, w_2, w_3, g]) for fancy-gym's ProDMP basis and
# timing (step t tracks q_d((t+1) dt)), found for CONTEXT offline (2026-11-26): least squares
# of all 12 entries so that the tracked K_p q_d + K_d q̇_d matches the previous θ's (found for
# the old t/τ-spaced basis, 1.56 m there), then a cross-entropy search of 15 generations × 20
# samples (5 elites, σ = 1 with floor 0.05, seed 0) maximising the torso height (−1 if the foot
# never touched down again); rounded to 3 decimals. Its max height is 1.8079 m.
JUMP_THETA = np.array(
    [0.743, 0.592, -0.242, 0.187, 6.486, 1.668, -0.948, 1.052, 4.139, -5.249, -0.331, -4.092]
)
START_HEIGHT = 1.5  # torso height at t = 0; every episode's h_max is at least ~1.4997


@pytest.fixture(scope="module")
def task() -> HopperJump:
    return HopperJump()


def test_layout_follows_the_thesis():
    assert HopperJump.context_names == ("q_thigh", "q_leg", "q_foot", "goal_x")
    np.testing.assert_array_equal(HopperJump.context_low, [-0.5, -0.2, 0.0, 0.3])
    np.testing.assert_array_equal(HopperJump.context_high, [0.0, 0.0, 0.785, 1.35])
    assert HopperJump.n_params == 12 and not HopperJump.has_success
    spec = HopperJump.spec
    assert (spec.n_dof, spec.n_basis, spec.tau, spec.alpha) == (3, 3, 0.8, 10.0)
    assert spec.tau_bounds is None and spec.goal == "learned"
    assert (spec.dt, spec.n_steps) == (0.008, 250)
    with pytest.raises(TypeError, match="takes no options"):
        HopperJump(sparse=False)


def test_start_state_and_goal(task):
    c = np.array([-0.4, -0.15, 0.7, 1.2])
    task.reset(c)
    m, d = task.model, task.data
    assert m.opt.timestep == 0.002
    np.testing.assert_allclose(d.qpos, [0, 1.5, 0, -0.4, -0.15, 0.7])
    np.testing.assert_array_equal(d.qvel, np.zeros(6))
    assert d.xipos[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "torso"), 2] == pytest.approx(1.5)
    goal = d.site_xpos[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, "goal_site")]
    np.testing.assert_allclose(goal, [1.2, 0, 0])


def test_first_recontact():
    f, t = False, True
    assert first_recontact([f, f, t, t, f, f, t, t]) == 6
    assert first_recontact([t, f, t]) == 2  # touching at the start counts as the first touch
    assert first_recontact([f, f, t, t, t]) is None  # never left the floor
    assert first_recontact([f, f, f]) is None  # never touched
    assert first_recontact([f, t, f, f]) is None  # left, never came back
    with pytest.raises(ValueError, match="1-D"):
        first_recontact(np.zeros((2, 2), dtype=bool))


def _record(n: int, goal_x: float, rng: np.random.Generator, contacts, qpos=None, qvel=None):
    heights = 1.2 + 0.3 * rng.random(n)
    foot = np.column_stack([rng.uniform(0, 1.5, n), np.zeros(n), rng.uniform(0, 0.5, n)])
    return JumpRecord(
        actions=rng.uniform(-1, 1, (n, 3)),
        heights=heights,
        foot=foot,
        contacts=np.asarray(contacts, dtype=bool),
        qpos=np.array([0.3, 1.0, 0.2, -0.3, -0.1, 0.2]) if qpos is None else np.asarray(qpos),
        qvel=np.full(6, 0.5) if qvel is None else np.asarray(qvel),
        goal=np.array([goal_x, 0.0, 0.0]),
    )


def test_reward_with_a_landing_after_the_jump():
    rng = np.random.default_rng(3)
    contacts = [0, 0, 1, 1, 0, 0, 0, 1, 0, 1]
    r = _record(10, 0.9, rng, contacts)
    ret, info = jump_reward(r)
    g = np.array([0.9, 0.0, 0.0])
    cost = 1e-3 * sum(float(a @ a) for a in r.actions)
    d_final = math.dist(r.foot[-1], g)
    d_contact = math.dist(r.foot[7], g)  # first touch after leaving the floor at step 4
    expected = 10 * max(r.heights) - 3 * d_final - 2 * d_contact + 2 - cost
    assert ret == pytest.approx(expected, rel=1e-12)
    assert info == pytest.approx(
        {
            "max_height": max(r.heights),
            "goal_distance": d_final,
            "contact_distance": d_contact,
            "healthy": 1.0,
        }
    )


def test_reward_without_a_landing_and_unhealthy():
    rng = np.random.default_rng(4)
    r = _record(6, 0.5, rng, [0, 1, 1, 1, 1, 1], qpos=[0, 0.45, 3.0, 0, 0, 0])
    ret, info = jump_reward(r)
    cost = 1e-3 * float(np.sum(r.actions**2))
    d_final = float(np.linalg.norm(r.foot[-1] - [0.5, 0, 0]))
    assert ret == pytest.approx(10 * r.heights.max() - 3 * d_final - 2 * 5 + 0 - cost)
    assert math.isnan(info["contact_distance"]) and info["healthy"] == 0.0
    with pytest.raises(ValueError, match="jump record"):
        jump_reward(
            JumpRecord(r.actions[:3], r.heights, r.foot, r.contacts, r.qpos, r.qvel, r.goal)
        )


def test_healthy_bounds():
    q, v = np.array([0, 0.5, 7.0, 0, 0, 0]), np.zeros(6)
    assert is_healthy(q, v)  # z = 0.5 is inside the thesis's [0.5, ∞]; the angle is unbounded
    assert not is_healthy(q - [0, 1e-9, 0, 0, 0, 0], v)
    assert is_healthy(q, np.full(6, 99.9))
    assert not is_healthy(q, [0, 0, 0, 100.0, 0, 0])
    assert is_healthy([1e6, 0.5, 0, 0, 0, 0], v)  # rootx is not part of the state check


def test_reward_from_placed_simulator_states(task):
    """Hopper standing with its heel exactly above the goal, then lying on the floor."""
    c = np.array([0.0, 0.0, 0.0, 1.0])
    task.reset(c)
    m, d = task.model, task.data
    site = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, "foot_site")
    torso = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "torso")
    d.qpos[:] = [0, 1.25, 0, 0, 0, 0]
    mujoco.mj_forward(m, d)
    d.qpos[0] = 1.0 - d.site_xpos[site, 0]  # slide the heel over the goal
    mujoco.mj_forward(m, d)
    heel, height = d.site_xpos[site].copy(), float(d.xipos[torso, 2])
    assert heel[0] == pytest.approx(1.0) and height == pytest.approx(1.25)
    n = 5
    stand = JumpRecord(
        np.zeros((n, 3)), np.full(n, height), np.tile(heel, (n, 1)),
        np.array([0, 1, 0, 1, 1], bool), d.qpos.copy(), d.qvel.copy(), np.array([1.0, 0, 0]),
    )  # fmt: skip
    ret, info = jump_reward(stand)
    assert info["goal_distance"] == pytest.approx(abs(heel[2]))
    assert ret == pytest.approx(10 * 1.25 - 3 * abs(heel[2]) - 2 * abs(heel[2]) + 2)
    d.qpos[1], d.qpos[2] = 0.1, -math.pi / 2  # lying flat: below the healthy height
    mujoco.mj_forward(m, d)
    assert not is_healthy(d.qpos, d.qvel)
    lying = JumpRecord(**{**stand.__dict__, "qpos": d.qpos.copy()})
    assert jump_reward(lying)[0] == pytest.approx(ret - 2)


def test_episodes_are_deterministic_and_consistent(task):
    theta = np.random.default_rng(0).normal(size=(2, 12))
    a = task.evaluate(theta, CONTEXT, workers=0)
    b = task.evaluate(theta, CONTEXT, workers=0)
    np.testing.assert_array_equal(a.returns, b.returns)
    for k in task.info_keys:
        np.testing.assert_array_equal(a.info[k], b.info[k])
    assert a.executed.all() and not a.success.any()
    record = task.simulate(theta[0], CONTEXT)
    assert jump_reward(record)[0] == a.returns[0]
    k = first_recontact(record.contacts)
    if k is not None:  # the foot touches the floor: the heel is within a foot's length of it
        assert record.foot[k, 2] < 0.195 + 0.06 + 0.1
    np.testing.assert_allclose(np.abs(record.actions).max(), 1.0)  # commands are clipped


@pytest.mark.slow
def test_a_worker_pool_gives_the_same_numbers():
    task = HopperJump()
    try:
        rng = np.random.default_rng(5)
        theta = rng.normal(size=(4, 12))
        contexts = task.sample_contexts(4, rng)
        a = task.evaluate(theta, contexts, workers=0)
        b = task.evaluate(theta, contexts, workers=2)
        np.testing.assert_array_equal(a.returns, b.returns)
        for k in task.info_keys:
            np.testing.assert_array_equal(a.info[k], b.info[k])
    finally:
        task.close()


def test_every_finite_theta_is_executed_and_bad_input_is_not_simulated():
    task = HopperJump()  # fresh: its simulator clock shows whether anything was stepped
    with pytest.raises(ValueError, match=r"theta must have shape \(n, 12\)"):
        task.evaluate(np.zeros(9), CONTEXT)
    with pytest.raises(ValueError, match="finite"):
        task.evaluate(np.full(12, np.nan), CONTEXT)
    with pytest.raises(ValueError, match=r"contexts must have shape \(n, 4\) \(q_thigh, q_leg"):
        task.evaluate(np.zeros(12), np.zeros(3))
    with pytest.raises(ValueError, match=r"outside the task's context space.*goal_x in \[0.3"):
        task.evaluate(np.zeros(12), [-0.25, -0.1, 0.4, 2.0])
    out = task.evaluate(np.zeros(12), [-0.25, -0.1, 0.4, 2.0], out_of_range="penalise")
    assert out.returns[0] == pytest.approx(-(0.65**2)) and not out.executed[0]
    assert task.data.time == 0.0
    huge = task.evaluate(np.full(12, 50.0), CONTEXT, workers=0)  # no invalid θ: τ is fixed
    assert huge.executed[0] and np.isfinite(huge.returns[0]) and task.data.time > 0


def test_sampled_contexts_fill_the_box(task):
    c = task.sample_contexts(400, np.random.default_rng(0))
    assert c.shape == (400, 4)
    assert np.all(c >= HopperJump.context_low) and np.all(c <= HopperJump.context_high)
    span = (c.max(0) - c.min(0)) / (HopperJump.context_high - HopperJump.context_low)
    assert np.all(span > 0.95)


def test_a_found_theta_jumps_higher_than_zero_and_random_theta(task):
    rng = np.random.default_rng(11)
    others = np.vstack([np.zeros(12), rng.normal(0, 1, (4, 12)), rng.normal(0, 2, (3, 12))])
    out = task.evaluate(np.vstack([JUMP_THETA, others]), CONTEXT, workers=0)
    h = out.info["max_height"]
    assert h[0] == pytest.approx(1.8079, abs=1e-3)
    assert h[0] > START_HEIGHT + 0.05  # the torso rose clearly above its start height
    assert np.all(h[1:] < START_HEIGHT + 1e-3)  # the others never beat their initial fall
    assert out.returns[0] > out.returns[1] + 5  # and it scores well above θ = 0
    assert not math.isnan(out.info["contact_distance"][0])  # it landed again


def test_one_step_gymnasium_wrapper(task):
    env = EpisodicEnv(task)
    obs, _ = env.reset(seed=0, options={"context": CONTEXT})
    np.testing.assert_array_equal(obs, CONTEXT)
    for theta in (np.zeros(12), JUMP_THETA):
        _, ret, terminated, truncated, info = env.step(theta)
        assert terminated and not truncated and info["executed"] and not info["success"]
        ep = task.episode(theta, CONTEXT)
        assert ret == ep.ret
        for k, v in ep.info.items():  # a number that does not apply (NaN) may be left out
            assert info[k] == v if not math.isnan(v) else math.isnan(info.get(k, math.nan))

"""The 5-link reachers: Chapter 4's 5LR and Chapter 3's Eqs. 3.8-3.10 variant (episodic + PPO)."""

import gymnasium as gym
import mujoco
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from scipy.optimize import least_squares

from vslbook.envs.robot.primitives import ProDMPSpec, promp_trajectory
from vslbook.envs.robot.reacher5 import (
    Q0_LEFT,
    Q0_RIGHT,
    Reacher5,
    Reacher5Ch3,
    ReacherSim,
    rewards_5lr,
    rewards_ch3,
    tip_position,
)
from vslbook.envs.robot.reacher5_step import Reacher5Ch3StepEnv


def ik(goal, q_init):
    """Joint angles whose tip is at ``goal`` (planar FK written out here, not the module's)."""

    def fk(q):
        phi = np.cumsum(q)
        lengths = [0.1, 0.1, 0.1, 0.1, 0.11]
        return np.array([np.dot(lengths, np.cos(phi)), np.dot(lengths, np.sin(phi))])

    q = least_squares(lambda q: np.r_[fk(q) - goal, 1e-2 * (q - q_init)], q_init).x
    return least_squares(lambda q: fk(q) - goal, q, xtol=1e-14, ftol=1e-14).x


def mj_tip(sim):
    mujoco.mj_kinematics(sim.model, sim.data)
    return sim.data.body("fingertip").xpos[:2].copy()


def test_counts_and_start_postures():
    assert Reacher5().n_params == 30  # default: the goal parameters are needed (docstring)
    assert Reacher5(goal_params=False).n_params == 25 and Reacher5(goal_params=True).n_params == 30
    assert Reacher5Ch3().n_params == 25 and Reacher5Ch3(mp="prodmp").n_params == 25
    sim = ReacherSim()
    sim.reset(Q0_RIGHT, np.array([0.1, 0.2]))
    np.testing.assert_allclose(mj_tip(sim), [0.51, 0.0], atol=1e-12)  # straight to the right
    np.testing.assert_allclose(sim.data.body("target").xpos[:2], [0.1, 0.2], atol=1e-12)
    sim.reset(Q0_LEFT, np.array([0.1, 0.2]))
    np.testing.assert_allclose(mj_tip(sim), [-0.51, 0.0], atol=1e-12)  # pointing left


def test_tip_position_matches_mujoco():
    sim = ReacherSim()
    rng = np.random.default_rng(0)
    for _ in range(5):
        q = rng.uniform(-3, 3, 5)
        sim.data.qpos[:5] = q
        np.testing.assert_allclose(tip_position(q), mj_tip(sim), atol=1e-12)


@pytest.mark.parametrize("goal_params", [False, True])
def test_5lr_trajectory_is_the_thesis_prodmp(goal_params):
    task = Reacher5(goal_params=goal_params)
    spec = ProDMPSpec(
        n_dof=5, n_basis=5, dt=0.02, duration=4.0, alpha=10.0, alpha_phase=3.0, tau=1.5,
        goal="relative" if goal_params else "disabled", weights_scale=0.3, goal_scale=0.3,
    )  # fmt: skip
    theta = np.random.default_rng(1).normal(size=(2, task.n_params))
    for th, ref in zip(theta, task.references(theta), strict=True):
        q, dq = spec.trajectory(th, np.zeros(5), np.zeros(5))
        np.testing.assert_allclose(ref, q[1:] + 0.1 * dq[1:], atol=1e-10)


def test_ch3_trajectory_is_a_promp_from_the_left_posture():
    task = Reacher5Ch3()
    th = np.random.default_rng(2).normal(size=25)
    q, dq = promp_trajectory(th.reshape(5, 5), 4.0, 0.02, Q0_LEFT)
    np.testing.assert_allclose(task.references(th[None])[0], q[1:] + 0.1 * dq[1:], atol=1e-10)


@pytest.mark.slow  # starting the worker processes takes ~10 s on a loaded machine
def test_deterministic_and_workers_agree():
    task = Reacher5(goal_params=False)
    rng = np.random.default_rng(3)
    th = rng.normal(size=(4, 25))
    c = task.sample_contexts(4, rng)
    a = task.evaluate(th, c, workers=1)
    b = task.evaluate(th, c, workers=1)
    np.testing.assert_array_equal(a.returns, b.returns)
    try:
        p = task.evaluate(th, c, workers=2)
    finally:
        task.close()
    np.testing.assert_array_equal(a.returns, p.returns)
    np.testing.assert_array_equal(a.info["tip_distance"], p.info["tip_distance"])
    assert len(set(a.returns.round(9))) == 4  # different θ, c give different returns


def test_5lr_reward_from_placed_state():
    sim = ReacherSim()
    goal = np.array([-0.2, 0.3])
    sim.reset(np.array([0.4, -0.3, 1.2, 0.0, 0.5]), goal)
    sim.data.qvel[:5] = [0.5, -1.0, 0.0, 2.0, 0.1]
    acts = np.full((200, 5), 0.1)
    acts[-1] = [1, -1, 0.5, 0, 0]
    r = rewards_5lr(acts, tip_position(sim.q), sim.dq, goal)
    d = np.linalg.norm(mj_tip(sim) - goal)
    assert r[0] == pytest.approx(-0.05)
    assert r[-1] == pytest.approx(-2.25 - 200 * d - 10 * (0.25 + 1 + 4 + 0.01))
    # at the goal, at rest: only the action cost is left.
    q = ik(goal, np.full(5, 0.5))
    sim.reset(q, goal)
    last = rewards_5lr(acts, tip_position(sim.q), sim.dq, goal)[-1]
    assert last == pytest.approx(-2.25, abs=1e-3)


def expected_ch3(reward, t, a, v, tip, g):
    """Eqs. 3.8-3.10 written out for one step."""
    dist = np.sqrt((tip[0] - g[0]) ** 2 + (tip[1] - g[1]) ** 2)
    a2, v2 = sum(x * x for x in a), sum(x * x for x in v)
    if reward == "3.8":
        return -dist - a2
    if reward == "3.9":
        return -a2 if t < 190 else -dist - a2
    return -a2 - v2 if t < 198 else -500 * dist - a2 - 1000 * v2


@pytest.mark.parametrize("reward", ["3.8", "3.9", "3.10"])
def test_ch3_rewards_on_a_hand_built_trajectory(reward):
    # states: the arm sweeps from the left posture towards the goal, slowing down.
    goal = np.array([0.2, -0.3])
    s = np.linspace(0, 1, 201)[1:, None]
    q = Q0_LEFT + s * (ik(goal, np.array([-2.0, 0.3, 0.3, 0.3, 0.3])) - Q0_LEFT)
    v = (1 - s) * np.array([1.0, -0.5, 0.2, 0.0, 0.3])
    acts = np.tile([0.2, -0.1, 0.0, 0.3, 0.05], (200, 1))
    r = rewards_ch3(reward, np.arange(200), acts, tip_position(q), v, goal)
    sim = ReacherSim()
    want = []
    for t in range(200):
        sim.data.qpos[:5] = q[t]
        want.append(expected_ch3(reward, t, acts[t], v[t], mj_tip(sim), goal))
    np.testing.assert_allclose(r, want, rtol=1e-12, atol=1e-12)
    assert r[-1] > -0.2  # the sweep ends at the goal, nearly at rest
    qs = np.vstack([Q0_LEFT, q])
    dqs = np.vstack([np.zeros(5), v])
    np.testing.assert_allclose(Reacher5Ch3(reward).step_rewards(acts, qs, dqs, goal), want)


@pytest.mark.parametrize(
    "task", [Reacher5(goal_params=False), Reacher5Ch3("3.10")], ids=["5LR", "ch3"]
)
def test_return_is_the_reward_of_the_simulated_states(task):
    th = 10 * np.random.default_rng(4).normal(size=task.n_params)  # large: the PD saturates
    goal = np.array([0.1, 0.3])
    acts, qs, dqs = task.rollout(th, goal)
    assert np.all(np.abs(acts) <= 1) and np.any(np.abs(acts) == 1)
    if isinstance(task, Reacher5):
        tip = qs[-1]
        d = np.linalg.norm(tip_position(tip) - goal)
        want = -np.sum(acts**2) - 200 * d - 10 * np.sum(dqs[-1] ** 2)
    else:
        tips = tip_position(qs[1:])
        want = sum(expected_ch3("3.10", t, acts[t], dqs[t + 1], tips[t], goal) for t in range(200))
    assert task.evaluate(th, goal, workers=1).returns[0] == pytest.approx(want, rel=1e-12)


def test_out_of_range_contexts_are_penalised_without_simulation():
    task = Reacher5(goal_params=False)
    r = task.evaluate(np.zeros((2, 25)), [[0.6, 0.0], [0.4, 0.4]], out_of_range="penalise")
    assert not r.executed.any() and r.n_executed == 0
    np.testing.assert_allclose(r.returns, [-(0.1**2), -((np.hypot(0.4, 0.4) - 0.5) ** 2)])
    assert task._sim is None  # the simulator was never built, let alone stepped


def test_ch3_out_of_range_goals_are_simulated_and_punished():
    """Chapter 3's reacher adds −k·d² to the simulated return (module docstring)."""
    rng = np.random.default_rng(0)
    theta = 0.3 * rng.standard_normal((4, 25))
    ctx = np.array([[-0.1, 0.2], [-0.3, 0.8], [0.4, 0.4], [0.2, 0.1]])
    d2 = np.array([0.01, 0.3**2 + 0.3**2, (np.hypot(0.4, 0.4) - 0.5) ** 2, 0.0])
    for reward, k in (("3.8", 1000), ("3.9", 1000), ("3.10", 50000)):
        ch3 = Reacher5Ch3(reward)
        r = ch3.evaluate(theta, ctx, out_of_range="penalise", workers=1)
        assert r.executed.all() and r.n_executed == 4
        plain = [ch3.episode(t, c).ret for t, c in zip(theta, ctx, strict=True)]
        np.testing.assert_allclose(r.returns, np.array(plain) - k * d2)
        with pytest.raises(ValueError, match="outside"):
            ch3.evaluate(theta, ctx, workers=1)


def test_bad_input_errors():
    task = Reacher5Ch3()
    with pytest.raises(ValueError, match="outside the task's context space"):
        task.evaluate(np.zeros(25), [-0.1, 0.0])  # the left half is not Chapter 3's space
    with pytest.raises(ValueError, match="outside"):
        Reacher5(goal_params=False).evaluate(
            np.zeros(25), [0.4, 0.4]
        )  # in the box, not in the disk
    with pytest.raises(ValueError, match=r"shape \(n, 2\)"):
        task.evaluate(np.zeros(25), [0.1, 0.0, 0.0])
    with pytest.raises(ValueError, match=r"theta must have shape"):
        task.evaluate(np.zeros(30), [0.1, 0.0])
    with pytest.raises(ValueError, match="reward must be one of"):
        Reacher5Ch3("3.11")
    with pytest.raises(ValueError, match="mp must be"):
        Reacher5Ch3(mp="dmp")
    with pytest.raises(TypeError, match="goal_params"):
        Reacher5(goal_params="yes")


def test_sampled_contexts_obey_the_rules():
    rng = np.random.default_rng(5)
    c = Reacher5(goal_params=False).sample_contexts(2000, rng)
    assert np.all(np.hypot(*c.T) <= 0.5)
    assert {(bool(x > 0), bool(y > 0)) for x, y in c} == {(a, b) for a in (0, 1) for b in (0, 1)}
    assert np.hypot(*c.T).max() > 0.49 and np.mean(np.hypot(*c.T) < 0.25) == pytest.approx(
        0.25, abs=0.04
    )  # uniform on the disk: a quarter of the area lies within half the radius
    c3 = Reacher5Ch3().sample_contexts(2000, rng)
    assert np.all(c3[:, 0] >= 0) and np.all(np.hypot(*c3.T) <= 0.5)
    assert c3[:, 1].min() < -0.45 and c3[:, 1].max() > 0.45


def test_constructed_solutions_score_far_better_than_random():
    rng = np.random.default_rng(6)
    # 5LR with the code's goal parameters: ProDMP goal = inverse kinematics, no weights.
    goal = np.array([-0.3, -0.2])
    task = Reacher5(goal_params=True)
    # mp_pytorch's layout: per joint [w_1 .. w_5, g]
    g = (ik(goal, np.full(5, -0.5)) - Q0_RIGHT) / 0.3
    th = np.column_stack([np.zeros((5, 5)), g]).ravel()
    good = task.evaluate(th, goal, workers=1)
    rand = task.evaluate(rng.normal(size=(8, 30)), goal, workers=1)
    assert good.info["tip_distance"][0] < 0.01 and good.returns[0] > -1
    assert rand.returns.max() < -50 and rand.info["tip_distance"].min() > 0.2
    # Chapter 3, Eq. 3.10: a slow ProMP (least squares on the affine map) to the IK posture.
    goal = np.array([0.2, -0.3])
    ch3 = Reacher5Ch3("3.10")
    q_goal = ik(goal, np.array([-2.0, 0.3, 0.3, 0.3, 0.3]))
    s = np.clip(np.arange(1, 201) * 0.02 / 3.0, 0, 1)[:, None]
    ramp = 10 * s**3 - 15 * s**4 + 6 * s**5  # minimum jerk, then hold
    dramp = (30 * s**2 - 60 * s**3 + 30 * s**4) / 3.0 * (s < 1)
    want = Q0_LEFT + ramp * (q_goal - Q0_LEFT) + 0.1 * dramp * (q_goal - Q0_LEFT)
    A = ch3._A.reshape(25, -1)
    th = np.linalg.lstsq(A.T, (want - ch3._b).reshape(-1), rcond=None)[0]
    good = ch3.evaluate(th, goal, workers=1)
    rand = ch3.evaluate(rng.normal(size=(8, 25)), goal, workers=1)
    assert good.info["tip_distance"][0] < 0.02
    assert good.returns[0] > 2 * rand.returns.max()  # returns are negative


@pytest.mark.slow
def test_5lr_thesis_parameters_quick_optimiser():
    """240 episodes of the cross-entropy method on the 25 thesis parameters, one goal."""
    task, goal = Reacher5(goal_params=False), np.array([0.35, 0.25])
    rng = np.random.default_rng(7)
    mu, sd = np.zeros(25), np.full(25, 3.0)
    for _ in range(10):
        th = mu + sd * rng.standard_normal((24, 25))
        elite = th[np.argsort(task.evaluate(th, goal, workers=1).returns)[-6:]]
        mu, sd = elite.mean(0), elite.std(0) + 0.05
    best = task.evaluate(mu, goal, workers=1)
    rand = task.evaluate(rng.normal(size=(8, 25)), goal, workers=1)
    still = -200 * np.hypot(0.51 - 0.35, 0.25)  # θ = 0: the arm stays straight
    assert task.evaluate(np.zeros(25), goal, workers=1).returns[0] == pytest.approx(still)
    # Without goal parameters the ProDMP returns towards its start posture once the forcing
    # has decayed (x = e^-8 at 4 s); with mp_pytorch's phase-space basis this short search
    # gets to 0.22 m (0.15 m was reached with the former t/τ-spaced basis).
    assert best.info["tip_distance"][0] < 0.25 and best.returns[0] > still + 10
    assert best.returns[0] > rand.returns.max() + 10


@pytest.mark.parametrize("reward", ["3.8", "3.10"])
def test_step_env_passes_check_env(reward):
    env = Reacher5Ch3StepEnv(reward=reward)
    check_env(env, skip_render_check=True)
    obs, _ = env.reset(seed=0)
    assert obs.shape == ((19,) if reward == "3.8" else (20,))


def test_step_env_registered_id_and_seeded_goals():
    from vslbook.envs.robot import STEP_IDS

    if "vslbook/Reacher5Ch3Step-v0" not in STEP_IDS:
        gym.register("vslbook/Reacher5Ch3Step-v0", entry_point=Reacher5Ch3StepEnv)
    env = gym.make("vslbook/Reacher5Ch3Step-v0", reward="3.9")
    g1 = [env.reset(seed=s)[1]["goal"] for s in range(20)]
    g2 = [env.reset(seed=s)[1]["goal"] for s in range(20)]
    np.testing.assert_array_equal(g1, g2)
    g = np.array(g1)
    assert len({tuple(x) for x in g}) == 20
    assert np.all(g[:, 0] >= 0) and np.all(np.hypot(*g.T) <= 0.5)
    env.close()


def test_step_env_replays_the_episodic_rollout():
    """Feeding the episodic rollout's commands gives the same states, rewards and return."""
    task, env = Reacher5Ch3("3.9"), Reacher5Ch3StepEnv(reward="3.9")
    th = np.random.default_rng(8).normal(size=25)
    goal = np.array([0.3, 0.2])
    acts, qs, dqs = task.rollout(th, goal)
    obs, _ = env.reset(options={"goal": goal})
    np.testing.assert_allclose(obs[:5], np.cos(Q0_LEFT))
    assert obs[-1] == 0.0
    total, truncated = 0.0, False
    for t in range(200):
        assert not truncated
        obs, r, terminated, truncated, info = env.step(acts[t])
        total += r
        assert not terminated
    assert truncated and obs[-1] == 1.0
    np.testing.assert_allclose(obs[17:19] + obs[10:12], tip_position(qs[-1]), atol=1e-12)
    np.testing.assert_allclose(obs[10:12], goal)
    np.testing.assert_allclose(obs[12:17], dqs[-1])
    assert total == pytest.approx(task.evaluate(th, goal, workers=1).returns[0], rel=1e-12)
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(5))
    with pytest.raises(ValueError, match="outside"):
        env.reset(options={"goal": [-0.2, 0.0]})

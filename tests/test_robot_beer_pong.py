"""Beer Pong (thesis Section 3.4, Appendix A.3.2): layout, determinism, reward cases from
placed ball states, validity checks before simulation, contexts, a throw into the cup, a ball
that bounces off the cup's floor and out, and the simulation loop (MuJoCo's PD actuators) held
to a plain per-step loop of the control law, under both readings of the reward."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from vslbook.envs.robot.assets import load_model
from vslbook.envs.robot.beer_pong import (
    CUP_Z,
    D_GAINS,
    DT,
    J_MAX,
    J_MIN,
    MODEL,
    MODEL_PATCHES,
    P_GAINS,
    Q0,
    BeerPong,
    desired_trajectory,
    use_pd_actuators,
)
from vslbook.envs.robot.beer_pong_reward import REWARD_VARIANTS, beer_pong_reward
from vslbook.envs.robot.primitives import promp_trajectory
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


# The geoms whose contact with the ball separates A.3.2's cond. 2 from cond. 1 in the authors'
# code (its table-top, wall and cup lists, written out by name) and in the thesis's text.
CODE_CONTACT_NAMES = {
    "table_contact_geom", "wall", "cup_base_table", "cup_base_table_contact",
    *(f"cup_geom_table{i}" for i in (3, 4, 5, 6, 7, 8, 9, 10, 15, 16, 17)), "cup_geom1_table8",
}  # fmt: skip
THESIS_CONTACT_NAMES = {"table", "table_contact_geom"}


@pytest.fixture(scope="module")
def task() -> BeerPong:
    t = BeerPong()
    yield t
    t.close()


@pytest.fixture(scope="module")
def thesis_task() -> BeerPong:
    t = BeerPong(reward="thesis")
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


def test_reward_variants_and_contact_geoms(task: BeerPong, thesis_task: BeerPong) -> None:
    assert task.reward == "code" and REWARD_VARIANTS == ("code", "thesis")
    names = {task.model.geom(int(g)).name for g in task.contact_geoms}
    assert names == CODE_CONTACT_NAMES  # every collision geom of the cup, the table top, wall
    names = {thesis_task.model.geom(int(g)).name for g in thesis_task.contact_geoms}
    assert names == THESIS_CONTACT_NAMES
    with pytest.raises(ValueError, match=r"reward must be one of 'code', 'thesis', got 'final'"):
        BeerPong(reward="final")
    from vslbook.envs.robot import make_task

    t = make_task("beer-pong", reward="thesis")
    assert t.reward == "thesis"
    t.close()


def test_contacts_from_placed_ball_states(task: BeerPong, thesis_task: BeerPong) -> None:
    task.reset(CONTEXT)
    top, bottom = task.cup_sites()
    # Cup placed at the context: its axis is 0.134 m along −y of the body origin.
    np.testing.assert_allclose(top[:2], bottom[:2])
    np.testing.assert_allclose(bottom, [0.0, -1.7 - 0.1337249, 0.865], atol=1e-6)
    assert top[2] > bottom[2]
    r = 0.025
    table_top = 0.4025 + 0.31 + 0.1
    # (in the cup, contact) under the authors' code / under the thesis's text
    cases = [
        (bottom + [0, 0, r - 1e-3], (True, True), (True, False)),  # on the cup floor
        (np.array([0.3, -1.4, table_top + r - 1e-3]), (False, True), (False, True)),  # table
        (np.array([0.0, -2.41 + r - 1e-3, 1.5]), (False, True), (False, False)),  # the wall
        (np.array([0.0, -1.729, 0.92]), (False, True), (False, False)),  # the cup's outside
        (top + [0, 0, 0.2], (False, False), (False, False)),  # in the air above the cup
    ]
    for pos, code, thesis in cases:
        assert _place_ball(task, pos) == code, pos
        assert _place_ball(thesis_task, pos) == thesis, pos


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


# -- the simulation loop against a plain reference ---------------------------------------------
# Two θ whose ball bounces off the table (found by sampling θ ~ [U(0.3, 1), N(0, 2²)], rounded,
# on random contexts until the task reported table contact; the ball leaves the table again).
TABLE_CASES = [
    (
        [0.34, -1.09, 1.45, 0.91, -0.56, -1.33, -0.11, 2.65, 0.7, 1.28, -0.3, -2.58, -1.42, 1.3,
         0.21],
        [-0.01, -1.95],
    ),
    (
        [0.99, 2.52, 2.96, 1.62, -0.3, 0.52, 1.24, -3.15, 2.49, -0.64, 0.53, 0.28, 1.82, 2.14,
         4.43],
        [0.03, -1.73],
    ),
]  # fmt: skip


def _plain_episode(
    m: mujoco.MjModel, d: mujoco.MjData, theta, context, extra_steps=500, reward="code",
    placed=None,
):  # fmt: skip
    """The task's episode written as a plain per-step loop of the original law, on a model
    loaded as the task loads it but with its own motors left as they are (ctrl = 0: unused).

    Each step k: mj_step1 → while k ≤ n pin the ball to the hand site (position and linear
    velocity; ``placed``: at k = n put the ball at the given position and velocity instead)
    → u = K_p (q_d − q) + K_d (q̇_d − q̇) + qfrc_bias into qfrc_applied (after the release
    q_d(l) with q̇_d = 0) → mj_step2. The contact list of step k's state (recomputed after
    the pin) gives the geoms the ball touches. ``reward="code"`` (the authors' SVSL code): in
    the cup if the ball touched the cup floor in the state of any step but the last, contact
    with the table top, the wall or the cup likewise, success: on the cup floor in the last
    step's state. ``"thesis"``: in the cup and success: on the cup floor at the end; contact:
    with the table after release or at the end.
    """
    theta, context = np.asarray(theta, dtype=float), np.asarray(context, dtype=float)
    hand = m.site("init_ball_pos").id
    ball = m.geom("ball_geom").id
    names = CODE_CONTACT_NAMES if reward == "code" else THESIS_CONTACT_NAMES
    counted = {m.geom(name).id for name in names}
    floor = m.geom("cup_base_table_contact").id
    side = mujoco.MjData(m)  # the contacts of a pinned state

    def touched(data: mujoco.MjData) -> set[int]:  # geoms the ball touches
        pairs = [tuple(g) for g in data.contact.geom[: data.ncon]]
        return {b if a == ball else a for a, b in pairs if ball in (a, b)}

    mujoco.mj_resetData(m, d)
    m.body_pos[m.body("cup_table").id] = (context[0], context[1], CUP_Z)
    d.qpos[:7] = Q0
    mujoco.mj_forward(m, d)
    d.qpos[7:10] = d.site_xpos[hand]
    mujoco.mj_forward(m, d)
    top = d.site_xpos[m.site("cup_goal_table").id].copy()
    bottom = d.site_xpos[m.site("cup_goal_final_table").id].copy()
    n = round(theta[0] / DT)
    w = np.zeros((7, 4))
    w[:, 2:] = theta[1:].reshape(7, 2) * math.sqrt(0.02)
    q_d, dq_d = promp_trajectory(w, n * DT, DT, Q0, width=0.1)
    balls, torques, steps_touched = [], [], []
    for k in range(n + extra_steps):
        mujoco.mj_step1(m, d)
        if k <= n:
            if placed is not None and k == n:
                d.qpos[7:10], d.qvel[7:10] = placed
            else:
                d.qpos[7:10] = d.site_xpos[hand]
                v = np.zeros(6)
                mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_SITE, hand, v, 0)
                d.qvel[7:10] = v[3:]
            side.qpos[:] = d.qpos
            mujoco.mj_fwdPosition(m, side)
            steps_touched.append(touched(side))
        else:
            steps_touched.append(touched(d))
        balls.append(d.qpos[7:10].copy())
        target, target_vel = (q_d[k], dq_d[k]) if k < n else (q_d[n], np.zeros(7))
        u = P_GAINS * (target - d.qpos[:7]) + D_GAINS * (target_vel - d.qvel[:7])
        u = u + d.qfrc_bias[:7]
        d.qfrc_applied[:7] = u
        torques.append(u)
        mujoco.mj_step2(m, d)
    mujoco.mj_forward(m, d)
    balls.append(d.qpos[7:10].copy())
    final = touched(d)
    if reward == "code":
        in_cup = any(floor in t for t in steps_touched[:-1])
        contact = any(t & counted for t in steps_touched[:-1])
        success = floor in steps_touched[-1]
    else:
        in_cup = success = floor in final
        contact = any(t & counted for t in steps_touched[n + 1 :]) or bool(final & counted)
    balls, torques = np.array(balls), np.array(torques)
    min_top = min(float(np.linalg.norm(b - top)) for b in balls)
    end_bottom = float(np.linalg.norm(balls[-1] - bottom))
    torque_cost = float(np.sum(torques**2)) / len(torques)
    if in_cup:
        ret = -(end_bottom**2) - 1.5e-4 * torque_cost
    else:
        ret = (-2.0 if contact else -4.0) - min_top**2 - 0.5 * end_bottom**2
        ret -= 1e-4 * torque_cost
    return {
        "ret": ret, "in_cup": in_cup, "success": success, "table_contact": contact,
        "min_dist_top": min_top, "final_dist_bottom": end_bottom, "torque_cost": torque_cost,
        "balls": balls, "torques": torques,
    }  # fmt: skip


@pytest.fixture(scope="module")
def plain_sim() -> tuple[mujoco.MjModel, mujoco.MjData]:
    m = load_model(MODEL, MODEL_PATCHES)  # a fresh model: its own motors, untouched
    return m, mujoco.MjData(m)


@pytest.mark.parametrize("reward", REWARD_VARIANTS)
def test_episodes_match_the_plain_loop(task: BeerPong, thesis_task: BeerPong, plain_sim, reward):
    task = task if reward == "code" else thesis_task
    rng = np.random.default_rng(7)
    random_cases = [
        (np.r_[rng.uniform(0.3, 1.0), rng.normal(0, 1.5, 14)], task.sample_contexts(1, rng)[0])
        for _ in range(4)
    ]
    cases = [(SUCCESS_THETA, CONTEXT), *TABLE_CASES, *random_cases]
    theta = np.array([c[0] for c in cases], dtype=float)
    contexts = np.array([c[1] for c in cases], dtype=float)
    r = task.evaluate(theta, contexts, workers=0)
    assert r.executed.all()
    # both kinds of ending are covered: in the cup, and off the table. The second table
    # case's ball hits the table's front face below its top geom: contact for the thesis's
    # "table", none for the authors' code (it counts the top geom ``table_contact_geom`` only).
    assert r.success[0] and r.info["table_contact"][1] == 1.0
    assert r.info["table_contact"][2] == (1.0 if reward == "thesis" else 0.0)
    for i, (th, c) in enumerate(cases):
        ref = _plain_episode(*plain_sim, th, c, reward=reward)
        # MuJoCo's actuators sum the same law in another order: the results agree to rounding
        # (up to ~3e-10 relative seen), not bit for bit
        assert r.returns[i] == pytest.approx(ref["ret"], rel=1e-7), i
        assert r.success[i] == ref["success"] and r.info["in_cup"][i] == float(ref["in_cup"]), i
        assert r.info["table_contact"][i] == float(ref["table_contact"]), i
        for key in ("min_dist_top", "final_dist_bottom", "torque_cost"):
            assert r.info[key][i] == pytest.approx(ref[key], rel=1e-7), (i, key)
    # the last episode's recorded ball and torque paths, step by step
    np.testing.assert_allclose(task.ball_path, ref["balls"], rtol=0, atol=1e-7)
    scale = np.abs(ref["torques"]).max()
    np.testing.assert_allclose(task.torque_path, ref["torques"], rtol=1e-7, atol=1e-9 * scale)


# A ball dropped into the cup by hand at the release of a short, nearly still movement: from
# 6 cm above the floor's centre site and 3 cm off the axis towards −x, at (2.5, 0, −6) m/s.
# It hits the cup's floor, bounces off it, leaves the cup, lands on the table and falls off it.
BOUNCE_THETA = np.r_[0.1, np.zeros(14)]
BOUNCE_OFFSET, BOUNCE_VEL = np.array([-0.03, 0.0, 0.06]), np.array([2.5, 0.0, -6.0])


def test_ball_bouncing_off_the_cup_floor_and_out(task: BeerPong, thesis_task, plain_sim):
    task.reset(CONTEXT)
    top, bottom = task.cup_sites()
    placed = (bottom + BOUNCE_OFFSET, BOUNCE_VEL)
    ep = task.episode_with_ball(BOUNCE_THETA, CONTEXT, *placed)
    balls, torques = task.ball_path.copy(), task.torque_path.copy()
    assert ep.executed and len(balls) == 20 + 500 + 1
    # the ball left the cup: it ends > 0.4 m off the cup's axis, below the table's top
    end = balls[-1]
    assert np.hypot(*(end - bottom)[:2]) > 0.4 and end[2] < 0.4025 + 0.31 + 0.1
    # A.3.2 with the authors' in-cup test: cond. 3 since the ball touched the floor, by hand
    # from the recorded path and torques
    d_bottom = float(np.sqrt(np.sum((end - bottom) ** 2)))
    tau = float(np.mean(np.sum(torques**2, axis=1)))
    want = -(d_bottom**2) - 1.5e-4 * tau
    assert ep.info["in_cup"] == 1.0 and not ep.success  # touched the floor, not in at the end
    assert ep.ret == pytest.approx(want, rel=1e-9)
    assert ep.ret == pytest.approx(-0.71, abs=0.01)
    # the thesis's reading: not in the cup at the end, table contact: cond. 2
    ept = thesis_task.episode_with_ball(BOUNCE_THETA, CONTEXT, *placed)
    np.testing.assert_array_equal(thesis_task.ball_path, balls)
    d_top = float(np.min(np.sqrt(np.sum((balls - top) ** 2, axis=1))))
    want_thesis = -2.0 - d_top**2 - 0.5 * d_bottom**2 - 1e-4 * tau
    assert ept.info["in_cup"] == 0.0 and ept.info["table_contact"] == 1.0 and not ept.success
    assert ept.ret == pytest.approx(want_thesis, rel=1e-9)
    assert ept.ret == pytest.approx(-2.37, abs=0.01)
    # the plain loop agrees, under both readings
    for e, reward in ((ep, "code"), (ept, "thesis")):
        ref = _plain_episode(*plain_sim, BOUNCE_THETA, CONTEXT, reward=reward, placed=placed)
        assert e.ret == pytest.approx(ref["ret"], rel=1e-7), reward
        assert (e.success, e.info["in_cup"]) == (ref["success"], float(ref["in_cup"])), reward
    # a bad ball state is refused, naming it
    with pytest.raises(ValueError, match="ball_vel must be 3 finite numbers"):
        task.episode_with_ball(BOUNCE_THETA, CONTEXT, bottom, [0.0, np.nan, 0.0])


def test_trajectory_is_the_promp_of_the_package() -> None:
    rng = np.random.default_rng(2)
    for duration in (0.1, 0.37, 0.645, 1.3):
        theta = np.r_[duration, rng.normal(0, 2, 14)]
        w = np.zeros((7, 4))
        w[:, 2:] = theta[1:].reshape(7, 2) * math.sqrt(0.02)
        n = round(duration / 0.005)
        expected = promp_trajectory(w, n * 0.005, 0.005, Q0, width=0.1)
        for got, want in zip(desired_trajectory(theta), expected, strict=True):
            np.testing.assert_array_equal(got, want)  # the cached ProMP: the same numbers


def test_pd_actuators_give_the_feedback_part_of_the_law() -> None:
    m = load_model(MODEL, MODEL_PATCHES)
    use_pd_actuators(m)
    d = mujoco.MjData(m)
    rng = np.random.default_rng(0)
    d.qpos[:7] = Q0 + rng.normal(0, 0.3, 7)
    d.qvel[:7] = rng.normal(0, 2, 7)
    d.qvel[7:] = rng.normal(0, 2, 3)
    d.ctrl[:] = rng.normal(0, 500, 7)  # far outside the motors' old range [−1, 1]: not clipped
    mujoco.mj_forward(m, d)
    want = d.ctrl - P_GAINS * d.qpos[:7] - D_GAINS * d.qvel[:7]
    np.testing.assert_allclose(d.actuator_force, want, rtol=1e-13, atol=1e-10)
    np.testing.assert_allclose(d.qfrc_actuator[:7], d.actuator_force, rtol=1e-13)  # gear 1
    assert not d.qfrc_actuator[7:].any()  # nothing on the ball
    # integrators that treat actuator damping implicitly would change the law: refused
    m2 = load_model(MODEL, MODEL_PATCHES)
    m2.opt.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    with pytest.raises(RuntimeError, match="would change the PD law"):
        use_pd_actuators(m2)


def test_torque_path_is_what_mj_step2_applied(task: BeerPong, monkeypatch) -> None:
    real_step2, applied = mujoco.mj_step2, []

    def step2(m, d):
        real_step2(m, d)
        # after mj_step2 the actuator force and qfrc_applied still are those of the step
        applied.append(d.actuator_force + d.qfrc_applied[:7])

    monkeypatch.setattr(mujoco, "mj_step2", step2)
    ep = task.episode(SUCCESS_THETA, CONTEXT)
    assert ep.executed and len(applied) == len(task.torque_path) == 129 + 500
    # the loop evaluates the actuator force after the fact as MuJoCo does (bit for bit where
    # neither uses fused multiply-adds)
    np.testing.assert_allclose(task.torque_path, np.array(applied), rtol=1e-12, atol=1e-9)
    assert ep.info["torque_cost"] == pytest.approx(np.sum(np.square(applied)) / 629, rel=1e-12)


def test_path_is_the_recorded_ball_path(task: BeerPong) -> None:
    path = task.path(SUCCESS_THETA, CONTEXT)["ball"]
    np.testing.assert_array_equal(path, task.ball_path)
    assert path.shape == (129 + 500 + 1, 3)


@pytest.mark.parametrize(
    ("array", "step"),
    [("qpos", 40), ("qpos", 300), ("qvel", 300), ("qpos", 600)],  # pinned, flying, last step
)
def test_non_finite_state_is_unstable(task: BeerPong, monkeypatch, array, step) -> None:
    theta = np.r_[0.5, np.zeros(14)]  # n = 100 steps, 600 in all
    assert task.episode(theta, CONTEXT).ret > -30.0
    real_step2, calls = mujoco.mj_step2, [0]

    def step2(m, d):
        real_step2(m, d)
        calls[0] += 1
        if calls[0] == step:
            getattr(d, array)[3] = np.nan  # MuJoCo resets the data at the next mj_step1

    monkeypatch.setattr(mujoco, "mj_step2", step2)
    before, path_before = task.n_physics_steps, task.ball_path
    ep = task.episode(theta, CONTEXT)
    assert ep.ret == -30.0 and ep.executed and not ep.success
    assert ep.info == {"duration": 0.5, "release_time": 0.5}
    assert task.n_physics_steps == before + 600 and calls[0] == 600
    assert task.ball_path is path_before  # left as the last stable episode's

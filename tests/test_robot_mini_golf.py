"""Robot Mini Golf (thesis Section 4.5.1, Appendix B.4.4)."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from vslbook.envs.robot.mini_golf import (
    D_GAINS,
    HORIZON,
    P_GAINS,
    Q0,
    TORQUE_MAX,
    MiniGolf,
    Trace,
    final_reward,
    invalid_penalty,
    step_cost,
)
from vslbook.envs.robot.task import EpisodicEnv

CTX = np.array([0.3, -0.5, 0.44, 0.55])  # obstacle far left, goal gap centred at x = 0.55
# A ball placed just touching the club head's lower edge (the robot holds q0): its first
# contact is a hit; pushed by hand towards (aim, -0.7) at 1.6 m/s.
BALL_AT_CLUB = np.array([0.44, 0.6095, 0.0063])
# A θ whose swing sends the ball through the goal gap. Found by a cross-entropy search
# (population 40, 8 elites, θ ~ N([τ 1.0, w 0], diag([0.3, 1.5, ..., 1.5]²)), numpy seed 0)
# for the ball at x = 0.44 and the moving obstacle at (0.3, -0.5), scoring a hit whose ball
# reaches y = -0.66 at x ∈ [0.27, 0.58]: the ball's path up to the goal line does not depend
# on x_goal, so x_goal was then put where the ball crosses the line (0.5233, rounded to
# 0.525). The first population of 40 already held it. Rounded to 6 decimals.
CTX_PASS = np.array([0.3, -0.5, 0.44, 0.525])
THETA_PASS = np.array([
    1.412648, -0.697413, -0.47867, -0.48046, -0.748003, -1.721859, -0.212927, 1.487021,
    1.3175, -1.251709, 1.06103, 0.174545, -1.68043, -1.602168, -2.241059, -1.492407,
    0.136616, -0.712911, 0.804888, 0.305455, 0.527284, -0.997824, -0.844455, -0.389246,
    0.016353, -0.862963, 0.924912, 0.947544, 0.27086,
])  # fmt: skip
Q_MAX = np.array([2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973])
Q_MIN = np.array([-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973])


@pytest.fixture(scope="module")
def task() -> MiniGolf:
    return MiniGolf()


def _still() -> tuple[np.ndarray, np.ndarray]:
    return np.repeat(Q0[None], HORIZON + 1, axis=0), np.zeros((HORIZON + 1, 7))


def _push(task: MiniGolf, start: np.ndarray, aim: float, speed: float = 1.6):
    v = np.array([aim, -0.7]) - start[:2]
    v = speed * v / np.linalg.norm(v)
    return task.simulate(*_still(), CTX, ball_pos=start, ball_vel=[v[0], v[1], 0.0])


def _costs(torque: np.ndarray) -> float:
    return -0.0005 * float(np.sum(torque[:99] ** 2))


def test_layout(task: MiniGolf) -> None:
    assert task.n_params == 29 and task.context_dim == 4
    assert task.context_names == ("x_obstacle", "y_obstacle", "x_ball", "x_goal")
    assert task.mp.tau_bounds == (0.45, 1.7) and task.mp.n_basis == 4
    m = task.model
    assert m.opt.timestep == pytest.approx(0.002)
    assert mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "box_0") == -1
    assert m.nq == 9 + 7 and m.nmocap == 2  # arm + fingers + ball; obstacle, goal
    with pytest.raises(ValueError, match="reward"):
        MiniGolf(reward="dense")
    with pytest.raises(ValueError, match=r"theta must have shape \(29,\)"):
        task.episode(np.zeros(28), CTX)


def test_scene_bodies_and_geoms(task: MiniGolf) -> None:
    c = np.array([0.37, -0.23, 0.52, 0.31])
    task.reset(c)
    m, d = task.model, task.data
    ball = m.geom("ball_contact")
    assert ball.size[0] == pytest.approx(0.025)
    assert m.body_mass[m.body("ball").id] == pytest.approx(0.05)
    np.testing.assert_allclose(ball.friction, [0.1, 0.1, 0.1])
    assert ball.priority[0] == 1 and ball.condim[0] == 4
    np.testing.assert_allclose(ball.solref, [0.1, 0.03])
    np.testing.assert_allclose(d.xpos[m.body("ball").id], [0.52, 0.5, 0.005])
    np.testing.assert_allclose(d.qpos[:7], Q0)
    for name, x in (("side_wall_left", 0.15), ("side_wall_right", 0.7)):
        np.testing.assert_allclose(d.geom(name).xpos, [x, -0.05, 0.025], atol=1e-12)
        np.testing.assert_allclose(m.geom(name).size, [0.005, 0.65, 0.08])
    np.testing.assert_allclose(d.geom("static_obstacle_geom").xpos, [0.425, -0.0625, 0.0])
    np.testing.assert_allclose(m.geom("static_obstacle_geom").size, [0.02, 0.02, 0.1])
    obs = m.body("obstacle").id
    assert m.body_mocapid[obs] >= 0
    np.testing.assert_allclose(d.geom("obstacle_geom").xpos, [0.37, -0.23, 0.0])
    np.testing.assert_allclose(m.geom("obstacle_geom").size, [0.03, 0.03, 0.1])
    for name in ("goal_wall_left", "goal_wall_right"):
        np.testing.assert_allclose(m.geom(name).size, [0.4, 0.005, 0.08])
        assert d.geom(name).xpos[1] == pytest.approx(-0.7)
    np.testing.assert_allclose(d.site("ball_target").xpos, [0.31, -0.7, 0.005], atol=1e-12)
    # the club: a 1.5 cm rod with a head, the rod tip at the head
    assert m.geom("rod_contact").size[0] == pytest.approx(0.015)
    np.testing.assert_allclose(m.geom("rod_contact2").size, [0.03, 0.02, 0.015])
    np.testing.assert_allclose(m.site("rod_tip").pos, [0, 0, 0.225])
    tip, head = d.site("rod_tip").xpos, d.geom("rod_contact2").xpos
    assert abs(tip[1] - 0.65) < 0.01 and tip[2] == pytest.approx(0.035, abs=0.002)
    assert np.linalg.norm(head - tip) == pytest.approx(0.015, abs=1e-6)


@pytest.mark.parametrize("x_goal", [0.25, 0.43, 0.6])
def test_goal_gap_is_5_6_cm_centred_at_goal(task: MiniGolf, x_goal: float) -> None:
    task.reset(np.array([0.45, -0.3, 0.4, x_goal]))
    m, d = task.model, task.data
    left, right = d.geom("goal_wall_left"), d.geom("goal_wall_right")
    inner_left = left.xpos[0] + m.geom("goal_wall_left").size[0]
    inner_right = right.xpos[0] - m.geom("goal_wall_right").size[0]
    assert inner_right - inner_left == pytest.approx(0.056, abs=1e-12)
    assert (inner_left + inner_right) / 2 == pytest.approx(x_goal, abs=1e-12)
    # the walls reach past both side walls: the gap is the only way through
    assert left.xpos[0] - 0.4 < 0.15 and right.xpos[0] + 0.4 > 0.7


def test_context_sampler_ranges(task: MiniGolf) -> None:
    c = task.sample_contexts(3000, np.random.default_rng(0))
    # the authors' box (x_goal in [0.18, 0.67]); B.4.4's with settings="thesis" below
    lo, hi = np.array([0.3, -0.5, 0.25, 0.18]), np.array([0.6, -0.1, 0.6, 0.67])
    assert np.all((c >= lo) & (c <= hi))
    np.testing.assert_array_less(c.min(axis=0), lo + 0.01)
    np.testing.assert_array_less(hi - 0.01, c.max(axis=0))
    # uniform: the means sit mid-range (4 standard errors)
    se = (hi - lo) / math.sqrt(12 * 3000)
    np.testing.assert_array_less(np.abs(c.mean(axis=0) - (lo + hi) / 2), 4 * se)
    again = task.sample_contexts(3000, np.random.default_rng(0))
    np.testing.assert_array_equal(c, again)
    # the authors' wider goal range is outside the thesis's context space
    thesis = MiniGolf(settings="thesis")
    assert thesis.reward == "thesis" and MiniGolf(settings="thesis", reward="code").reward == "code"
    np.testing.assert_array_equal(thesis.context_low, [0.3, -0.5, 0.25, 0.25])
    np.testing.assert_array_equal(thesis.context_high, [0.6, -0.1, 0.6, 0.6])
    assert task.context_valid(np.array([0.4, -0.3, 0.4, 0.65]))
    with pytest.raises(ValueError, match="outside the task's context space"):
        thesis.evaluate(np.zeros(29), [0.4, -0.3, 0.4, 0.65], workers=0)
    thesis.close()
    with pytest.raises(ValueError, match=r"settings must be one of \('code', 'thesis'\), got 'x'"):
        MiniGolf(settings="x")


def test_invalid_theta_penalised_not_simulated(task: MiniGolf) -> None:
    steps = task.physics_steps
    th = np.zeros(29)
    th[0] = 2.0  # τ 0.3 above its bound; zero weights keep q_d = q0
    r = task.evaluate(th, CTX, workers=0)
    assert not r.executed[0] and not r.success[0] and r.n_rejected == 1
    assert r.returns[0] == pytest.approx(-20 * 3 * 0.3 - 5)
    assert math.isnan(r.info["hit"][0])
    th[0] = 0.3
    assert task.evaluate(th, CTX, workers=0).returns[0] == pytest.approx(-20 * 3 * 0.15 - 5)
    th = np.zeros(29)
    th[0] = 1.0
    th[1 + 3 * 4 : 1 + 4 * 4] = 60.0  # joint 4 pushed above its upper limit (-0.0698)
    q_d, _ = task.mp.trajectory(th, Q0)
    q_d = q_d[1:]  # row 0 is the start; control step k tracks row k + 1
    hi = float(np.mean(np.maximum(q_d - Q_MAX, 0.0)))
    lo = float(np.mean(np.maximum(Q_MIN - q_d, 0.0)))
    assert hi > 0
    assert invalid_penalty(th, q_d) == pytest.approx(-20 * (hi + lo) - 5)
    r = task.evaluate(th, CTX, workers=0)
    assert not r.executed[0] and r.returns[0] == pytest.approx(-20 * (hi + lo) - 5)
    assert task.physics_steps == steps
    # τ on its bounds is valid and simulated
    th = np.zeros(29)
    for tau in (0.45, 1.7):
        th[0] = tau
        assert invalid_penalty(th, task.mp.trajectory(th, Q0)[0]) == 0.0
    r = task.evaluate(th, CTX, workers=0)
    assert r.executed[0] and task.physics_steps == steps + 1000
    free = MiniGolf(joint_limit_check=False)
    th[0] = 2.0
    assert free.evaluate(th, CTX, workers=0).executed[0] and free.physics_steps == 1000


def test_ball_through_the_gap_after_a_hit_succeeds(task: MiniGolf) -> None:
    tr = _push(task, BALL_AT_CLUB, aim=0.563)
    assert tr.hit and tr.passed and not tr.unstable and tr.steps == HORIZON
    np.testing.assert_allclose(tr.ball[0, :2], BALL_AT_CLUB[:2], atol=0.01)
    crossing = np.flatnonzero(tr.ball[:, 1] < -0.7)[0]
    assert abs(tr.ball[crossing, 0] - 0.55) < 0.028 - 0.025 + 0.005  # inside the gap
    assert np.any(tr.ball[:, 1] - 0.025 < -0.75)
    assert task.trace_return(tr) == pytest.approx(_costs(tr.torque) + 6.0, rel=1e-12)


def test_ball_aimed_at_a_wall_does_not_pass(task: MiniGolf) -> None:
    tr = _push(task, BALL_AT_CLUB, aim=0.65)
    assert tr.hit and not tr.passed
    assert tr.ball[:, 1].min() > -0.725  # bounced off the goal wall
    # third case, computed from the recorded ball positions by hand: the authors' code
    # (the default) ...
    goal = np.array([0.55, -0.7, 0.005])
    d_goal = np.min(np.sqrt(np.sum((tr.ball - goal) ** 2, axis=1)))
    y_min = tr.ball[:, 1].min()
    expected = 2 - 2 * math.tanh(d_goal) + 0.5 * (1 - math.tanh(y_min + 0.75))
    assert task.reward == "code"
    assert task.trace_return(tr) == pytest.approx(_costs(tr.torque) + expected, rel=1e-12)
    # ... and B.4.4's printed form
    thesis = MiniGolf(reward="thesis")
    tr_thesis = _push(thesis, BALL_AT_CLUB, aim=0.65)
    np.testing.assert_array_equal(tr_thesis.ball, tr.ball)
    expected_thesis = 2 - 2 * math.tanh(d_goal) - math.tanh(abs(y_min + 0.75))
    assert thesis.trace_return(tr_thesis) == pytest.approx(
        _costs(tr.torque) + expected_thesis, rel=1e-12
    )


def _resting_trace(hit: bool, tip_y: float = 0.65) -> Trace:
    """A whole episode with the ball resting at its start (0.44, 0.5, 0.005), the robot still
    (no torque) and the club tip at (0.44, tip_y, 0.005), goal at (0.55, −0.7, 0.005)."""
    n = HORIZON * 10
    return Trace(
        ball=np.tile([0.44, 0.5, 0.005], (n, 1)), rod_tip=np.tile([0.44, tip_y, 0.005], (n, 1)),
        torque=np.zeros((HORIZON, 7)), goal=np.array([0.55, -0.7, 0.005]), hit=hit,
        passed=False, unstable=False, steps=HORIZON,
    )  # fmt: skip


def test_touched_ball_that_stays_put_ranks_above_a_miss_only_under_the_code_reward() -> None:
    code, thesis = MiniGolf(), MiniGolf(reward="thesis")
    assert code.reward == "code"
    touched, missed = _resting_trace(hit=True), _resting_trace(hit=False)
    # B.4.4's cases 2 and 3 with the numbers of these traces, by hand: ‖p_b − p_g‖ =
    # √(0.11² + 1.2²), y_b + 0.75 = 1.25, club 0.15 m from the ball
    d_goal = math.sqrt(0.11**2 + 1.2**2)
    miss = 0.2 - 0.2 * math.tanh(0.15)  # 0.1702
    hit_code = 2 - 2 * math.tanh(d_goal) + 0.5 * (1 - math.tanh(1.25))  # 0.4055
    hit_thesis = 2 - 2 * math.tanh(d_goal) - math.tanh(1.25)  # −0.5186
    assert (miss, hit_code, hit_thesis) == pytest.approx((0.17022, 0.40549, -0.51865), abs=5e-5)
    assert code.trace_return(touched) == pytest.approx(hit_code, rel=1e-12)
    assert thesis.trace_return(touched) == pytest.approx(hit_thesis, rel=1e-12)
    for t in (code, thesis):  # a miss scores the same under both
        assert t.trace_return(missed) == pytest.approx(miss, rel=1e-12)
    assert code.trace_return(touched) > miss > thesis.trace_return(touched)
    # The same in the simulator: the still robot's club head grazes a ball placed against it
    # at y = 0.60815 (a hit that moves the ball < 1 mm; 0.05 mm farther from the club head
    # there is no contact, 0.05 mm deeper the contact pushes it 1 cm) vs the ball at its
    # start (a miss).
    ball = np.array([0.44, 0.60815, 0.0063])
    tr = code.simulate(*_still(), CTX, ball_pos=ball, ball_vel=[0.0, 0.0, 0.0])
    assert tr.hit and not tr.passed and np.abs(tr.ball - ball).max() < 1e-3
    d_goal = np.min(np.linalg.norm(tr.ball - [0.55, -0.7, 0.005], axis=1))
    y_min = tr.ball[:, 1].min()
    want_code = 2 - 2 * math.tanh(d_goal) + 0.5 * (1 - math.tanh(y_min + 0.75))
    want_thesis = 2 - 2 * math.tanh(d_goal) - math.tanh(abs(y_min + 0.75))
    got_code, got_thesis = code.trace_return(tr), thesis.trace_return(tr)
    assert got_code == pytest.approx(_costs(tr.torque) + want_code, rel=1e-12)
    assert got_thesis == pytest.approx(_costs(tr.torque) + want_thesis, rel=1e-12)
    tr_miss = code.simulate(*_still(), CTX)
    assert not tr_miss.hit
    d_tip = np.min(np.linalg.norm(tr_miss.ball - tr_miss.rod_tip, axis=1))
    got_miss = code.trace_return(tr_miss)
    assert got_miss == pytest.approx(_costs(tr_miss.torque) + 0.2 - 0.2 * math.tanh(d_tip))
    assert got_code > got_miss > got_thesis
    assert (got_code, got_miss, got_thesis) == pytest.approx((0.33, 0.17, -0.61), abs=0.01)


def test_unknown_reward_is_rejected() -> None:
    with pytest.raises(ValueError, match=r"reward must be one of 'code', 'thesis', got 'dense'"):
        MiniGolf(reward="dense")
    from vslbook.envs.robot import make_task

    assert make_task("mini-golf", reward="thesis").reward == "thesis"
    assert make_task("mini-golf").reward == "code"


def test_ball_through_the_gap_without_a_hit_is_no_success(task: MiniGolf) -> None:
    start = np.array([0.44, 0.55, 0.0063])  # 2 cm in front of the club: never touched
    tr = _push(task, start, aim=0.55)
    assert not tr.hit and not tr.passed
    assert tr.ball[:, 1].min() < -0.8  # it did roll through the gap
    d_tip = np.min(np.sqrt(np.sum((tr.ball - tr.rod_tip) ** 2, axis=1)))
    assert 0.05 < d_tip < 0.15
    expected = 0.2 - 0.2 * math.tanh(d_tip)
    assert task.trace_return(tr) == pytest.approx(_costs(tr.torque) + expected, rel=1e-12)


def test_reward_terms_by_hand() -> None:
    assert step_cost(np.array([1.0, -2.0, 0, 0, 0, 0, 3.0])) == pytest.approx(-0.0005 * 14)
    assert final_reward(False, False, 0.5, 9.0, 9.0) == pytest.approx(0.2 - 0.2 * math.tanh(0.5))
    assert final_reward(False, True, 0.0, 9.0, 9.0) == pytest.approx(0.2)  # no hit, no bonus
    assert final_reward(True, False, 9.0, 0.3, -0.6) == pytest.approx(  # the code's, default
        2 - 2 * math.tanh(0.3) + 0.5 - 0.5 * math.tanh(0.15)
    )
    assert final_reward(True, False, 9.0, 0.3, -0.6, "thesis") == pytest.approx(
        2 - 2 * math.tanh(0.3) - math.tanh(0.15)
    )
    # below the threshold the code's term exceeds 0.5 (no absolute value), the thesis's not
    assert final_reward(True, False, 9.0, 0.3, -0.8) == pytest.approx(
        2 - 2 * math.tanh(0.3) + 0.5 + 0.5 * math.tanh(0.05)
    )
    assert final_reward(True, False, 9.0, 0.3, -0.8, "thesis") == pytest.approx(
        2 - 2 * math.tanh(0.3) - math.tanh(0.05)
    )
    assert final_reward(True, True, 9.0, 9.0, 9.0) == 6.0
    with pytest.raises(ValueError, match="variant"):
        final_reward(True, True, 0, 0, 0, "dense")


def test_still_robot_episode(task: MiniGolf) -> None:
    th = np.zeros(29)
    th[0] = 1.0
    r = task.evaluate(th, CTX, workers=0)
    assert r.executed[0] and not r.success[0]
    assert r.info["hit"][0] == 0.0 and r.info["min_ball_y"][0] == pytest.approx(0.5, abs=1e-3)
    # club head 15 cm behind the ball; the robot holds still, so the costs are tiny
    d_tip = r.info["min_rod_ball_dist"][0]
    assert 0.12 < d_tip < 0.18
    assert r.returns[0] == pytest.approx(0.2 - 0.2 * math.tanh(d_tip), abs=1e-3)


def test_pd_tracks_a_ramp(task: MiniGolf) -> None:
    # joints 1 and 4 ramp by 0.3 and 0.2 rad over the 2 s (ball out of the way at x = 0.25)
    s = np.linspace(0.0, 1.0, HORIZON + 1)
    q_d = Q0 + np.outer(s, [0.3, 0, 0, 0.2, 0, 0, 0])
    dq_d = np.tile([0.15, 0, 0, 0.1, 0, 0, 0], (HORIZON + 1, 1))
    tr = task.simulate(q_d, dq_d, np.array([0.3, -0.5, 0.25, 0.55]))
    assert not tr.unstable and tr.steps == HORIZON
    np.testing.assert_allclose(task.data.qpos[:7], q_d[-1], atol=0.03)


def test_evaluate_is_deterministic(task: MiniGolf) -> None:
    rng = np.random.default_rng(11)
    c = task.sample_contexts(2, rng)
    th = np.concatenate([rng.uniform(0.5, 1.6, (2, 1)), 0.5 * rng.normal(size=(2, 28))], axis=1)
    a = task.evaluate(th, c, workers=0)
    b = MiniGolf().evaluate(th, c, workers=0)
    assert a.executed.all()
    np.testing.assert_array_equal(a.returns, b.returns)
    for k in task.info_keys:
        np.testing.assert_array_equal(a.info[k], b.info[k])


@pytest.mark.slow
def test_workers_match_in_process(task: MiniGolf) -> None:
    rng = np.random.default_rng(5)
    c = task.sample_contexts(3, rng)
    th = np.concatenate([rng.uniform(0.5, 1.6, (3, 1)), 0.5 * rng.normal(size=(3, 28))], axis=1)
    a = task.evaluate(th, c, workers=0)
    try:
        w = task.evaluate(th, c, workers=2)
    finally:
        task.close()
    np.testing.assert_array_equal(a.returns, w.returns)
    np.testing.assert_array_equal(a.success, w.success)


def test_one_step_env_passes_check_env() -> None:
    from gymnasium.utils.env_checker import check_env

    env = EpisodicEnv(MiniGolf)
    check_env(env, skip_render_check=True)
    env.reset(seed=0, options={"context": CTX})
    th = np.zeros(29)
    th[0] = 2.0
    _, r, term, trunc, info = env.step(th)
    assert term and not trunc and not info["executed"] and r == pytest.approx(-23.0)


def test_found_theta_succeeds(task: MiniGolf) -> None:
    r = task.evaluate(THETA_PASS, CTX_PASS, workers=0)
    assert r.executed[0] and r.success[0]
    assert r.info["hit"][0] == 1.0 and r.info["passed"][0] == 1.0
    # the ball went through the gap, close to its centre (x_goal, -0.7, 0.005) ...
    assert r.info["min_ball_goal_dist"][0] < 0.028 and r.info["min_ball_y"][0] < -0.75
    # ... and the return is the passed-case 6 plus the (negative) step costs
    assert 2.0 < r.returns[0] < 6.0
    # the same swing with the gap moved 5 cm aside hits a goal wall
    for x_goal in (CTX_PASS[3] - 0.05, CTX_PASS[3] + 0.05):
        miss = task.evaluate(THETA_PASS, [*CTX_PASS[:3], x_goal], workers=0)
        assert miss.info["hit"][0] == 1.0 and not miss.success[0]


def test_found_theta_survives_a_small_perturbation(task: MiniGolf) -> None:
    rng = np.random.default_rng(0)
    th = THETA_PASS + 1e-3 * rng.standard_normal((2, 29))
    r = task.evaluate(th, CTX_PASS, workers=0)
    assert r.executed.all() and np.all(np.isfinite(r.returns))
    assert r.success.all()  # the pass is not a knife-edge of θ


# -- the substep loop against the plain reading of the events -----------------------------
def _plain_simulate(task: MiniGolf, q_d: np.ndarray, dq_d: np.ndarray, context: np.ndarray):
    """One episode the plain way: after every substep the breakdown tests, the hit
    (``_club_contact``), passed and the positions, in the order of the module docstring.
    Returns the trace's fields, the physics steps, the path and the substep of the hit."""
    m, d = task.model, task.data
    task.reset(context)
    ball_id, tip_id = m.body("ball").id, m.site("rod_tip").id
    start = d.xpos[ball_id].copy(), d.site_xpos[tip_id].copy()
    points, balls, tips, torques = [start], [], [], []
    hit = passed = broken = False
    steps, hit_at = 0, None
    for t in range(HORIZON):
        a = P_GAINS * (q_d[t + 1] - d.qpos[:7]) + D_GAINS * (dq_d[t + 1] - d.qvel[:7])
        torque = 10.0 * np.clip(a, -1.0, 1.0)
        torques.append(torque)
        d.ctrl[:] = np.clip(torque + d.qfrc_bias[:7], -TORQUE_MAX, TORQUE_MAX)
        for _ in range(10):
            mujoco.mj_step(m, d)
            steps += 1
            bad = d.warning[mujoco.mjtWarning.mjWARN_BADQACC].number > 0
            if bad or not np.all(np.isfinite(d.qpos)):
                broken = True
                break
            if not hit:
                hit = task._club_contact()
                hit_at = len(balls) if hit else None
            elif not passed:
                passed = bool(d.xpos[ball_id][1] - 0.025 < -0.75)
            balls.append(d.xpos[ball_id].copy())
            tips.append(d.site_xpos[tip_id].copy())
        if broken:
            break
        points.append((d.xpos[ball_id].copy(), d.site_xpos[tip_id].copy()))
    fields = {
        "ball": np.array(balls or [start[0]]), "rod_tip": np.array(tips or [start[1]]),
        "torque": np.array(torques), "hit": hit, "passed": passed and not broken,
        "unstable": broken, "steps": t + 1,
    }  # fmt: skip
    return fields, steps, points, hit_at


def _same_as_plain(task: MiniGolf, theta: np.ndarray, context: np.ndarray):
    q_d, dq_d = task.mp.trajectory(theta, Q0)
    want, want_steps, want_points, hit_at = _plain_simulate(task, q_d, dq_d, context)
    before = task.physics_steps
    got = task.simulate(q_d, dq_d, context)
    assert task.physics_steps - before == want_steps
    for k, v in want.items():
        np.testing.assert_array_equal(getattr(got, k), v, err_msg=k)
    path = task.path(theta, context)
    np.testing.assert_array_equal(path["ball"], [p[0] for p in want_points])
    np.testing.assert_array_equal(path["club"], [p[1] for p in want_points])
    return got, hit_at


def test_simulate_matches_the_plain_loop(task: MiniGolf) -> None:
    passed, hit_at = _same_as_plain(task, THETA_PASS, CTX_PASS)
    assert passed.hit and passed.passed and hit_at is not None
    wall, _ = _same_as_plain(task, THETA_PASS, [*CTX_PASS[:3], CTX_PASS[3] + 0.05])
    assert wall.hit and not wall.passed
    rng = np.random.default_rng(4)
    c = task.sample_contexts(2, rng)
    for ctx in c:
        th = np.r_[rng.uniform(0.5, 1.6), 0.3 * rng.normal(size=28)]
        _same_as_plain(task, th, ctx)
    # with a ten times longer physics step MuJoCo diverges in mid-episode
    coarse = MiniGolf(joint_limit_check=False)
    coarse.model.opt.timestep = 0.02
    broke = [_same_as_plain(coarse, np.r_[0.5, 2.0 * rng.normal(size=28)], ctx)[0] for ctx in c]
    assert any(tr.unstable for tr in broke)


@pytest.mark.parametrize("when", ["first", "before_hit", "after_hit"])
def test_non_finite_state_ends_the_episode_where_it_appeared(task: MiniGolf, when, monkeypatch):
    """A NaN put into qpos after one physics step (and taken out before the next, so that
    the swing goes on as before) ends the episode at that substep: the positions, the hit
    and passed are those of the substeps before it."""
    q_d, dq_d = task.mp.trajectory(THETA_PASS, Q0)
    hit_at = _plain_simulate(task, q_d, dq_d, CTX_PASS)[3]
    at = {"first": 0, "before_hit": hit_at - 3, "after_hit": hit_at + 40}[when]
    real, calls, kept = mujoco.mj_step, [0], [0.0]

    def step(m, d, nstep: int = 1) -> None:
        for _ in range(nstep):
            if calls[0] == at + 1:
                d.qpos[2] = kept[0]
            real(m, d)
            if calls[0] == at:
                kept[0], d.qpos[2] = d.qpos[2], np.nan
            calls[0] += 1

    monkeypatch.setattr(mujoco, "mj_step", step)
    calls[0] = 0
    want, want_steps, want_points, _ = _plain_simulate(task, q_d, dq_d, CTX_PASS)
    calls[0] = 0
    before = task.physics_steps
    got = task.simulate(q_d, dq_d, CTX_PASS)
    assert task.physics_steps - before == want_steps == at + 1
    for k, v in want.items():
        np.testing.assert_array_equal(getattr(got, k), v, err_msg=k)
    assert got.unstable and not got.passed and got.hit == (when == "after_hit")
    assert len(got.ball) == max(at, 1) and got.steps == at // 10 + 1
    calls[0] = 0
    path = task.path(THETA_PASS, CTX_PASS)
    np.testing.assert_array_equal(path["ball"], [p[0] for p in want_points])
    assert task.trace_return(got) == pytest.approx(_costs(got.torque[:-1]) - 50.0, rel=1e-12)

"""Box Pushing with Obstacle (thesis Section 4.5.1, Appendix B.4.2.1; the authors'
BoxPushingObstacleTemporalSparse by default, ``settings="code"``)."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from vslbook.envs.robot import make_task
from vslbook.envs.robot.box_pushing import (
    BOX_START,
    Q0,
    BoxPushingObstacle,
    goal_quat,
    is_success,
    prodmp_spec,
    step_reward,
    unstable,
)
from vslbook.envs.robot.examples import EXAMPLES, THESIS_EXAMPLES
from vslbook.envs.robot.primitives import joint_limit_excess
from vslbook.envs.robot.task import EpisodicEnv

# A context with the obstacle beside the straight path from the start to the goal, and a θ
# (thesis settings, 28 parameters) built by IK along that path (least-squares fit of the
# ProDMP weights) and polished by a few dozen evaluations of a cross-entropy search;
# refitted (2026-11-26) to fancy-gym's ProDMP basis by least squares of the weights on the
# tracked K_p q_d + K_d q̇_d of the previous θ (which missed by 0.12 m under the new basis);
# it succeeds (0.012 m, 0.25 rad). THETA_CODE: the same θ in the code's 35-parameter layout,
# each joint's goal g_j = q0_j / 0.3 (what the disabled goal uses), rounded to 1e-6.
THETA_OK, CTX = THESIS_EXAMPLES["box-pushing-obstacle"].arrays()
THETA_CODE, _CTX_CODE = EXAMPLES["box-pushing-obstacle"].arrays()
assert np.array_equal(CTX, _CTX_CODE)


def _with_start_goal(theta28: np.ndarray) -> np.ndarray:
    """A 28-parameter θ (goal disabled) in the code's 35-parameter layout, per joint
    [w_1 … w_4, g] with the goal at the start posture: 0.3 g_j = q0_j."""
    return np.concatenate([theta28.reshape(7, 4), (Q0 / 0.3)[:, None]], axis=1).reshape(-1)


@pytest.fixture(scope="module")
def task() -> BoxPushingObstacle:
    """The default: the authors' environment (settings="code")."""
    return BoxPushingObstacle()


@pytest.fixture(scope="module")
def thesis() -> BoxPushingObstacle:
    """B.4.2.1's text (settings="thesis")."""
    return BoxPushingObstacle(settings="thesis")


def _lim(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    q_max = np.array([2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973])
    q_min = np.array([-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973])
    return q_min, q_max


def test_layout_and_options(task: BoxPushingObstacle, thesis: BoxPushingObstacle) -> None:
    # the code: 7 joints × (4 weights + 1 goal); B.4.2.1: 7 × 4
    assert task.n_params == 35 and task.context_dim == 5
    assert thesis.n_params == 28
    assert (task.settings, task.mp.goal, task.reward, task.distance_rule) == (
        "code",
        "learned",
        "code",
        "y",
    )
    assert (thesis.settings, thesis.mp.goal, thesis.reward, thesis.distance_rule) == (
        "thesis",
        "disabled",
        "thesis",
        "euclidean",
    )
    assert task.joint_limit_check is False and thesis.joint_limit_check is True
    assert make_task("box-pushing-obstacle").n_params == 35
    assert make_task("box-pushing-obstacle", settings="thesis").n_params == 28
    # an explicit option wins over the settings
    assert BoxPushingObstacle(goal="disabled").n_params == 28
    assert BoxPushingObstacle(settings="thesis", goal="learned").n_params == 35
    mixed = BoxPushingObstacle(settings="thesis", reward="code", distance_rule="y",
                               joint_limit_check=False)  # fmt: skip
    assert (mixed.reward, mixed.distance_rule, mixed.joint_limit_check, mixed.n_params) == (
        "code",
        "y",
        False,
        28,
    )
    with pytest.raises(ValueError, match="goal"):
        BoxPushingObstacle(goal="relative")
    with pytest.raises(ValueError, match="theta must have shape"):
        task.evaluate(np.zeros(28), CTX, workers=0)
    with pytest.raises(ValueError, match="theta must have shape"):
        thesis.evaluate(np.zeros(35), CTX, workers=0)
    assert task.model.opt.timestep == pytest.approx(0.002)
    # the code's layout is mp_pytorch's: per joint [w_1 ... w_4, g], absolute goal 0.3 g
    spec = prodmp_spec("learned")
    assert (spec.weights_scale, spec.goal_scale, spec.goal) == (0.3, 0.3, "learned")
    _, _, w, g = spec.split(np.arange(35.0))
    np.testing.assert_array_equal(w[1], [5, 6, 7, 8])
    np.testing.assert_array_equal(g, [4, 9, 14, 19, 24, 29, 34])


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"settings": "paper"}, "settings"),
        ({"settings": None}, "settings"),
        ({"reward": "otto"}, "reward"),
        ({"distance_rule": "manhattan"}, "distance_rule"),
        ({"joint_limit_check": 1}, "joint_limit_check"),
    ],
)
def test_unknown_settings_and_options_raise(kwargs: dict, name: str) -> None:
    with pytest.raises(ValueError, match=name) as err:
        BoxPushingObstacle(**kwargs)
    value = next(iter(kwargs.values()))
    assert repr(value) in str(err.value)
    if name == "settings":  # the message names the choices
        assert "'code'" in str(err.value) and "'thesis'" in str(err.value)
    with pytest.raises(ValueError, match="settings"):
        make_task("box-pushing-obstacle", settings="Code")
    with pytest.raises(TypeError, match="obstacle"):
        BoxPushingObstacle(obstacle="no")


def test_obstacle_goal_and_box_placed_from_context(task: BoxPushingObstacle) -> None:
    c = np.array([0.45, -0.5, 1.0, 0.33, -0.12])
    task.reset(c)
    m, d = task.model, task.data
    obs = m.body("obstacle").id
    np.testing.assert_allclose(d.xpos[obs], [0.33, -0.12, -0.01])
    base = m.geom("obstacle_base")
    assert base.bodyid[0] == obs and m.body_mocapid[obs] >= 0
    np.testing.assert_allclose(base.size, [0.05, 0.05, 0.01])
    assert base.priority[0] == 1
    np.testing.assert_allclose(base.friction, [0.3, 0.001, 0.0001])
    walls = [m.geom(f"obstacle_wall{i}") for i in range(4)]
    assert all(w.bodyid[0] == obs and w.size[2] == pytest.approx(0.045) for w in walls)
    tgt = m.body("replan_target_pos").id
    np.testing.assert_allclose(d.xpos[tgt], [0.45, -0.5, -0.01])
    np.testing.assert_allclose(d.xquat[tgt], [math.cos(0.5), 0, 0, math.sin(0.5)], atol=1e-12)
    np.testing.assert_allclose(d.xpos[m.body("box_0").id], BOX_START)
    np.testing.assert_allclose(d.qpos[:7], Q0)
    # the obstacle collides with the box: put the box on it and look for a contact pair
    adr = m.jnt_qposadr[m.joint("box_joint").id]
    d.qpos[adr : adr + 2] = [0.33 + 0.09, -0.12]
    mujoco.mj_forward(m, d)
    box, geoms = m.body("box_0").id, {int(base.id)} | {int(w.id) for w in walls}
    pairs = {(int(d.contact[i].geom1), int(d.contact[i].geom2)) for i in range(d.ncon)}
    assert any(
        (m.geom_bodyid[a] == box and b in geoms) or (m.geom_bodyid[b] == box and a in geoms)
        for a, b in pairs
    )


def _rules(c: np.ndarray) -> np.ndarray:
    """B.4.2.1's rules, Euclidean distances."""
    g, o, s = c[:, :2], c[:, 3:], np.array([0.4, 0.3])
    return (
        (np.hypot(*(g - s).T) > 0.3)
        & (np.hypot(*(o - s).T) >= 0.15)
        & (np.hypot(*(o - g).T) >= 0.15)
        & (c[:, 1] < c[:, 4])
    )


def _code_rules(c: np.ndarray) -> np.ndarray:
    """The authors' reset_model: cond_1 ... cond_5 with the box start (0.4, 0.3)."""
    g, y_o = c[:, :2], c[:, 4]
    return (
        (np.hypot(*(g - [0.4, 0.3]).T) > 0.3)
        & (y_o < 0.3)
        & (np.abs(y_o - 0.3) >= 0.15)
        & (y_o > g[:, 1])
        & (np.abs(y_o - g[:, 1]) >= 0.15)
    )


def test_sampled_contexts_obey_rules(task: BoxPushingObstacle, thesis: BoxPushingObstacle) -> None:
    lo, hi = [0.3, -0.7, 0, 0.3, -0.3], [0.6, 0.45, 2 * math.pi, 0.6, 0.15]
    raw = np.random.default_rng(4).uniform(lo, hi, (4000, 5))
    for t, rules in ((thesis, _rules), (task, _code_rules)):
        c = t.sample_contexts(500, np.random.default_rng(3))
        assert np.all((c >= lo) & (c <= hi))
        assert rules(c).all()
        np.testing.assert_array_equal(t.context_valid(raw), rules(raw))
        assert t.context_valid(CTX[None])[0]
    # each rule rejects on its own (Euclidean distance, as in the thesis)
    for bad in (
        [0.45, 0.05, 1.0, 0.3, 0.15],  # goal 0.255 m from the start
        [0.4, -0.3, 1.0, 0.5, -0.2],  # obstacle 0.141 m from the goal (|dy| = 0.1)
        [0.35, -0.2, 1.0, 0.5, -0.25],  # obstacle not between (y_o < y_g)
    ):
        assert not thesis.context_valid(np.array([bad]))[0], bad
        assert not task.context_valid(np.array([bad]))[0], bad
    # |o - start| >= 0.15 is implied by the box (y_o <= 0.15 = 0.3 - 0.15): never binds
    assert np.all(np.hypot(raw[:, 3] - 0.4, raw[:, 4] - 0.3) >= 0.15)
    # |o - start| >= 0.15 is implied by the box (y_o <= 0.15 = 0.3 - 0.15), so it never binds
    assert np.all(np.hypot(raw[:, 3] - 0.4, raw[:, 4] - 0.3) >= 0.15)


def test_distance_rules_differ_where_y_and_euclidean_distances_do(
    task: BoxPushingObstacle, thesis: BoxPushingObstacle
) -> None:
    """|Δy| <= ‖Δ‖: the code's y-rule is the stricter one. An obstacle 0.206 m from the goal
    but only 0.05 m from it in y: B.4.2.1 accepts it, the code rejects it. Nothing the
    y-rule accepts is rejected by the Euclidean rule."""
    beside = np.array([[0.35, -0.3, 1.0, 0.55, -0.25]])
    assert math.hypot(0.55 - 0.35, -0.25 + 0.3) >= 0.15 > abs(-0.25 + 0.3)
    assert thesis.context_valid(beside)[0] and not task.context_valid(beside)[0]
    # the switch alone decides: the code's settings with the Euclidean rule accept it
    assert BoxPushingObstacle(distance_rule="euclidean").context_valid(beside)[0]
    assert not BoxPushingObstacle(settings="thesis", distance_rule="y").context_valid(beside)[0]
    with pytest.raises(ValueError, match=r"\|y_obstacle - y_goal\| >= 0.15"):
        task.evaluate(THETA_CODE, beside[0], workers=0)
    raw = np.random.default_rng(9).uniform(task.context_low, task.context_high, (20000, 5))
    code_ok, thesis_ok = task.context_valid(raw), thesis.context_valid(raw)
    assert not np.any(code_ok & ~thesis_ok)  # y-rule ⊂ Euclidean rule
    assert np.any(thesis_ok & ~code_ok)
    c = task.sample_contexts(300, np.random.default_rng(1))
    assert np.all(np.abs(c[:, 4] - c[:, 1]) >= 0.15)


@pytest.mark.parametrize("settings", ["code", "thesis"])
def test_bad_contexts_give_clear_errors(settings: str) -> None:
    task = BoxPushingObstacle(settings=settings)
    th = np.zeros(task.n_params)
    with pytest.raises(ValueError, match=r"shape \(n, 5\)"):
        task.evaluate(th, np.zeros(4), workers=0)
    with pytest.raises(ValueError, match="outside the task's context space"):
        task.evaluate(th, [0.45, 0.05, 1.0, 0.55, 0.15], workers=0)
    with pytest.raises(ValueError, match="y_goal < y_obstacle"):
        task.evaluate(th, [0.9, -0.2, 1.0, 0.5, 0.0], workers=0)
    steps = task.physics_steps
    r = task.evaluate(th, [0.9, -0.2, 1.0, 0.5, 0.0], workers=0, out_of_range="penalise")
    assert not r.executed[0] and r.returns[0] == pytest.approx(-(0.3**2))
    assert task.physics_steps == steps


def _expected_reward(bp, bq, gp, gq, tip, rq, q, dq, tau, final) -> float:
    """B.4.2.1's R_tot, written out here."""
    q_min, q_max = _lim(q)
    qd_max = np.array([2.175] * 4 + [2.61] * 3)
    r = -min(max(np.linalg.norm(bp - tip), 0.05), 10.0)
    r -= min(max(2 / math.pi * math.acos(min(abs(rq @ [0, 1, 0, 0]), 1)), 0.25), 2.0)
    r -= 0.02 * tau @ tau
    for j in range(7):
        r -= max(q[j] - q_max[j], 0) + max(q_min[j] - q[j], 0) + max(abs(dq[j]) - qd_max[j], 0)
    if final:
        r -= 350 * np.linalg.norm(bp - gp) + 200 / math.pi * math.acos(min(abs(bq @ gq), 1))
    return r


def _expected_code_reward(bp, bq, gp, gq, tip, rq, q, dq, tau, final) -> float:
    """BoxPushingObstacleTemporalSparse's reward (CH3_CH4_FACTS §1.5), written out here:
    joint-limit penalties, −2 clip(‖box − tip‖, 0.05, 100), −0.02 Σ τ², −tilt/π above
    π/4; at the end −350 ‖Δp‖ − 100 d_rot/π − 50 ‖q̇‖."""
    q_min, q_max = _lim(q)
    qd_max = np.array([2.175] * 4 + [2.61] * 3)
    r = 0.0
    for j in range(7):
        r -= max(q[j] - q_max[j], 0) + max(q_min[j] - q[j], 0) + max(abs(dq[j]) - qd_max[j], 0)
    r -= 2 * min(max(math.dist(bp, tip), 0.05), 100.0)
    r -= 0.02 * sum(x * x for x in tau)
    tilt = 2 * math.acos(min(abs(rq[1]), 1.0))  # ⟨rq, (0, 1, 0, 0)⟩ = rq[1]
    if tilt > math.pi / 4:
        r -= tilt / math.pi
    if final:
        d_rot = 2 * math.acos(min(abs(sum(a * b for a, b in zip(bq, gq, strict=True))), 1.0))
        r -= 350 * math.dist(bp, gp) + 100 * d_rot / math.pi
        r -= 50 * math.sqrt(sum(v * v for v in dq))
    return r


def test_step_reward_matches_formula() -> None:
    rng = np.random.default_rng(0)
    tilts = 0
    for k in range(40):
        unit = [rng.normal(size=4) for _ in range(2)]
        bq, rq = (u / np.linalg.norm(u) for u in unit)
        if k % 4 == 0:  # a rod close to upright: below the code's π/4 threshold
            rq = np.array([0.05, 1.0, -0.1, 0.08]) + 0.05 * rng.normal(size=4)
            rq /= np.linalg.norm(rq)
            tilts += 2 * math.acos(abs(rq[1])) < math.pi / 4
        args = (
            rng.uniform(-0.5, 0.5, 3), bq, rng.uniform(-0.5, 0.5, 3), goal_quat(rng.uniform(0, 6)),
            rng.uniform(-0.5, 0.5, 3), rq, rng.uniform(-3.5, 3.5, 7), rng.uniform(-4, 4, 7),
            rng.uniform(-10, 10, 7), bool(k % 2),
        )  # fmt: skip
        assert step_reward(*args, variant="thesis") == pytest.approx(
            _expected_reward(*args), rel=1e-12
        )
        want = _expected_code_reward(*args)
        assert step_reward(*args) == pytest.approx(want, rel=1e-12)  # the default: the code's
        assert step_reward(*args, variant="code") == pytest.approx(want, rel=1e-12)
    assert tilts >= 5
    # a rod tip 1 cm from the box, upright rod, no torque: only the clipped costs remain
    z = np.zeros(3)
    up = np.array([0, 1.0, 0, 0])
    r = step_reward(z, bq, z, bq, z + 0.01, up, Q0, np.zeros(7), z, True, variant="thesis")
    assert r == pytest.approx(-0.05 - 0.25)
    # the code: 2 · 0.05 for the tip, nothing for an upright rod, 50 ‖q̇_T‖ at the end only
    dq = np.array([0.3, 0, 0, 0, 0, 0.4, 0])
    assert step_reward(z, bq, z, bq, z + 0.01, up, Q0, dq, z, False) == pytest.approx(-0.1)
    assert step_reward(z, bq, z, bq, z + 0.01, up, Q0, dq, z, True) == pytest.approx(-0.1 - 25)
    with pytest.raises(ValueError, match="variant must be one of"):
        step_reward(z, bq, z, bq, z, up, Q0, dq, z, True, variant="paper")


def _place_box(task: BoxPushingObstacle, pos, yaw: float) -> tuple[float, float, float]:
    gp, gq = task.reset(CTX)
    m, d = task.model, task.data
    adr = m.jnt_qposadr[m.joint("box_joint").id]
    d.qpos[adr : adr + 3] = pos
    d.qpos[adr + 3 : adr + 7] = goal_quat(yaw)
    mujoco.mj_forward(m, d)
    return task.state_reward(gp, gq, np.zeros(7), final=True)


@pytest.mark.parametrize(("settings", "rod_weight"), [("code", 2.0), ("thesis", 1.0)])
def test_reward_cases_from_placed_states(settings: str, rod_weight: float) -> None:
    task = BoxPushingObstacle(settings=settings)
    goal = np.array([CTX[0], CTX[1], -0.01])
    r_on, p_on, a_on = _place_box(task, goal, CTX[2])
    assert p_on == pytest.approx(0.0, abs=1e-12) and a_on == pytest.approx(0.0, abs=1e-6)
    assert is_success(p_on, a_on)
    r_pos, p6, a6 = _place_box(task, goal + [0.06, 0, 0], CTX[2])
    assert p6 == pytest.approx(0.06) and not is_success(p6, a6)
    # the goal term drops by 350 · 0.06; the rod-tip term (rod_weight-Lipschitz) moves by
    # ≤ rod_weight · 0.06 (the robot is at rest after the reset: no −50 ‖q̇_T‖)
    slack = rod_weight * 0.06 + 1e-9
    assert 350 * 0.06 - slack <= r_on - r_pos <= 350 * 0.06 + slack
    r_rot, p_r, a_r = _place_box(task, goal, CTX[2] + 0.6)
    assert a_r == pytest.approx(0.6, abs=1e-9) and not is_success(p_r, a_r)
    # the rotation term alone changes by 200/π · arccos(cos 0.3) = 200 · 0.3 / π
    assert r_on - r_rot == pytest.approx(200 * 0.3 / math.pi, rel=1e-9)
    assert is_success(0.049, 0.49) and not is_success(0.051, 0.1)


def test_invalid_theta_not_simulated(thesis: BoxPushingObstacle) -> None:
    task = thesis
    th = np.zeros(28)
    th[12:16] = 40.0  # joint 4 far beyond its upper limit
    q_d, _ = task.mp.trajectory(th, Q0)
    q_d = q_d[1:]  # the rows the control steps track (t = dt, ..., T dt), as fancy-gym
    q_min, q_max = _lim(q_d)
    hi = np.mean(np.maximum(q_d - q_max, 0))
    lo = np.mean(np.maximum(q_min - q_d, 0))
    assert hi > 0
    assert (hi, lo) == pytest.approx(joint_limit_excess(q_d, q_min, q_max))
    steps = task.physics_steps
    r = task.evaluate(th, CTX, workers=0)
    assert not r.executed[0] and not r.success[0]
    assert r.returns[0] == pytest.approx(-1000 - 1000 * (hi + lo))
    assert task.physics_steps == steps
    free = BoxPushingObstacle(settings="thesis", joint_limit_check=False)
    assert free.evaluate(th, CTX, workers=0).executed[0] and free.physics_steps == 1000
    # the code rejects no θ: the same motion in its layout (goal = the start posture) runs
    code = BoxPushingObstacle()
    th_code = _with_start_goal(th)
    np.testing.assert_allclose(code.mp.trajectory(th_code, Q0)[0][1:], q_d, atol=1e-9)
    r = code.evaluate(th_code, CTX, workers=0)
    assert r.executed[0] and code.physics_steps > 0
    checked = BoxPushingObstacle(joint_limit_check=True).evaluate(th_code, CTX, workers=0)
    assert checked.returns[0] == pytest.approx(-1000 - 1000 * (hi + lo), rel=1e-9)


@pytest.mark.slow
def test_determinism_in_process_and_workers(task: BoxPushingObstacle) -> None:
    rng = np.random.default_rng(5)
    c = task.sample_contexts(3, rng)
    th = 0.5 * rng.normal(size=(3, task.n_params))
    a = task.evaluate(th, c, workers=0)
    b = task.evaluate(th, c, workers=0)
    np.testing.assert_array_equal(a.returns, b.returns)
    np.testing.assert_array_equal(a.info["pos_error"], b.info["pos_error"])
    try:
        w = task.evaluate(th, c, workers=2)
    finally:
        task.close()
    np.testing.assert_array_equal(a.returns, w.returns)
    np.testing.assert_array_equal(a.success, w.success)


@pytest.mark.parametrize("settings", ["code", "thesis"])
def test_constructed_theta_succeeds_random_theta_do_not(settings: str) -> None:
    task = BoxPushingObstacle(settings=settings)
    theta = THETA_CODE if settings == "code" else THETA_OK
    good = task.evaluate(theta, CTX, workers=0)
    assert good.executed[0] and good.success[0]
    assert good.info["pos_error"][0] < 0.05 and good.info["rot_error"][0] < 0.5
    rand = task.evaluate(np.random.default_rng(7).normal(size=(6, task.n_params)), CTX, workers=0)
    assert not rand.success.any()
    assert good.returns[0] > rand.returns.max() + 50
    # holding still (goal = the start posture) leaves the box at its start (0.5 m from this
    # goal)
    still = np.zeros(28) if settings == "thesis" else _with_start_goal(np.zeros(28))
    still = task.evaluate(still, CTX, workers=0)
    assert still.info["pos_error"][0] == pytest.approx(0.502, abs=0.03)


def test_code_example_is_the_thesis_example_with_the_start_as_goal(
    task: BoxPushingObstacle, thesis: BoxPushingObstacle
) -> None:
    """The 35-parameter example: the 28 weights of the thesis's, each joint's goal
    g_j = q0_j / 0.3 (rounded to 1e-6): the same desired trajectory, the same physics, the
    same errors; only the reward differs."""
    blocks = THETA_CODE.reshape(7, 5)
    np.testing.assert_array_equal(blocks[:, :4].reshape(-1), THETA_OK)
    np.testing.assert_allclose(0.3 * blocks[:, 4], Q0, atol=0.3 * 5e-7)
    q_code, dq_code = task.mp.trajectory(THETA_CODE, Q0)
    q_thesis, dq_thesis = thesis.mp.trajectory(THETA_OK, Q0)
    np.testing.assert_allclose(q_code, q_thesis, atol=1e-6)
    a, b = task.evaluate(THETA_CODE, CTX, workers=0), thesis.evaluate(THETA_OK, CTX, workers=0)
    assert a.success[0] and b.success[0]
    for k in ("pos_error", "rot_error"):
        assert a.info[k][0] == pytest.approx(b.info[k][0], abs=1e-5)
    # the code's return is lower here: the box–rod term counts twice and the arm still moves
    # at the end (−50 ‖q̇_T‖)
    assert a.returns[0] < b.returns[0]


def test_one_step_env_passes_check_env() -> None:
    from gymnasium.utils.env_checker import check_env

    env = EpisodicEnv(BoxPushingObstacle)
    check_env(env, skip_render_check=True)
    assert env.action_space.shape == (35,)
    obs, _ = env.reset(seed=0, options={"context": CTX})
    _, r, term, trunc, info = env.step(np.zeros(35))
    assert term and not trunc and info["executed"] and np.isfinite(r)


@pytest.mark.parametrize("breakage", ["velocity", "position", "nan"])
def test_unstable_catches_every_kind_of_breakdown(breakage):
    """MuJoCo resets a diverged state to the model's default silently (bad velocity or
    position warning); the task must still see that the simulation broke down."""
    task = BoxPushingObstacle()
    m, d = task.scene(task.sample_contexts(1, np.random.default_rng(0))[0])
    assert not unstable(d)
    mujoco.mj_step(m, d)
    assert not unstable(d), "a normal step is stable"
    if breakage == "velocity":
        d.qvel[:7] = 1e12
    elif breakage == "position":
        d.qpos[:7] = 1e12
    else:
        d.qpos[0] = np.nan
    mujoco.mj_step(m, d)
    assert unstable(d)

"""Recorded paths of the robot tasks (EpisodicTask.path).

Each path is checked against numbers the episode reports in ``info`` (computed by the
reward from the simulator's full sub-step record) or against a direct MuJoCo query of the
start state, and against positions worked out by hand (the serve, the box's start, the
straight arm).
"""

from __future__ import annotations

import numpy as np
import pytest

from vslbook.envs.robot import make_task
from vslbook.envs.robot.examples import EXAMPLES
from vslbook.envs.robot.reacher5 import tip_position

# Parameters that succeed (or, for the hopper, a jump): the book's examples
# (vslbook.envs.robot.examples, where each task's test file says how its θ was found).
TT_THETA, TT_CONTEXT = EXAMPLES["table-tennis-4d"].arrays()
MG_THETA, MG_CONTEXT = EXAMPLES["mini-golf"].arrays()
BP_THETA, BP_CONTEXT = EXAMPLES["beer-pong"].arrays()
BPO_THETA, BPO_CONTEXT = EXAMPLES["box-pushing-obstacle"].arrays()
HJ_THETA, HJ_CONTEXT = EXAMPLES["hopper-jump"].arrays()


def _one(task, theta, context):
    """evaluate's numbers for one episode, as plain floats."""
    r = task.evaluate(theta, context, workers=0)
    return r, {k: float(v[0]) for k, v in r.info.items()}


def _check_shapes(paths, names, rows):
    assert tuple(paths) == names
    for v in paths.values():
        assert v.dtype == np.float64 and v.shape == (rows, 3) and np.isfinite(v).all()


# -- table tennis -------------------------------------------------------------------------------
def test_table_tennis_ball_path_from_serve_to_landing():
    task = make_task("table-tennis-4d")
    r, info = _one(task, TT_THETA, TT_CONTEXT)
    assert r.success[0]
    p = task.path(TT_THETA, TT_CONTEXT)
    # one row for the start, one per control step simulated
    _check_shapes(p, ("ball", "racket"), int(info["steps"]) + 1)
    ball, racket = p["ball"], p["racket"]
    # the serve: joint coordinates (x, y, 1.75), the ball body sits 0.1 above them
    np.testing.assert_allclose(ball[0], [-0.5, 0.0, 1.85], atol=1e-12)
    # it ends where evaluate saw it land: on the table (top at z = 0.77), at (landing_x, _y)
    np.testing.assert_allclose(ball[-1, :2], [info["landing_x"], info["landing_y"]], atol=1e-12)
    assert 0.77 < ball[-1, 2] < 0.81 and ball[-1, 0] < 0
    # the racket starts where MuJoCo puts the bat (body "EE") in the scene
    m, d = task.scene(TT_CONTEXT)
    np.testing.assert_allclose(racket[0], d.xpos[m.body("EE").id], atol=1e-12)
    # the path is a subsample of the sub-steps the reward looked at: the closest approach on
    # it is no closer than evaluate's, and not far off (4 sub-steps of a ≤ 8 m/s ball)
    gap = np.min(np.linalg.norm(ball - racket, axis=1))
    assert info["min_ball_racket_dist"] - 1e-12 <= gap < info["min_ball_racket_dist"] + 0.07
    # the ball flew towards the robot (x grows) and came back over the net (x < 0 at the end)
    assert ball[:, 0].max() > 0.5


def test_table_tennis_variants_share_the_recorder():
    hard = make_task("table-tennis-hard")
    four = make_task("table-tennis-4d")
    c5 = np.array([TT_CONTEXT[0], TT_CONTEXT[1], 2.5, TT_CONTEXT[2], TT_CONTEXT[3]])
    a, b = four.path(TT_THETA, TT_CONTEXT), hard.path(TT_THETA, c5)
    np.testing.assert_array_equal(a["ball"], b["ball"])
    ch3 = make_task("table-tennis-ch3")
    c = np.array([-0.6, 0.0, -0.5, 0.2])  # goal first, then the ball's start
    th = np.zeros(22)
    th[0] = 1.0  # the arm holds still; the served ball flies past
    p = ch3.path(th, c)
    _, info = _one(ch3, th, c)
    np.testing.assert_allclose(p["ball"][0], [-0.5, 0.2, 1.85], atol=1e-12)
    assert len(p["ball"]) == int(info["steps"]) + 1
    assert info["hit"] == 0.0 and p["ball"][-1, 2] < 0.1  # it fell to the floor
    with pytest.raises(ValueError, match="rejected before simulation"):
        ch3.path(np.r_[0.05, np.zeros(21)], c)  # duration below 0.1 s


# -- mini golf ----------------------------------------------------------------------------------
def test_mini_golf_ball_passes_through_the_gap():
    task = make_task("mini-golf")
    r, info = _one(task, MG_THETA, MG_CONTEXT)
    assert r.success[0]
    p = task.path(MG_THETA, MG_CONTEXT)
    _check_shapes(p, ("ball", "club"), 101)
    ball = p["ball"]
    np.testing.assert_allclose(ball[0], [MG_CONTEXT[2], 0.5, 0.005], atol=1e-9)
    # where the path crosses the goal line y = -0.7 it is inside the 5.6 cm gap around x_goal
    k = int(np.flatnonzero(ball[:, 1] < -0.7)[0])
    s = (-0.7 - ball[k - 1, 1]) / (ball[k, 1] - ball[k - 1, 1])
    x_cross = ball[k - 1, 0] + s * (ball[k, 0] - ball[k - 1, 0])
    assert abs(x_cross - MG_CONTEXT[3]) < 0.028
    # a subsample of the reward's sub-steps: never below evaluate's minimum y, and past the line
    assert ball[:, 1].min() >= info["min_ball_y"] - 1e-12 and ball[:, 1].min() < -0.75
    m, d = task.scene(MG_CONTEXT)
    np.testing.assert_allclose(p["club"][0], d.site_xpos[m.site("rod_tip").id], atol=1e-12)
    th = MG_THETA.copy()
    th[0] = 2.0  # τ above its bound
    with pytest.raises(ValueError, match="mini-golf: theta is invalid"):
        task.path(th, MG_CONTEXT)


# -- beer pong ----------------------------------------------------------------------------------
def test_beer_pong_ball_path_from_hand_to_cup():
    task = make_task("beer-pong")
    r, info = _one(task, BP_THETA, BP_CONTEXT)
    assert r.success[0]
    p = task.path(BP_THETA, BP_CONTEXT)
    n = round(BP_THETA[0] / 0.005)
    _check_shapes(p, ("ball",), n + 500 + 1)
    ball = p["ball"]
    m, d = task.scene(BP_CONTEXT)
    np.testing.assert_allclose(ball[0], d.site_xpos[m.site("init_ball_pos").id], atol=1e-12)
    top = d.site_xpos[m.site("cup_goal_table").id]
    bottom = d.site_xpos[m.site("cup_goal_final_table").id]
    assert np.linalg.norm(ball[-1] - bottom) == pytest.approx(info["final_dist_bottom"], abs=1e-12)
    assert np.min(np.linalg.norm(ball - top, axis=1)) == pytest.approx(
        info["min_dist_top"], abs=1e-12
    )
    with pytest.raises(ValueError, match="rejected before simulation"):
        task.path(np.r_[2.0, BP_THETA[1:]], BP_CONTEXT)  # duration above 1.3 s


# -- box pushing --------------------------------------------------------------------------------
def test_box_path_starts_at_the_box_and_ends_at_the_reported_error():
    task = make_task("box-pushing-obstacle")
    r, info = _one(task, BPO_THETA, BPO_CONTEXT)
    assert r.success[0]
    p = task.path(BPO_THETA, BPO_CONTEXT)
    _check_shapes(p, ("box", "rod_tip"), 101)
    box = p["box"]
    np.testing.assert_allclose(box[0], [0.4, 0.3, -0.01], atol=1e-9)  # the box's start
    goal = np.array([BPO_CONTEXT[0], BPO_CONTEXT[1], -0.01])
    assert np.linalg.norm(box[-1] - goal) == pytest.approx(info["pos_error"], abs=1e-12)
    assert np.linalg.norm(box[-1, :2] - box[0, :2]) > 0.4  # it was pushed across the table
    m, d = task.scene(BPO_CONTEXT)
    np.testing.assert_allclose(p["rod_tip"][0], d.site_xpos[m.site("rod_tip").id], atol=1e-12)
    # the code (default) simulates every θ; the thesis settings reject one far outside the
    # joint limits before simulating it, so it has no path
    assert BPO_THETA.shape == (35,)
    thesis = make_task("box-pushing-obstacle", settings="thesis")
    with pytest.raises(ValueError, match="rejected before simulation"):
        thesis.path(np.full(28, 40.0), BPO_CONTEXT)


# -- reachers -----------------------------------------------------------------------------------
@pytest.mark.parametrize(("name", "start_x"), [("reacher5", 0.51), ("reacher5-ch3", -0.51)])
def test_reacher_tip_path_ends_where_evaluate_says(name, start_x):
    task = make_task(name)
    goal = np.array([0.2, 0.3])
    theta = np.random.default_rng(0).normal(0.0, 1.0, task.n_params)
    _, info = _one(task, theta, goal)
    tip = task.path(theta, goal)["fingertip"]
    assert tip.shape == (201, 3)
    # the arm starts straight (0.4 m of links + 0.11 m to the tip) to the right or the left
    np.testing.assert_allclose(tip[0, :2], [start_x, 0.0], atol=1e-12)
    assert np.linalg.norm(tip[-1, :2] - goal) == pytest.approx(info["tip_distance"], abs=1e-9)
    # MuJoCo's kinematics agree with the planar formula on the whole path
    _, qs, _ = task.rollout(theta, goal)
    np.testing.assert_allclose(tip[:, :2], tip_position(qs), atol=1e-9)
    assert np.ptp(tip[:, 2]) < 1e-12  # planar


def test_planar_reacher_has_no_path():
    task = make_task("planar-reacher")
    with pytest.raises(NotImplementedError, match="planar-reacher"):
        task.path(np.zeros(10), np.array([5.0, 0.0]))


# -- hopper -------------------------------------------------------------------------------------
def test_hopper_paths_match_the_reported_height_and_distance():
    task = make_task("hopper-jump")
    _, info = _one(task, HJ_THETA, HJ_CONTEXT)
    p = task.path(HJ_THETA, HJ_CONTEXT)
    _check_shapes(p, ("foot", "torso"), 251)
    assert p["torso"][1:, 2].max() == pytest.approx(info["max_height"], abs=1e-12)
    goal = np.array([HJ_CONTEXT[3], 0.0, 0.0])
    assert np.linalg.norm(p["foot"][-1] - goal) == pytest.approx(info["goal_distance"], abs=1e-12)
    m, d = task.scene(HJ_CONTEXT)
    np.testing.assert_allclose(p["foot"][0], d.site_xpos[m.site("foot_site").id], atol=1e-12)
    assert p["torso"][0, 2] == pytest.approx(1.5, abs=0.01)  # starts 1.5 m up (rootz)


# -- the interface ------------------------------------------------------------------------------
def test_path_leaves_evaluate_unchanged_and_checks_its_input():
    task = make_task("mini-golf")
    before = task.evaluate(MG_THETA, MG_CONTEXT, workers=0)
    a = task.path(MG_THETA, MG_CONTEXT)
    b = task.path(MG_THETA, MG_CONTEXT)
    after = task.evaluate(MG_THETA, MG_CONTEXT, workers=0)
    np.testing.assert_array_equal(a["ball"], b["ball"])
    assert before.returns[0] == after.returns[0]
    assert task._recorder is None  # recording is off again
    with pytest.raises(ValueError, match="outside the task's context space"):
        task.path(MG_THETA, [0.3, -0.5, 0.44, 0.9])
    with pytest.raises(ValueError, match="one context"):
        task.path(MG_THETA, np.tile(MG_CONTEXT, (2, 1)))
    with pytest.raises(ValueError, match=r"theta must have shape \(1, 29\)"):
        task.path(MG_THETA[:-1], MG_CONTEXT)
    with pytest.raises(ValueError, match="finite"):
        task.path(np.full(29, np.nan), MG_CONTEXT)

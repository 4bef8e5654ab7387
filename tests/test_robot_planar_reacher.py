"""The planar 10-link reacher with obstacles (Section 3.4.1, Fig. 3.1, App. A.3.1)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import minimize

from vslbook.envs.robot.planar_reacher import (
    OBSTACLES,
    PlanarReacherTask,
    link_points,
    segments_hit_rectangles,
)
from vslbook.envs.robot.task import EpisodicEnv

RECTS = [(2.5, 3.3, -0.5, 0.5), (2.7, 3.5, -3.5, -2.5), (3.0, 3.8, 2.5, 3.5)]


@pytest.fixture(scope="module")
def task() -> PlanarReacherTask:
    return PlanarReacherTask(exclude_base_joint=False)  # the thesis's reward, A.3.1


# -- independent references, written as plain loops -------------------------------------
def fk_loop(theta: np.ndarray) -> np.ndarray:
    """Link end points (11, 2) of one joint vector, by walking the chain."""
    pts = [(0.0, 0.0)]
    angle, x, y = 0.0, 0.0, 0.0
    for q in theta:
        angle += q
        x += math.cos(angle)
        y += math.sin(angle)
        pts.append((x, y))
    return np.array(pts)


def sampled_hits(a, b, rect, n=2001, grow=0.0) -> bool:
    """Dense point sampling of segment ab against a rectangle grown by ``grow``."""
    t = np.linspace(0.0, 1.0, n)[:, None]
    p = np.asarray(a) + t * (np.asarray(b) - np.asarray(a))
    x0, x1, y0, y1 = rect
    inside = (
        (p[:, 0] >= x0 - grow)
        & (p[:, 0] <= x1 + grow)
        & (p[:, 1] >= y0 - grow)
        & (p[:, 1] <= y1 + grow)
    )
    return bool(inside.any())


def chain_collides(theta, n=401):
    """(surely, maybe): sampled collision of the chain, exact rectangles and grown ones."""
    pts = fk_loop(theta)
    grow = 1.0 / (n - 1)
    sure = maybe = False
    for a, b in zip(pts[:-1], pts[1:], strict=True):
        for r in RECTS:
            sure |= sampled_hits(a, b, r, n)
            maybe |= sampled_hits(a, b, r, n, grow)
    return sure, maybe


def wrap(q: float) -> float:
    return (q + math.pi) % (2 * math.pi) - math.pi


def reward_ref(theta, c, collision, exclude_base=False) -> float:
    tip = fk_loop(theta)[-1]
    joints = theta[1:] if exclude_base else theta
    joint_cost = sum(wrap(q) ** 2 for q in joints)
    outside = not (4.5 <= c[0] <= 7.0 and -6.0 <= c[1] <= 6.0)
    dist2 = (tip[0] - c[0]) ** 2 + (tip[1] - c[1]) ** 2
    return -joint_cost - 2.0 * dist2 - 10.0 * outside - 3.0 * collision


# -- kinematics and collision --------------------------------------------------------------
def test_forward_kinematics_matches_a_loop():
    rng = np.random.default_rng(1)
    theta = rng.uniform(-3 * np.pi, 3 * np.pi, (50, 10))
    pts = link_points(theta)
    assert pts.shape == (50, 11, 2)
    for th, p in zip(theta, pts, strict=True):
        np.testing.assert_allclose(p, fk_loop(th), atol=1e-9)
    # batch dimensions are kept; one vector gives (11, 2)
    assert link_points(theta.reshape(5, 10, 10)).shape == (5, 10, 11, 2)
    np.testing.assert_allclose(link_points(np.zeros(10))[-1], [10.0, 0.0])
    np.testing.assert_allclose(link_points(np.r_[np.pi / 2, np.zeros(9)])[-1], [0, 10], atol=1e-12)
    with pytest.raises(ValueError, match="shape"):
        link_points(np.zeros(9))


def test_obstacles_constant():
    np.testing.assert_array_equal(OBSTACLES, np.array(RECTS))
    with pytest.raises(ValueError):
        OBSTACLES[0, 0] = 0.0


def test_segment_rectangle_intersection_matches_dense_sampling():
    rng = np.random.default_rng(2)
    n = 600
    a = rng.uniform([1.5, -4.5], [4.5, 4.5], (n, 2))
    b = a + rng.normal(0.0, 1.0, (n, 2))
    # axis-parallel segments, points on the sides, degenerate and fully inside segments
    b[:60, 1] = a[:60, 1]
    b[60:120, 0] = a[60:120, 0]
    a[120:140, 1] = 0.5
    b[120:140, 1] = 0.5
    a[140:150, 0] = 3.3
    b[140:150, 0] = 3.3
    b[150:160] = a[150:160]
    a[160:170], b[160:170] = [2.8, -0.2], [3.1, 0.3]
    exact = segments_hit_rectangles(a, b)
    assert exact.shape == (n, 3) and exact.dtype == bool
    step = np.linalg.norm(b - a, axis=1) / 2000
    n_agree = 0
    for i in range(n):
        for j, r in enumerate(RECTS):
            sure = sampled_hits(a[i], b[i], r)
            maybe = sampled_hits(a[i], b[i], r, grow=step[i] + 1e-12)
            # sample points on the segment inside the rectangle prove a hit; a hit puts a
            # sample within half a step of the rectangle
            assert (not sure) or exact[i, j], (i, j)
            assert (not exact[i, j]) or maybe, (i, j)
            n_agree += sure == maybe
    assert n_agree > 0.98 * 3 * n
    assert 50 < exact.sum() < 3 * n - 50
    # lying on the top side y = 0.5 of the first obstacle: a hit iff the x-ranges overlap
    lo, hi = np.minimum(a[120:140, 0], b[120:140, 0]), np.maximum(a[120:140, 0], b[120:140, 0])
    overlap = (lo <= 3.3) & (hi >= 2.5)
    np.testing.assert_array_equal(exact[120:140, 0], overlap)
    assert 0 < overlap.sum() < 20
    assert exact[160:170, 0].all()


def test_collision_near_a_corner_is_exact(task):
    # a straight arm along φ passes the corner (2.5, 0.5) of the first obstacle at tan φ = 0.2
    phi = math.atan(0.2)
    for d, hit in [(-1e-9, True), (1e-9, False)]:
        th = np.r_[phi + d, np.zeros(9)]
        assert bool(task.compute(th[None], np.array([[5.0, 0.0]]))["collision"][0]) is hit


# -- reward ---------------------------------------------------------------------------------
def test_reward_of_constructed_states(task):
    c = np.array([[5.0, 1.0], [5.0, 1.0], [6.0, -2.0]])
    straight = np.zeros(10)  # along +x through the first obstacle
    up = np.r_[np.pi / 2, np.zeros(9)]  # along +y, free
    bent = np.r_[0.5, np.zeros(8), 2 * np.pi + 0.25]  # wraps to 0.25: joint cost 0.25 + 0.0625
    out = task.compute(np.stack([straight, up, bent]), c)
    assert out["collision"].tolist() == [True, False, False]
    tip_bent = fk_loop(np.r_[0.5, np.zeros(8), 0.25])[-1]
    expected = [
        -0.0 - 2 * (25 + 1) - 3,
        -((np.pi / 2) ** 2) - 2 * (25 + 81),
        -(0.25 + 0.0625) - 2 * np.sum((tip_bent - c[2]) ** 2),
    ]
    np.testing.assert_allclose(out["return"], expected, rtol=1e-12)
    np.testing.assert_allclose(out["tip_distance"][:2], [math.sqrt(26), math.sqrt(106)])
    np.testing.assert_allclose(out["joint_cost"], [0.0, (np.pi / 2) ** 2, 0.3125])
    # the code's variant (the default) leaves the base joint out of the penalty
    code = PlanarReacherTask().compute(np.stack([up, bent]), c[1:])
    np.testing.assert_allclose(code["joint_cost"], [0.0, 0.0625])
    assert PlanarReacherTask().exclude_base_joint and not task.exclude_base_joint


def test_reward_formula_on_random_episodes(task):
    rng = np.random.default_rng(3)
    n = 120
    theta = rng.normal(0.0, 1.2, (n, 10))
    theta[:10] += 2 * np.pi  # wrapping
    c = rng.uniform([3.5, -7.0], [8.0, 7.0], (n, 2))  # some outside the box
    for exclude in (False, True):
        t = PlanarReacherTask(exclude_base_joint=exclude)
        ro = t.evaluate(theta, c, out_of_range="penalise")
        assert ro.executed.all() and not ro.success.any()
        n_checked = 0
        for i in range(n):
            sure, maybe = chain_collides(theta[i])
            if sure != maybe:
                continue
            assert ro.info["collision"][i] == float(sure)
            ref = reward_ref(theta[i], c[i], sure, exclude)
            assert ro.returns[i] == pytest.approx(ref, rel=1e-9, abs=1e-9)
            tip = fk_loop(theta[i])[-1]
            assert ro.info["tip_distance"][i] == pytest.approx(np.linalg.norm(tip - c[i]))
            n_checked += 1
        assert n_checked > 0.9 * n
        assert 0 < ro.info["collision"].sum() < n
    outside = ~task.context_valid(c)
    assert 0 < outside.sum() < n


def test_context_outside_the_box_adds_l_c(task):
    theta = np.random.default_rng(4).normal(0, 0.3, (2, 10))
    c_in = np.array([[7.0, 6.0], [4.5, -6.0]])  # corners: inside (closed box)
    c_out = np.array([[7.0 + 1e-9, 6.0], [4.5, -6.5]])
    inside = task.evaluate(theta, c_in)
    outside = task.evaluate(theta, c_out, out_of_range="penalise")
    assert outside.executed.all() and inside.executed.all()
    for i in range(2):
        col = bool(inside.info["collision"][i])
        assert inside.returns[i] == pytest.approx(reward_ref(theta[i], c_in[i], col), abs=1e-9)
        tip = fk_loop(theta[i])[-1]
        no_lc = -np.sum(theta[i] ** 2) - 2 * np.sum((tip - c_out[i]) ** 2) - 3 * col
        assert outside.returns[i] == pytest.approx(no_lc - 10.0, abs=1e-9)
    np.testing.assert_array_equal(task.context_penalty([[5, 0], [8, 0], [5, 6.1]]), [0, -10, -10])


# -- input checks ---------------------------------------------------------------------------
def test_bad_input_gives_clear_errors(task):
    th = np.zeros(10)
    with pytest.raises(ValueError, match="outside the task's context space"):
        task.evaluate(th, [8.0, 0.0])
    with pytest.raises(ValueError, match=r"contexts must have shape \(n, 2\)"):
        task.evaluate(th, [5.0, 0.0, 1.0])
    with pytest.raises(ValueError, match="finite"):
        task.evaluate(th, [np.nan, 0.0])
    with pytest.raises(ValueError, match=r"theta must have shape \(n, 10\)"):
        task.evaluate(np.zeros(9), [5.0, 0.0])
    with pytest.raises(ValueError, match="finite"):
        task.evaluate(np.r_[np.inf, np.zeros(9)], [5.0, 0.0])
    with pytest.raises(ValueError, match="3 parameter vectors for 2 contexts"):
        task.evaluate(np.zeros((3, 10)), [[5.0, 0.0], [6.0, 0.0]])
    with pytest.raises(ValueError, match="out_of_range"):
        task.evaluate(th, [5.0, 0.0], out_of_range="clip")
    with pytest.raises(ValueError, match="workers"):
        task.evaluate(np.zeros((2, 10)), [5.0, 0.0], workers=-1)
    with pytest.raises(TypeError, match="exclude_base_joint"):
        PlanarReacherTask(exclude_base_joint="yes")
    with pytest.raises(ValueError, match="theta must have shape"):
        task.episodes(np.zeros((2, 11)), np.zeros((2, 2)))


def test_sampled_contexts_fill_the_box(task):
    c = task.sample_contexts(4000, np.random.default_rng(5))
    assert c.shape == (4000, 2)
    assert task.context_valid(c).all()
    assert c[:, 0].min() < 4.6 and c[:, 0].max() > 6.9
    assert c[:, 1].min() < -5.8 and c[:, 1].max() > 5.8
    np.testing.assert_allclose(c.mean(axis=0), [5.75, 0.0], atol=0.2)


# -- determinism and the execution paths ----------------------------------------------------
def test_deterministic_and_same_on_every_path(task):
    rng = np.random.default_rng(6)
    theta = rng.normal(0.0, 1.0, (40, 10))
    c = task.sample_contexts(40, rng)
    c[:3] = [[8.0, 0.0], [5.0, -7.0], [3.0, 9.0]]
    a = task.evaluate(theta, c, out_of_range="penalise")
    b = task.evaluate(theta.copy(), c.copy(), out_of_range="penalise")
    np.testing.assert_array_equal(a.returns, b.returns)
    eps = task.episodes(theta, c)
    np.testing.assert_array_equal([e.ret for e in eps], a.returns)
    for k in task.info_keys:
        np.testing.assert_array_equal([e.info[k] for e in eps], a.info[k])
    env = EpisodicEnv(PlanarReacherTask, exclude_base_joint=False)
    obs, _ = env.reset(seed=0, options={"context": c[5]})
    _, r, term, trunc, info = env.step(theta[5])
    assert (r, term, trunc) == (a.returns[5], True, False)
    assert info["tip_distance"] == a.info["tip_distance"][5] and info["executed"]
    obs, _ = env.reset(seed=1)
    assert task.context_valid(obs)


@pytest.mark.slow
def test_worker_pool_gives_the_in_process_numbers(task):
    rng = np.random.default_rng(9)
    theta = rng.normal(0.0, 1.0, (30, 10))
    c = task.sample_contexts(30, rng)
    c[:2] = [[8.0, 0.0], [5.0, -7.0]]
    a = task.evaluate(theta, c, out_of_range="penalise")
    pooled = PlanarReacherTask(exclude_base_joint=False)
    try:
        p = pooled.evaluate(theta, c, workers=2, out_of_range="penalise")
    finally:
        pooled.close()
    np.testing.assert_array_equal(p.returns, a.returns)
    np.testing.assert_array_equal(p.executed, a.executed)
    np.testing.assert_array_equal(p.success, a.success)
    for k in task.info_keys:
        np.testing.assert_array_equal(p.info[k], a.info[k])


# -- solving the task -----------------------------------------------------------------------
def test_optimised_theta_reaches_behind_the_obstacle_random_theta_do_not(task):
    # c = (5.5, 0): the straight arm towards it passes through the first obstacle
    c = np.array([5.5, 0.0])
    calls = []

    def negative_reward(th):
        calls.append(1)
        return -task.evaluate(th, c).returns[0]

    def gradient(th):  # of the smooth part: ∂f/∂θ_k = (tip − p_{k−1}) turned by 90°
        pts = fk_loop(th)
        lever = pts[-1] - pts[:-1]
        dtip = np.stack([-lever[:, 1], lever[:, 0]], axis=1)
        return 2 * th + 4 * dtip @ (pts[-1] - c)

    th0 = np.full(10, 0.3)
    eps = 1e-6
    fd = [(negative_reward(th0 + eps * e) - negative_reward(th0 - eps * e)) / (2 * eps)
          for e in np.eye(10)]  # fmt: skip
    np.testing.assert_allclose(gradient(th0), fd, rtol=1e-5)
    calls.clear()
    runs = [
        minimize(negative_reward, np.full(10, s), jac=gradient, method="L-BFGS-B",
                 options={"maxfun": 150})
        for s in (0.1, -0.1)
    ]  # fmt: skip
    assert len(calls) <= 400
    best = max((task.evaluate(r.x, c) for r in runs), key=lambda ro: ro.returns[0])
    assert best.info["collision"][0] == 0.0
    assert best.info["tip_distance"][0] < 0.2
    assert best.returns[0] > -2.5
    theta = max(runs, key=lambda r: -r.fun).x
    assert not chain_collides(theta, n=4001)[0]  # (it passes close to the first obstacle)
    # straight towards the target collides; random joint angles score far worse
    assert task.evaluate(np.zeros(10), c).info["collision"][0] == 1.0
    rand = task.evaluate(np.random.default_rng(8).uniform(-np.pi, np.pi, (200, 10)), c)
    assert rand.returns.max() < -8.0
    assert (rand.info["tip_distance"] > 0.2).all()

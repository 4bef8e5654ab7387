"""Box Pushing with Obstacle: the episode loop (thesis Section 4.5.1, Appendix B.4.2.1)
against the plain per-step reading: the vectorised rewards of an episode equal the scalar
formula step by step, and an episode equals a loop over the torque law, the breakdown test
and the reward of the simulator's state after every control step."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from vslbook.envs.robot.box_pushing import (
    D_GAINS,
    HORIZON,
    P_GAINS,
    Q0,
    BoxPushingObstacle,
    apply_torque,
    goal_quat,
    is_success,
    step_reward,
    step_rewards,
    unstable,
)
from vslbook.envs.robot.examples import EXAMPLES, THESIS_EXAMPLES

# the succeeding θ of each layout and its context (tests/test_robot_box_pushing.py says how
# they were built)
THETA_OK, CTX = THESIS_EXAMPLES["box-pushing-obstacle"].arrays()
THETA_CODE, _ = EXAMPLES["box-pushing-obstacle"].arrays()


@pytest.fixture(scope="module")
def task() -> BoxPushingObstacle:
    """The default: the authors' environment (settings="code")."""
    return BoxPushingObstacle()


@pytest.fixture(scope="module")
def thesis() -> BoxPushingObstacle:
    """B.4.2.1's text (settings="thesis")."""
    return BoxPushingObstacle(settings="thesis")


def _random_states(rng: np.random.Generator, n: int) -> dict[str, np.ndarray]:
    """n random states, some beyond the joint and velocity limits and the reward's clips."""

    def unit(k: int) -> np.ndarray:
        u = rng.normal(size=(k, 4))
        return u / np.linalg.norm(u, axis=1, keepdims=True)

    return {
        "box_pos": rng.uniform(-0.5, 0.5, (n, 3)), "box_quat": unit(n),
        "rod_tip": rng.uniform(-0.5, 0.5, (n, 3)), "rod_quat": unit(n),
        "q": rng.uniform(-3.5, 3.5, (n, 7)), "dq": rng.uniform(-4, 4, (n, 7)),
        "torque": rng.uniform(-10, 10, (n, 7)),
    }  # fmt: skip


@pytest.mark.parametrize("variant", ["code", "thesis"])
@pytest.mark.parametrize("final", [False, True])
def test_step_rewards_match_step_reward_row_by_row(final: bool, variant: str) -> None:
    """The vectorised rewards of a whole episode equal the scalar formula, step by step."""
    rng = np.random.default_rng(1)
    s = _random_states(rng, 60)
    s["rod_tip"][:5] = s["box_pos"][:5] + 0.01  # R_rod below its clip at 0.05
    s["rod_quat"][5:10] = [0.0, 1.0, 0.0, 0.0]  # upright rod: the 0.25 clip
    tilt = np.array([math.cos(0.39), math.sin(0.39)])  # rotations by 0.78 rad (< π/4) ...
    s["rod_quat"][10:12] = [[0.0, tilt[0], tilt[1], 0.0]] * 2
    tilt = np.array([math.cos(0.4), math.sin(0.4)])  # ... and 0.8 rad (> π/4) from upright
    s["rod_quat"][12:14] = [[0.0, tilt[0], 0.0, tilt[1]]] * 2
    gp, gq = rng.uniform(-0.5, 0.5, 3), goal_quat(rng.uniform(0, 6))
    got = step_rewards(**s, goal_pos=gp, goal_quat=gq, final=final, variant=variant)
    want = [
        step_reward(
            **{k: v[t] for k, v in s.items()},
            goal_pos=gp,
            goal_quat=gq,
            final=final and t == 59,
            variant=variant,
        )
        for t in range(60)
    ]
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=0.0)
    empty = {k: v[:0] for k, v in s.items()}
    assert step_rewards(**empty, goal_pos=gp, goal_quat=gq, final=final).shape == (0,)
    with pytest.raises(ValueError, match="variant must be one of"):
        step_rewards(**s, goal_pos=gp, goal_quat=gq, final=final, variant="otto")
    with pytest.raises(ValueError, match=r"goal_pos and goal_quat must have shapes"):
        step_rewards(**s, goal_pos=gp[:2], goal_quat=gq, final=final)
    with pytest.raises(ValueError, match=r"rod_quat must have shape \(60, 4\)"):
        step_rewards(**{**s, "rod_quat": s["rod_quat"][:, :3]}, goal_pos=gp, goal_quat=gq,
                     final=final)  # fmt: skip


def _plain_episode(task: BoxPushingObstacle, theta: np.ndarray, context: np.ndarray):
    """One episode the plain way: the torque law, the breakdown test and the reward of the
    simulator's state after every control step, through the per-step functions."""
    q_d, dq_d = task.mp.trajectory(theta, Q0)
    gp, gq = task.reset(context)
    m, d = task.model, task.data
    box, tip = m.body("box_0").id, m.site("rod_tip").id
    points = [(d.xpos[box].copy(), d.site_xpos[tip].copy())]
    ret, pos_err, rot_err, steps = 0.0, math.nan, math.nan, 0
    for t in range(HORIZON):
        a = P_GAINS * (q_d[t + 1] - d.qpos[:7]) + D_GAINS * (dq_d[t + 1] - d.qvel[:7])
        torque = apply_torque(m, d, a)
        steps += 10
        if unstable(d):
            ret += -50.0 * (HORIZON - t)
            pos_err = rot_err = math.nan
            break
        r, pos_err, rot_err = task.state_reward(gp, gq, torque, final=t == HORIZON - 1)
        ret += r
        points.append((d.xpos[box].copy(), d.site_xpos[tip].copy()))
    return ret, pos_err, rot_err, steps, points


def _same_as_plain(task: BoxPushingObstacle, theta: np.ndarray, context: np.ndarray) -> bool:
    want_ret, want_pos, want_rot, want_steps, want_points = _plain_episode(task, theta, context)
    before = task.physics_steps
    got = task.evaluate(theta, context, workers=0)
    assert task.physics_steps - before == want_steps
    assert got.returns[0] == pytest.approx(want_ret, rel=1e-9, abs=1e-9)
    np.testing.assert_array_equal(got.info["pos_error"], [want_pos])
    np.testing.assert_array_equal(got.info["rot_error"], [want_rot])
    assert got.success[0] == is_success(want_pos, want_rot)
    path = task.path(theta, context)
    np.testing.assert_array_equal(path["box"], [p[0] for p in want_points])
    np.testing.assert_array_equal(path["rod_tip"], [p[1] for p in want_points])
    return bool(math.isnan(want_pos))


def test_episode_matches_the_plain_loop(
    task: BoxPushingObstacle, thesis: BoxPushingObstacle
) -> None:
    rng = np.random.default_rng(2)
    c = thesis.sample_contexts(2, rng)
    for th, ctx in (
        (THETA_OK, CTX),
        (rng.normal(size=28), c[0]),
        (0.1 * rng.normal(size=28), c[1]),
    ):
        assert not _same_as_plain(thesis, th, ctx)
    for th in (THETA_CODE, THETA_CODE + 0.3 * np.random.default_rng(3).normal(size=35)):
        assert not _same_as_plain(task, th, CTX)
    # with a ten times longer physics step MuJoCo diverges in mid-episode
    coarse = BoxPushingObstacle(settings="thesis", joint_limit_check=False)
    coarse.model.opt.timestep = 0.02
    broke = [_same_as_plain(coarse, 2.0 * rng.normal(size=28), ctx) for ctx in c]
    assert any(broke)


@pytest.mark.parametrize(
    ("breakage", "after", "steps"),
    [("velocity", 37, 40), ("position", 37, 40), ("nan", 37, 40), ("nan", 40, 40), ("nan", 41, 50)],
)
def test_episode_ends_at_an_injected_breakdown(breakage, after, steps, monkeypatch) -> None:
    """A state broken after physics step ``after`` ends the episode at the end of that
    control step (MuJoCo flags it at the next physics step, or the finiteness test sees
    it at the end of the control step), with −50 per remaining step, as the plain loop."""
    task = BoxPushingObstacle(settings="thesis")
    real = mujoco.mj_step
    calls = [0]

    def step(m, d, nstep: int = 1) -> None:
        for _ in range(nstep):
            real(m, d)
            calls[0] += 1
            if calls[0] == after:
                if breakage == "velocity":
                    d.qvel[:7] = 1e12
                elif breakage == "position":
                    d.qpos[:7] = 1e12
                else:
                    d.qpos[2] = np.nan

    monkeypatch.setattr(mujoco, "mj_step", step)
    want_ret, *_ = _plain_episode(task, THETA_OK, CTX)
    calls[0] = 0
    got = task.evaluate(THETA_OK, CTX, workers=0)
    assert math.isnan(got.info["pos_error"][0]) and not got.success[0]
    assert got.returns[0] == pytest.approx(want_ret, rel=1e-12)
    assert want_ret < -50.0 * (HORIZON - steps // 10)
    assert task.physics_steps == steps

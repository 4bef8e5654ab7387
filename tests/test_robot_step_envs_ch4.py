"""Step-based Chapter 4 tasks for PPO: Box Pushing with Obstacle and the sparse 5-link reacher."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from vslbook.envs.robot.box_pushing import BoxPushingObstacle
from vslbook.envs.robot.box_pushing_step import BoxPushingObstacleStepEnv
from vslbook.envs.robot.examples import EXAMPLES, THESIS_EXAMPLES
from vslbook.envs.robot.reacher5 import Reacher5
from vslbook.envs.robot.reacher5_sparse_step import Reacher5SparseStepEnv

# The succeeding (context, θ) pairs of tests/test_robot_box_pushing.py: the code's layout
# (35 parameters, the default) and the thesis's (28).
THETA_CODE, CTX = EXAMPLES["box-pushing-obstacle"].arrays()
THETA_OK, _ = THESIS_EXAMPLES["box-pushing-obstacle"].arrays()
THETAS = {"code": THETA_CODE, "thesis": THETA_OK}

# Numbers of Appendix B.4.2.1 / the Franka data sheet, written out here on purpose.
KP = 0.01 * np.array([120.0, 120, 120, 120, 50, 30, 10])
KD = 0.01 * np.array([10.0, 10, 10, 10, 6, 5, 3])
Q_HI = np.array([2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973])
Q_LO = np.array([-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973])
QD_HI = np.array([2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61])
Q_START = np.array([0.387, 0.176, 0.250, -2.399, -0.080, 2.569, 1.480])


@pytest.fixture(scope="module")
def bp_env() -> BoxPushingObstacleStepEnv:
    return BoxPushingObstacleStepEnv()


@pytest.fixture(scope="module")
def rc_env() -> Reacher5SparseStepEnv:
    return Reacher5SparseStepEnv()


# -- shared ----------------------------------------------------------------------------------
@pytest.mark.parametrize("cls", [BoxPushingObstacleStepEnv, Reacher5SparseStepEnv])
def test_passes_check_env(cls) -> None:
    env = cls()
    check_env(env, skip_render_check=True)
    obs, _ = env.reset(seed=0)
    assert obs.shape == env.observation_space.shape == ((30,) if "Box" in cls.__name__ else (20,))
    assert env.action_space.shape == ((7,) if "Box" in cls.__name__ else (5,))


@pytest.mark.parametrize("cls", [BoxPushingObstacleStepEnv, Reacher5SparseStepEnv])
def test_seed_determinism(cls) -> None:
    acts = np.random.default_rng(3).uniform(-1, 1, (40, 7 if "Box" in cls.__name__ else 5))

    def run(env, seed):
        obs, info = env.reset(seed=seed)
        out = [obs]
        rewards = []
        for a in acts:
            obs, r, *_ = env.step(a)
            out.append(obs)
            rewards.append(r)
        return np.array(out), np.array(rewards), info

    a, b = cls(), cls()
    o1, r1, i1 = run(a, 11)
    o2, r2, i2 = run(b, 11)
    o3, r3, _ = run(a, 11)  # the same instance after other episodes
    np.testing.assert_array_equal(o1, o2)
    np.testing.assert_array_equal(r1, r2)
    np.testing.assert_array_equal(o1, o3)
    np.testing.assert_array_equal(r1, r3)
    key = "context" if "Box" in cls.__name__ else "goal"
    np.testing.assert_array_equal(i1[key], i2[key])
    assert not np.array_equal(run(b, 12)[2][key], i1[key])


@pytest.mark.parametrize("cls", [BoxPushingObstacleStepEnv, Reacher5SparseStepEnv])
def test_bad_input_errors(cls) -> None:
    env = cls()
    n = env.action_space.shape[0]
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(n))
    env.reset(seed=0)
    with pytest.raises(ValueError, match=rf"shape \({n},\), got shape \({n + 1},\)"):
        env.step(np.zeros(n + 1))
    with pytest.raises(ValueError, match=rf"got shape \(1, {n}\)"):
        env.step(np.zeros((1, n)))
    with pytest.raises(ValueError, match="finite"):
        env.step(np.full(n, np.nan))
    with pytest.raises(ValueError, match="numbers"):
        env.step(["a"] * n)
    with pytest.raises(ValueError, match="unknown reset options"):
        env.reset(options={"ctx": 1})
    with pytest.raises(ValueError, match="render_mode"):
        cls(render_mode="human")
    key, bad = ("context", [0.45, 0.3, 0.0, 0.4, 0.0]) if n == 7 else ("goal", [0.4, 0.4])
    with pytest.raises(ValueError, match="outside the task's context space"):
        env.reset(options={key: bad})
    with pytest.raises(ValueError, match="shape"):
        env.reset(options={key: [0.1]})


# -- box pushing ---------------------------------------------------------------------------
def _hand_reward(
    d: mujoco.MjData, m: mujoco.MjModel, a: np.ndarray, final: bool, settings: str = "code"
) -> float:
    """The reward from the MuJoCo state, written out independently of the package:
    ``settings="thesis"``: B.4.2.1's R_tot; ``"code"``: BoxPushingObstacleTemporalSparse's
    (rod–box weight 2, clip at 100, tilt cost only above π/4, −50 ‖q̇_T‖ at the end)."""
    box = d.xpos[m.body("box_0").id]
    box_q = d.xquat[m.body("box_0").id]
    tip = d.site_xpos[m.site("rod_tip").id]
    rod_q = d.xquat[m.body("push_rod").id]
    q, qd = d.qpos[:7], d.qvel[:7]
    tilt = 2 * math.acos(min(abs(rod_q[1]), 1.0))  # the angle to (0, 1, 0, 0)
    if settings == "thesis":
        r = -min(max(math.dist(box, tip), 0.05), 10.0)
        r -= min(max(2 / math.pi * math.acos(min(abs(rod_q[1]), 1.0)), 0.25), 2.0)
    else:
        r = -2 * min(max(math.dist(box, tip), 0.05), 100.0)
        r -= tilt / math.pi if tilt > math.pi / 4 else 0.0
    r -= 0.02 * sum((10 * x) ** 2 for x in a)
    for i in range(7):
        r -= max(q[i] - Q_HI[i], 0) + max(Q_LO[i] - q[i], 0) + max(abs(qd[i]) - QD_HI[i], 0)
    if final:
        goal = np.array([CTX[0], CTX[1], -0.01])
        gq = np.array([math.cos(CTX[2] / 2), 0, 0, math.sin(CTX[2] / 2)])
        r -= 350 * math.dist(box, goal)
        r -= 200 * math.acos(min(abs(float(box_q @ gq)), 1.0)) / math.pi
        if settings == "code":
            r -= 50 * math.sqrt(sum(v * v for v in qd))
    return r


@pytest.mark.parametrize("settings", ["code", "thesis"])
def test_box_replay_equals_episodic_return(settings: str) -> None:
    """The PD actions of a succeeding θ, sent step by step: per-step rewards equal the
    settings' formula on the MuJoCo state, their sum equals the episodic return, and success
    is reported at the end."""
    env = BoxPushingObstacleStepEnv(settings=settings)
    task = BoxPushingObstacle(settings=settings)
    assert env.task.reward == task.reward == settings
    q_d, dq_d = task.mp.trajectory(THETAS[settings], Q_START)
    obs, info = env.reset(options={"context": CTX})
    m, d = env.task.model, env.task.data
    np.testing.assert_array_equal(info["context"], CTX)
    np.testing.assert_allclose(obs[:7], Q_START)
    np.testing.assert_allclose(obs[14:21], [0.4, 0.3, -0.01, 0, 0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(obs[21:27], [0.35, -0.2, 0, 0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(obs[27:30], [0.58, 0.05, 0.0])
    rewards = []
    for t in range(100):
        a = np.clip(KP * (q_d[t + 1] - d.qpos[:7]) + KD * (dq_d[t + 1] - d.qvel[:7]), -1, 1)
        obs, r, term, trunc, info = env.step(a)
        want = _hand_reward(d, m, a, final=t == 99, settings=settings)
        assert r == pytest.approx(want, rel=1e-12, abs=1e-12)
        assert term == (t == 99) and not trunc and obs[-1] == pytest.approx((t + 1) / 100)
        rewards.append(r)
    ep = task.evaluate(THETAS[settings], CTX, workers=0)
    assert sum(rewards) == pytest.approx(ep.returns[0], rel=1e-12)
    assert ep.success[0] and info["success"] is True
    assert info["pos_error"] == pytest.approx(ep.info["pos_error"][0], rel=1e-12)
    # the goal terms are paid only at the last step: it is far below every other step
    assert rewards[-1] < min(rewards[:-1]) - 1.0
    np.testing.assert_array_equal(obs[:7], d.qpos[:7])
    np.testing.assert_array_equal(obs[14:17], d.qpos[m.jnt_qposadr[m.joint("box_joint").id] :][:3])
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(7))


def test_box_torque_law_and_clipping(bp_env: BoxPushingObstacleStepEnv) -> None:
    env = bp_env
    env.reset(seed=4)
    d = env.task.data
    a = np.array([3.0, -0.5, 0.2, -7.0, 0.9, -1.0, 0.05])  # out-of-range entries clip to ±1
    bias = d.qfrc_bias[:7].copy()
    _, r, *_ = env.step(a)
    ac = np.array([1.0, -0.5, 0.2, -1.0, 0.9, -1.0, 0.05])
    lim = np.array([90.0, 90, 90, 90, 12, 12, 12])
    np.testing.assert_allclose(d.ctrl, np.clip(10 * ac + bias, -lim, lim), rtol=0, atol=1e-12)
    # torque cost 0.02 Σ(10 a)² of the clipped action: 2 Σ a²
    m = env.task.model
    assert r == pytest.approx(_hand_reward(d, m, ac, final=False), rel=1e-12)  # the code's
    assert 2 * np.sum(ac**2) == pytest.approx(0.02 * np.sum((10 * ac) ** 2))


def test_box_unstable_simulation_ends_with_remaining_penalty(
    bp_env: BoxPushingObstacleStepEnv,
) -> None:
    env = bp_env
    env.reset(seed=1)
    for _ in range(3):
        env.step(np.zeros(7))
    env.task.data.qvel[:] = 1e5  # MuJoCo flags a bad acceleration on the next step
    obs, r, term, trunc, info = env.step(np.zeros(7))
    assert r == -50.0 * (100 - 3) and term and not trunc
    assert info["unstable"] and info["success"] is False and np.all(np.isfinite(obs))
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(7))


def test_box_sampled_contexts_follow_the_task_rules(bp_env: BoxPushingObstacleStepEnv) -> None:
    env = bp_env
    cs = np.array([env.reset(seed=s)[1]["context"] for s in range(30)])
    assert len({tuple(c) for c in cs}) == 30
    g, o = cs[:, :2], cs[:, 3:5]
    assert np.all(np.hypot(*(g - [0.4, 0.3]).T) > 0.3)
    # the code's y-distances (which imply B.4.2.1's Euclidean ones)
    assert np.all(np.abs(o[:, 1] - g[:, 1]) >= 0.15) and np.all(np.abs(o[:, 1] - 0.3) >= 0.15)
    assert np.all(np.hypot(*(o - g).T) >= 0.15) and np.all(cs[:, 1] < cs[:, 4])
    assert np.all((cs >= [0.3, -0.7, 0, 0.3, -0.3]) & (cs <= [0.6, 0.45, 2 * np.pi, 0.6, 0.15]))
    # B.4.2.1's Euclidean rule accepts an obstacle beside the goal that the code rejects
    beside = [0.35, -0.3, 1.0, 0.55, -0.25]
    with pytest.raises(ValueError, match="outside the task's context space"):
        env.reset(options={"context": beside})
    thesis = BoxPushingObstacleStepEnv(settings="thesis")
    np.testing.assert_array_equal(thesis.reset(options={"context": beside})[1]["context"], beside)


def test_box_settings_options_and_the_scene_without_obstacle() -> None:
    with pytest.raises(ValueError, match=r"settings must be one of \('code', 'thesis'\), got 'x'"):
        BoxPushingObstacleStepEnv(settings="x")
    env = BoxPushingObstacleStepEnv(settings="thesis", reward="code")
    assert (env.task.reward, env.task.distance_rule, env.task.joint_limit_check) == (
        "code", "euclidean", False)  # fmt: skip
    free = BoxPushingObstacleStepEnv(obstacle=False)
    m = free.task.model
    assert "obstacle" not in {m.body(i).name for i in range(m.nbody)}
    obs, _ = free.reset(options={"context": CTX})
    np.testing.assert_allclose(obs[27:29], CTX[3:5])  # the context's obstacle entries
    with_obstacle = BoxPushingObstacleStepEnv()
    with_obstacle.reset(options={"context": CTX})
    # away from the obstacle both scenes step alike: the same state after a few steps
    for _ in range(5):
        a = np.full(7, 0.05)
        o1, r1, *_ = free.step(a)
        o2, r2, *_ = with_obstacle.step(a)
    np.testing.assert_allclose(o1, o2, rtol=0, atol=1e-9)
    assert r1 == pytest.approx(r2, abs=1e-9)


# -- 5-link reacher --------------------------------------------------------------------------
def _mujoco_tip(env: Reacher5SparseStepEnv) -> np.ndarray:
    """Fingertip (x, y) from MuJoCo's forward kinematics of the current qpos."""
    m = env.sim.model
    d = mujoco.MjData(m)
    d.qpos[:] = env.sim.data.qpos
    mujoco.mj_forward(m, d)
    return d.xpos[m.body("fingertip").id, :2].copy()


def test_reacher_zero_actions_pay_only_the_final_distance(rc_env: Reacher5SparseStepEnv) -> None:
    env = rc_env
    obs, info = env.reset(options={"goal": [0.0, 0.4]})
    np.testing.assert_allclose(obs[:5], 1.0)  # cos 0: arm straight to the right
    np.testing.assert_allclose(obs[17:19], [0.51, -0.4], atol=1e-12)
    rewards = []
    for _ in range(200):
        obs, r, term, trunc, info = env.step(np.zeros(5))
        rewards.append(r)
    assert rewards[:-1] == [0.0] * 199
    assert rewards[-1] == pytest.approx(-200 * math.hypot(0.51, 0.4), rel=1e-9)
    assert term and not trunc and obs[-1] == 1.0 and "success" not in info


def test_reacher_rewards_by_hand_and_terminal_only_at_the_end(
    rc_env: Reacher5SparseStepEnv,
) -> None:
    env = rc_env
    goal = np.array([-0.2, -0.3])
    env.reset(seed=5, options={"goal": goal})
    acts = np.random.default_rng(2).uniform(-1.5, 1.5, (200, 5))
    clipped = np.clip(acts, -1, 1)
    for t in range(200):
        obs, r, term, trunc, info = env.step(acts[t])
        cost = float(np.sum(clipped[t] ** 2))
        if t < 199:
            assert r == pytest.approx(-cost, rel=1e-12) and not term and not trunc
        else:
            tip = _mujoco_tip(env)
            vel = float(np.sum(env.sim.data.qvel[:5] ** 2))
            want = -cost - 200 * float(np.linalg.norm(tip - goal)) - 10 * vel
            assert r == pytest.approx(want, rel=1e-9) and term and not trunc
            assert info["tip_distance"] == pytest.approx(np.linalg.norm(tip - goal), rel=1e-9)
            np.testing.assert_allclose(obs[17:19] + goal, tip, atol=1e-9)
            np.testing.assert_allclose(obs[10:12], goal)


def test_reacher_replay_equals_episodic_return(rc_env: Reacher5SparseStepEnv) -> None:
    env, task = rc_env, Reacher5()
    th = np.random.default_rng(8).normal(size=30)
    goal = np.array([0.1, -0.35])
    acts, qs, dqs = task.rollout(th, goal)
    env.reset(options={"goal": goal})
    total = 0.0
    for t in range(200):
        obs, r, *_ = env.step(acts[t])
        total += r
    np.testing.assert_allclose(obs[12:17], dqs[-1], rtol=0, atol=1e-12)
    assert total == pytest.approx(task.evaluate(th, goal, workers=1).returns[0], rel=1e-12)


def test_reacher_goals_fill_the_whole_disk(rc_env: Reacher5SparseStepEnv) -> None:
    g = np.array([rc_env.reset(seed=s)[1]["goal"] for s in range(200)])
    assert np.all(np.hypot(*g.T) <= 0.5)
    # all four quadrants (B.4.3), unlike Chapter 3's right half disk
    quads = {(bool(x >= 0), bool(y >= 0)) for x, y in g}
    assert len(quads) == 4


@pytest.mark.parametrize(
    ("env_id", "cls"),
    [
        ("vslbook/BoxPushingObstacleStep-v0", BoxPushingObstacleStepEnv),
        ("vslbook/Reacher5SparseStep-v0", Reacher5SparseStepEnv),
    ],
)
def test_gym_make_with_the_proposed_ids(env_id: str, cls: type) -> None:
    import gymnasium as gym

    import vslbook.envs.robot  # noqa: F401  (registers the package's ids)

    if env_id not in gym.registry:
        gym.register(env_id, entry_point=cls)
    env = gym.make(env_id)
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    _, r, term, trunc, _ = env.step(env.action_space.sample())
    assert np.isfinite(r) and not term and not trunc
    env.close()

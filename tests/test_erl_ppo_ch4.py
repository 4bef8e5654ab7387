"""PPO baselines of Chapter 4 (vslbook.erl.ppo_ch4): Tables B.3/B.6, evaluation, resume."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
import torch
from stable_baselines3.common.vec_env import VecNormalize

from vslbook.envs.robot.box_pushing_step import BoxPushingObstacleStepEnv
from vslbook.envs.robot.reacher5_sparse_step import Reacher5SparseStepEnv
from vslbook.erl.ppo import CHECKPOINT_FILE
from vslbook.erl.ppo_ch4 import (
    PPOCh4Config,
    evaluate,
    evaluation_contexts,
    make_ppo_ch4,
    matched_total_steps,
    ppo_ch4_config,
    train_ppo_ch4,
)

TASKS = ("reacher5", "box-pushing-obstacle")
# 2 environments × 128 steps per update: after the first update both tasks are mid-episode
# (5LR: 128 of 200 steps, BPO: 28 of 100), after the second one 5LR is 56 steps into its
# second episode and BPO has finished its second
TINY = {"n_rollout_steps": 256, "n_envs": 2, "n_epochs": 2, "batch_size": 64, "total_steps": 512}
TINY_RUN = {"eval_every": 256, "eval_episodes": 2}


def _tiny(task: str, **changes) -> PPOCh4Config:
    return ppo_ch4_config(task, **{**TINY, **changes})


def _without_wall_clock(metrics: list[dict]) -> list[dict]:
    return [{k: v for k, v in row.items() if k != "env_steps_per_s"} for row in metrics]


@pytest.fixture(scope="module", params=TASKS)
def uninterrupted(request) -> tuple[str, list[dict]]:
    task = request.param
    return task, train_ppo_ch4(task, _tiny(task), seed=3, **TINY_RUN)


def _linear_widths(net: torch.nn.Module) -> list[int]:
    return [m.out_features for m in net.modules() if isinstance(m, torch.nn.Linear)]


# -- the tables -----------------------------------------------------------------------------


def test_configs_are_tables_b3_and_b6() -> None:
    lr = ppo_ch4_config("reacher5")
    # Table B.3, PPO: [32, 32] policy and critic, lr 3e-4, 10 epochs, minibatch 512, 32
    # minibatches, 16384 samples, γ = 1
    assert (lr.net_arch, lr.learning_rate, lr.n_epochs) == ((32, 32), 3e-4, 10)
    assert (lr.batch_size, lr.n_minibatches, lr.n_rollout_steps) == (512, 32, 16384)
    assert lr.gamma == 1.0
    bpo = ppo_ch4_config("box-pushing-obstacle")
    # Table B.6, PPO: [256, 256], lr 1e-4, 10 epochs, minibatch 410, 40 minibatches, 16384
    assert (bpo.net_arch, bpo.learning_rate, bpo.n_epochs) == ((256, 256), 1e-4, 10)
    assert (bpo.batch_size, bpo.n_minibatches, bpo.n_rollout_steps) == (410, 40, 16384)
    assert bpo.gamma == 1.0
    for c in (lr, bpo):  # our choices (SB3 / Chapter 3) and the code-level optimisations
        assert (c.gae_lambda, c.clip_range, c.clip_range_vf) == (0.95, 0.2, 0.2)
        assert (c.n_envs, c.normalize, c.anneal_lr) == (16, True, True)


def test_full_budget_matches_diskills_episodes() -> None:
    # Di-SkilL at the full budget: 5LR 3000 iterations × 10 experts × 25 episodes of 200
    # steps; BPO 4500 × 10 × 50 episodes of 100 steps; rounded up to whole rollouts of 16384
    for task, steps, updates in (
        ("reacher5", 3000 * 10 * 25 * 200, 9156),
        ("box-pushing-obstacle", 4500 * 10 * 50 * 100, 13733),
    ):
        assert (updates - 1) * 16384 < steps <= updates * 16384
        assert matched_total_steps(task) == updates * 16384
        assert ppo_ch4_config(task).total_steps == updates * 16384
    # a smaller rollout rounds to its own multiple
    assert ppo_ch4_config("reacher5", n_rollout_steps=1600).total_steps == 150_000_000
    assert matched_total_steps("box-pushing-obstacle", 7) == math.ceil(225e6 / 7) * 7


@pytest.mark.parametrize(
    "task, obs_dim, act_dim, width, lr, batch",
    [("reacher5", 20, 5, 32, 3e-4, 512), ("box-pushing-obstacle", 30, 7, 256, 1e-4, 410)],
)
def test_model_carries_the_table(task, obs_dim, act_dim, width, lr, batch) -> None:
    model = make_ppo_ch4(task, ppo_ch4_config(task), seed=0)
    assert model.n_steps * model.n_envs == 16384 and model.get_env().num_envs == 16
    assert model.batch_size == batch and model.n_epochs == 10
    assert model.gamma == 1.0 and model.gae_lambda == 0.95
    assert model.clip_range(0.5) == 0.2 and model.clip_range_vf(0.5) == 0.2
    assert model.lr_schedule(1.0) == pytest.approx(lr) and model.lr_schedule(0.0) == 0.0
    assert model.policy.optimizer.param_groups[0]["lr"] == pytest.approx(lr)
    assert model.ent_coef == 0.0 and model.max_grad_norm == 0.5 and model.normalize_advantage
    assert model.policy.ortho_init
    extractor = model.policy.mlp_extractor
    assert _linear_widths(extractor.policy_net) == [width, width]
    assert _linear_widths(extractor.value_net) == [width, width]
    units = [m for m in extractor.policy_net if not isinstance(m, torch.nn.Linear)]
    assert len(units) == 2 and all(isinstance(m, torch.nn.Tanh) for m in units)
    assert model.observation_space.shape == (obs_dim,)
    assert model.policy.action_net.out_features == act_dim
    # diagonal covariance, state-independent, σ = 1 at the start
    assert model.policy.log_std.shape == (act_dim,) and torch.all(model.policy.log_std == 0.0)
    normalizer = model.get_vec_normalize_env()
    assert isinstance(normalizer, VecNormalize)
    assert normalizer.norm_obs and normalizer.norm_reward and normalizer.gamma == 1.0
    assert normalizer.clip_obs == 10.0 and normalizer.clip_reward == 10.0


def test_step_size_decays_over_the_whole_run() -> None:
    """Update k of U takes α (1 − k / U), also when learn() is called once per update."""
    config = _tiny("reacher5", n_rollout_steps=64, total_steps=3 * 64, batch_size=32)
    model = make_ppo_ch4("reacher5", config, seed=0)
    seen = []
    for _ in range(3):
        model.learn(64, reset_num_timesteps=False, log_interval=None)
        seen.append(model.policy.optimizer.param_groups[0]["lr"])
    assert seen == pytest.approx([3e-4, 3e-4 * 2 / 3, 3e-4 / 3], rel=1e-12)
    fixed = make_ppo_ch4("reacher5", _tiny("reacher5", anneal_lr=False), seed=0)
    fixed.learn(256, log_interval=None)
    assert fixed.policy.optimizer.param_groups[0]["lr"] == 3e-4


# -- evaluation -----------------------------------------------------------------------------


def test_evaluation_contexts_are_fixed_draws_from_p_c() -> None:
    goals = evaluation_contexts("reacher5", 100)
    assert goals.shape == (100, 2) and np.all(np.hypot(goals[:, 0], goals[:, 1]) <= 0.5)
    assert goals[:, 0].min() < -0.2 and goals[:, 0].max() > 0.2  # the whole disk
    np.testing.assert_array_equal(goals, evaluation_contexts("reacher5", 100))
    assert not np.array_equal(goals, evaluation_contexts("reacher5", 100, seed=1))
    c = evaluation_contexts("box-pushing-obstacle", 50)
    assert c.shape == (50, 5)
    start = np.array([0.4, 0.3])  # B.4.2.1: goal and obstacle away from the box start
    assert np.all((c >= [0.3, -0.7, 0.0, 0.3, -0.3]) & (c <= [0.6, 0.45, 2 * np.pi, 0.6, 0.15]))
    assert np.all(np.linalg.norm(c[:, :2] - start, axis=1) > 0.3)
    assert np.all(np.linalg.norm(c[:, 3:] - start, axis=1) >= 0.15)
    assert np.all(np.linalg.norm(c[:, 3:] - c[:, :2], axis=1) >= 0.15)
    assert np.all(c[:, 1] < c[:, 4])


def _set_statistics(model, dim: int) -> None:
    rng = np.random.default_rng(0)  # non-trivial statistics, so normalisation matters
    normalizer = model.get_vec_normalize_env()
    normalizer.obs_rms.mean = rng.normal(size=dim)
    normalizer.obs_rms.var = rng.uniform(0.5, 2.0, size=dim)


def _hand_mean_action(model, obs: np.ndarray) -> np.ndarray:
    rms = model.get_vec_normalize_env().obs_rms
    z = np.clip((obs - rms.mean) / np.sqrt(rms.var + 1e-8), -10.0, 10.0)
    with torch.no_grad():
        dist = model.policy.get_distribution(torch.as_tensor(z[None], dtype=torch.float32))
    return np.clip(dist.distribution.mean.numpy()[0], -1.0, 1.0)


def test_evaluate_reacher_matches_a_hand_written_rollout() -> None:
    """Mean action on normalised observations; return −Σ|a|² − 200 d_T − 10 |q̇_T|²."""
    model = make_ppo_ch4("reacher5", _tiny("reacher5"), seed=5)
    _set_statistics(model, 20)
    goals = np.array([[0.3, 0.2], [-0.1, -0.35]])
    got = evaluate(model, "reacher5", [Reacher5SparseStepEnv() for _ in goals], goals)
    lengths = np.array([0.1, 0.1, 0.1, 0.1, 0.11])
    returns, distances = [], []
    for goal in goals:
        env = Reacher5SparseStepEnv()
        obs, _ = env.reset(options={"goal": goal})
        total = 0.0
        for _ in range(200):
            action = _hand_mean_action(model, obs)
            obs, _, _, _, _ = env.step(action)
            total -= np.sum(action.astype(np.float64) ** 2)
        phi = np.cumsum(env.sim.q)
        distance = np.linalg.norm(
            [np.cos(phi) @ lengths - goal[0], np.sin(phi) @ lengths - goal[1]]
        )
        total -= 200.0 * distance + 10.0 * np.sum(env.sim.dq**2)
        returns.append(total)
        distances.append(distance)
    assert set(got) == {"test_return", "test_return_std", "test_tip_distance"}
    assert got["test_return"] == pytest.approx(np.mean(returns), rel=1e-6)
    assert got["test_return_std"] == pytest.approx(np.std(returns), rel=1e-4)
    assert got["test_tip_distance"] == pytest.approx(np.mean(distances), rel=1e-6)


def test_evaluate_box_pushing_matches_a_hand_written_rollout() -> None:
    """Sum of the step rewards; success: final position error < 0.05 m, rotation < 0.5 rad."""
    model = make_ppo_ch4("box-pushing-obstacle", _tiny("box-pushing-obstacle"), seed=5)
    _set_statistics(model, 30)
    contexts = evaluation_contexts("box-pushing-obstacle", 2)
    envs = [BoxPushingObstacleStepEnv() for _ in contexts]
    got = evaluate(model, "box-pushing-obstacle", envs, contexts)
    returns, success = [], []
    for c in contexts:
        env = BoxPushingObstacleStepEnv()
        obs, _ = env.reset(options={"context": c})
        total, done = 0.0, False
        while not done:
            obs, r, done, _, info = env.step(_hand_mean_action(model, obs))
            total += r
        box = env.task.data.body("box_0")
        goal_q = np.array([np.cos(c[2] / 2), 0.0, 0.0, np.sin(c[2] / 2)])  # yaw φ_g
        rotation = 2.0 * np.arccos(min(abs(float(box.xquat @ goal_q)), 1.0))
        position = np.linalg.norm(box.xpos - [c[0], c[1], -0.01])  # the goal at z = -0.01
        returns.append(total)
        success.append(position < 0.05 and rotation < 0.5 and not info["unstable"])
    assert set(got) == {"test_return", "test_return_std", "test_success"}
    assert got["test_return"] == pytest.approx(np.mean(returns), rel=1e-6)
    assert got["test_success"] == np.mean(success)


class _FixedLengthEnv:
    """Stand-in environment whose episode ends after ``length`` steps (reward 1 per step)."""

    def __init__(self, length: int) -> None:
        self.length, self.t = length, 0
        self.task = SimpleNamespace(context_dim=2)

    def reset(self, options=None):
        self.t = 0
        return np.zeros(20), {}

    def step(self, action):
        if self.t >= self.length:
            raise RuntimeError("stepped after the end of the episode")
        self.t += 1
        info = {"tip_distance": float(self.length)}
        return np.full(20, self.t / 10.0), 1.0, self.t == self.length, False, info


def test_evaluate_stops_each_episode_at_its_end() -> None:
    """Episodes that end early (an unstable box-pushing simulation) are not stepped on."""
    model = make_ppo_ch4("reacher5", _tiny("reacher5"), seed=0)
    envs = [_FixedLengthEnv(n) for n in (3, 7, 5)]
    got = evaluate(model, "reacher5", envs, np.zeros((3, 2)))
    assert [e.t for e in envs] == [3, 7, 5]
    assert got["test_return"] == 5.0 and got["test_return_std"] == pytest.approx(np.std([3, 7, 5]))
    assert got["test_tip_distance"] == 5.0


# -- training, determinism, resume ----------------------------------------------------------


def test_metrics_layout(uninterrupted) -> None:
    task, rows = uninterrupted
    assert [r["env_steps"] for r in rows] == [0, 256, 512]
    assert [r["updates"] for r in rows] == [0, 1, 2]
    # finished episodes: 2 environments × 128 / 256 steps of 200 (5LR) or 100 (BPO) steps
    assert [r["episodes"] for r in rows] == ([0, 0, 2] if task == "reacher5" else [0, 2, 4])
    key = "test_tip_distance" if task == "reacher5" else "test_success"
    for r in rows:
        assert np.isfinite(r["test_return"]) and r["test_return"] < 0.0 and key in r
    assert "approx_kl" not in rows[0] and rows[1]["approx_kl"] > 0.0


def test_the_seed_changes_the_run() -> None:
    a = make_ppo_ch4("reacher5", _tiny("reacher5"), seed=0).policy.state_dict()
    b = make_ppo_ch4("reacher5", _tiny("reacher5"), seed=1).policy.state_dict()
    c = make_ppo_ch4("reacher5", _tiny("reacher5"), seed=0).policy.state_dict()
    assert all(torch.equal(a[k], c[k]) for k in a)
    assert not all(torch.equal(a[k], b[k]) for k in a)


def test_resume_gives_the_uninterrupted_metrics(tmp_path, uninterrupted) -> None:
    """Same seed, same numbers; interrupted after the mid-episode checkpoint and resumed."""
    task, rows = uninterrupted
    first = train_ppo_ch4(
        task, _tiny(task), seed=3, run_dir=tmp_path, stop_after_evals=2, **TINY_RUN
    )
    assert len(first) == 2 and (tmp_path / CHECKPOINT_FILE).exists()
    assert _without_wall_clock(first) == _without_wall_clock(rows[:2])
    resumed = train_ppo_ch4(task, _tiny(task), seed=3, run_dir=tmp_path, **TINY_RUN)
    assert _without_wall_clock(resumed) == _without_wall_clock(rows)
    assert not list(tmp_path.glob("*.tmp"))


def test_checkpoint_of_another_run_is_refused(tmp_path) -> None:
    train_ppo_ch4(
        "reacher5", _tiny("reacher5"), 3, run_dir=tmp_path, stop_after_evals=1, **TINY_RUN
    )
    with pytest.raises(ValueError, match="seed"):
        train_ppo_ch4("reacher5", _tiny("reacher5"), 4, run_dir=tmp_path, **TINY_RUN)
    with pytest.raises(ValueError, match="task"):
        box = _tiny("box-pushing-obstacle", net_arch=(32, 32), learning_rate=3e-4, batch_size=64)
        train_ppo_ch4("box-pushing-obstacle", box, 3, run_dir=tmp_path, **TINY_RUN)
    # the step size is annealed over total_steps, so the run's length is part of it
    with pytest.raises(ValueError, match="lr_schedule_steps"):
        longer = _tiny("reacher5", total_steps=1024)
        train_ppo_ch4("reacher5", longer, 3, run_dir=tmp_path, **TINY_RUN)


# -- bad input ------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "changes, match",
    [
        ({"batch_size": 1}, "batch_size"),
        ({"batch_size": 257}, "batch_size"),
        ({"clip_range_vf": -0.1}, "clip_range_vf"),
        ({"clip_range_vf": True}, "clip_range_vf"),
        ({"anneal_lr": 1}, "anneal_lr"),
        ({"normalize": "yes"}, "normalize"),
        ({"gamma": 0.0}, "gamma"),
        ({"learning_rate": float("nan")}, "learning_rate"),
        ({"net_arch": ()}, "net_arch"),
        ({"total_steps": 300}, "total_steps"),
        ({"n_envs": 3}, "n_rollout_steps"),
        ({"n_epochs": 0}, "n_epochs"),
        ({"n_rollout": 10}, "unknown PPOCh4Config fields"),
    ],
)
def test_bad_config_is_refused(changes, match) -> None:
    with pytest.raises(ValueError, match=match):
        _tiny("reacher5", **changes)


def test_bad_arguments_are_refused() -> None:
    with pytest.raises(ValueError, match="task must be one of"):
        ppo_ch4_config("reacher5-ch3")
    with pytest.raises(ValueError, match="task must be one of"):
        train_ppo_ch4("hopper-jump", _tiny("reacher5"), 0, **TINY_RUN)
    with pytest.raises(ValueError, match="n_rollout_steps"):
        matched_total_steps("reacher5", 0)
    with pytest.raises(ValueError, match="n must be"):
        evaluation_contexts("reacher5", 0)
    config = _tiny("reacher5")
    for kwargs, match in (
        ({"config": "ppo"}, "PPOCh4Config"),
        ({"seed": -1}, "seed"),
        ({"eval_every": 100}, "eval_every"),
        ({"eval_episodes": 0}, "eval_episodes"),
        ({"stop_after_evals": 0}, "stop_after_evals"),
    ):
        args = {"config": config, "seed": 0, **TINY_RUN, **kwargs}
        with pytest.raises(ValueError, match=match):
            train_ppo_ch4("reacher5", **args)


def test_evaluate_refuses_bad_contexts() -> None:
    model = make_ppo_ch4("reacher5", _tiny("reacher5"), seed=0)
    envs = [Reacher5SparseStepEnv() for _ in range(2)]
    for contexts in (np.zeros((3, 2)), np.zeros((2, 5)), np.array([[0.1, np.nan], [0.1, 0.1]])):
        with pytest.raises(ValueError, match="contexts must be finite with shape"):
            evaluate(model, "reacher5", envs, contexts)
    with pytest.raises(ValueError, match="outside the task's context space"):
        evaluate(model, "reacher5", envs, np.array([[0.6, 0.0], [0.1, 0.1]]))

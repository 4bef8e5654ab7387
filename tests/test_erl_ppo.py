"""PPO baseline of Chapter 3 (vslbook.erl.ppo): Table A.5, evaluation, determinism, resume."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from stable_baselines3.common.vec_env import VecNormalize

from vslbook.envs.robot.reacher5_step import Reacher5Ch3StepEnv
from vslbook.erl.ppo import (
    CHECKPOINT_FILE,
    PPOConfig,
    evaluate,
    evaluation_goals,
    make_ppo,
    train_ppo,
)

# a few PPO updates of 512 steps from 2 environments (256 steps each: mid-episode)
TINY = PPOConfig(n_rollout_steps=512, n_envs=2, n_epochs=2, total_steps=3 * 512)
TINY_RUN = {"eval_every": 512, "eval_episodes": 3}


def _without_wall_clock(metrics: list[dict]) -> list[dict]:
    return [{k: v for k, v in row.items() if k != "env_steps_per_s"} for row in metrics]


@pytest.fixture(scope="module")
def uninterrupted() -> list[dict]:
    return train_ppo("3.9", TINY, seed=3, **TINY_RUN)


def _linear_widths(net: torch.nn.Module) -> list[int]:
    return [m.out_features for m in net.modules() if isinstance(m, torch.nn.Linear)]


@pytest.mark.parametrize("reward, obs_dim", [("3.8", 19), ("3.10", 20)])
def test_model_carries_table_a5(reward: str, obs_dim: int) -> None:
    model = make_ppo(reward, PPOConfig(), seed=0)
    # Table A.5: α 1e-4, N 16384, GAE λ 0.95, γ 0.99, K 64, ϵ 0.2, [64, 64] for π and V
    assert model.learning_rate == 1e-4
    assert model.lr_schedule(1.0) == 1e-4 and model.lr_schedule(0.0) == 1e-4
    assert model.policy.optimizer.param_groups[0]["lr"] == 1e-4
    assert model.n_steps * model.n_envs == 16384
    assert model.rollout_buffer.buffer_size * model.rollout_buffer.n_envs == 16384
    assert model.gae_lambda == 0.95
    assert model.gamma == 0.99
    assert model.batch_size == 64
    assert model.clip_range(1.0) == 0.2 and model.clip_range(0.0) == 0.2
    assert model.clip_range_vf is None
    assert model.n_epochs == 10  # not in the thesis: SB3's default
    assert model.observation_space.shape == (obs_dim,)
    extractor = model.policy.mlp_extractor
    assert _linear_widths(extractor.policy_net) == [64, 64]
    assert _linear_widths(extractor.value_net) == [64, 64]
    assert model.policy.action_net.in_features == 64 and model.policy.action_net.out_features == 5
    assert model.policy.value_net.in_features == 64
    first = next(m for m in extractor.policy_net.modules() if isinstance(m, torch.nn.Linear))
    assert first.in_features == obs_dim
    normalizer = model.get_vec_normalize_env()
    assert isinstance(normalizer, VecNormalize)
    assert normalizer.norm_obs and normalizer.norm_reward and normalizer.gamma == 0.99
    assert model.get_env().num_envs == 16


def test_evaluation_goals_are_fixed_and_in_the_right_half_disk() -> None:
    goals = evaluation_goals(200)
    assert goals.shape == (200, 2)
    assert np.all(goals[:, 0] >= 0.0) and np.all(np.hypot(goals[:, 0], goals[:, 1]) <= 0.5)
    assert goals[:, 1].min() < -0.2 and goals[:, 1].max() > 0.2  # spread over the half disk
    np.testing.assert_array_equal(goals, evaluation_goals(200))
    assert not np.array_equal(goals, evaluation_goals(200, seed=1))


def test_evaluate_matches_a_hand_written_rollout() -> None:
    """Deterministic policy on normalised observations, thesis return, final tip distance."""
    model = make_ppo("3.9", TINY, seed=5)
    normalizer = model.get_vec_normalize_env()
    rng = np.random.default_rng(0)  # non-trivial statistics, so normalisation matters
    normalizer.obs_rms.mean = rng.normal(size=20)
    normalizer.obs_rms.var = rng.uniform(0.5, 2.0, size=20)
    goals = np.array([[0.3, 0.2], [0.1, -0.35]])
    got = evaluate(model, [Reacher5Ch3StepEnv("3.9") for _ in goals], goals)

    lengths = np.array([0.1, 0.1, 0.1, 0.1, 0.11])
    returns, distances = [], []
    for goal in goals:
        env = Reacher5Ch3StepEnv("3.9")
        obs, _ = env.reset(options={"goal": goal})
        total = 0.0
        for t in range(200):
            z = np.clip((obs - normalizer.obs_rms.mean) / np.sqrt(normalizer.obs_rms.var + 1e-8),
                        -10.0, 10.0)  # fmt: skip
            with torch.no_grad():
                dist = model.policy.get_distribution(torch.as_tensor(z[None], dtype=torch.float32))
            action = np.clip(dist.distribution.mean.numpy()[0], -1.0, 1.0)
            obs, _, _, _, _ = env.step(action)
            phi = np.cumsum(env.sim.q)
            tip = np.array([np.cos(phi) @ lengths, np.sin(phi) @ lengths])
            distance = np.linalg.norm(tip - goal)
            total += -np.sum(action**2) - (distance if t >= 190 else 0.0)  # Eq. 3.9
        returns.append(total)
        distances.append(distance)
    assert got["eval_return"] == pytest.approx(np.mean(returns), rel=1e-5)
    assert got["eval_return_std"] == pytest.approx(np.std(returns), rel=1e-4)
    assert got["eval_tip_distance"] == pytest.approx(np.mean(distances), rel=1e-6)


def test_metrics_layout(uninterrupted: list[dict]) -> None:
    assert [row["env_steps"] for row in uninterrupted] == [0, 512, 1024, 1536]
    assert [row["updates"] for row in uninterrupted] == [0, 1, 2, 3]
    # 2 environments × 256, 512, 768 steps: 1, 2, 3 finished 200-step episodes each
    assert [row["episodes"] for row in uninterrupted] == [0, 2, 4, 6]
    for row in uninterrupted:
        assert np.isfinite(row["eval_return"]) and row["eval_return"] < 0.0
        assert 0.0 <= row["eval_tip_distance"] <= 1.01
    assert "approx_kl" not in uninterrupted[0] and "approx_kl" in uninterrupted[1]


def test_same_seed_same_metrics(uninterrupted: list[dict]) -> None:
    again = train_ppo("3.9", TINY, seed=3, **TINY_RUN)
    assert _without_wall_clock(again) == _without_wall_clock(uninterrupted)
    one_update = PPOConfig(n_rollout_steps=512, n_envs=2, n_epochs=2, total_steps=512)
    other = train_ppo("3.9", one_update, seed=4, **TINY_RUN)
    assert other[1]["eval_return"] != uninterrupted[1]["eval_return"]


def test_training_makes_no_logger_folder(tmp_path, monkeypatch) -> None:
    """SB3 gives a model without a logger of its own an empty folder SB3-<time> (under
    ``SB3_LOGDIR``, else the temp dir) on every ``learn``; the training loop sets one that
    writes nowhere, and still copies the update statistics into the metrics."""
    monkeypatch.setenv("SB3_LOGDIR", str(tmp_path / "sb3"))
    one_update = PPOConfig(n_rollout_steps=512, n_envs=2, n_epochs=2, total_steps=512)
    rows = train_ppo("3.9", one_update, seed=4, **TINY_RUN)
    assert not (tmp_path / "sb3").exists()
    assert "approx_kl" in rows[1]


@pytest.mark.parametrize("stop_after_evals", [1, 2])
def test_resume_gives_the_uninterrupted_metrics(
    tmp_path, uninterrupted: list[dict], stop_after_evals: int
) -> None:
    """Interrupted after its first (initial) or second (mid-episode) checkpoint, resumed."""
    first = train_ppo(
        "3.9", TINY, seed=3, run_dir=tmp_path, stop_after_evals=stop_after_evals, **TINY_RUN
    )
    assert len(first) == stop_after_evals and (tmp_path / CHECKPOINT_FILE).exists()
    resumed = train_ppo("3.9", TINY, seed=3, run_dir=tmp_path, **TINY_RUN)
    assert _without_wall_clock(resumed) == _without_wall_clock(uninterrupted)
    assert not list(tmp_path.glob("*.tmp"))
    # a finished run resumes to the same metrics without training
    assert _without_wall_clock(
        train_ppo("3.9", TINY, seed=3, run_dir=tmp_path, **TINY_RUN)
    ) == _without_wall_clock(uninterrupted)


def test_checkpoint_of_another_run_is_refused(tmp_path) -> None:
    train_ppo("3.9", TINY, seed=3, run_dir=tmp_path, stop_after_evals=1, **TINY_RUN)
    with pytest.raises(ValueError, match="seed"):
        train_ppo("3.9", TINY, seed=4, run_dir=tmp_path, **TINY_RUN)


def test_bad_input() -> None:
    with pytest.raises(ValueError, match="3.7"):
        train_ppo("3.7", TINY, seed=0, **TINY_RUN)
    with pytest.raises(ValueError, match="3.7"):
        make_ppo("3.7", TINY, seed=0)
    with pytest.raises(ValueError, match="eval_every"):
        train_ppo("3.8", TINY, seed=0, eval_every=500)
    with pytest.raises(ValueError, match="seed"):
        train_ppo("3.8", TINY, seed=-1, **TINY_RUN)
    with pytest.raises(ValueError, match="n_envs"):
        PPOConfig(n_rollout_steps=1000, n_envs=16)
    with pytest.raises(ValueError, match="total_steps"):
        PPOConfig(total_steps=1000)
    with pytest.raises(ValueError, match="gamma"):
        PPOConfig(gamma=1.5)
    with pytest.raises(ValueError, match="net_arch"):
        PPOConfig(net_arch=(64, 0))

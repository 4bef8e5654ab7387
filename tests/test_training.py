"""Determinism, exact resume and bad input for the run machinery (via the erl-pg loop)."""

import json

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from vslbook.envs import make
from vslbook.results import RunDir
from vslbook.training import run

ENV = "vslbook/PointReach-v0"


def _metrics(rd: RunDir):
    return [json.loads(line) for line in (rd.path / "metrics.jsonl").read_text().splitlines()]


def test_point_reach_passes_env_checker():
    env = make(ENV)
    check_env(env.unwrapped, skip_render_check=True)
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs)


def test_point_reach_is_solvable_by_a_linear_policy():
    env = make(ENV).unwrapped
    c = env.sample_contexts(16, np.random.default_rng(0))
    # the final position is linear in θ: solve Φ_T θ = c in the least-squares sense per context
    basis = env.trajectories(np.eye(env.n_params))[:, -1, :]  # (n_params, 2)
    theta = np.linalg.lstsq(basis.T, c.T, rcond=None)[0].T
    ret, success = env.evaluate(theta, c)
    assert success.all() and ret.max() <= 0


def test_unknown_env_and_algorithm_are_clear_errors(tmp_path):
    with pytest.raises(ValueError, match=r"unknown environment 'vslbook/Nope-v0'"):
        make("vslbook/Nope-v0")
    with pytest.raises(ValueError, match=r"unknown algorithm 'nope'.*erl-pg"):
        run("nope", ENV, root=tmp_path)
    with pytest.raises(ValueError, match=r"does not support env 'Pendulum-v1'"):
        run("erl-pg", "Pendulum-v1", root=tmp_path)
    with pytest.raises(ValueError, match=r"has no field 'lr'.*learning_rate"):
        run("erl-pg", ENV, root=tmp_path, overrides={"lr": 1})
    with pytest.raises(ValueError, match=r"samples_per_iteration must be >= 1, got 0"):
        run("erl-pg", ENV, root=tmp_path, overrides={"samples_per_iteration": 0})


def test_wrong_action_shape_is_a_clear_error():
    env = make(ENV)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"action must have shape \(10,\), got \(3,\)"):
        env.step(np.zeros(3))


def test_same_seed_same_metrics(tmp_path):
    a = run("erl-pg", ENV, seed=3, budget="smoke", root=tmp_path / "a", progress=False)
    b = run("erl-pg", ENV, seed=3, budget="smoke", root=tmp_path / "b", progress=False)
    c = run("erl-pg", ENV, seed=4, budget="smoke", root=tmp_path / "c", progress=False)
    assert a.done and b.done
    assert _metrics(a) == _metrics(b)
    assert _metrics(a) != _metrics(c)


def test_learning_happens(tmp_path):
    rd = run("erl-pg", ENV, seed=0, budget="smoke", root=tmp_path, progress=False)
    rows = [r for r in _metrics(rd) if "eval_return" in r]
    assert rows[-1]["eval_return"] > rows[0]["eval_return"]


def test_resume_after_clean_stop_is_exact(tmp_path):
    full = run("erl-pg", ENV, seed=1, budget="smoke", root=tmp_path / "full", progress=False)
    part = run(
        "erl-pg", ENV, seed=1, budget="smoke", root=tmp_path / "part", progress=False, stop_after=7
    )
    assert not part.done
    resumed = run("erl-pg", ENV, seed=1, budget="smoke", root=tmp_path / "part", progress=False)
    assert resumed.done and _metrics(resumed) == _metrics(full)


def test_resume_after_crash_between_checkpoints_is_exact(tmp_path, monkeypatch):
    over = {"checkpoint_every": 5}
    full = run(
        "erl-pg",
        ENV,
        seed=2,
        budget="smoke",
        root=tmp_path / "full",
        progress=False,
        overrides=over,
    )
    original_log = RunDir.log

    def crashing_log(self, step, **metrics):
        if step == 13:
            raise KeyboardInterrupt("simulated interruption")
        return original_log(self, step, **metrics)

    monkeypatch.setattr(RunDir, "log", crashing_log)
    with pytest.raises(KeyboardInterrupt):
        run(
            "erl-pg",
            ENV,
            seed=2,
            budget="smoke",
            root=tmp_path / "crash",
            progress=False,
            overrides=over,
        )
    monkeypatch.setattr(RunDir, "log", original_log)
    resumed = run(
        "erl-pg",
        ENV,
        seed=2,
        budget="smoke",
        root=tmp_path / "crash",
        progress=False,
        overrides=over,
    )
    assert _metrics(resumed) == _metrics(full)


def test_done_run_is_not_retrained(tmp_path):
    rd = run("erl-pg", ENV, seed=0, budget="smoke", root=tmp_path, progress=False)
    before = (rd.path / "metrics.jsonl").read_bytes()
    again = run("erl-pg", ENV, seed=0, budget="smoke", root=tmp_path, progress=False)
    assert again.path == rd.path and (rd.path / "metrics.jsonl").read_bytes() == before


def test_gym_make_registered_id():
    assert "vslbook/PointReach-v0" in gym.registry


def test_a_partial_run_made_by_other_code_that_replays_identically_resumes(tmp_path, capsys):
    """A refactor must never cost a trained run: a partial run whose code fingerprint differs
    is kept when today's code replays its first rows, and resumes exactly."""
    full = run("erl-pg", ENV, seed=5, budget="smoke", root=tmp_path / "full", progress=False)
    part = run("erl-pg", ENV, seed=5, budget="smoke", root=tmp_path / "part", progress=False,
               stop_after=7)  # fmt: skip
    env = json.loads((part.path / "env.json").read_text())
    env["code_hash"] = "f" * 64
    (part.path / "env.json").write_text(json.dumps(env))
    resumed = run("erl-pg", ENV, seed=5, budget="smoke", root=tmp_path / "part", progress=False)
    assert "replay identically with today's code: kept" in capsys.readouterr().out
    assert resumed.done and _metrics(resumed) == _metrics(full)
    assert not (tmp_path / "part" / "_stale").exists()

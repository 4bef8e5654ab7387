"""DIME's training loop (Algorithm 4): runs, determinism, exact resume, α, bad configs."""

import json

import pytest
import torch

from vslbook.srl.dime import (
    DIMEConfig,
    actor_update,
    alpha_update,
    make_agent,
)
from vslbook.srl.replay import ReplayBuffer
from vslbook.training import run

ENV = "Pendulum-v1"
# Tiny networks and a few hundred steps: the full-budget counts are scaled by "smoke" (0.2 %).
TINY = dict(
    total_steps=200_000,  # -> 400 env steps (two Pendulum episodes) at the smoke budget
    learning_starts=0,  # updates from the first step (the default 5000 scales to 1000)
    critic_hidden=32,
    actor_hidden=32,
    n_diffusion_steps=2,
    batch_size=32,
    eval_every=100_000,  # -> 1000 minimum: one evaluation at the end
    eval_episodes=1,
    checkpoint_every=100_000,
    v_min=-1600.0,
    v_max=100.0,
    num_threads=1,
)


def _tiny(**extra):
    over = dict(TINY)
    over.update(extra)
    return over


def _metrics(rd):
    return [json.loads(x) for x in (rd.path / "metrics.jsonl").read_text().splitlines()]



def _run(root, algo="dime", seed=0, **extra):
    return run(algo, ENV, seed, "smoke", root=root, overrides=_tiny(**extra), progress=False)


def test_loop_runs_updates_and_logs(tmp_path):
    rd = _run(tmp_path, learning_starts=0)
    rows = _metrics(rd)
    assert rd.done and rows[-1]["step"] == 400
    assert rows[-1]["critic_updates"] > 0 and "eval_return" in rows[-1]


def test_same_seed_same_metrics(tmp_path):
    a = _run(tmp_path / "a", learning_starts=0)
    b = _run(tmp_path / "b", learning_starts=0)
    drop = {"critic_updates_per_s", "env_steps_per_s"}
    strip = [{k: v for k, v in r.items() if k not in drop} for r in _metrics(a)]
    assert strip == [{k: v for k, v in r.items() if k not in drop} for r in _metrics(b)]


@pytest.mark.slow
def test_resume_is_exact(tmp_path):
    over = dict(learning_starts=0)
    full = _run(tmp_path / "full", **over)
    part = run(
        "dime",
        ENV,
        0,
        "smoke",
        root=tmp_path / "part",
        overrides=_tiny(**over),
        progress=False,
        stop_after=200,
    )
    assert not part.done
    resumed = _run(tmp_path / "part", **over)
    drop = {"critic_updates_per_s", "env_steps_per_s"}
    clean = lambda rows: [{k: v for k, v in r.items() if k not in drop} for r in rows]  # noqa: E731
    assert clean(_metrics(resumed)) == clean(_metrics(full))


@pytest.mark.parametrize("algo", ["crossq", "dime-gaussian"])
def test_variants_run(tmp_path, algo):
    rd = _run(tmp_path, algo=algo, learning_starts=0)
    assert rd.done


def test_ablation_switches_run(tmp_path):
    rd = _run(
        tmp_path,
        learning_starts=0,
        critic="scalar",
        general_bridges=True,
        use_target_network=True,
        fixed_alpha=0.1,
    )
    assert rd.done and _metrics(rd)[-1]["alpha"] == pytest.approx(0.1)


def _agent(**over):
    cfg = DIMEConfig(
        **{
            **dict(critic_hidden=16, actor_hidden=16, n_diffusion_steps=2, v_min=-10.0, v_max=10.0),
            **over,
        }
    )
    return make_agent(3, 2, cfg, v_min=cfg.v_min, v_max=cfg.v_max)


def test_alpha_moves_towards_the_entropy_target():
    agent = _agent()
    before = agent.alpha.item()
    # running cost far below the target (entropy above target) -> α decreases; above -> increases
    alpha_update(agent, torch.full((8,), agent.h_target - 100.0))
    assert agent.alpha.item() < before
    agent = _agent()
    alpha_update(agent, torch.full((8,), agent.h_target + 100.0))
    assert agent.alpha.item() > before


def test_actor_update_leaves_critic_untouched():
    agent = _agent()
    weights = [p.detach().clone() for p in agent.critic.parameters()]
    buffers = [b.detach().clone() for b in agent.critic.buffers()]
    actor_update(agent, torch.randn(16, 3))
    assert all(p.grad is None for p in agent.critic.parameters())
    assert all(torch.equal(a, b) for a, b in zip(weights, agent.critic.parameters(), strict=True))
    assert all(torch.equal(a, b) for a, b in zip(buffers, agent.critic.buffers(), strict=True))


def test_replay_round_trip():
    buf = ReplayBuffer(10, 3, 2, torch.device("cpu"))
    for i in range(13):
        buf.add([i, 0, 0], [0.0, 1.0], float(i), [i + 1, 0, 0], False)
    other = ReplayBuffer(10, 3, 2, torch.device("cpu"))
    other.load_state_dict(buf.state_dict())
    import numpy as np

    a = buf.sample(5, np.random.default_rng(0))
    b = other.sample(5, np.random.default_rng(0))
    assert torch.equal(a.obs, b.obs) and torch.equal(a.reward, b.reward)


def test_replay_indices_from_a_device_generator():
    import numpy as np

    from vslbook.srl.replay import replay_generator

    buf = ReplayBuffer(50, 1, 1, torch.device("cpu"))
    for i in range(30):  # 30 of 50 rows filled: indices must stay below 30
        buf.add([i], [0.0], float(i), [i + 1], False)
    gen = replay_generator("device", torch.device("cpu"), 7)
    draws = torch.cat([buf.sample(64, gen).reward for _ in range(200)])
    assert draws.min() == 0 and draws.max() == 29 and torch.equal(draws, draws.round())
    counts = torch.bincount(draws.long(), minlength=30).double()  # uniform: chi-square test
    chi2 = float(((counts - counts.mean()) ** 2 / counts.mean()).sum())
    assert chi2 < 58.3  # the 0.999 quantile of chi-square with 29 degrees of freedom
    again = replay_generator("device", torch.device("cpu"), 7)  # same seed, same batch
    assert torch.equal(buf.sample(64, again).obs, buf.sample(64, replay_generator(
        "device", torch.device("cpu"), 7)).obs)  # fmt: skip
    assert replay_generator("auto", torch.device("cpu"), 7) is None  # CPU: numpy's stream
    assert replay_generator("numpy", torch.device("cpu"), 7) is None
    with pytest.raises(ValueError, match="unknown replay_sampler 'gpu'"):
        replay_generator("gpu", torch.device("cpu"), 7)
    on_meta = ReplayBuffer(4, 1, 1, torch.device("meta"))
    on_meta.add([0.0], [0.0], 0.0, [0.0], False)
    with pytest.raises(ValueError, match="the index generator is on cpu, the buffer on meta"):
        on_meta.sample(2, gen)
    assert buf.sample(3, np.random.default_rng(0)).obs.shape == (3, 1)


@pytest.mark.parametrize(
    ("over", "match"),
    [
        (dict(v_min=5.0, v_max=5.0), "need v_min < v_max"),
        (dict(replay_sampler="gpu"), "unknown replay_sampler 'gpu'"),
        (dict(n_diffusion_steps=0), "n_diffusion_steps must be an integer >= 1"),
        (dict(utd=0), "utd must be an integer >= 1"),
        (dict(policy="flow"), "unknown policy 'flow'"),
        (dict(critic="quantile"), "unknown critic 'quantile'"),
        (dict(v_min=1.0), "set both v_min and v_max"),
    ],
)
def test_bad_configs_are_clear_errors(over, match):
    with pytest.raises(ValueError, match=match):
        DIMEConfig(**over)

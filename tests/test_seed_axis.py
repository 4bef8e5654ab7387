"""DIME over a seed axis (vslbook.srl.seed_axis): each seed's updates are its own.

The stacked updates are compared with S separate agents updated by the ordinary
single-seed functions on the same batches and the same random numbers.
"""

from __future__ import annotations

import copy

import pytest
import torch

from vslbook.srl.dime_config import DIMEConfig
from vslbook.srl.dime_updates import actor_update, alpha_update, critic_update, make_agent
from vslbook.srl.replay import Batch
from vslbook.srl.seed_axis import SeedStack

OBS, ACT, B = 6, 2, 32


def _agents(cfg: DIMEConfig, n: int) -> list:
    out = []
    for s in range(n):
        torch.manual_seed(s)
        out.append(make_agent(OBS, ACT, cfg, v_min=-10.0, v_max=10.0))
    return out


def _with_generator(g: torch.Generator, fn, *args):
    """``fn(*args)`` drawing from ``g`` where the single-seed code draws from the global RNG."""
    saved = torch.get_rng_state()
    torch.set_rng_state(g.get_state())
    try:
        out = fn(*args)
        g.set_state(torch.get_rng_state())
        return out
    finally:
        torch.set_rng_state(saved)


def _close(a: float, b: float) -> bool:
    return abs(a - b) <= 1e-4 * (1.0 + abs(a))


@pytest.mark.parametrize(
    "cfg",
    [
        DIMEConfig(critic_hidden=64, actor_hidden=32, n_diffusion_steps=3, renorm_warmup=2),
        DIMEConfig(critic_hidden=64, actor_hidden=32, policy="gaussian", critic="scalar",
                   q_reduce="min", renorm_warmup=2),  # fmt: skip
    ],
    ids=["dime", "gaussian-scalar-min"],
)
@pytest.mark.parametrize("n_seeds", [1, 3])
def test_each_seed_updates_as_it_would_alone(cfg, n_seeds):
    torch.manual_seed(1234)
    alone = _agents(cfg, n_seeds)
    stack = SeedStack([copy.deepcopy(a) for a in alone])
    gen_alone = [torch.Generator().manual_seed(100 + s) for s in range(n_seeds)]
    gen_stack = [torch.Generator().manual_seed(100 + s) for s in range(n_seeds)]
    data_rng = torch.Generator().manual_seed(7)
    for k in range(6):  # BatchRenorm warms up for 2 passes, then renormalises
        per_seed = [
            Batch(torch.randn(B, OBS, generator=data_rng), torch.rand(B, ACT, generator=data_rng),
                  torch.randn(B, generator=data_rng), torch.randn(B, OBS, generator=data_rng),
                  (torch.rand(B, generator=data_rng) < 0.2).float())  # fmt: skip
            for _ in range(n_seeds)
        ]
        stacked = Batch(*[torch.stack(x) for x in zip(*per_seed, strict=True)])
        got = stack.critic_update(stacked, stack.noise(gen_stack, B))
        for s, agent in enumerate(alone):
            want = _with_generator(gen_alone[s], critic_update, agent, per_seed[s])
            assert _close(want.loss.item(), got.loss[s].item()), (k, s)
            assert _close(want.value.item(), got.value[s].item()), (k, s)
        if k % 2:
            obs = stacked.obs
            got = stack.actor_update(obs, stack.noise(gen_stack, B))
            got_alpha = stack.alpha_update(got.running_cost)
            for s, agent in enumerate(alone):
                want = _with_generator(gen_alone[s], actor_update, agent, obs[s])
                want_alpha = alpha_update(agent, want.running_cost)
                assert _close(want.loss.item(), got.loss[s].item()), (k, s)
                assert _close(want_alpha.item(), got_alpha[s].item()), (k, s)
    for s, agent in enumerate(alone):  # parameters, statistics, α and Adam moments
        mine, ref = stack.agent_state(s), agent.state_dict()
        for part in ("policy", "critic"):
            assert mine[part].keys() == ref[part].keys()
            for key, value in ref[part].items():
                torch.testing.assert_close(mine[part][key], value, rtol=1e-4, atol=1e-5)
        torch.testing.assert_close(mine["log_alpha"], ref["log_alpha"], rtol=1e-5, atol=1e-7)
        for opt in ("critic_opt", "actor_opt", "alpha_opt"):
            for i, st in ref[opt]["state"].items():
                torch.testing.assert_close(mine[opt]["state"][i]["exp_avg"], st["exp_avg"],
                                           rtol=1e-3, atol=1e-6)  # fmt: skip
                assert float(mine[opt]["state"][i]["step"]) == float(st["step"])


def test_a_seeds_state_is_an_ordinary_checkpoint_and_stacks_back():
    cfg = DIMEConfig(critic_hidden=32, actor_hidden=16, n_diffusion_steps=2)
    stack = SeedStack(_agents(cfg, 2))
    gens = [torch.Generator().manual_seed(s) for s in range(2)]
    batch = Batch(torch.randn(2, B, OBS), torch.rand(2, B, ACT), torch.randn(2, B),
                  torch.randn(2, B, OBS), torch.zeros(2, B))  # fmt: skip
    stack.critic_update(batch, stack.noise(gens, B))
    stack.actor_update(batch.obs, stack.noise(gens, B))
    restored = _agents(cfg, 2)
    for s, agent in enumerate(restored):
        agent.load_state_dict(stack.agent_state(s))
    again = SeedStack(restored)
    for name, value in stack.params.items():
        torch.testing.assert_close(again.params[name], value, rtol=0, atol=0)
    # the two continue identically
    g1 = [torch.Generator().manual_seed(9 + s) for s in range(2)]
    g2 = [torch.Generator().manual_seed(9 + s) for s in range(2)]
    a = stack.critic_update(batch, stack.noise(g1, B))
    b = again.critic_update(batch, again.noise(g2, B))
    torch.testing.assert_close(a.loss, b.loss, rtol=0, atol=0)


def test_seeds_stay_apart():
    """Changing one seed's batch changes no other seed's update."""
    cfg = DIMEConfig(critic_hidden=32, actor_hidden=16, n_diffusion_steps=2)
    agents = _agents(cfg, 3)
    one, two = SeedStack(copy.deepcopy(agents)), SeedStack(copy.deepcopy(agents))
    batch = Batch(torch.randn(3, B, OBS), torch.rand(3, B, ACT), torch.randn(3, B),
                  torch.randn(3, B, OBS), torch.zeros(3, B))  # fmt: skip
    other = Batch(*[x.clone() for x in batch])
    other.obs[1] += 1.0
    g1 = [torch.Generator().manual_seed(s) for s in range(3)]
    g2 = [torch.Generator().manual_seed(s) for s in range(3)]
    a = one.critic_update(batch, one.noise(g1, B))
    b = two.critic_update(other, two.noise(g2, B))
    assert a.loss[0] == b.loss[0] and a.loss[2] == b.loss[2] and a.loss[1] != b.loss[1]
    for name in one.buffers:  # BatchRenorm statistics are per seed
        if "running_mean" in name:
            assert torch.equal(one.buffers[name][0], two.buffers[name][0])
            assert not torch.equal(one.buffers[name][1], two.buffers[name][1])


def test_bad_input_is_a_clear_error():
    cfg = DIMEConfig(critic_hidden=32, actor_hidden=16, n_diffusion_steps=2)
    with pytest.raises(ValueError, match="at least one agent"):
        SeedStack([])
    other = DIMEConfig(critic_hidden=16, actor_hidden=16, n_diffusion_steps=2)
    with pytest.raises(ValueError, match="same configuration"):
        SeedStack(_agents(cfg, 1) + _agents(other, 1))
    target = DIMEConfig(critic_hidden=32, actor_hidden=16, n_diffusion_steps=2,
                        use_target_network=True)  # fmt: skip
    with pytest.raises(ValueError, match="without a target network"):
        SeedStack(_agents(target, 2))
    stack = SeedStack(_agents(cfg, 2))
    with pytest.raises(ValueError, match="need 2 generators, got 1"):
        stack.noise([torch.Generator()], B)
    with pytest.raises(ValueError, match=r"seed index must be in \[0, 2\), got 2"):
        stack.agent_state(2)

"""Di-SkilL's updates (Algorithm 2, lines 7-8; Eqs. 4.7, 4.8): the hand-written energy pass
against autograd, the batched updates against K independent single-expert updates, and the
float32 networks against float64 from the same start."""

from __future__ import annotations

import copy
from typing import ClassVar

import numpy as np
import pytest
import torch

from vslbook.envs.robot.task import Episode, EpisodicTask
from vslbook.erl import diskill_updates as U
from vslbook.erl.diskill import DiSkill
from vslbook.erl.diskill_config import DiSkillConfig
from vslbook.erl.diskill_nets import EnergyNets, GaussianExperts, ValueCritics

F64 = torch.float64


class Bowl(EpisodicTask):
    """c ∈ [−1, 1]⁴, θ ∈ R²³ (table tennis's sizes): R = −‖θ_:4 − c‖² − 0.1 ‖θ_4:‖² + c₀."""

    name = "toy-bowl"
    context_names = ("c0", "c1", "c2", "c3")
    context_low = -np.ones(4)
    context_high = np.ones(4)
    n_params = 23
    has_success: ClassVar[bool] = False

    def episodes(self, theta: np.ndarray, contexts: np.ndarray) -> list[Episode]:
        r = (-((theta[:, :4] - contexts) ** 2).sum(1) - 0.1 * (theta[:, 4:] ** 2).sum(1)
             + contexts[:, 0])  # fmt: skip
        return [Episode(float(x)) for x in r]


def config(**kw) -> DiSkillConfig:
    """Table tennis 4D's networks (Table B.2) with fewer contexts and epochs."""
    base = dict(
        n_experts=3, alpha=1e-3, beta=4.0, expert_hidden=(64,), critic_hidden=(8, 8),
        samples_per_expert=30, mean_bound=0.05, cov_bound=0.005, iterations=3,
        env_contexts=1000, epochs=20, critic_epochs=20, context_epochs=20, test_every=3,
        test_contexts=10, normaliser_contexts=500, lr_policy=3e-3, lr_context=1e-3,
    )  # fmt: skip
    return DiSkillConfig(**(base | kw))


def _randomise(module: torch.nn.Module, seed: int, scale: float = 0.5) -> None:
    g = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for p in module.parameters():
            p.copy_(scale * torch.randn(p.shape, generator=g, dtype=F64).to(p.dtype))


# ---------------------------------------------------------------- the energy networks' pass


@pytest.mark.parametrize("hidden", [(16, 16), (7,), (), (5, 6, 4)])
def test_energy_pass_equals_energies_and_their_autograd_gradient(hidden):
    torch.manual_seed(0)
    net = EnergyNets(3, 2, hidden)
    _randomise(net, 1)
    c = torch.rand(50, 2, dtype=F64) * 2 - 1
    g = torch.randn(3, 50, dtype=F64)
    phi, accumulate = U.energy_pass(net, c)
    ref = net.energies(c)
    torch.testing.assert_close(phi, ref.detach(), rtol=1e-12, atol=1e-12)
    (ref * g).sum().backward()
    expected = [p.grad.clone() for p in net.parameters()]
    net.zero_grad(set_to_none=True)
    accumulate(g)
    for p, e in zip(net.parameters(), expected, strict=True):
        torch.testing.assert_close(p.grad, e, rtol=1e-10, atol=1e-12)
    accumulate(g)  # a second call adds
    for p, e in zip(net.parameters(), expected, strict=True):
        torch.testing.assert_close(p.grad, 2 * e, rtol=1e-10, atol=1e-12)
    assert U.energy_pass(net, c, backward=False)[1] is None


def test_energy_pass_rejects_contexts_of_another_shape_or_dtype():
    net = EnergyNets(2, 3)
    with pytest.raises(ValueError, match=r"contexts must have shape \(N, 3\)"):
        U.energy_pass(net, torch.zeros(4, 2, dtype=F64))
    with pytest.raises(ValueError, match="dtype torch.float64"):
        U.energy_pass(net, torch.zeros(4, 3))


#: The energy networks' output bias: π(c | o), a softmax over contexts, does not depend on it,
#: so its gradient is rounding noise (±1e-13), which Adam turns into steps of size lr whose
#: signs depend on the rounding; comparisons of parameters leave it out.
HEAD_BIAS = "net.biases.2"


def _autograd_context_update(energies, opt, batch, adv, cfg):
    """Eq. 4.8 as the update was written before the hand-written pass: autograd through
    :meth:`EnergyNets.energies` (torch.tanh)."""
    c_env, idx, gate = batch["c_env"], batch["idx"], batch["log_gate_env"]
    params = list(energies.parameters())
    with torch.no_grad():
        logp_old = torch.log_softmax(energies.energies(c_env), -1).gather(1, idx)
    for _ in range(cfg.context_epochs):
        logp = torch.log_softmax(energies.energies(c_env), -1)
        ratio = torch.exp(logp.gather(1, idx) - logp_old)
        clipped = ratio.clamp(1 - cfg.context_clip, 1 + cfg.context_clip)
        surrogate = torch.minimum(ratio * adv, clipped * adv).mean(1)
        p = logp.exp()
        entropy = -(p * logp).sum(1)
        resp = (p * gate).sum(1)
        loss = (-surrogate - cfg.beta * entropy - (cfg.beta - cfg.alpha) * resp).sum()
        opt.zero_grad()
        loss.backward()
        U.clip_per_expert(params, cfg.context_grad_clip)
        opt.step()


# ---------------------------------------------------------------- a batch from the model


def _model_and_batch(cfg: DiSkillConfig, seed: int = 0):
    model = DiSkill(Bowl(), cfg, seed, workers=0)
    model.iterate()  # away from the initial model
    batch = model.collect()
    with torch.no_grad():
        entropy_old = model.experts.entropy(batch["chol_old"])
    return model, batch, entropy_old


def _context_adv(model, batch, entropy_old):
    cfg = model.config
    baseline = torch.as_tensor(batch["episode_returns"].mean(1), dtype=model.dtype)
    entropy = entropy_old[:, None]
    return batch["returns"] - baseline[:, None] + cfg.alpha * (batch["log_resp"] + entropy)


def _expert_adv(model, batch):
    with torch.no_grad():
        values = model.critics.values(batch["ctx"])
    return U.standardise(batch["returns"] - values + model.config.alpha * batch["log_resp"])


def test_context_update_equals_the_autograd_update():
    """The hand-written pass changes nothing but rounding: 20 epochs in float64 end within
    1e-10 of the same update through autograd and torch.tanh."""
    cfg = config(dtype="float64", n_experts=3)
    model, batch, entropy_old = _model_and_batch(cfg)
    adv = _context_adv(model, batch, entropy_old)
    ref = copy.deepcopy(model.energies)
    ref_opt = torch.optim.Adam(ref.parameters(), lr=cfg.lr_context, eps=1e-8)
    ref_opt.load_state_dict(copy.deepcopy(model.opt_context.state_dict()))
    U.update_contexts(model.energies, model.opt_context, batch, adv, cfg)
    _autograd_context_update(ref, ref_opt, batch, adv, cfg)
    for (name, p), q in zip(model.energies.named_parameters(), ref.parameters(), strict=True):
        if name != HEAD_BIAS:
            torch.testing.assert_close(p, q, rtol=1e-10, atol=1e-12, msg=name)


# ---------------------------------------------------------------- batched = K single experts


def _slice(module: torch.nn.Module, k: int, make) -> torch.nn.Module:
    """A one-expert copy of ``module`` holding its expert k."""
    one = make()
    one.load_state_dict({name: t[k : k + 1] if t.dim() > 0 else t
                         for name, t in module.state_dict().items()})  # fmt: skip
    return one


def _slice_batch(batch: dict, k: int) -> dict:
    """Expert k's part of a batch (the contexts from p(c) are every expert's)."""
    return {key: v if key == "c_env" or v is None else v[k : k + 1] for key, v in batch.items()}


def test_batched_updates_equal_independent_single_expert_updates():
    """Lines 7-8 for K experts at once equal K separate one-expert updates (float64): the
    experts share no parameter, Adam is elementwise and the energies' gradient clip is per
    expert."""
    cfg = config(dtype="float64", n_experts=3)
    model, batch, entropy_old = _model_and_batch(cfg)
    task, k_all = model.task, cfg.n_experts
    dc, d = task.context_dim, task.n_params
    one = config(dtype="float64", n_experts=1)
    e_adv, c_adv = _expert_adv(model, batch), _context_adv(model, batch, entropy_old)

    def adam(module: torch.nn.Module, lr: float) -> torch.optim.Adam:
        return torch.optim.Adam(module.parameters(), lr=lr, eps=1e-8)

    singles = []
    for k in range(k_all):
        experts = _slice(model.experts, k, lambda: GaussianExperts(
            1, dc, d, cfg.expert_hidden, init_std=cfg.init_std, dtype=F64))  # fmt: skip
        critics = _slice(model.critics, k, lambda: ValueCritics(1, dc, cfg.critic_hidden))
        energies = _slice(model.energies, k, lambda: EnergyNets(1, dc, cfg.context_hidden))
        b = _slice_batch(batch, k)
        U.update_experts(experts, adam(experts, cfg.lr_policy), b, e_adv[k : k + 1], one)
        U.update_critics(critics, adam(critics, cfg.lr_critic), b["ctx"], b["returns"],
                         cfg.critic_epochs)  # fmt: skip
        U.update_contexts(energies, adam(energies, cfg.lr_context), b, c_adv[k : k + 1], one)
        singles.append((experts, critics, energies))
    U.update_experts(model.experts, adam(model.experts, cfg.lr_policy), batch, e_adv, cfg)
    U.update_critics(model.critics, adam(model.critics, cfg.lr_critic), batch["ctx"],
                     batch["returns"], cfg.critic_epochs)  # fmt: skip
    U.update_contexts(model.energies, adam(model.energies, cfg.lr_context), batch, c_adv, cfg)
    for k, nets in enumerate(singles):
        for batched, single in zip((model.experts, model.critics, model.energies), nets,
                                   strict=True):  # fmt: skip
            for (name, p), q in zip(batched.named_parameters(), single.parameters(),
                                    strict=True):  # fmt: skip
                if not (batched is model.energies and name == HEAD_BIAS):
                    torch.testing.assert_close(p[k : k + 1], q, rtol=1e-9, atol=1e-11, msg=name)


# ---------------------------------------------------------------- float32 against float64

#: float32 against float64, one update of each network from the same start (K = 5, 5000
#: contexts, 100 epochs and the thesis's step sizes measured ≤ 2e-5 relative on the updates,
#: ≤ 1.3e-6 on the losses, ≤ 3.1e-7 total variation of π(c | o)); the bounds hold 10x more.
TOL_UPDATE = 2e-4  # ‖Δθ₃₂ − Δθ₆₄‖ / ‖Δθ₆₄‖ per network, Δθ the update's change
TOL_METRIC = 2e-5  # relative, the losses, the KL parts and the entropies
TOL_TV = 5e-6  # total variation between the float32 and float64 π(c | o) after the update
TOL_OUT = 1e-5  # absolute, the experts' means, Cholesky factors and the critics' values


def _float32_copy(model64: DiSkill, cfg: DiSkillConfig) -> DiSkill:
    model = DiSkill(model64.task, cfg, model64.seed, workers=0)
    for net, start in ((model.experts, model64.experts), (model.critics, model64.critics),
                       (model.energies, model64.energies)):  # fmt: skip
        net.load_state_dict(start.state_dict())  # the same start, rounded
    return model


def _one_update_each(model: DiSkill, batch: dict, entropy_old: torch.Tensor) -> dict:
    cfg = model.config
    before = {n: copy.deepcopy(getattr(model, n)) for n in ("experts", "critics", "energies")}

    def adam(module: torch.nn.Module, lr: float) -> torch.optim.Adam:
        return torch.optim.Adam(module.parameters(), lr=lr, eps=1e-8)

    metrics = U.update_experts(model.experts, adam(model.experts, cfg.lr_policy), batch,
                               _expert_adv(model, batch), cfg)  # fmt: skip
    metrics |= U.update_critics(model.critics, adam(model.critics, cfg.lr_critic), batch["ctx"],
                                batch["returns"], cfg.critic_epochs)  # fmt: skip
    metrics |= U.update_contexts(model.energies, adam(model.energies, cfg.lr_context), batch,
                                 _context_adv(model, batch, entropy_old), cfg)  # fmt: skip
    delta = {}
    for name, start in before.items():
        delta[name] = torch.cat([
            (p.detach() - q.detach()).double().flatten()
            for (pn, p), q in zip(getattr(model, name).named_parameters(), start.parameters(),
                                  strict=True)
            if not (name == "energies" and pn == HEAD_BIAS)
        ])  # fmt: skip
    with torch.no_grad():
        out = {
            "mean": model.experts.mean(batch["ctx"]).double(),
            "chol": model.experts.chol().double(),
            "values": model.critics.values(batch["ctx"]).double(),
            "pc": torch.softmax(model.energies.energies(batch["c_env"]), -1).double(),
        }
    return {"metrics": metrics, "delta": delta, "out": out}


def test_float32_updates_agree_with_float64_from_the_same_start():
    """One expert update (Eq. 4.7), one critic update and one context update (Eq. 4.8) in
    float32 and in float64 from the same parameters and the same batch: the parameters move
    alike (TOL_UPDATE), the losses, KL parts and entropies agree (TOL_METRIC), the context
    distributions π(c | o) too (TOL_TV), and so do the experts' means and factors and the
    critics' values (TOL_OUT)."""
    cfg64 = config(dtype="float64")
    model64, batch64, entropy64 = _model_and_batch(cfg64)
    model32 = _float32_copy(model64, config(dtype="float32"))
    batch32 = {k: v.float() if isinstance(v, torch.Tensor) and v.is_floating_point() else v
               for k, v in batch64.items()}  # fmt: skip
    a = _one_update_each(model64, batch64, entropy64)
    b = _one_update_each(model32, batch32, entropy64.float())
    for name, d64 in a["delta"].items():
        assert float(d64.norm()) > 1e-2  # the update moved the network
        rel = float((b["delta"][name] - d64).norm() / d64.norm())
        assert rel < TOL_UPDATE, (name, rel)
    for key, v64 in a["metrics"].items():
        assert abs(b["metrics"][key] - v64) <= TOL_METRIC * abs(v64), (key, v64, b["metrics"][key])
    for key in ("mean", "chol", "values"):
        assert float((b["out"][key] - a["out"][key]).abs().max()) < TOL_OUT, key
    tv = 0.5 * (b["out"]["pc"] - a["out"]["pc"]).abs().sum(1)
    assert float(tv.max()) < TOL_TV


def test_float32_is_the_default_and_float64_is_kept_on_request():
    model = DiSkill(Bowl(), config(), 0, workers=0)
    assert model.config.dtype == "float32"
    for net in (model.experts, model.critics, model.energies):
        assert {p.dtype for p in net.parameters()} == {torch.float32}
    model64 = DiSkill(Bowl(), config(dtype="float64"), 0, workers=0)
    assert {p.dtype for p in model64.experts.parameters()} == {F64}
    # the same seeded start: float32's parameters are float64's, rounded
    for p, q in zip(model.energies.parameters(), model64.energies.parameters(), strict=True):
        assert torch.equal(p, q.float())
    with pytest.raises(ValueError, match="dtype must be one of"):
        config(dtype="float16")
    with pytest.raises(ValueError, match="checkpoint holds torch.float64 networks"):
        model.load_state_dict(model64.state_dict())

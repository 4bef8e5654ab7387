"""The maths of DIME's three updates, recomputed from the equations inside the tests.

Each test runs one update of :mod:`vslbook.srl.dime_updates` on a tiny agent (obs 3, act 2,
widths 16, 2 diffusion steps, 11 atoms on [-10, 10], BatchRenorm on, float64) and a fixed
batch of 8 transitions, then recomputes the same quantity on a copy of the networks taken
before the step, with the formula written out here rather than through the module's helpers
(``CategoricalSupport.project``, ``bellman_atoms``, ``categorical_loss``, ``combine_q``,
``q_values``). The networks themselves (critic forward, policy ``sample``) supply the inputs;
the global torch seed is set identically before the update and before the reference, so both
draw the same a' ~ π(·|s') (critic) or a ~ π(·|s) (actor).

* Critic, distributional (Eq. 5.21 with C51): Tz_i = r + γ (1 - terminated)(z_i - α c(s')),
  c = running + terminal cost = minus the entropy bound of a'; each critic's next distribution
  is projected onto the support (a plain loop below), the two projections averaged, and the
  loss is Σ_k mean_b [CE(target, p_k) - 0.005 H(p_k)] (the authors' sign, Appendix C.4).
* Critic, scalar (Eq. 5.24): y = r + γ (1 - terminated)(Q̄(s', a') - α c(s')), Q̄ the mean
  (DIME) or min (CrossQ) of the two critics; loss Σ_k ½ mean_b (Q_k - y)².
  Both critics run CrossQ's joint batch: [(s, a); (s', a')] in one train-mode pass, so the
  BatchRenorm statistics come from the 2B rows, with the s' half detached.
* Actor (Eq. 5.27): mean[α (running + terminal cost) - Q̄(s, a)], critics in eval mode,
  Q = Σ_i p_i z_i for C51, Q̄ = ½(Q1 + Q2) for DIME (min for CrossQ).
* Temperature (Eq. 5.28): J = α (H_target - mean running cost) in log α, so the gradient is
  α (H_target - mean running cost) and Adam's first step moves log α by -lr·sign(gradient):
  a running cost above the target (too little entropy) makes α grow.

Loss values and the gradients of every parameter are compared, and the first Adam step is
checked against its closed form Δ = -lr · g / (|g| + eps) (m̂ = g, v̂ = g² on step one), so
an optimiser that ascends instead of descends is caught too. Everything is float64 and both
sides do the same arithmetic up to summation order, hence the tight tolerances.
"""

import copy
import math

import numpy as np
import pytest
import torch

from vslbook.srl.dime_config import CrossQConfig, DIMEConfig
from vslbook.srl.dime_updates import Agent, actor_update, alpha_update, critic_update, make_agent
from vslbook.srl.replay import Batch

OBS_DIM, ACT_DIM, BATCH = 3, 2, 8
V_MIN, V_MAX, N_ATOMS = -10.0, 10.0, 11
LOG_ALPHA = -1.25  # α ≈ 0.29 != 1, so a dropped α shows; exact in float32 (make_agent)
ENTROPY_COEF = 0.005  # c in CE - c H(p), Appendix C.4 (sign of the authors' code)
ADAM_EPS = 1e-8
SEED = 1234
TINY = dict(
    actor_hidden=16,
    actor_layers=2,
    n_diffusion_steps=2,
    critic_hidden=16,
    critic_layers=2,
    n_atoms=N_ATOMS,
    init_log_alpha=LOG_ALPHA,
    device="cpu",
)
TIGHT = dict(rtol=1e-9, atol=1e-12)

DIME_SCALAR = (DIMEConfig, dict(critic="scalar"))  # Fig. 5.5c-d ablation: mean of the critics
CROSSQ = (CrossQConfig, {})  # Gaussian policy, scalar critics, min of the critics


@pytest.fixture(autouse=True)
def _one_thread():
    old = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(old)


# --------------------------------------------------------------------------- fixtures and helpers


def _agent(cfg_cls=DIMEConfig, **over) -> Agent:
    """A seeded tiny agent in float64; the score network's output layer gets real weights."""
    cfg = cfg_cls(**{**TINY, **over})
    torch.manual_seed(0)
    agent = make_agent(OBS_DIM, ACT_DIM, cfg, v_min=V_MIN, v_max=V_MAX)
    agent.policy.double()
    agent.critic.double()
    if agent.support is not None:
        agent.support.double()
    agent.log_alpha.data = agent.log_alpha.data.double()
    if cfg.policy == "diffusion":  # its output layer starts at ~1e-8: make f_θ matter
        with torch.no_grad():
            agent.policy.score_net.out.weight.normal_(0.0, 0.5)
            agent.policy.score_net.out.bias.normal_(0.0, 0.5)
    return agent


def _batch() -> Batch:
    """8 transitions; rewards of a few units push some moved atoms past ±10; rows 2, 6 end."""
    g = torch.Generator().manual_seed(1)
    kw = dict(generator=g, dtype=torch.float64)
    return Batch(
        obs=torch.randn(BATCH, OBS_DIM, **kw),
        action=torch.rand(BATCH, ACT_DIM, **kw) * 1.8 - 0.9,
        reward=3.0 * torch.randn(BATCH, **kw),
        next_obs=torch.randn(BATCH, OBS_DIM, **kw),
        terminated=torch.tensor([0, 0, 1, 0, 0, 0, 1, 0], dtype=torch.float64),
    )


def _alpha(agent: Agent) -> float:
    """α from the configuration: the fixed value, else exp(initial log α)."""
    fixed = agent.cfg.fixed_alpha
    return fixed if fixed is not None else math.exp(LOG_ALPHA)


def _atoms() -> np.ndarray:
    """z_i = v_min + i Δz, i = 0..n_atoms-1."""
    dz = (V_MAX - V_MIN) / (N_ATOMS - 1)
    return np.array([V_MIN + i * dz for i in range(N_ATOMS)])


def _project(values: np.ndarray, probs: np.ndarray) -> np.ndarray:
    """C51 projection, written out: the mass probs[b, j] sitting at values[b, j] (clipped to
    [v_min, v_max]) is split linearly between the two support atoms around it."""
    dz = (V_MAX - V_MIN) / (N_ATOMS - 1)
    out = np.zeros_like(probs)
    for b in range(values.shape[0]):
        for j in range(values.shape[1]):
            pos = (min(max(values[b, j], V_MIN), V_MAX) - V_MIN) / dz  # fractional atom index
            lo, hi = math.floor(pos), math.ceil(pos)
            if lo == hi:  # exactly on an atom
                out[b, lo] += probs[b, j]
            else:
                out[b, lo] += probs[b, j] * (hi - pos)
                out[b, hi] += probs[b, j] * (pos - lo)
    return out


def _softmax(logits: torch.Tensor) -> torch.Tensor:
    e = torch.exp(logits - logits.max(dim=-1, keepdim=True).values)
    return e / e.sum(dim=-1, keepdim=True)


def _combine(q: torch.Tensor, how: str) -> torch.Tensor:
    """Q̄ from the two critics' values q (2, B): their mean or their min."""
    return 0.5 * (q[0] + q[1]) if how == "mean" else torch.minimum(q[0], q[1])


def _joint_pass(critic, batch: Batch, next_action: torch.Tensor):
    """CrossQ's joint batch through the critic's public forward (train mode): (current, next)."""
    out = critic(torch.cat([batch.obs, batch.next_obs]), torch.cat([batch.action, next_action]))
    return out[:, :BATCH], out[:, BATCH:].detach()


def _assert_grads_match(module, reference, clip: float = 0.0) -> None:
    """Every parameter's gradient equals the reference's (clipped elementwise when clip > 0)."""
    pairs = list(zip(module.named_parameters(), reference.parameters(), strict=True))
    checked = 0
    for (name, p), ref in pairs:
        if ref.grad is None or not p.requires_grad:
            continue
        expected = ref.grad.clamp(-clip, clip) if clip > 0 else ref.grad
        assert p.grad is not None, f"no gradient for {name}"
        torch.testing.assert_close(p.grad, expected, **TIGHT, msg=f"gradient of {name}")
        checked += 1
    assert checked >= 3


def _assert_first_adam_step(before, module, lr: float) -> None:
    """Adam's first step (m̂ = g, v̂ = g²) moves each weight by -lr g / (|g| + eps)."""
    for old, p in zip(before, module.parameters(), strict=True):
        if p.grad is None:
            continue
        g = p.grad
        torch.testing.assert_close(
            p.detach() - old, -lr * g / (g.abs() + ADAM_EPS), rtol=1e-7, atol=1e-13
        )


# --------------------------------------------------------------------------- critic


@pytest.mark.parametrize("fixed_alpha", [None, 0.2], ids=["learned-alpha", "fixed-alpha"])
def test_distributional_critic_loss_and_gradient_follow_eq_5_21(fixed_alpha):
    agent, batch = _agent(fixed_alpha=fixed_alpha), _batch()
    policy, critic = copy.deepcopy(agent.policy), copy.deepcopy(agent.critic)
    before = [p.detach().clone() for p in agent.critic.parameters()]
    torch.manual_seed(SEED)
    stats = critic_update(agent, batch)

    torch.manual_seed(SEED)
    with torch.no_grad():
        nxt = policy.sample(batch.next_obs)  # the same a' ~ π(·|s')
    logits, next_logits = _joint_pass(critic, batch, nxt.action)
    cost = (nxt.running_cost + nxt.terminal_cost).numpy()  # c(s') = -entropy bound
    r, not_done, z = batch.reward.numpy(), 1.0 - batch.terminated.numpy(), _atoms()
    moved = r[:, None] + agent.cfg.gamma * not_done[:, None] * (
        z[None, :] - _alpha(agent) * cost[:, None]
    )  # Tz_i, Eq. 5.21
    assert (moved > V_MAX).any() or (moved < V_MIN).any()  # the clipping is exercised
    next_probs = _softmax(next_logits).numpy()
    projected = [_project(moved, next_probs[k]) for k in range(2)]  # each critic's
    target = torch.from_numpy(0.5 * (projected[0] + projected[1]))  # averaged
    torch.testing.assert_close(target.sum(-1), torch.ones(BATCH, dtype=torch.float64))
    log_p = torch.log(_softmax(logits))
    cross_entropy = -(target * log_p).sum(-1)  # (2, B)
    entropy = -(log_p.exp() * log_p).sum(-1)
    loss = (cross_entropy - ENTROPY_COEF * entropy).mean(dim=1).sum()  # Σ over both critics
    loss.backward()

    torch.testing.assert_close(stats.loss, loss.detach(), **TIGHT)
    q_mean = (_softmax(logits.detach()) * torch.from_numpy(z)).sum(-1).mean()
    torch.testing.assert_close(stats.value, q_mean, **TIGHT)
    _assert_grads_match(agent.critic, critic)
    _assert_first_adam_step(before, agent.critic, agent.cfg.critic_lr)
    # one joint pass: the BatchRenorm statistics were updated once, from the 2B rows
    for got, ref in zip(agent.critic.buffers(), critic.buffers(), strict=True):
        torch.testing.assert_close(got, ref, **TIGHT)


@pytest.mark.parametrize("cfg_cls, over", [DIME_SCALAR, CROSSQ], ids=["dime-mean", "crossq-min"])
def test_scalar_critic_loss_and_gradient_follow_eq_5_24(cfg_cls, over):
    agent, batch = _agent(cfg_cls, **over), _batch()
    how = "mean" if cfg_cls is DIMEConfig else "min"
    assert agent.cfg.q_reduce == how and agent.support is None
    policy, critic = copy.deepcopy(agent.policy), copy.deepcopy(agent.critic)
    before = [p.detach().clone() for p in agent.critic.parameters()]
    torch.manual_seed(SEED)
    stats = critic_update(agent, batch)

    torch.manual_seed(SEED)
    with torch.no_grad():
        nxt = policy.sample(batch.next_obs)
    q, q_next = _joint_pass(critic, batch, nxt.action)  # (2, B) each
    cost = nxt.running_cost + nxt.terminal_cost
    y = batch.reward + agent.cfg.gamma * (1.0 - batch.terminated) * (
        _combine(q_next, how) - _alpha(agent) * cost
    )
    loss = sum(0.5 * ((q[k] - y) ** 2).mean() for k in range(2))  # Eq. 5.24 for each critic
    loss.backward()

    torch.testing.assert_close(stats.loss, loss.detach(), **TIGHT)
    torch.testing.assert_close(stats.value, q.detach().mean(), **TIGHT)
    _assert_grads_match(agent.critic, critic)
    _assert_first_adam_step(before, agent.critic, agent.cfg.critic_lr)
    for got, ref in zip(agent.critic.buffers(), critic.buffers(), strict=True):
        torch.testing.assert_close(got, ref, **TIGHT)


# --------------------------------------------------------------------------- actor


@pytest.mark.parametrize("cfg_cls, over", [(DIMEConfig, {}), CROSSQ], ids=["dime", "crossq"])
def test_actor_loss_and_gradient_follow_eq_5_27(cfg_cls, over):
    agent, batch = _agent(cfg_cls, **over), _batch()
    # a critic that has trained one step, so its eval-mode (running) statistics are not the
    # initial ones and differ from any train-mode batch statistics
    critic_update(agent, batch)
    policy, critic = copy.deepcopy(agent.policy), copy.deepcopy(agent.critic)
    before = [p.detach().clone() for p in agent.policy.parameters()]
    torch.manual_seed(SEED)
    stats = actor_update(agent, batch.obs)

    torch.manual_seed(SEED)
    sample = policy.sample(batch.obs)  # reparameterised: gradients flow through the chain
    critic.eval()
    out = critic(batch.obs, sample.action)
    if agent.support is not None:  # expected Q = Σ_i p_i z_i
        q = (_softmax(out) * torch.from_numpy(_atoms())).sum(-1)
        how = "mean"
    else:
        q, how = out, "min"
    cost = sample.running_cost + sample.terminal_cost
    loss = (_alpha(agent) * cost - _combine(q, how)).mean()
    loss.backward()

    torch.testing.assert_close(stats.loss, loss.detach(), **TIGHT)
    # the α update is fed the running cost alone (Eq. 5.28), the value is the entropy bound
    torch.testing.assert_close(stats.running_cost, sample.running_cost.detach(), **TIGHT)
    torch.testing.assert_close(stats.value, -cost.detach().mean(), **TIGHT)
    _assert_grads_match(agent.policy, policy, clip=agent.cfg.actor_grad_clip)
    _assert_first_adam_step(before, agent.policy, agent.cfg.actor_lr)


# --------------------------------------------------------------------------- temperature


@pytest.mark.parametrize("offset", [2.5, -2.5], ids=["cost-above-target", "cost-below-target"])
def test_alpha_loss_and_first_step_follow_eq_5_28(offset):
    agent = _agent()
    h_target = 4.0 * ACT_DIM  # Table C.2: H_target = 4 dim(A), on the running cost
    assert agent.h_target == h_target
    running_cost = h_target + offset + torch.linspace(-1.0, 1.0, BATCH, dtype=torch.float64)
    loss = alpha_update(agent, running_cost)

    alpha = math.exp(LOG_ALPHA)
    expected_loss = alpha * (h_target - running_cost.mean().item())  # J(α), Eq. 5.28
    grad = expected_loss  # dJ / d log α = α (H_target - mean running cost)
    expected = LOG_ALPHA - agent.cfg.alpha_lr * grad / (abs(grad) + ADAM_EPS)
    assert loss.item() == pytest.approx(expected_loss, rel=1e-12)
    assert agent.log_alpha.item() == pytest.approx(expected, rel=0, abs=1e-12)
    # too little entropy (running cost above the target) -> α grows by lr in log space
    assert math.copysign(1.0, agent.log_alpha.item() - LOG_ALPHA) == math.copysign(1.0, offset)


def test_fixed_alpha_is_not_updated():
    agent = _agent(fixed_alpha=0.2)
    loss = alpha_update(agent, torch.full((BATCH,), 100.0, dtype=torch.float64))
    assert loss.item() == 0.0 and agent.log_alpha.item() == pytest.approx(LOG_ALPHA)
    assert agent.alpha.item() == pytest.approx(0.2)

"""Tests for the DIME building blocks in ``vslbook.srl`` (Chapter 5, Appendix C)."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
import torch
from torch import nn

from vslbook.bounds.dime import linear_gaussian_chain
from vslbook.srl import (
    BatchRenorm1d,
    CategoricalSupport,
    DiffusionPolicy,
    DiffusionPolicyConfig,
    DistributionalCritic,
    DoubleCritic,
    GaussianPolicy,
    ScalarCritic,
    categorical_loss,
    cosine_schedule,
    polyak_update,
    tanh_log_det_jacobian,
)

SMALL = dict(hidden=16, n_frequencies=8, n_layers=2)


def assert_close(actual, expected, rtol=1e-5, atol=1e-6, msg=""):
    """Shape and value check (torch.testing's first call imports enough to cost ~1.5 s)."""
    expected = torch.as_tensor(expected, dtype=actual.dtype, device=actual.device)
    assert actual.shape == expected.shape, f"{msg} shape {actual.shape} != {expected.shape}"
    diff = (actual - expected).abs().max().item()
    assert torch.allclose(actual, expected, rtol=rtol, atol=atol), f"{msg} max |diff| {diff}"


# --------------------------------------------------------------------------- linear-Gaussian chain


class LinearDrift(nn.Module):
    """Stand-in for a score network: f(x, n, s) = slope * x + offset (keeps the chain Gaussian)."""

    def __init__(self, slope: float, offset: list[float]) -> None:
        super().__init__()
        self.slope = slope
        self.register_buffer("offset", torch.tensor(offset))

    def embed_steps(self, steps: torch.Tensor) -> torch.Tensor:
        return torch.zeros(len(steps), 1)

    def forward(self, x, step_embedding, obs):
        return self.slope * x + self.offset


def _closed_form(etas, sigma0, gen, noise):
    """Per dimension: x_0 mean/var and KL(generative joint || noising joint started at x_0).

    etas (N, d) in sampling order; gen = (slope, offsets (d,)) of f_θ; noise = the same for the
    noising drift (zero slope/offset for DIME's fixed OU step). See linear_gaussian_chain.
    """
    chain = linear_gaussian_chain(
        etas, sigma0, gen[0], np.array(gen[1]), noise[0], np.array(noise[1])
    )
    return chain.marginal_mean, chain.marginal_var, chain.kl


@pytest.mark.parametrize("case", ["zero_network", "linear_drift", "general_bridges"])
def test_entropy_bound_matches_closed_form_in_linear_gaussian_chain(case):
    """Eq. 5.15-5.20 where everything is Gaussian: E[entropy_bound] = H(x_0) - KL <= H(x_0).

    KL is between the generative joint and the noising joint started from the generative
    marginal of x_0, i.e. E_{x_0} KL of the conditionals of x_{1:N} given x_0 (Eq. C.2).
    """
    torch.manual_seed(0)
    cfg = DiffusionPolicyConfig(
        n_steps=3, sigma0=1.5, dt=3.0, squash=False,
        general_bridges=case == "general_bridges", **SMALL,
    )
    policy = DiffusionPolicy(obs_dim=3, act_dim=2, config=cfg)
    with torch.no_grad():
        policy.raw_noise.copy_(torch.log(torch.expm1(1.0 / torch.tensor([1.0, 0.5]))))
    gen, noise = (0.0, [0.0, 0.0]), (0.0, [0.0, 0.0])
    if case == "zero_network":
        nn.init.zeros_(policy.score_net.out.weight)  # f_θ ≡ 0 through the real network
    else:
        gen = (-0.5, [1.0, -1.0])
        policy.score_net = LinearDrift(*gen)
    if case == "general_bridges":
        noise = (-0.2, [0.1, 0.3])
        policy.noising_net = LinearDrift(*noise)

    n = 40_000
    with torch.no_grad():
        out = policy.sample(torch.randn(n, 3), generator=torch.Generator().manual_seed(1))
        etas = policy.step_sizes.double().numpy()
    mean, var, kl = _closed_form(etas, cfg.sigma0, gen, noise)

    # (a) moments of x_0
    x0 = out.latent.double().numpy()
    assert np.all(np.abs(x0.mean(0) - mean) < 5 * np.sqrt(var / n))
    assert np.all(np.abs(x0.var(0) / var - 1.0) < 5 * np.sqrt(2 / n))

    # (b) the bound: E[entropy_bound] = H - KL, checked on the whole estimate ...
    entropy = float(np.sum(0.5 * np.log(2 * math.pi * math.e * var)))
    estimate = out.entropy_bound.double().numpy()
    se = estimate.std() / math.sqrt(n)
    assert abs(estimate.mean() - (entropy - kl.sum())) < 5 * se
    assert estimate.mean() < entropy - 5 * se
    # ... and on the gap alone, -(entropy_bound + log π_0(x_0)), whose mean is the KL (>= 0)
    log_marginal = np.sum(-0.5 * ((x0 - mean) ** 2 / var + np.log(2 * math.pi * var)), axis=1)
    gap = -(estimate + log_marginal)
    gap_se = gap.std() / math.sqrt(n)
    assert kl.sum() > 10 * gap_se
    assert abs(gap.mean() - kl.sum()) < 5 * gap_se


def test_terminal_cost_is_prior_density_at_chain_start_and_trajectory_shapes():
    cfg = DiffusionPolicyConfig(n_steps=3, squash=False, **SMALL)
    policy = DiffusionPolicy(3, 2, cfg)
    out = policy.sample(torch.randn(5, 3), return_trajectory=True)
    assert out.trajectory.shape == (4, 5, 2)
    assert torch.equal(out.trajectory[-1], out.latent)
    x_n = out.trajectory[0]
    prior = torch.distributions.Normal(0.0, cfg.sigma0).log_prob(x_n).sum(-1)
    assert_close(out.terminal_cost, prior)
    assert_close(out.cost, out.running_cost + out.terminal_cost)


def test_squash_adds_tanh_correction_to_running_cost():
    """Eq. C.30: same chain, the squashed cost differs by -Σ log(1 - tanh² x_0)."""
    obs = torch.randn(64, 3)
    plain = DiffusionPolicy(3, 2, DiffusionPolicyConfig(n_steps=3, squash=False, **SMALL))
    squashed = DiffusionPolicy(3, 2, DiffusionPolicyConfig(n_steps=3, squash=True, **SMALL))
    squashed.load_state_dict(plain.state_dict())
    a = plain.sample(obs, generator=torch.Generator().manual_seed(3))
    b = squashed.sample(obs, generator=torch.Generator().manual_seed(3))
    assert_close(b.latent, a.latent)
    assert_close(b.action, torch.tanh(a.latent))
    assert_close(b.running_cost, a.running_cost - tanh_log_det_jacobian(a.latent))
    assert_close(b.terminal_cost, a.terminal_cost)


# --------------------------------------------------------------------------------- tanh correction


def test_tanh_density_matches_histogram():
    """p(a) = N(atanh a; μ, s²) / (1 - a²), via log N(x) - Σ log(1 - tanh² x)."""
    gen = torch.Generator().manual_seed(0)
    mu, s, n = 0.3, 0.8, 400_000
    a = torch.tanh(mu + s * torch.randn(n, generator=gen, dtype=torch.float64))
    edges = np.linspace(-0.95, 0.95, 39)
    counts, _ = np.histogram(a.numpy(), bins=edges)
    empirical = counts / (n * np.diff(edges))
    centres = torch.tensor(0.5 * (edges[1:] + edges[:-1]))
    x = torch.atanh(centres)[:, None]
    log_density = torch.distributions.Normal(mu, s).log_prob(x[:, 0]) - tanh_log_det_jacobian(x)
    np.testing.assert_allclose(empirical, log_density.exp().numpy(), rtol=0.05)
    # the change-of-variables density integrates to one over (-1, 1)
    grid = torch.linspace(-8, 8, 20_001, dtype=torch.float64)[:, None]
    dens = (torch.distributions.Normal(mu, s).log_prob(grid[:, 0])).exp()
    a_grid = torch.tanh(grid[:, 0])
    p_a = dens / tanh_log_det_jacobian(grid).exp()
    assert abs(torch.trapezoid(p_a, a_grid).item() - 1.0) < 1e-4


def test_tanh_log_det_is_stable_for_large_inputs():
    x = torch.tensor([[-40.0], [-20.0], [-3.0], [0.0], [3.0], [20.0], [40.0]])
    stable = tanh_log_det_jacobian(x)
    assert torch.isfinite(stable).all()
    assert torch.isinf(torch.log(1 - torch.tanh(x) ** 2)).any()  # the naive formula fails
    xd = x.double().abs()
    reference = -2.0 * (xd + torch.log1p(torch.exp(-2.0 * xd)) - math.log(2.0))  # -2 log cosh
    assert_close(stable.double(), reference[:, 0], rtol=1e-6, atol=1e-5)


# ---------------------------------------------------------------------------------------- C51


def _brute_project(values, probs, v_min, v_max, n_atoms):
    dz = (v_max - v_min) / (n_atoms - 1)
    out = np.zeros_like(probs)
    for i in range(values.shape[0]):
        for j in range(n_atoms):
            b = (min(max(values[i, j], v_min), v_max) - v_min) / dz
            lo, hi = math.floor(b), math.ceil(b)
            if lo == hi:
                out[i, lo] += probs[i, j]
            else:
                out[i, lo] += probs[i, j] * (hi - b)
                out[i, hi] += probs[i, j] * (b - lo)
    return out


@pytest.mark.parametrize("n_atoms", [2, 11, 51])
def test_c51_projection_matches_brute_force_and_conserves_mass(n_atoms):
    support = CategoricalSupport(-10.0, 10.0, n_atoms).double()
    gen = torch.Generator().manual_seed(n_atoms)
    probs = torch.softmax(torch.randn(8, n_atoms, generator=gen, dtype=torch.float64), -1)
    values = 15.0 * (2 * torch.rand(8, n_atoms, generator=gen, dtype=torch.float64) - 1)
    projected = support.project(values, probs)
    assert_close(projected.sum(-1), torch.ones(8, dtype=torch.float64))
    expected = _brute_project(values.numpy(), probs.numpy(), -10.0, 10.0, n_atoms)
    np.testing.assert_allclose(projected.numpy(), expected, atol=1e-12)


def test_c51_projection_exact_grid_hits_and_out_of_range():
    support = CategoricalSupport(-2.0, 2.0, 5)  # atoms -2, -1, 0, 1, 2
    probs = torch.softmax(torch.randn(3, 5), -1)
    assert_close(support.project(support.atoms.expand(3, 5), probs), probs)
    shifted = support.project(support.atoms.expand(3, 5) + 1.0, probs)  # every atom on the grid
    assert_close(shifted[:, 0], torch.zeros(3))
    assert_close(shifted[:, 1:4], probs[:, :3])
    assert_close(shifted[:, 4], probs[:, 3] + probs[:, 4])
    far = support.project(torch.full((3, 5), 100.0), probs)  # everything clipped to v_max
    assert_close(far, torch.tensor([0.0, 0, 0, 0, 1]).expand(3, 5))
    low = support.project(torch.full((3, 5), -100.0), probs)
    assert_close(low, torch.tensor([1.0, 0, 0, 0, 0]).expand(3, 5))


def test_c51_projection_of_a_nan_target_is_nan_and_leaves_other_rows_alone():
    support = CategoricalSupport(-2.0, 2.0, 5)
    probs = torch.softmax(torch.randn(3, 5, generator=torch.Generator().manual_seed(0)), -1)
    values = torch.tensor([[0.3, -1.2, 5.0, 0.0, 1.5]] * 3)
    values[1, 2] = float("nan")  # one diverged atom poisons its row only
    values[2, 0] = float("inf")  # ±inf is clipped to the support like any large value
    out = support.project(values, probs)
    assert torch.isnan(out[1]).all()
    clipped = values[2].clone()
    clipped[0] = 2.0
    assert_close(out[0], support.project(values[:1], probs[:1])[0])
    assert_close(out[2], support.project(clipped[None], probs[2:])[0])
    expected = _brute_project(values[[0]].numpy(), probs[[0]].numpy(), -2.0, 2.0, 5)
    np.testing.assert_allclose(out[[0]].numpy(), expected, atol=1e-6)


def test_bellman_atoms_mean_and_categorical_loss():
    support = CategoricalSupport(-5.0, 5.0, 11)
    reward, done = torch.tensor([1.0, 2.0]), torch.tensor([0.0, 1.0])
    bonus = torch.tensor([0.5, 7.0])
    tz = support.bellman_atoms(reward, done, 0.9, bonus)
    assert_close(tz[0], 1.0 + 0.9 * (support.atoms + 0.5))
    assert_close(tz[1], torch.full((11,), 2.0))  # terminal: reward only
    probs = torch.softmax(torch.randn(2, 11), -1)
    assert_close(support.mean(probs), (probs * support.atoms).sum(-1))

    logits = torch.randn(2, 4, 11)
    target = torch.softmax(torch.randn(4, 11), -1)
    p = torch.softmax(logits, -1)
    ce = -(target * torch.log(p)).sum(-1)
    entropy = -(p * torch.log(p)).sum(-1)
    per_critic = (ce - 0.005 * entropy).mean(-1)
    assert_close(categorical_loss(logits, target), per_critic.sum())
    assert_close(categorical_loss(logits[0], target), per_critic[0])


# ------------------------------------------------------------------------------ BatchRenorm


def test_batchrenorm_equals_batchnorm_during_warmup():
    torch.manual_seed(0)
    brn = BatchRenorm1d(4, momentum=0.99, eps=1e-3, warmup_steps=10)
    bn = nn.BatchNorm1d(4, eps=1e-3, momentum=0.01)  # PyTorch's momentum is 1 - ours
    with torch.no_grad():
        for m in (brn, bn):
            m.weight.copy_(torch.tensor([1.0, 2.0, 0.5, -1.0]))
            m.bias.copy_(torch.tensor([0.1, -0.2, 0.3, 0.0]))
    for _ in range(5):
        x = 3.0 * torch.randn(32, 4) + 2.0
        assert_close(brn(x), bn(x))
    assert_close(brn.running_mean, bn.running_mean)
    assert_close(brn.running_var, bn.running_var)
    assert int(brn.steps) == 5 and not brn.renormalizing
    brn.eval()
    bn.eval()
    x = torch.randn(8, 4)
    assert_close(brn(x), bn(x))


def test_batchrenorm_uses_clipped_r_and_d_after_warmup():
    torch.manual_seed(1)
    brn = BatchRenorm1d(3, momentum=0.9, eps=1e-3, r_max=1.5, d_max=0.5, warmup_steps=2)
    for _ in range(2):
        brn(torch.randn(64, 3))
    assert brn.renormalizing
    running_mean, running_var = brn.running_mean.clone(), brn.running_var.clone()
    x = (4.0 * torch.randn(64, 3) + 3.0).requires_grad_(True)  # far from the running stats
    out = brn(x)

    mean, std = x.mean(0), torch.sqrt(x.var(0, unbiased=False) + 1e-3)
    running_std = torch.sqrt(running_var + 1e-3)
    r = (std / running_std).detach().clamp(1 / 1.5, 1.5)
    d = ((mean - running_mean) / running_std).detach().clamp(-0.5, 0.5)
    expected = (x - mean) / std * r + d
    assert_close(out, expected)
    assert not torch.allclose(out, (x - mean) / std)  # differs from plain batch norm

    w = torch.randn(64, 3)
    (grad,) = torch.autograd.grad((out * w).sum(), x)
    (grad_expected,) = torch.autograd.grad((expected * w).sum(), x)
    assert_close(grad, grad_expected)  # no gradient through r and d


def test_batchrenorm_eval_uses_running_statistics_and_freezes_them():
    brn = BatchRenorm1d(3, warmup_steps=0)
    for _ in range(3):
        brn(torch.randn(16, 3) + 1.0)
    brn.eval()
    state = {k: v.clone() for k, v in brn.state_dict().items()}
    x = torch.randn(5, 3)
    expected = (x - brn.running_mean) / torch.sqrt(brn.running_var + brn.eps)
    assert_close(brn(x), expected)
    for k, v in brn.state_dict().items():
        assert torch.equal(v, state[k]), k


def test_batchrenorm_state_dict_round_trip_keeps_step_counter():
    brn = BatchRenorm1d(3, warmup_steps=4)
    for _ in range(6):
        brn(torch.randn(16, 3))
    fresh = BatchRenorm1d(3, warmup_steps=4)
    assert not fresh.renormalizing
    fresh.load_state_dict(brn.state_dict())
    assert int(fresh.steps) == 6 and fresh.renormalizing
    x = torch.randn(16, 3) * 5
    assert_close(fresh(x), brn(x))


# ---------------------------------------------------------------------------------- critics


def test_double_critic_joint_batch_equals_one_pass_on_concatenation():
    torch.manual_seed(0)
    critic = DoubleCritic(3, 2, hidden=16, n_atoms=11, renorm_kwargs={"warmup_steps": 0})
    for _ in range(2):  # move the running statistics away from their initial values
        critic(torch.randn(8, 3), torch.randn(8, 2))
    reference = copy.deepcopy(critic)
    obs, act, next_obs, next_act = (torch.randn(8, 3), torch.randn(8, 2), torch.randn(6, 3),
                                    torch.randn(6, 2))
    current, nxt = critic.joint_forward(obs, act, next_obs, next_act)
    assert current.shape == (2, 8, 11) and nxt.shape == (2, 6, 11)
    for i in range(2):
        full = reference.critics[i](torch.cat([obs, next_obs]), torch.cat([act, next_act]))
        assert_close(current[i], full[:8])
        assert_close(nxt[i], full[8:])
    for (name, a), (_, b) in zip(critic.named_buffers(), reference.named_buffers(), strict=True):
        assert_close(a, b, msg=name)
    separate = copy.deepcopy(reference)(obs, act)
    assert not torch.allclose(separate, current)  # the shared batch statistics matter


def test_critic_variants_shapes_and_plain_critic_with_target_network():
    obs, act = torch.randn(5, 3), torch.randn(5, 2)
    assert DistributionalCritic(3, 2, hidden=8, n_atoms=7)(obs, act).shape == (5, 7)
    assert ScalarCritic(3, 2, hidden=8)(obs, act).shape == (5,)
    scalar = DoubleCritic(3, 2, hidden=8, distributional=False)
    assert scalar(obs, act).shape == (2, 5)
    plain = DoubleCritic(3, 2, hidden=8, n_atoms=7, use_batchrenorm=False)
    assert not any(isinstance(m, BatchRenorm1d) for m in plain.modules())
    assert sum(isinstance(m, BatchRenorm1d) for m in DoubleCritic(3, 2, hidden=8).modules()) == 6
    target = copy.deepcopy(plain)
    with torch.no_grad():
        for p in plain.parameters():
            p.add_(1.0)
    before = [p.clone() for p in target.parameters()]
    polyak_update(target, plain, tau=0.25)
    for t, b, o in zip(target.parameters(), before, plain.parameters(), strict=True):
        assert_close(t, 0.75 * b + 0.25 * o)


# ---------------------------------------------------------------------------------- policies


@pytest.mark.parametrize(
    ("n_steps", "first", "last", "total"),
    # dt_n = 0.1 · (0.999 cos²(½π (1.008 - t_n)/1.008) + 0.001), t_n = (N - n)/N, by hand:
    # N = 16: t = 1 -> 0.1 · (0.999 cos²(0.01246) + 0.001) = 0.099984; t = 1/16 -> 0.0010446
    [(16, 0.099984, 0.0010446, 0.84437), (4, 0.099984, 0.014511, 0.24863)],
)
def test_step_sizes_follow_the_unnormalised_cosine_schedule(n_steps, first, last, total):
    """Step sizes of the released DIME code: first ≈ 0.1, last ≈ 0.001, total ≈ 0.84 at N = 16."""
    policy = DiffusionPolicy(4, 3, DiffusionPolicyConfig(n_steps=n_steps, **SMALL))
    assert_close(policy.dt_scale, torch.tensor(0.1))
    assert_close(policy.noise_var, torch.ones(3))  # σ² = 1 at init, so η_n = dt_n
    dt = policy.step_sizes[:, 0].double()
    assert policy.step_sizes.shape == (n_steps, 3)
    assert abs(dt[0].item() - first) < 2e-6 and abs(dt[-1].item() - last) < 2e-6
    assert abs(dt.sum().item() - total) < 2e-5
    assert (dt[1:] < dt[:-1]).all()  # large steps away from the prior, small ones at the action
    schedule = cosine_schedule(n_steps)
    assert schedule.sum() > 1.0  # not normalised
    assert_close(policy.step_sizes, 0.1 * schedule[:, None] * policy.noise_var)


@pytest.mark.parametrize("general_bridges", [False, True])
def test_gradients_reach_score_network_step_size_and_noise(general_bridges):
    cfg = DiffusionPolicyConfig(n_steps=3, general_bridges=general_bridges, **SMALL)
    policy = DiffusionPolicy(3, 2, cfg)
    out = policy.sample(torch.randn(32, 3))
    loss = (-out.action.sum(-1) + 0.1 * out.cost).mean()  # an actor-style loss
    loss.backward()
    for name, p in policy.named_parameters():
        assert p.grad is not None and torch.isfinite(p.grad).all(), name
    nets = [policy.score_net] + ([policy.noising_net] if general_bridges else [])
    for net in nets:
        assert net.out.weight.grad.abs().sum() > 0
    assert policy.raw_dt.grad.abs() > 0
    assert policy.raw_noise.grad.abs().sum() > 0

    frozen = DiffusionPolicy(3, 2, DiffusionPolicyConfig(n_steps=3, learn_beta=False, **SMALL))
    assert not frozen.raw_noise.requires_grad
    assert "raw_noise" not in {n for n, p in frozen.named_parameters() if p.requires_grad}


def test_diffusion_policy_seeded_determinism_dtype_and_output_clip():
    cfg = DiffusionPolicyConfig(n_steps=2, **SMALL)
    policy = DiffusionPolicy(3, 2, cfg)
    obs = torch.randn(4, 3)
    a = policy.sample(obs, generator=torch.Generator().manual_seed(7))
    b = policy.sample(obs, generator=torch.Generator().manual_seed(7))
    assert_close(a.action, b.action)
    assert_close(a.entropy_bound, b.entropy_bound)
    det = policy.sample(obs, deterministic=True)
    assert_close(det.action, policy.sample(obs, deterministic=True).action)
    assert policy.double().sample(obs.double()).action.dtype == torch.float64
    policy.float()
    with torch.no_grad():
        policy.score_net.out.bias.fill_(1e6)
    emb = policy.score_net.embed_steps(torch.tensor([1.0]))
    assert policy.score_net(torch.zeros(4, 2), emb[0], obs).abs().max() == cfg.out_clip


def test_gaussian_policy_log_prob_and_interface():
    torch.manual_seed(0)
    policy = GaussianPolicy(3, 2, hidden=16)
    obs = torch.randn(10, 3)
    out = policy.sample(obs)
    mean, log_std = policy.distribution(obs)
    tanh = torch.distributions.transforms.TanhTransform()
    reference = (torch.distributions.Normal(mean, log_std.exp()).log_prob(out.latent).sum(-1)
                 - tanh.log_abs_det_jacobian(out.latent, out.action).sum(-1))
    assert_close(out.running_cost, reference)
    assert_close(out.entropy_bound, -reference)
    assert torch.equal(out.terminal_cost, torch.zeros(10))
    assert_close(policy.sample(obs, deterministic=True).action, torch.tanh(mean))
    out.cost.mean().backward()
    assert all(p.grad is not None for p in policy.parameters())


# ------------------------------------------------------------------------------ bad configs


@pytest.mark.parametrize(
    ("make", "match"),
    [
        (lambda: CategoricalSupport(1.0, 1.0), "v_min < v_max"),
        (lambda: CategoricalSupport(2.0, -2.0), "v_min < v_max"),
        (lambda: CategoricalSupport(-1.0, 1.0, n_atoms=1), "n_atoms must be >= 2"),
        (lambda: DistributionalCritic(3, 2, n_atoms=1), "n_atoms must be >= 2"),
        (lambda: DoubleCritic(3, 2, hidden=0), "hidden and n_layers must be >= 1"),
        (lambda: DiffusionPolicyConfig(n_steps=0), "n_steps must be >= 1"),
        (lambda: DiffusionPolicyConfig(n_steps=-4), "n_steps must be >= 1"),
        (lambda: DiffusionPolicyConfig(sigma0=0.0), "sigma0 must be > 0"),
        (lambda: DiffusionPolicyConfig(sigma0=-2.5), "sigma0 must be > 0"),
        (lambda: DiffusionPolicyConfig(dt=0.0), "dt must be > 0"),
        (lambda: DiffusionPolicyConfig(sigma_init=-1.0), "sigma_init must be > 0"),
        (lambda: DiffusionPolicyConfig(freq_min=0.0), "freq_min"),
        (lambda: BatchRenorm1d(4, momentum=1.0), "momentum must be in"),
        (lambda: BatchRenorm1d(4, eps=0.0), "eps must be > 0"),
        (lambda: BatchRenorm1d(4, r_max=0.5), "r_max >= 1"),
        (lambda: BatchRenorm1d(4, warmup_steps=-1), "warmup_steps must be >= 0"),
        (lambda: GaussianPolicy(3, 2, log_std_bounds=(2.0, -20.0)), "low < high"),
        (lambda: polyak_update(nn.Linear(1, 1), nn.Linear(1, 1), 0.0), "tau must be in"),
    ],
)
def test_bad_configuration_raises_value_error(make, match):
    with pytest.raises(ValueError, match=match):
        make()


def test_shape_errors_name_the_expected_shape():
    with pytest.raises(ValueError, match=r"\(batch, 4\)"):
        BatchRenorm1d(4)(torch.randn(3, 5))
    support = CategoricalSupport(-1.0, 1.0, 5)
    with pytest.raises(ValueError, match=r"\(B, 5\)"):
        support.project(torch.zeros(2, 4), torch.zeros(2, 4))

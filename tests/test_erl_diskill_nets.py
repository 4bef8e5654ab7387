"""Di-SkilL's batched networks (Appendix B.3.1, Eq. 4.6): batching, initialisation, densities."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from torch.distributions import MultivariateNormal

from vslbook.erl.diskill_nets import (
    BatchedMLP,
    EnergyNets,
    GaussianExperts,
    ValueCritics,
    log_gating,
    log_responsibilities,
)

F64 = torch.float64


def _randomise(module: torch.nn.Module, seed: int, scale: float = 0.5) -> None:
    """Replace every parameter by random numbers (so biases and heads are not trivial)."""
    g = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for p in module.parameters():
            p.copy_(scale * torch.randn(p.shape, generator=g, dtype=p.dtype))


def _random_chol(k: int, d: int, seed: int) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    low = torch.tril(0.3 * torch.randn(k, d, d, generator=g, dtype=F64), diagonal=-1)
    diag = 0.2 + torch.rand(k, d, generator=g, dtype=F64)
    return low + torch.diag_embed(diag)


# ---------------------------------------------------------------------- 1. BatchedMLP


@pytest.mark.parametrize("hidden", [(5, 6), (7,)])
def test_batched_mlp_equals_separate_sequentials(hidden):
    torch.manual_seed(0)
    k, n_in, n_out, b = 3, 4, 2, 9
    net = BatchedMLP(k, n_in, hidden, n_out, head_gain=0.7)
    _randomise(net, 1)
    x = torch.randn(k, b, n_in, dtype=F64)
    out = net(x)
    assert out.shape == (k, b, n_out)
    sizes = (n_in, *hidden, n_out)
    for j in range(k):
        layers: list[torch.nn.Module] = []
        for layer, (a, c) in enumerate(zip(sizes[:-1], sizes[1:], strict=True)):
            lin = torch.nn.Linear(a, c, dtype=F64)
            with torch.no_grad():
                lin.weight.copy_(net.weights[layer][j].T)
                lin.bias.copy_(net.biases[layer][j, 0])
            layers.append(lin)
            if layer < len(sizes) - 2:
                layers.append(torch.nn.Tanh())
        ref = torch.nn.Sequential(*layers)
        torch.testing.assert_close(out[j], ref(x[j]), rtol=1e-12, atol=1e-12)


def test_batched_mlp_without_hidden_layers_is_affine():
    torch.manual_seed(0)
    net = BatchedMLP(2, 3, (), 4, head_gain=1.0)
    _randomise(net, 2)
    assert len(net.weights) == 1
    x1, x2 = torch.randn(2, 2, 5, 3, dtype=F64)
    a = 0.3
    torch.testing.assert_close(net(a * x1 + (1 - a) * x2), a * net(x1) + (1 - a) * net(x2))
    expected = np.einsum("kbi,kio->kbo", x1.numpy(), net.weights[0].detach().numpy())
    expected += net.biases[0].detach().numpy()
    np.testing.assert_allclose(net(x1).detach().numpy(), expected, rtol=1e-12, atol=1e-12)


def _gram(w: torch.Tensor) -> torch.Tensor:
    """WᵀW or WWᵀ, whichever is the Gram matrix of the smaller side."""
    return w.T @ w if w.shape[0] >= w.shape[1] else w @ w.T


@pytest.mark.parametrize("head_gain", [0.01, 1.0, 3.0])
def test_init_is_orthogonal_with_the_right_gains_and_zero_bias(head_gain):
    torch.manual_seed(3)
    k = 4
    net = BatchedMLP(k, 6, (6, 8), 6, head_gain=head_gain)
    gains = [math.sqrt(2.0), math.sqrt(2.0), head_gain]
    for w, b, gain in zip(net.weights, net.biases, gains, strict=True):
        assert w.dtype == F64 and w.shape[0] == k
        assert torch.count_nonzero(b) == 0
        for j in range(k):
            eye = torch.eye(min(w.shape[1:]), dtype=F64)
            torch.testing.assert_close(_gram(w[j].detach()), gain**2 * eye, rtol=0, atol=1e-12)
        # square layers: WᵀW = g² I exactly in both orders
        if w.shape[1] == w.shape[2]:
            torch.testing.assert_close(
                w[0].detach() @ w[0].detach().T,
                gain**2 * torch.eye(6, dtype=F64),
                atol=1e-12,
                rtol=0,
            )
        # the copies are drawn independently
        assert not torch.allclose(w[0], w[1])


def test_init_is_seeded_by_torch_global_stream():
    def weights(seed):
        torch.manual_seed(seed)
        net = BatchedMLP(3, 2, (4,), 2, head_gain=0.01)
        return torch.cat([p.detach().flatten() for p in net.parameters()])

    torch.testing.assert_close(weights(5), weights(5), rtol=0, atol=0)
    assert not torch.allclose(weights(5), weights(6))


def test_numpy_integer_sizes_are_accepted():
    experts = GaussianExperts(np.int64(2), np.int64(3), np.int64(4), (np.int64(5),))
    assert experts.chol().shape == (2, 4, 4)
    assert experts.mean(torch.zeros(2, 1, 3, dtype=F64)).shape == (2, 1, 4)


def test_float32_parameters_on_request():
    net = GaussianExperts(2, 3, 4, (5,), dtype=torch.float32)
    assert {p.dtype for p in net.parameters()} == {torch.float32}
    assert net.chol().dtype == torch.float32
    assert net.mean(torch.zeros(2, 1, 3)).dtype == torch.float32


def test_gradients_are_isolated_between_experts():
    torch.manual_seed(0)
    k, d, dc = 3, 2, 3
    experts = GaussianExperts(k, dc, d, (4, 4))
    energy = EnergyNets(k, dc)
    critic = ValueCritics(k, dc, (5,))
    c = torch.randn(k, 6, dc, dtype=F64)
    theta = torch.randn(k, 6, d, dtype=F64)
    for j in range(k):
        for m in (experts, energy, critic):
            m.zero_grad()
        experts.log_prob(theta, experts.mean(c), experts.chol())[j].sum().backward()
        energy.energies(c)[j].sum().backward()  # (log-softmax ignores the head's bias)
        critic.values(c)[j].sum().backward()
        for m in (experts, energy, critic):
            for p in m.parameters():
                others = torch.cat([p.grad[i].flatten() for i in range(k) if i != j])
                assert torch.count_nonzero(others) == 0
                assert torch.count_nonzero(p.grad[j]) > 0 or p.grad[j].numel() == 0


def test_output_layer_gains_of_the_three_networks():
    torch.manual_seed(0)
    experts = GaussianExperts(3, 2, 5, (8,))
    energy = EnergyNets(3, 2)
    critic = ValueCritics(3, 2, (8, 8))
    eye5 = torch.eye(5, dtype=F64)
    for w in experts.mean_net.weights[-1]:  # (8, 5): WᵀW = 0.01² I
        torch.testing.assert_close(w.detach().T @ w.detach(), 1e-4 * eye5, rtol=0, atol=1e-14)
    for net, gain in ((energy.net, 0.01), (critic.net, 1.0)):
        norms = net.weights[-1].detach().norm(dim=1)[:, 0]  # (K, hidden, 1) columns
        torch.testing.assert_close(norms, torch.full((3,), gain, dtype=F64), rtol=1e-12, atol=0)
    assert [w.shape[1:] for w in energy.net.weights] == [(2, 16), (16, 16), (16, 1)]


# -------------------------------------------------------------------- 2. GaussianExperts


def test_log_prob_and_entropy_equal_torch_distributions():
    torch.manual_seed(0)
    k, d, dc, b = 3, 4, 2, 7
    experts = GaussianExperts(k, dc, d, (5,))
    _randomise(experts.mean_net, 4)
    c = torch.randn(k, b, dc, dtype=F64)
    mean = experts.mean(c)
    chol = _random_chol(k, d, 5)
    theta = mean + torch.randn(k, b, d, dtype=F64)
    lp = experts.log_prob(theta, mean, chol)
    ent = experts.entropy(chol)
    assert lp.shape == (k, b) and ent.shape == (k,)
    for j in range(k):
        dist = MultivariateNormal(mean[j].detach(), scale_tril=chol[j])
        torch.testing.assert_close(lp[j].detach(), dist.log_prob(theta[j]), rtol=1e-12, atol=1e-12)
        torch.testing.assert_close(ent[j].expand(b), dist.entropy(), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("init_std", [1.0, 0.3, 2.5])
def test_initial_cholesky_is_init_std_times_identity(init_std):
    torch.manual_seed(0)
    k, d = 20, 10
    experts = GaussianExperts(k, 2, d, (4,), init_std=init_std)
    L = experts.chol().detach()
    diag = torch.diagonal(L, dim1=-2, dim2=-1)
    torch.testing.assert_close(diag, torch.full_like(diag, init_std), rtol=1e-12, atol=0)
    assert torch.count_nonzero(torch.triu(L, 1)) == 0
    off = L[torch.tril(torch.ones(d, d, dtype=torch.bool), -1).expand(k, d, d)]
    assert off.numel() == k * d * (d - 1) // 2
    assert 0.008 < float(off.std()) < 0.012  # N(0, 0.01²)
    assert float(off.abs().max()) < 0.06
    sigma = L @ L.transpose(1, 2)
    # Σ₀ = init_std² I up to the off-diagonal scale: |Σ₀ − s²I| ≲ 2·s·|off| + d·off²
    bound = 2 * init_std * 0.06 + d * 0.06**2
    err = (sigma - init_std**2 * torch.eye(d, dtype=F64)).abs().max()
    assert float(err) < bound


def test_initial_mean_is_small():
    torch.manual_seed(0)
    experts = GaussianExperts(2, 3, 4, (16, 16))
    with torch.no_grad():
        mean = experts.mean(torch.randn(2, 50, 3, dtype=F64))
    assert float(mean.abs().max()) < 0.05


@pytest.mark.parametrize(
    ("seed", "d", "first_diag"),
    [(0, 1, 2e-5), (1, 2, 1e-3), (2, 3, 0.5), (3, 4, 7.0), (4, 5, 50.0), (5, 3, 1.0)],
)
def test_set_chol_round_trip(seed, d, first_diag):
    torch.manual_seed(seed)
    k = 2
    experts = GaussianExperts(k, 3, d, (), init_std=0.7)
    target = _random_chol(k, d, seed)
    target[0, 0, 0] = first_diag  # from just above the floor 1e-5 to the linear regime
    experts.set_chol(target)
    torch.testing.assert_close(experts.chol().detach(), target, rtol=1e-9, atol=1e-12)


def test_set_chol_rejects_invalid_factors():
    experts = GaussianExperts(2, 3, 3, ())
    good = _random_chol(2, 3, 0)
    small = good.clone()
    small[1, 2, 2] = 1e-5
    with pytest.raises(ValueError, match="diagonal"):
        experts.set_chol(small)
    upper = good.clone()
    upper[0, 0, 2] = 0.1
    with pytest.raises(ValueError, match="lower triangular"):
        experts.set_chol(upper)
    with pytest.raises(ValueError, match=r"chol must have shape \(2, 3, 3\)"):
        experts.set_chol(good[:1])
    before = experts.chol().detach().clone()
    with pytest.raises(ValueError):
        experts.set_chol(good.clone().fill_(float("nan")))
    torch.testing.assert_close(experts.chol().detach(), before, rtol=0, atol=0)


def test_state_dict_round_trip_keeps_init_std():
    torch.manual_seed(0)
    a = GaussianExperts(2, 3, 3, (4,), init_std=0.2)
    a.set_chol(_random_chol(2, 3, 1))
    b = GaussianExperts(2, 3, 3, (4,), init_std=1.0)
    b.load_state_dict(a.state_dict())
    c = torch.randn(2, 5, 3, dtype=F64)
    torch.testing.assert_close(b.chol(), a.chol(), rtol=0, atol=0)
    torch.testing.assert_close(b.mean(c), a.mean(c), rtol=0, atol=0)


def test_sample_statistics_match_the_parameters():
    torch.manual_seed(0)
    k, d, dc, n = 2, 3, 2, 20_000
    experts = GaussianExperts(k, dc, d, (6,))
    _randomise(experts.mean_net, 7)
    chol = _random_chol(k, d, 8)
    experts.set_chol(chol)
    c = torch.rand(k, n, dc, dtype=F64)
    with torch.no_grad():
        theta, mean = experts.sample(c, torch.Generator().manual_seed(9))
        torch.testing.assert_close(mean, experts.mean(c), rtol=0, atol=0)
    resid = (theta - mean).numpy()  # ~ N(0, LLᵀ) at every context
    sigma = (chol @ chol.transpose(1, 2)).numpy()
    for j in range(k):
        se_mean = np.sqrt(np.diag(sigma[j]) / n)
        assert np.all(np.abs(resid[j].mean(0)) < 4.5 * se_mean)
        cov = np.cov(resid[j].T)
        v = np.diag(sigma[j])
        se_cov = np.sqrt((np.outer(v, v) + sigma[j] ** 2) / n)
        assert np.all(np.abs(cov - sigma[j]) < 4.5 * se_cov)


def test_sample_is_deterministic_under_a_generator_seed():
    torch.manual_seed(0)
    experts = GaussianExperts(3, 2, 4, (5,))
    c = torch.randn(3, 6, 2, dtype=F64)
    with torch.no_grad():
        a, _ = experts.sample(c, torch.Generator().manual_seed(1))
        b, _ = experts.sample(c, torch.Generator().manual_seed(1))
        other, _ = experts.sample(c, torch.Generator().manual_seed(2))
    torch.testing.assert_close(a, b, rtol=0, atol=0)
    assert not torch.allclose(a, other)


# ------------------------------------------------------------- 3. energies and critics


def test_energy_log_probs_normalise_over_the_batch():
    torch.manual_seed(0)
    k, n, dc = 3, 40, 2
    energy = EnergyNets(k, dc, (8, 8))
    _randomise(energy, 3)
    c = torch.randn(n, dc, dtype=F64)
    lp = energy.log_probs(c).detach().numpy()
    assert lp.shape == (k, n)
    np.testing.assert_allclose(np.exp(lp).sum(1), np.ones(k), rtol=1e-12)
    e = energy.energies(c).detach().numpy()
    direct = np.exp(e) / np.exp(e).sum(1, keepdims=True)  # Eq. 4.6, Z = Σ_i exp φ(c_i)
    np.testing.assert_allclose(np.exp(lp), direct, rtol=1e-12)


def test_energy_shared_and_per_expert_inputs_agree():
    torch.manual_seed(0)
    k, n, dc = 4, 11, 3
    energy = EnergyNets(k, dc)
    _randomise(energy, 5)
    c = torch.randn(n, dc, dtype=F64)
    shared = energy.energies(c)
    torch.testing.assert_close(energy.energies(c.expand(k, n, dc)), shared, rtol=0, atol=0)
    torch.testing.assert_close(energy.log_probs(c.expand(k, n, dc)), energy.log_probs(c))
    # different contexts per expert: row j is expert j's energy on its own contexts
    per = torch.randn(k, n, dc, dtype=F64)
    out = energy.energies(per)
    for j in range(k):
        torch.testing.assert_close(out[j], energy.energies(per[j])[j], rtol=1e-12, atol=1e-12)


def test_critic_values_shape_and_per_expert_inputs():
    torch.manual_seed(0)
    critic = ValueCritics(3, 2, (4,))
    _randomise(critic, 1)
    c = torch.randn(3, 5, 2, dtype=F64)
    v = critic.values(c)
    assert v.shape == (3, 5)
    x = c[1] @ critic.net.weights[0][1] + critic.net.biases[0][1]
    ref = torch.tanh(x) @ critic.net.weights[1][1] + critic.net.biases[1][1]
    torch.testing.assert_close(v[1], ref[:, 0])


# ------------------------------------------------------------------ 4. Bayes' rule


def test_log_gating_is_bayes_rule_with_uniform_prior():
    rng = np.random.default_rng(0)
    k, n = 4, 30
    e = rng.normal(size=(k, n)) * 2
    log_pc = e - np.log(np.exp(e).sum(1, keepdims=True))
    out = log_gating(torch.as_tensor(log_pc)).numpy()
    np.testing.assert_allclose(np.exp(out).sum(0), np.ones(n), rtol=1e-12)
    prior = np.full((k, 1), 1.0 / k)
    joint = np.exp(log_pc) * prior
    np.testing.assert_allclose(np.exp(out), joint / joint.sum(0, keepdims=True), rtol=1e-12)


def test_log_responsibilities_equal_a_per_sample_loop():
    torch.manual_seed(0)
    k, d, dc, b = 3, 2, 2, 4
    experts = GaussianExperts(k, dc, d, (4,))
    _randomise(experts.mean_net, 11, scale=0.8)
    experts.set_chol(_random_chol(k, d, 12) + 0.5 * torch.eye(d, dtype=F64))
    energy = EnergyNets(k, dc, (5,))
    _randomise(energy, 13)
    c = torch.rand(k, b, dc, dtype=F64)
    with torch.no_grad():
        theta, _ = experts.sample(c, torch.Generator().manual_seed(14))
        # log π(c_kb | o') normalised over the K·B sampled contexts, rows o'
        log_pc = energy.log_probs(c.reshape(k * b, dc)).reshape(k, k, b)
        out = log_responsibilities(theta, c, experts, log_pc).numpy()
        chol = experts.chol()
    assert out.shape == (k, b)
    ref = np.zeros((k, b))
    for j in range(k):
        for i in range(b):
            means = experts.mean(c[j, i].expand(k, 1, dc)).detach()[:, 0]  # every expert at c_ji
            dens = np.array(
                [
                    float(MultivariateNormal(means[o], scale_tril=chol[o]).log_prob(theta[j, i]))
                    for o in range(k)
                ]
            )
            p_c = np.exp(log_pc[:, j, i].numpy())
            gate = p_c / p_c.sum()  # π(o | c) with π(o) = 1/K
            weights = np.exp(dens) * gate
            ref[j, i] = np.log(weights[j] / weights.sum())
    np.testing.assert_allclose(out, ref, rtol=1e-10, atol=1e-12)
    assert np.all(out <= 1e-12)


def test_log_responsibilities_of_one_expert_are_zero():
    torch.manual_seed(0)
    experts = GaussianExperts(1, 2, 3, ())
    c = torch.randn(1, 5, 2, dtype=F64)
    theta = torch.randn(1, 5, 3, dtype=F64)
    out = log_responsibilities(theta, c, experts, torch.randn(1, 1, 5, dtype=F64))
    torch.testing.assert_close(out, torch.zeros(1, 5, dtype=F64), rtol=0, atol=1e-14)


# -------------------------------------------------------------------- 5. bad input


def _bad_calls():
    experts = GaussianExperts(2, 3, 4, (5,))
    energy = EnergyNets(2, 3)
    critic = ValueCritics(2, 3, (5,))
    mlp = BatchedMLP(2, 3, (), 1, head_gain=1.0)
    c = torch.zeros(2, 5, 3, dtype=F64)
    th = torch.zeros(2, 5, 4, dtype=F64)
    chol = experts.chol().detach()
    nan_c = c.clone()
    nan_c[0, 0, 0] = float("nan")
    return {
        "mlp wrong experts": (lambda: mlp(torch.zeros(3, 5, 3, dtype=F64)), "x"),
        "mlp 2-d": (lambda: mlp(torch.zeros(5, 3, dtype=F64)), "x"),
        "mean wrong dim": (lambda: experts.mean(torch.zeros(2, 5, 2, dtype=F64)), "contexts"),
        "mean float32": (lambda: experts.mean(c.float()), "dtype"),
        "mean nan": (lambda: experts.mean(nan_c), "finite"),
        "log_prob theta": (lambda: experts.log_prob(th[:, :, :3], th[:, :, :3], chol), "theta"),
        "log_prob mean": (lambda: experts.log_prob(th, th[:, :4], chol), "mean"),
        "log_prob chol": (lambda: experts.log_prob(th, th, chol[:1]), "chol"),
        "log_prob chol diag": (lambda: experts.log_prob(th, th, -chol), "chol"),
        "entropy chol": (lambda: experts.entropy(chol[..., :3]), "chol"),
        "energies 1-d": (lambda: energy.energies(torch.zeros(3, dtype=F64)), "contexts"),
        "energies dim": (lambda: energy.energies(torch.zeros(7, 2, dtype=F64)), "contexts"),
        "energies experts": (lambda: energy.energies(torch.zeros(3, 7, 3, dtype=F64)), "contexts"),
        "energies inf": (lambda: energy.energies(nan_c[0].abs() / 0), "finite"),
        "values 2-d": (lambda: critic.values(c[0]), "contexts"),
        "gating 1-d": (lambda: log_gating(torch.zeros(3, dtype=F64)), "log_pc"),
        "gating nan": (lambda: log_gating(nan_c[0]), "log_pc"),
        "resp log_pc": (
            lambda: log_responsibilities(th, c, experts, torch.zeros(2, 5, dtype=F64)),
            "log_pc",
        ),
        "resp contexts": (
            lambda: log_responsibilities(th, c[:, :4], experts, torch.zeros(2, 2, 5, dtype=F64)),
            "contexts",
        ),
        "resp theta": (
            lambda: log_responsibilities(th[..., :2], c, experts, torch.zeros(2, 2, 5, dtype=F64)),
            "theta",
        ),
        "n_models": (lambda: BatchedMLP(0, 3, (), 1, head_gain=1.0), "n_models"),
        "hidden zero": (lambda: BatchedMLP(2, 3, (4, 0), 1, head_gain=1.0), "hidden"),
        "hidden int": (lambda: ValueCritics(2, 3, 4), "hidden"),
        "head_gain": (lambda: BatchedMLP(2, 3, (), 1, head_gain=0.0), "head_gain"),
        "init_std": (lambda: GaussianExperts(2, 3, 4, (), init_std=1e-5), "init_std"),
        "init_std nan": (lambda: GaussianExperts(2, 3, 4, (), init_std=float("nan")), "init_std"),
        "theta_dim": (lambda: GaussianExperts(2, 3, 0, ()), "theta_dim"),
        "context_dim": (lambda: EnergyNets(2, 1.5), "context_dim"),
        "n_experts bool": (lambda: EnergyNets(True, 2), "n_experts"),
    }


@pytest.mark.parametrize("case", list(_bad_calls()))
def test_bad_input_raises_value_error_naming_the_value(case):
    call, name = _bad_calls()[case]
    with pytest.raises(ValueError, match=name):
        call()

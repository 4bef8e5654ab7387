"""Tests for vslbook.dists: Gaussians and mixtures against scipy and brute force."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.stats import entropy as scipy_entropy
from scipy.stats import multivariate_normal

from vslbook.dists import (
    LinearGaussianMoE,
    categorical_entropy,
    condition_gaussian,
    gaussian_entropy,
    gaussian_kl,
    gaussian_log_prob,
    marginal_gaussian,
    moe_log_prob,
    responsibilities,
)


def random_gaussians(seed: int, batch: tuple[int, ...], d: int, dtype=torch.float64):
    g = torch.Generator().manual_seed(seed)
    a = torch.randn(*batch, d, d, generator=g, dtype=torch.float64)
    cov = a @ a.mT / d + 0.5 * torch.eye(d, dtype=torch.float64)
    mean = torch.randn(*batch, d, generator=g, dtype=torch.float64)
    return mean.to(dtype), cov.to(dtype)


# ------------------------------------------------------------------------- Gaussians


def test_log_prob_matches_scipy_with_broadcasting():
    mean, cov = random_gaussians(0, (4,), 3)
    x = torch.randn(5, 1, 3, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    out = gaussian_log_prob(x, mean, cov)
    assert out.shape == (5, 4)
    expected = np.array(
        [
            [
                multivariate_normal(mean[j].numpy(), cov[j].numpy()).logpdf(x[i, 0].numpy())
                for j in range(4)
            ]
            for i in range(5)
        ]
    )
    np.testing.assert_allclose(out.numpy(), expected, rtol=1e-12, atol=1e-12)


def test_log_prob_float32_close_to_float64():
    mean, cov = random_gaussians(2, (6,), 4)
    x = mean + 0.3
    out64 = gaussian_log_prob(x, mean, cov)
    out32 = gaussian_log_prob(x.float(), mean.float(), cov.float())
    assert out32.dtype == torch.float32
    np.testing.assert_allclose(out32.numpy(), out64.numpy(), rtol=1e-5, atol=1e-5)


def test_log_prob_accepts_numpy():
    out = gaussian_log_prob(np.zeros(2), np.zeros(2), np.eye(2))
    assert out.dtype == torch.float64
    assert float(out) == pytest.approx(-np.log(2 * np.pi))


def test_entropy_matches_scipy():
    mean, cov = random_gaussians(3, (3,), 3)
    out = gaussian_entropy(cov)
    for j in range(3):
        expected = multivariate_normal(mean[j].numpy(), cov[j].numpy()).entropy()
        assert float(out[j]) == pytest.approx(expected, rel=1e-12)


def test_kl_of_identical_gaussians_is_zero():
    mean, cov = random_gaussians(4, (5,), 3)
    np.testing.assert_allclose(gaussian_kl(mean, cov, mean, cov).numpy(), 0.0, atol=1e-12)


def test_kl_matches_monte_carlo():
    mp, cp = random_gaussians(5, (), 3)
    mq, cq = random_gaussians(6, (), 3)
    kl = float(gaussian_kl(mp, cp, mq, cq))
    rng = np.random.default_rng(0)
    x = rng.multivariate_normal(mp.numpy(), cp.numpy(), size=200_000)
    ratio = multivariate_normal(mp.numpy(), cp.numpy()).logpdf(x) - multivariate_normal(
        mq.numpy(), cq.numpy()
    ).logpdf(x)
    se = ratio.std() / np.sqrt(ratio.size)
    assert kl > 0
    assert abs(ratio.mean() - kl) < 5 * se


def test_kl_one_dimensional_formula_and_float32():
    kl = gaussian_kl([1.0], [[4.0]], [0.0], [[1.0]])
    expected = 0.5 * (4.0 + 1.0 - 1.0 - np.log(4.0))
    assert float(kl) == pytest.approx(expected, rel=1e-12)
    kl32 = gaussian_kl(torch.ones(1), 4 * torch.ones(1, 1), torch.zeros(1), torch.ones(1, 1))
    assert kl32.dtype == torch.float32
    assert float(kl32) == pytest.approx(expected, rel=1e-5)


@pytest.mark.parametrize("idx_obs", [[0], [3, 1], [0, 2, 4]])
def test_conditioning_matches_precision_formula_and_density_ratio(idx_obs):
    mean, cov = random_gaussians(7, (), 5)
    x = torch.randn(8, 5, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    x_obs = x[:, idx_obs]
    cond_mean, cond_cov = condition_gaussian(mean, cov, idx_obs, x_obs)
    unobs = [i for i in range(5) if i not in idx_obs]
    # Brute force 1: the precision matrix, Lambda_uu^{-1} and mean_u - Lambda_uu^{-1} Lambda_uo r.
    prec = torch.linalg.inv(cov)
    l_uu = prec[unobs][:, unobs]
    l_uo = prec[unobs][:, idx_obs]
    expected_cov = torch.linalg.inv(l_uu)
    expected_mean = mean[unobs] - ((expected_cov @ l_uo) @ (x_obs - mean[idx_obs]).T).T
    np.testing.assert_allclose(cond_cov.numpy(), expected_cov.numpy(), atol=1e-10)
    np.testing.assert_allclose(cond_mean.numpy(), expected_mean.numpy(), atol=1e-10)
    # Brute force 2: log p(x_u | x_o) = log p(x) - log p(x_o).
    m_obs, c_obs = marginal_gaussian(mean, cov, idx_obs)
    lhs = gaussian_log_prob(x[:, unobs], cond_mean, cond_cov)
    rhs = gaussian_log_prob(x, mean, cov) - gaussian_log_prob(x_obs, m_obs, c_obs)
    np.testing.assert_allclose(lhs.numpy(), rhs.numpy(), atol=1e-10)


def test_conditioning_is_batched():
    mean, cov = random_gaussians(8, (3,), 4)
    x_obs = torch.randn(3, 2, dtype=torch.float64)
    cm, cc = condition_gaussian(mean, cov, [1, 2], x_obs)
    assert cm.shape == (3, 2) and cc.shape == (3, 2, 2)
    for j in range(3):
        mj, cj = condition_gaussian(mean[j], cov[j], [1, 2], x_obs[j])
        np.testing.assert_allclose(cm[j].numpy(), mj.numpy(), atol=1e-12)
        np.testing.assert_allclose(cc[j].numpy(), cj.numpy(), atol=1e-12)


def test_marginal_matches_scipy_of_sub_block():
    mean, cov = random_gaussians(9, (), 4)
    m, c = marginal_gaussian(mean, cov, [2, 0])
    assert m.tolist() == [mean[2].item(), mean[0].item()]
    x = np.array([0.3, -0.2])
    expected = multivariate_normal(mean.numpy()[[2, 0]], cov.numpy()[np.ix_([2, 0], [2, 0])])
    assert float(gaussian_log_prob(x, m, c)) == pytest.approx(expected.logpdf(x), rel=1e-12)


# ------------------------------------------------------------------------- mixtures


def random_mixture(seed: int, k: int = 3, d: int = 2):
    means, covs = random_gaussians(seed, (k,), d)
    g = torch.Generator().manual_seed(seed + 100)
    log_weights = torch.log_softmax(torch.randn(k, generator=g, dtype=torch.float64), 0)
    return log_weights, 2 * means, covs


def direct_mixture_terms(x, log_weights, means, covs):
    terms = np.stack(
        [
            np.exp(log_weights[o].item())
            * multivariate_normal(means[o].numpy(), covs[o].numpy()).pdf(x.numpy())
            for o in range(len(log_weights))
        ],
        axis=-1,
    )
    return terms


def test_moe_log_prob_matches_direct_sum():
    lw, means, covs = random_mixture(0)
    x = torch.randn(50, 2, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    expected = np.log(direct_mixture_terms(x, lw, means, covs).sum(-1))
    np.testing.assert_allclose(moe_log_prob(x, lw, means, covs).numpy(), expected, rtol=1e-10)


def test_single_component_mixture_is_gaussian():
    mean, cov = random_gaussians(1, (), 3)
    x = torch.randn(7, 3, dtype=torch.float64)
    out = moe_log_prob(x, torch.zeros(1, dtype=torch.float64), mean[None], cov[None])
    np.testing.assert_allclose(out.numpy(), gaussian_log_prob(x, mean, cov).numpy(), atol=1e-12)


def test_responsibilities_sum_to_one_and_match_bayes():
    lw, means, covs = random_mixture(2, k=4)
    x = torch.randn(30, 2, generator=torch.Generator().manual_seed(3), dtype=torch.float64)
    resp = responsibilities(x, lw, means, covs)
    np.testing.assert_allclose(resp.sum(-1).numpy(), 1.0, atol=1e-12)
    terms = direct_mixture_terms(x, lw, means, covs)
    np.testing.assert_allclose(resp.numpy(), terms / terms.sum(-1, keepdims=True), atol=1e-10)


def test_responsibilities_float32():
    lw, means, covs = random_mixture(4)
    x = torch.randn(10, 2, dtype=torch.float64)
    r64 = responsibilities(x, lw, means, covs)
    r32 = responsibilities(x.float(), lw.float(), means.float(), covs.float())
    assert r32.dtype == torch.float32
    np.testing.assert_allclose(r32.numpy(), r64.numpy(), atol=1e-4)


def test_categorical_entropy_matches_scipy_and_handles_zeros():
    probs = torch.tensor([[0.2, 0.3, 0.5], [1.0, 0.0, 0.0]], dtype=torch.float64)
    out = categorical_entropy(probs)
    np.testing.assert_allclose(out.numpy(), scipy_entropy(probs.numpy(), axis=-1), atol=1e-14)
    assert float(out[1]) == 0.0


# ------------------------------------------------------------------ LinearGaussianMoE


@pytest.fixture
def moe() -> LinearGaussianMoE:
    return LinearGaussianMoE.random(3, context_dim=2, param_dim=2, seed=0)


def test_gating_is_bayes_rule(moe):
    c, _ = moe.sample_contexts(25, torch.Generator().manual_seed(0))
    joint = np.stack(
        [
            moe.weights[o].item()
            * multivariate_normal(moe.context_means[o].numpy(), moe.context_covs[o].numpy()).pdf(c)
            for o in range(3)
        ],
        axis=-1,
    )
    np.testing.assert_allclose(
        moe.gating(c).numpy(), joint / joint.sum(-1, keepdims=True), atol=1e-12
    )


def test_moe_log_prob_is_gated_sum_of_experts(moe):
    g = torch.Generator().manual_seed(1)
    c = torch.randn(10, 2, generator=g, dtype=torch.float64)
    theta = torch.randn(10, 2, generator=g, dtype=torch.float64)
    expected = np.zeros(10)
    gate = moe.gating(c).numpy()
    for o in range(3):
        mean = (moe.gains[o] @ c.T).T + moe.offsets[o]
        for i in range(10):
            expected[i] += gate[i, o] * multivariate_normal(
                mean[i].numpy(), moe.covs[o].numpy()
            ).pdf(theta[i].numpy())
    np.testing.assert_allclose(moe.log_prob(theta, c).numpy(), np.log(expected), rtol=1e-10)
    np.testing.assert_allclose(
        moe.joint_log_prob(theta, c).numpy(),
        (moe.log_prob(theta, c) + moe.context_log_prob(c)).numpy(),
        atol=1e-12,
    )


def test_moe_sampling_is_reproducible_and_follows_gating(moe):
    c = torch.tensor([[0.5, -0.3]], dtype=torch.float64).expand(20_000, 2)
    theta1, o1 = moe.sample(c, torch.Generator().manual_seed(3))
    theta2, o2 = moe.sample(c, torch.Generator().manual_seed(3))
    assert theta1.shape == (20_000, 2) and o1.shape == (20_000,)
    assert torch.equal(theta1, theta2) and torch.equal(o1, o2)
    gate = moe.gating(c[0]).numpy()
    freq = np.bincount(o1.numpy(), minlength=3) / o1.numel()
    assert np.all(np.abs(freq - gate) < 4 * np.sqrt(gate * (1 - gate) / o1.numel()) + 1e-12)


def test_moe_float32_parameters():
    m = LinearGaussianMoE.random(2, 1, 3, seed=1, dtype=torch.float32)
    theta, o = m.sample(torch.zeros(4, 1), torch.Generator().manual_seed(0))
    assert theta.dtype == torch.float32
    assert m.log_prob(theta, torch.zeros(4, 1)).dtype == torch.float32


# ------------------------------------------------------------------------ bad inputs


def test_non_positive_definite_covariance_raises():
    cov = torch.tensor([[1.0, 2.0], [2.0, 1.0]], dtype=torch.float64)
    with pytest.raises(ValueError, match="positive definite"):
        gaussian_log_prob(torch.zeros(2), torch.zeros(2), cov)


def test_asymmetric_covariance_raises():
    cov = torch.tensor([[1.0, 0.5], [0.0, 1.0]])
    with pytest.raises(ValueError, match="symmetric"):
        gaussian_entropy(cov)


def test_shape_mismatches_raise():
    with pytest.raises(ValueError, match=r"x must have shape \(\.\.\., 3\)"):
        gaussian_log_prob(torch.zeros(2), torch.zeros(3), torch.eye(3))
    with pytest.raises(ValueError, match=r"cov must have shape \(\.\.\., 3, 3\)"):
        gaussian_log_prob(torch.zeros(3), torch.zeros(3), torch.eye(2))
    with pytest.raises(ValueError, match="do not broadcast"):
        gaussian_log_prob(torch.zeros(4, 3), torch.zeros(5, 3), torch.eye(3))
    with pytest.raises(ValueError, match="dimension 2 but q has dimension 3"):
        gaussian_kl(torch.zeros(2), torch.eye(2), torch.zeros(3), torch.eye(3))


def test_bad_conditioning_indices_raise():
    mean, cov = torch.zeros(3), torch.eye(3)
    with pytest.raises(ValueError, match=r"indices in \[0, 3\)"):
        condition_gaussian(mean, cov, [3], torch.zeros(1))
    with pytest.raises(ValueError, match="must not repeat"):
        condition_gaussian(mean, cov, [1, 1], torch.zeros(2))
    with pytest.raises(ValueError, match="between 1 and 2"):
        condition_gaussian(mean, cov, [0, 1, 2], torch.zeros(3))
    with pytest.raises(ValueError, match=r"x_obs must have shape \(\.\.\., 2\)"):
        condition_gaussian(mean, cov, [0, 1], torch.zeros(3))


def test_unnormalised_mixture_weights_raise():
    lw, means, covs = random_mixture(0)
    with pytest.raises(ValueError, match="normalised"):
        moe_log_prob(torch.zeros(2), lw + 0.1, means, covs)
    with pytest.raises(ValueError, match=r"means must have shape \(\.\.\., 3, d\)"):
        responsibilities(torch.zeros(2), lw, means[:2], covs[:2])


def test_bad_probabilities_raise():
    with pytest.raises(ValueError, match="sum to 1"):
        categorical_entropy(torch.tensor([0.5, 0.6]))
    with pytest.raises(ValueError, match="non-negative"):
        categorical_entropy(torch.tensor([1.5, -0.5]))
    m = LinearGaussianMoE.random(2, 1, 1)
    with pytest.raises(ValueError, match="weights must sum to 1"):
        LinearGaussianMoE([0.5, 0.6], m.context_means, m.context_covs, m.gains, m.offsets, m.covs)
    with pytest.raises(ValueError, match=r"gains must have shape \(2, 1, 1\)"):
        LinearGaussianMoE(
            m.weights, m.context_means, m.context_covs, m.gains[:, :, :0], m.offsets, m.covs
        )
    with pytest.raises(ValueError, match=r"c must have shape \(\.\.\., 1\)"):
        m.gating(torch.zeros(4, 2))

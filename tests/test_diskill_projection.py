import numpy as np
import torch
from scipy.stats import multivariate_normal

from vslbook.bounds import diskill_projection as TR

S_o = np.array([[0.5, 0.2], [0.2, 0.3]])
S = np.array([[0.15, -0.05], [-0.05, 0.6]])


def test_gauss_kl_against_monte_carlo():
    rng = np.random.default_rng(0)
    mu1, mu2 = np.array([0.3, -0.2]), np.array([0.0, 0.5])
    x = rng.multivariate_normal(mu1, S, 400_000)
    mc = multivariate_normal(mu1, S).logpdf(x) - multivariate_normal(mu2, S_o).logpdf(x)
    assert abs(TR.gauss_kl(mu1, S, mu2, S_o) - mc.mean()) < 5 * mc.std() / np.sqrt(x.shape[0])
    assert abs(TR.gauss_kl(mu1, S, mu1, S)) < 1e-14


def test_random_chol_and_tril_from_free():
    torch.manual_seed(0)
    L = TR.random_chol(3, dim=4, spread=0.5)
    assert L.shape == (3, 4, 4) and torch.equal(L, torch.tril(L))
    assert bool((torch.diagonal(L, dim1=-2, dim2=-1) > 0).all())
    v = torch.tensor([1.0, 2.0, 3.0], dtype=torch.float64)
    expected = torch.tensor([[1.0, 0.0], [2.0, 3.0]], dtype=torch.float64)
    assert torch.equal(TR.tril_from_free(v), expected)


def test_cov_of_is_a_cholesky_parametrisation():
    L = np.linalg.cholesky(S)
    assert np.allclose(TR.cov_of([np.log(L[0, 0]), L[1, 0], np.log(L[1, 1])]), S)


def test_sigma_tilde_path_and_eta_readout():
    assert np.allclose(TR.sigma_tilde(0.0, S, S_o), S)
    assert np.allclose(TR.sigma_tilde(1e9, S, S_o), S_o, atol=1e-7)
    eta, off = TR.eta_on_path(TR.sigma_tilde(0.7, S, S_o), S, S_o)
    assert abs(eta - 0.7) < 1e-10 and off < 1e-12


def test_dual_minimiser_meets_the_bound():
    eps = 0.1
    eta = TR.dual_minimiser(S, S_o, eps)
    z = np.zeros(2)
    # at the optimum the covariance part of the KL equals its bound (g'(η*) = 0)
    assert abs(TR.gauss_kl(z, TR.sigma_tilde(eta, S, S_o), z, S_o) - eps) < 1e-7


def test_slsqp_projections_land_on_the_border():
    mu_o, mu, eps = np.zeros(2), np.array([0.9, -0.5]), 0.25
    x = TR.slsqp_mean_projection(mu, mu_o, S_o, eps)
    m = 0.5 * (x - mu_o) @ np.linalg.solve(S_o, x - mu_o)
    assert abs(m - eps) < 1e-8
    # the closed form of the mean projection: on the segment from mu_o to mu
    assert np.allclose(x, mu_o + (mu - mu_o) * np.sqrt(eps / (0.5 * mu @ np.linalg.solve(S_o, mu))),
                       atol=1e-6)  # fmt: skip
    res = TR.slsqp_cov_projection(S, S_o, 0.1)
    z = np.zeros(2)
    assert abs(TR.gauss_kl(z, TR.cov_of(res.x), z, S_o) - 0.1) < 1e-6

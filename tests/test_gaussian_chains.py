import math

import numpy as np
from scipy.stats import norm

from vslbook.bounds.gaussian_chains import chain_joint, expected_log_normal, log_normal


def test_log_normal_is_scipy_logpdf():
    x = np.linspace(-3, 3, 11)
    assert np.allclose(log_normal(x, 0.4, 2.5), norm(0.4, math.sqrt(2.5)).logpdf(x))


def test_expected_log_normal_by_monte_carlo():
    rng = np.random.default_rng(0)
    y = rng.normal(0.3, 0.8, 500_000)  # E[(y − mu)²] = 0.8² + 0.3² for mu = 0
    mc = norm(0.0, math.sqrt(1.7)).logpdf(y)
    assert abs(expected_log_normal(0.64 + 0.09, 1.7) - mc.mean()) < 5 * mc.std() / math.sqrt(y.size)


def test_chain_joint_by_simulation():
    rng = np.random.default_rng(1)
    B = np.array([[0.0, 0.0, 0.0], [0.9, 0.0, 0.0], [0.0, -0.5, 0.0]])
    b, std = np.array([0.2, -0.1, 0.4]), np.array([0.7, 0.3, 0.5])
    n = 400_000
    x = np.zeros((n, 3))
    for i in range(3):  # simulate the chain state by state
        x[:, i] = x @ B[i] + b[i] + std[i] * rng.standard_normal(n)
    mean, cov = chain_joint(B, b, std)
    assert np.allclose(mean, x.mean(0), atol=0.01)
    assert np.allclose(cov, np.cov(x.T), atol=0.01)

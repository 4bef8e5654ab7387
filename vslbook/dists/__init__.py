"""Gaussian and mixture-of-experts densities in torch (thesis Sections 2.6.2 and 2.7).

``gaussian``  full-covariance Gaussians: log density, entropy, KL, conditioning, marginals
``mixture``   Gaussian mixtures (Eq. 2.47), responsibilities (Eq. 2.64) and the contextual
              mixture of linear-Gaussian experts with Bayes-rule gating (Eqs. 2.48-2.49)
"""

from vslbook.dists.gaussian import (
    cholesky,
    condition_gaussian,
    gaussian_entropy,
    gaussian_kl,
    gaussian_log_prob,
    marginal_gaussian,
)
from vslbook.dists.mixture import (
    LinearGaussianMoE,
    categorical_entropy,
    component_log_probs,
    log_responsibilities,
    moe_log_prob,
    responsibilities,
)

__all__ = [
    "LinearGaussianMoE",
    "categorical_entropy",
    "cholesky",
    "component_log_probs",
    "condition_gaussian",
    "gaussian_entropy",
    "gaussian_kl",
    "gaussian_log_prob",
    "log_responsibilities",
    "marginal_gaussian",
    "moe_log_prob",
    "responsibilities",
]

"""Numerical checks of the results of Chapter 5 (DIME).

Each ``check_*`` function builds a small, seeded problem, computes both sides of an equation or
inequality of the thesis and returns a :class:`~vslbook.bounds.CheckReport` whose ``data``
holds the arrays a notebook needs to plot the experiment. Every check takes an optional
candidate (an entropy formula, a bound estimator, a Bellman operator, a policy-improvement
step); the default is the thesis's answer, and a wrong candidate makes the report fail, which
is how the tests show that the checks have teeth.

The checks live in one module per section of the thesis; this module re-exports them:

* :mod:`vslbook.bounds.dime_entropy`, Section 5.4.1: the entropy lower bound ``ℓ`` of Eq. 5.15
  (derived in Eq. C.2), its gap, the KL between the generative and the noising chain
  (Eqs. 5.18-5.20) and the approximate inference form of Eq. C.11, on
  :class:`~vslbook.srl.DiffusionPolicy` itself with an affine score network, so that its chain
  is linear-Gaussian and every quantity has a closed form (:func:`linear_gaussian_chain`).
* Section 5.4.2, the Bellman operator of Eq. 5.21 (Proposition 5.4.1), policy improvement
  (Proposition 5.4.2, Eqs. 5.22-5.23, proof Eqs. C.15-C.28) and policy iteration
  (Proposition 5.4.3), twice: :mod:`vslbook.bounds.dime_tabular` (the operator) and
  :mod:`vslbook.bounds.dime_tabular_iteration` (improvement, iteration) on random tabular MDPs
  with the exact entropy of a discrete policy (SAC's soft policy iteration, no diffusion chain), and
  :mod:`vslbook.bounds.dime_policy_iteration` with the diffusion policies of Section 5.4.1 and
  the bound ``ℓ`` on a linear-quadratic problem (:func:`check_diffusion_policy_iteration`).
* :mod:`vslbook.bounds.dime_score_matching`, Section 5.3.2: the denoising score-matching loss of
  Eq. 5.9 and the denoising process of Eq. 5.10 it trains, on a Gaussian-mixture target
  (:func:`check_score_matching`).
* Section 5.6, general bridges (Eqs. 5.29-5.38): the bridge, its samplers and estimators in
  :mod:`vslbook.bounds.dime_bridges`, closed forms for affine drifts in
  :mod:`vslbook.bounds.dime_bridges_linear`, and the checks in
  :mod:`vslbook.bounds.dime_bridges_checks` against closed forms
  (:func:`check_general_bridge`) and :mod:`vslbook.bounds.dime_bridges_quadrature` against
  quadrature with nonlinear drifts (:func:`check_bridge_quadrature`); and in
  :mod:`vslbook.bounds.dime_bridges_special`, DIME (thesis notation and the library's
  ``DiffusionPolicy``, with and without ``general_bridges``) as the special case
  (:func:`check_dime_as_bridge`).

Every check runs in about a second or less on one CPU thread.
"""

from __future__ import annotations

from vslbook.bounds import CheckReport
from vslbook.bounds.dime_bridges import (
    GeneralBridge,
    bridge_kl_samples,
    dime_bridge,
    entropy_bound_samples,
    log_backward_joint,
    log_forward_conditional,
    make_bridge,
    policy_bridge,
    sample_backward,
    sample_forward,
)
from vslbook.bounds.dime_bridges_checks import check_general_bridge
from vslbook.bounds.dime_bridges_linear import (
    LinearBridge,
    affine_map,
    linear_bridge_closed_form,
    linear_sde_moments,
)
from vslbook.bounds.dime_bridges_quadrature import check_bridge_quadrature
from vslbook.bounds.dime_bridges_special import check_dime_as_bridge
from vslbook.bounds.dime_entropy import (
    AffineScore,
    LinearGaussianChain,
    check_entropy_lower_bound,
    gaussian_entropy,
    linear_gaussian_chain,
    linear_gaussian_policy,
)
from vslbook.bounds.dime_policy_iteration import check_diffusion_policy_iteration
from vslbook.bounds.dime_score_matching import (
    OUProcess,
    check_score_matching,
    mixture_log_density_and_score,
    score_matching_loss,
)
from vslbook.bounds.dime_tabular import (
    check_soft_bellman_contraction,
    policy_entropy,
    soft_bellman_operator,
)
from vslbook.bounds.dime_tabular_iteration import check_soft_policy_iteration, mirror_step

__all__ = [
    "AffineScore",
    "GeneralBridge",
    "LinearBridge",
    "LinearGaussianChain",
    "OUProcess",
    "affine_map",
    "bridge_kl_samples",
    "check_bridge_quadrature",
    "check_diffusion_policy_iteration",
    "check_dime_as_bridge",
    "check_entropy_lower_bound",
    "check_general_bridge",
    "check_score_matching",
    "check_soft_bellman_contraction",
    "check_soft_policy_iteration",
    "dime_bridge",
    "dime_checks",
    "entropy_bound_samples",
    "gaussian_entropy",
    "linear_bridge_closed_form",
    "linear_gaussian_chain",
    "linear_gaussian_policy",
    "linear_sde_moments",
    "log_backward_joint",
    "log_forward_conditional",
    "make_bridge",
    "mirror_step",
    "mixture_log_density_and_score",
    "policy_bridge",
    "policy_entropy",
    "sample_backward",
    "sample_forward",
    "score_matching_loss",
    "soft_bellman_operator",
]


def dime_checks(seed: int = 0) -> list[CheckReport]:
    """Run every Chapter 5 check with default settings (about a second or less each)."""
    return [
        check_score_matching(seed),
        check_entropy_lower_bound(seed),
        check_soft_bellman_contraction(seed),
        check_soft_policy_iteration(seed),
        check_diffusion_policy_iteration(seed),
        check_general_bridge(seed),
        check_bridge_quadrature(seed),
        check_dime_as_bridge(seed),
    ]

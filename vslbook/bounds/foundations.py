"""Numerical checks of the results of Chapter 2 (Foundations).

Each ``check_*`` function builds a small, seeded problem, computes both sides of an equation
or inequality of the thesis and returns a :class:`~vslbook.bounds.CheckReport`: a tuple of
:class:`~vslbook.bounds.Check` plus the arrays a notebook needs to plot the experiment. Several
checks take an optional candidate (a policy, a closed form, a variational distribution); the
default is the thesis's answer, and passing a wrong one makes the report fail, which is how the
tests show that the checks have teeth.

Sections covered: 2.4 (soft value iteration, Eqs. 2.39-2.42), 2.5 (self-paced curricula,
Eq. 2.44), 2.6.2 (mixture-of-experts gating, Eqs. 2.47-2.49), 2.6.3 (Ornstein-Uhlenbeck forward
process, Eq. 2.51), 2.7 (variational inference, Eqs. 2.60-2.71) and 2.8 (mutual information,
Eqs. 2.72-2.74). Every function runs in well under a second.

One module per section: :mod:`~vslbook.bounds.foundations_maxent` (2.4),
:mod:`~vslbook.bounds.foundations_curriculum` (2.5), :mod:`~vslbook.bounds.foundations_moe`
(2.6.2), :mod:`~vslbook.bounds.foundations_ou` (2.6.3),
:mod:`~vslbook.bounds.foundations_variational` (2.7) and
:mod:`~vslbook.bounds.foundations_information` (2.8); this module gathers their public names
and runs them all (:func:`foundations_checks`).
"""

from __future__ import annotations

from vslbook.bounds import CheckReport
from vslbook.bounds.foundations_curriculum import (
    check_self_paced,
    self_paced_objective,
    self_paced_optimum,
    self_paced_problem,
)
from vslbook.bounds.foundations_information import check_mutual_information
from vslbook.bounds.foundations_maxent import (
    SoftValueResult,
    boltzmann_policy,
    check_soft_optimal_policy,
    maxent_objective,
    random_mdp,
    soft_policy_evaluation,
    soft_value,
    soft_value_iteration,
)
from vslbook.bounds.foundations_moe import check_moe_gating
from vslbook.bounds.foundations_ou import check_ou_marginals, ou_marginal, simulate_ou
from vslbook.bounds.foundations_variational import (
    check_diffusion_kl,
    check_kl_chain_rule,
    check_maxent_as_inference,
    check_mixture_estep_bound,
)

__all__ = [
    "SoftValueResult",
    "boltzmann_policy",
    "check_diffusion_kl",
    "check_kl_chain_rule",
    "check_maxent_as_inference",
    "check_mixture_estep_bound",
    "check_moe_gating",
    "check_mutual_information",
    "check_ou_marginals",
    "check_self_paced",
    "check_soft_optimal_policy",
    "foundations_checks",
    "maxent_objective",
    "ou_marginal",
    "random_mdp",
    "self_paced_objective",
    "self_paced_optimum",
    "self_paced_problem",
    "simulate_ou",
    "soft_policy_evaluation",
    "soft_value",
    "soft_value_iteration",
]


def foundations_checks(seed: int = 0) -> list[CheckReport]:
    """Run every Chapter 2 check with default settings (about a second in total)."""
    return [
        check_soft_optimal_policy(seed),
        check_self_paced(seed),
        check_moe_gating(seed),
        check_ou_marginals(seed),
        check_kl_chain_rule(seed),
        check_mixture_estep_bound(seed),
        check_diffusion_kl(seed),
        check_maxent_as_inference(seed),
        check_mutual_information(seed),
    ]

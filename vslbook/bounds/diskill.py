"""Numerical checks of the Chapter 4 (Di-SkilL) objective, its bounds and its sample forms.

Di-SkilL keeps the curriculum max-ent objective of Chapter 3 (Eq. 4.3 = Eq. 3.3) with the prior
``pi(o)`` fixed to uniform (B.3.1), the per-expert bounds (Eq. 4.4 = Eq. 3.5 for the experts,
Eq. 4.5 = Eq. 3.6 for the context distributions) and the closed-form auxiliaries of Appendix B.1,
but models every per-expert context distribution as an energy-based model

    pi(c|o) = exp(phi_o(c)) / Z_o,   Z_o = int exp(phi_o(c)) dc     (Eq. 4.6)

on the support of the task distribution ``p(c)``. The normaliser is estimated from contexts
drawn from ``p(c)`` (environment resets), so in practice ``pi(c|o)`` is a categorical
distribution over a batch of contexts, and the context update maximises the sample form
Eq. 4.8.

The checks run on a 1-D toy, :class:`EnergyMoE` on the
:class:`~vslbook.bounds.svsl_toy.ToyProblem` of Chapter 3 (a bounded context interval with
uniform ``p(c)``, a 1-D parameter, linear-Gaussian experts, a bimodal reward), whose energies
are a few fixed tanh features, so that every expectation can be computed by quadrature to
about ten digits. The two sides of every comparison are computed along different routes
(mixture densities against decomposed terms, normalisers and entropies on the Gauss-Legendre
nodes against adaptive quadrature, Monte-Carlo sums against quadrature).

Each ``check_*`` function returns a :class:`~vslbook.bounds.CheckReport` and takes an optional
candidate (a bound, a per-expert objective, the sum form of Eq. 4.8, a normaliser estimator,
a gating rule); the default is the thesis's formula, and a wrong candidate makes the report
fail, which is how the tests show that the checks have teeth.

Covered:

* :func:`check_curriculum_objective`: Eq. 4.3 = Eq. B.1 with uniform ``pi(o)``
  (``beta H[pi(o)] = beta log K``) and energy-based ``pi(c|o)`` (Eq. 4.6); the bound obtained
  with auxiliary responsibilities and its two gaps (the identity of Eq. A.4, which B.1 defers
  to Celik et al. 2021).
* :func:`check_expert_bound`: Eq. 4.4 (the objective of Eq. 4.7 without its trust region)
  with the auxiliary ``pi~(o|c, theta) = pi_old(o|c, theta)`` of B.1.
* :func:`check_context_bound`: Eq. 4.5 with ``pi~(o|c) = pi_old(o|c)`` of B.1, for
  perturbations of an energy ``phi_o``.
* :func:`check_sample_context_objective`: Eq. 4.8 (categorical over ``N`` contexts from
  ``p(c)``) against Eq. 4.5 (density, quadrature): equal up to ``beta log(N / V)``.
* :func:`check_energy_normaliser`: the Monte-Carlo normaliser of Eq. 4.6 and the
  self-normalised expectations under the batch categorical, in 1-D and 2-D.
* :func:`check_gating`: the gating ``pi(o|c)`` of Algorithm 3 / B.3.1 from batch-normalised
  categoricals, same batch against different batches (sizes 75 and 5000).

The experts' trust-region layers (Otto et al. 2021, "Differentiable trust region layers for
deep reinforcement learning", ICLR) constrain the update of Eq. 4.7 but not the bound it
maximises; they are checked with the algorithm in :mod:`vslbook.erl`.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from vslbook.bounds import Check, CheckReport
from vslbook.bounds.diskill_samples import (
    GatingFn,
    NormaliserFn,
    SampleObjectiveFn,
    check_energy_normaliser,
    check_gating,
    check_sample_context_objective,
)
from vslbook.bounds.diskill_toy import (
    EnergyBoundFn,
    EnergyMoE,
    ebm_context_entropy,
    ebm_context_objective,
    ebm_curriculum_objective,
    ebm_expected_responsibility_kls,
    ebm_expert_objective,
    ebm_log_contexts,
    ebm_log_normaliser,
    ebm_lower_bound,
    ebm_responsibilities,
    expert_context_values,
    mc_normaliser,
    random_energy_moe,
    sample_context_objective,
    self_normalised_expectation,
    uniform_prior_gating,
)
from vslbook.bounds.svsl import BoundToy, auxiliary_bounds
from vslbook.bounds.svsl import bound_check as svsl_bound_check
from vslbook.bounds.svsl_toy import (
    ToyProblem,
    perturb_expert,
)
from vslbook.bounds.toy_numerics import quadrature_tol, seeded_rng, worst_check

__all__ = [
    "EnergyBoundFn",
    "EnergyMoE",
    "GatingFn",
    "NormaliserFn",
    "SampleObjectiveFn",
    "check_context_bound",
    "check_curriculum_objective",
    "check_energy_normaliser",
    "check_expert_bound",
    "check_gating",
    "check_sample_context_objective",
    "diskill_checks",
    "ebm_context_entropy",
    "ebm_context_objective",
    "ebm_curriculum_objective",
    "ebm_expected_responsibility_kls",
    "ebm_expert_objective",
    "ebm_log_contexts",
    "ebm_log_normaliser",
    "ebm_lower_bound",
    "ebm_responsibilities",
    "expert_context_values",
    "mc_normaliser",
    "random_energy_moe",
    "sample_context_objective",
    "self_normalised_expectation",
    "uniform_prior_gating",
]


# ------------------------------------------------------------------------------ checks


def check_curriculum_objective(
    seed: int = 0,
    alpha: float = 0.5,
    beta: float = 1.0,
    n_auxiliaries: int = 6,
    bound: EnergyBoundFn | None = None,
) -> CheckReport:
    """Eq. 4.3 = Eq. B.1 for energy-based ``pi(c|o)`` and uniform ``pi(o)``, and its bound.

    On a random 3-expert :class:`EnergyMoE`: Eq. 4.3 from the mixture densities (energies
    normalised on the Gauss-Legendre nodes) equals Eq. B.1 term by term (``Z_o`` and
    ``H[pi(c|o)] = log Z_o - E[phi_o]`` by adaptive quadrature, ``beta H[pi(o)] = beta log K``);
    for random auxiliaries ``J = bound + alpha E[KL_theta] + (beta - alpha) E[KL_c]`` and
    ``bound <= J`` (which needs ``beta >= alpha``). Two supporting checks: the energy-based
    densities integrate to one on the grid, and the quadrature entropy equals
    ``-int pi log pi`` on the grid.

    Args:
        alpha, beta: temperatures of Eq. 4.3.
        bound: candidate for Eq. B.1 with auxiliaries ``(problem, model, log_aux_theta,
            log_aux_context)``; defaults to :func:`ebm_lower_bound`.

    Returns:
        Report with data ``objective``, ``bounds`` (per auxiliary), ``kl_theta``,
        ``kl_context``, ``contexts``, ``context_density`` (K, n_c) and ``gating`` (K, n_c).
    """
    problem = ToyProblem(alpha=alpha, beta=beta)
    bound = bound or ebm_lower_bound
    rng = seeded_rng(seed, 12)
    model = random_energy_moe(seed)
    objective = ebm_curriculum_objective(problem, model)
    log_rt, log_rc = ebm_responsibilities(problem, model)
    bounds, kl_t, kl_c = auxiliary_bounds(
        problem, model, bound, ebm_expected_responsibility_kls, log_rt, rng, n_auxiliaries
    )
    tol = quadrature_tol(objective, *bounds)
    own = float(bound(problem, model, log_rt, log_rc))
    fine = ToyProblem(alpha=alpha, beta=beta, n_context=128, n_theta=1201)
    c, c_w = problem.contexts
    log_ctx = ebm_log_contexts(problem, model)
    ctx = np.exp(log_ctx)
    checks = (
        Check(
            "Eq. 4.3 (mixture densities) = Eq. B.1 (own responsibilities, beta log K)",
            "Eqs. 4.3, 4.6, B.1",
            objective,
            own,
            tol,
        ),
        Check(
            "Eq. 4.3 on a 2x finer grid agrees (quadrature converged)",
            "Eq. 4.3",
            ebm_curriculum_objective(fine, model),
            objective,
            tol,
        ),
        worst_check(
            f"J = bound + alpha E[KL_theta] + (beta-alpha) E[KL_c] for {len(bounds)} auxiliaries",
            "Eq. B.1 (A.4)",
            np.full(bounds.shape, objective),
            bounds + alpha * kl_t + (beta - alpha) * kl_c,
            tol,
        ),
        worst_check(
            f"bound <= J for {len(bounds)} auxiliaries (needs beta >= alpha)",
            "Eqs. 4.4, 4.5",
            bounds,
            objective,
            tol,
            "<=",
        ),
        worst_check(
            "int pi(c|o) dc = 1 (Z_o by adaptive quadrature)", "Eq. 4.6", ctx @ c_w, 1.0, 1e-9
        ),
        worst_check(
            "H[pi(c|o)] = log Z - E[phi] equals -int pi log pi on the grid",
            "Eq. 4.6",
            ebm_context_entropy(problem, model),
            -(ctx * log_ctx) @ c_w,
            1e-9,
        ),
    )
    data = {
        "objective": np.array(objective),
        "bounds": bounds,
        "kl_theta": kl_t,
        "kl_context": kl_c,
        "contexts": c,
        "context_density": ctx,
        "gating": np.exp(log_rc),
    }
    return CheckReport(
        "Decomposition of the curriculum max-ent objective, energy-based pi(c|o) (Section 4.2)",
        checks,
        data,
    )


def _perturb_energy(model: EnergyMoE, rng: np.random.Generator, o: int, t: float, d=None):
    d = rng.normal(size=(3, model.amplitude.shape[1])) if d is None else d
    amplitude, slope, shift = model.amplitude.copy(), model.slope.copy(), model.shift.copy()
    amplitude[o] += 0.5 * t * d[0]
    slope[o] += 0.5 * t * d[1]
    shift[o] += 0.3 * t * d[2]
    return model.replace(amplitude=amplitude, slope=slope, shift=shift), d


#: The energy-based toy for :func:`vslbook.bounds.svsl.bound_check` (π(o) = 1/K scales the
#: per-expert objectives).
EBM_TOY = BoundToy(
    random_energy_moe, ebm_responsibilities, ebm_curriculum_objective, ebm_lower_bound,
    ebm_expected_responsibility_kls, 13,
    ("bound is tight at new = old (B.1 closed-form auxiliaries)", "Eq. B.1"), "Eq. B.1 (A.4)",
    "change of the bound = pi(o) x change of the {kind} objective",
)  # fmt: skip


def _bound_check(
    kind: str,
    seed: int,
    alpha: float,
    beta: float,
    n_perturbations: int,
    perturb: Callable,
    surrogate: Callable[[ToyProblem, EnergyMoE, np.ndarray, np.ndarray, int], float],
    equation: str,
    title: str,
) -> CheckReport:
    """Chapter 3's bound check (:func:`vslbook.bounds.svsl.bound_check`) on the EBM toy."""
    return svsl_bound_check(
        kind, seed, alpha, beta, n_perturbations, perturb, surrogate,
        lambda model, o: 1.0 / model.n_components, equation, title, EBM_TOY,
    )  # fmt: skip


def check_expert_bound(
    seed: int = 0,
    alpha: float = 0.5,
    beta: float = 1.0,
    n_perturbations: int = 6,
    objective: Callable[[ToyProblem, EnergyMoE, np.ndarray, int], float] | None = None,
) -> CheckReport:
    """The expert bound, Eq. 4.4 with ``aux(o|c, theta) = pi_old(o|c, theta)`` (B.1).

    For random perturbations of one expert of a random :class:`EnergyMoE`, auxiliaries fixed
    to the old model's responsibilities: the bound (Eq. B.1 with auxiliaries) never exceeds
    Eq. 4.3 of the new model, touches it at ``new = old``, its gap is
    ``alpha E[KL_theta] + (beta - alpha) E[KL_c]`` (the second term is zero here: the gating
    does not move), its change is ``pi(o) = 1/K`` times the change of Eq. 4.4, and so Eq. 4.3
    improves at least as much as the bound.

    Args:
        objective: candidate for Eq. 4.4, ``(problem, model, log_aux_theta, o)``; defaults to
            :func:`ebm_expert_objective`.

    Returns:
        Report with data ``t``, ``path_objective``, ``path_bound`` along one perturbation path
        through the current model (``t = 0``), ``objective_new``, ``bound_new``,
        ``objective_old``.
    """
    objective = objective or ebm_expert_objective
    return _bound_check(
        "experts",
        seed,
        alpha,
        beta,
        n_perturbations,
        perturb_expert,
        lambda problem, model, aux_t, aux_c, o: objective(problem, model, aux_t, o),
        "Eq. 4.4, B.1",
        "Lower bound for the experts (Eq. 4.4)",
    )


def check_context_bound(
    seed: int = 0,
    alpha: float = 0.5,
    beta: float = 1.0,
    n_perturbations: int = 6,
    objective: Callable[[ToyProblem, EnergyMoE, np.ndarray, np.ndarray, int], float] | None = None,
) -> CheckReport:
    """The context bound, Eq. 4.5 with both auxiliaries from the old model (B.1).

    As :func:`check_expert_bound`, for perturbations of one energy ``phi_o`` (amplitudes,
    slopes and shifts of its features). Moving ``pi(c|o)`` moves the gating, so the gap is
    ``alpha E[KL_theta] + (beta - alpha) E[KL_c]``, non-negative because ``beta >= alpha``.

    Args:
        objective: candidate for Eq. 4.5, ``(problem, model, log_aux_theta, log_aux_context,
            o)``; defaults to :func:`ebm_context_objective`.
    """
    return _bound_check(
        "energies",
        seed,
        alpha,
        beta,
        n_perturbations,
        _perturb_energy,
        objective or ebm_context_objective,
        "Eq. 4.5, B.1",
        "Lower bound for the energy-based context distributions (Eq. 4.5)",
    )


def diskill_checks(seed: int = 0) -> list[CheckReport]:
    """Run every Chapter 4 derivation check with default settings."""
    return [
        check_curriculum_objective(seed),
        check_expert_bound(seed),
        check_context_bound(seed),
        check_sample_context_objective(seed),
        check_energy_normaliser(seed),
        check_gating(seed),
    ]

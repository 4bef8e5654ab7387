"""Numerical checks of the lower bounds of Chapter 3 (SVSL, Section 3.3 and Appendix A.1).

The checks run on the toy mixture of experts of :mod:`vslbook.bounds.svsl_toy` (Section 3.3.1,
A.1.1: the model, Eqs. 3.3, 3.4 and A.4), where every expectation is computed by quadrature to
about ten digits, and test the per-part objectives of :mod:`vslbook.bounds.svsl_decomposition`
(Sections 3.3.2-3.3.3, A.1.2-A.1.4: Eqs. 3.5-3.7 and the REPS update of the weights). Every
public name of both modules is re-exported here.

Each ``check_*`` function returns a :class:`~vslbook.bounds.CheckReport`. Several take an
optional candidate (a lower-bound function, a per-expert objective, a REPS update); the default
is the thesis's formula, and a wrong candidate (a flipped sign, the unweighted entropy of
Eq. A.5 as printed, a weight update that ignores the trust region) or ``beta < alpha`` makes
the report fail, which is how the tests show that the checks have teeth.

Covered: Eqs. 3.1-3.4 and A.1-A.4 (:func:`check_objective_decomposition`), the expert bound
Eq. 3.5 / A.1.2 (:func:`check_expert_bound`), the context bound Eq. 3.6 / A.1.3
(:func:`check_context_bound`), the weight bound Eq. 3.7 / A.5 (:func:`check_weight_bound`) and
the REPS update of the weights (:func:`check_reps_weights`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.special import softmax

from vslbook.bounds import Check, CheckReport
from vslbook.bounds.svsl_decomposition import (
    context_objective,
    expert_objective,
    reps_categorical,
    reps_dual,
    weight_objective,
    weight_rewards,
)
from vslbook.bounds.svsl_reps import check_reps_weights
from vslbook.bounds.svsl_toy import (
    BoundFn,
    ToyMoE,
    ToyProblem,
    bimodal_reward,
    decomposed_objective,
    expected_responsibility_kls,
    log_contexts,
    lower_bound,
    maxent_curriculum_objective,
    perturb_context,
    perturb_expert,
    perturb_weights,
    random_aux,
    random_toy_moe,
    responsibilities,
)
from vslbook.bounds.toy_numerics import check_count, quadrature_tol, seeded_rng, worst_check

__all__ = [
    "BoundFn",
    "ToyMoE",
    "ToyProblem",
    "auxiliary_bounds",
    "bimodal_reward",
    "bound_check",
    "check_context_bound",
    "check_expert_bound",
    "check_objective_decomposition",
    "check_reps_weights",
    "check_weight_bound",
    "context_objective",
    "decomposed_objective",
    "expected_responsibility_kls",
    "expert_objective",
    "lower_bound",
    "maxent_curriculum_objective",
    "random_toy_moe",
    "reps_categorical",
    "reps_dual",
    "responsibilities",
    "svsl_checks",
    "weight_objective",
    "weight_rewards",
]


# ------------------------------------------------------------------------------ checks


def auxiliary_bounds(
    problem: ToyProblem,
    model: object,
    bound: Callable,
    kls: Callable,
    log_rt: np.ndarray,
    rng: np.random.Generator,
    n_auxiliaries: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The bound and its two expected KLs for ``n_auxiliaries`` random auxiliaries plus one
    that is exact in ``theta`` (``log_rt``) and wrong in ``c`` (Eq. A.4's identity)."""
    k = model.n_components  # type: ignore[attr-defined]
    n = check_count("n_auxiliaries", n_auxiliaries)
    auxes = [random_aux(rng, problem, k, 1.0) for _ in range(n)]
    auxes.append((log_rt, random_aux(rng, problem, k, 2.0)[1]))  # exact in theta, wrong in c
    bounds, kl_t, kl_c = [], [], []
    for aux in auxes:
        bounds.append(float(bound(problem, model, *aux)))
        kt, kc = kls(problem, model, *aux)
        kl_t.append(kt)
        kl_c.append(kc)
    return np.array(bounds), np.array(kl_t), np.array(kl_c)


def check_objective_decomposition(
    seed: int = 0,
    alpha: float = 0.5,
    beta: float = 1.0,
    n_auxiliaries: int = 6,
    bound: BoundFn | None = None,
) -> CheckReport:
    """Eq. 3.3 = Eq. 3.4 (A.1-A.3), and the auxiliary-distribution identity of Eq. A.4.

    On a random 3-expert :class:`ToyMoE`: the curriculum max-ent objective computed directly
    from the mixture densities (Eq. 3.3) equals the decomposed form with the model's own
    responsibilities (Eq. 3.4, ``beta log p(c)`` kept); for ``n_auxiliaries`` random
    auxiliary distributions plus one that is exact in ``theta`` and wrong in ``c``,
    ``J = bound + alpha E[KL_theta] + (beta - alpha) E[KL_c]`` (Eq. A.4); ``bound <= J`` (which
    needs ``beta >= alpha``: with ``beta < alpha`` this check fails); and the bound is tight
    at the model's responsibilities.

    Args:
        alpha, beta: temperatures of Eq. 3.3.
        bound: candidate lower bound ``(problem, model, log_aux_theta, log_aux_context)``;
            defaults to :func:`lower_bound`.

    Returns:
        Report with data ``objective`` (Eq. 3.3), ``bounds`` (per auxiliary), ``kl_theta``,
        ``kl_context``, ``contexts``, ``gating`` (K, n_c) and ``context_density`` (K, n_c).
    """
    problem = ToyProblem(alpha=alpha, beta=beta)
    bound = bound or lower_bound
    rng = seeded_rng(seed, 2)
    model = random_toy_moe(seed)
    objective = maxent_curriculum_objective(problem, model)
    log_rt, log_rc = responsibilities(problem, model)
    bounds, kl_t, kl_c = auxiliary_bounds(
        problem, model, bound, expected_responsibility_kls, log_rt, rng, n_auxiliaries
    )
    identity_rhs = bounds + alpha * kl_t + (beta - alpha) * kl_c
    tol = quadrature_tol(objective, *bounds)
    own = float(bound(problem, model, log_rt, log_rc))
    # the same objective from a finer quadrature: the grid is not what makes them agree
    fine = ToyProblem(alpha=alpha, beta=beta, n_context=128, n_theta=1201)
    fine_objective = maxent_curriculum_objective(fine, model)
    checks = (
        Check(
            "Eq. 3.3 (mixture densities) = Eq. 3.4 (own responsibilities, beta log p kept)",
            "Eqs. 3.3, 3.4, A.1-A.3",
            objective,
            own,
            tol,
        ),
        Check(
            "Eq. 3.3 on a 2x finer grid agrees (quadrature converged)",
            "Eq. 3.3",
            fine_objective,
            objective,
            tol,
        ),
        worst_check(
            f"J = bound + alpha E[KL_theta] + (beta-alpha) E[KL_c] for {len(bounds)} auxiliaries",
            "Eq. A.4",
            np.full(bounds.shape, objective),
            identity_rhs,
            tol,
        ),
        worst_check(
            f"bound <= J for {len(bounds)} auxiliaries (needs beta >= alpha)",
            "Eq. A.4",
            bounds,
            objective,
            tol,
            "<=",
        ),
        worst_check(
            "expected KLs are non-negative", "Eq. A.4", -np.r_[kl_t, kl_c], 0.0, 1e-12, "<="
        ),
    )
    c, _ = problem.contexts
    data = {
        "objective": np.array(objective),
        "bounds": bounds,
        "kl_theta": kl_t,
        "kl_context": kl_c,
        "contexts": c,
        "gating": np.exp(log_rc),
        "context_density": np.exp(log_contexts(problem, model)),
    }
    return CheckReport(
        "Decomposition of the curriculum max-ent objective (Section 3.3.1)", checks, data
    )


@dataclass(frozen=True)
class BoundToy:
    """The toy a bound check perturbs: how to draw it and compute its objective and bound.

    ``random(seed)`` draws the old model; ``responsibilities(problem, model)`` its
    responsibilities (the tight auxiliaries); ``objective``, ``bound`` and ``kls`` are the
    curriculum objective, the lower bound with auxiliaries and the two expected KLs of its
    gap; ``stream`` the random stream of the perturbations; ``tight`` the name and equation
    of the tightness check; ``gap_equation`` where the gap comes from; ``change`` the name
    of the check that the bound moves with the per-part objective (``{kind}`` filled in).
    """

    random: Callable[[int], object]
    responsibilities: Callable
    objective: Callable
    bound: Callable
    kls: Callable
    stream: int
    tight: tuple[str, str | None]
    gap_equation: str
    change: str = (
        "change of the bound = change of the {kind} objective (it holds all the dependence)"
    )


#: Chapter 3's toy (:mod:`vslbook.bounds.svsl_toy`); the tightness check cites the bound's
#: own equation (``None``).
SVSL_TOY = BoundToy(
    random_toy_moe, responsibilities, maxent_curriculum_objective, lower_bound,
    expected_responsibility_kls, 3, ("bound is tight at new = old", None), "Eq. A.4",
)  # fmt: skip


def bound_check(
    kind: str,
    seed: int,
    alpha: float,
    beta: float,
    n_perturbations: int,
    perturb: Callable,
    surrogate: Callable[[ToyProblem, object, np.ndarray, np.ndarray, int], float],
    surrogate_scale: Callable[[object, int], float],
    equation: str,
    title: str,
    toy: BoundToy = SVSL_TOY,
) -> CheckReport:
    """Shared body of the expert, context and weight bound checks (Chapters 3 and 4)."""
    problem = ToyProblem(alpha=alpha, beta=beta)
    rng = seeded_rng(seed, toy.stream)
    old = toy.random(seed)
    aux = toy.responsibilities(problem, old)
    j_old = toy.objective(problem, old)
    lb_old = toy.bound(problem, old, *aux)
    s_old = [surrogate(problem, old, *aux, o) for o in range(old.n_components)]
    j_new, lb_new, gap_pred, d_lb, d_sur = [], [], [], [], []
    for _ in range(check_count("n_perturbations", n_perturbations)):
        o = int(rng.integers(old.n_components))
        new, _ = perturb(old, rng, o, 1.0)
        j = toy.objective(problem, new)
        lb = toy.bound(problem, new, *aux)
        kt, kc = toy.kls(problem, new, *aux)
        j_new.append(j)
        lb_new.append(lb)
        gap_pred.append(alpha * kt + (beta - alpha) * kc)
        d_lb.append(lb - lb_old)
        d_sur.append(surrogate_scale(old, o) * (surrogate(problem, new, *aux, o) - s_old[o]))
    j_new, lb_new, gap_pred = np.array(j_new), np.array(lb_new), np.array(gap_pred)
    d_lb, d_sur = np.array(d_lb), np.array(d_sur)
    tol = quadrature_tol(j_old, *j_new, *lb_new)

    # one perturbation path through the current model, for plotting
    ts = np.linspace(-1.0, 1.0, 11)
    o_path = int(rng.integers(old.n_components))
    _, d = perturb(old, rng, o_path, 0.0)
    path_j, path_lb = [], []
    for t in ts:
        m, _ = perturb(old, rng, o_path, float(t), d)
        path_j.append(toy.objective(problem, m))
        path_lb.append(toy.bound(problem, m, *aux))
    tight_name, tight_eq = toy.tight
    checks = (
        worst_check(
            f"bound(new; aux = old) <= J(new) for {len(j_new)} perturbed {kind}",
            equation,
            lb_new,
            j_new,
            tol,
            "<=",
        ),
        Check(tight_name, tight_eq or equation, lb_old, j_old, tol),
        worst_check(
            "J(new) - bound(new) = alpha E[KL_theta] + (beta-alpha) E[KL_c]",
            toy.gap_equation,
            j_new - lb_new,
            gap_pred,
            tol,
        ),
        worst_check(
            toy.change.format(kind=kind),
            equation,
            d_lb,
            d_sur,
            tol,
        ),
        worst_check(
            "J(new) - J(old) >= change of the bound (monotonic improvement)",
            equation,
            d_lb,
            j_new - j_old,
            tol,
            "<=",
        ),
    )
    data = {
        "t": ts,
        "path_objective": np.array(path_j),
        "path_bound": np.array(path_lb),
        "objective_new": j_new,
        "bound_new": lb_new,
        "objective_old": np.array(j_old),
    }
    return CheckReport(title, checks, data)


def check_expert_bound(
    seed: int = 0,
    alpha: float = 0.5,
    beta: float = 1.0,
    n_perturbations: int = 6,
    objective: Callable[[ToyProblem, ToyMoE, np.ndarray, int], float] | None = None,
) -> CheckReport:
    """The expert lower bound, Eq. 3.5 with ``aux(o|c, theta) = pi_old(o|c, theta)`` (A.1.2).

    For random perturbations of one expert ``pi(theta|c, o)`` of a random :class:`ToyMoE`,
    with the auxiliaries fixed to the old model's responsibilities: the bound of Eq. A.4 never
    exceeds the true objective (Eq. 3.3) of the new model, touches it at ``new = old``, its gap
    is ``alpha E[KL(pi_new(o|c,theta) || pi_old(o|c,theta))]`` (the gating, and so the context
    gap, does not move), its change equals ``pi(o)`` times the change of the per-expert
    objective (Eq. 3.5 with the auxiliary), and hence the true objective improves at least
    as much as the bound does.

    Args:
        objective: candidate per-expert objective ``(problem, model, log_aux_theta, o)``;
            defaults to :func:`expert_objective`.

    Returns:
        Report with data ``t``, ``path_objective`` and ``path_bound`` along one perturbation
        path through the current model (``t = 0``), ``objective_new``, ``bound_new`` and
        ``objective_old``.
    """
    objective = objective or expert_objective
    return bound_check(
        "experts",
        seed,
        alpha,
        beta,
        n_perturbations,
        perturb_expert,
        lambda problem, model, aux_t, aux_c, o: objective(problem, model, aux_t, o),
        lambda model, o: float(model.weights[o]),
        "Eq. 3.5, A.1.2",
        "Lower bound for the experts (Section 3.3.2)",
    )


def check_context_bound(
    seed: int = 0,
    alpha: float = 0.5,
    beta: float = 1.0,
    n_perturbations: int = 6,
    objective: Callable[[ToyProblem, ToyMoE, np.ndarray, np.ndarray, int], float] | None = None,
) -> CheckReport:
    """The context lower bound, Eq. 3.6 with both auxiliaries from the old model (A.1.3).

    As :func:`check_expert_bound`, for perturbations of one ``pi(c|o)`` (mean and scale).
    Moving a context distribution moves the gating ``pi(o|c)`` and with it ``pi(o|c, theta)``,
    so the gap is ``alpha E[KL_theta] + (beta - alpha) E[KL_c]``: non-negative only because
    ``beta >= alpha`` (with ``beta = 0`` it equals ``-alpha E_c[KL(pi_new(theta|c) ||
    pi_old(theta|c))] < 0`` and the check fails).

    Args:
        objective: candidate per-expert context objective
            ``(problem, model, log_aux_theta, log_aux_context, o)``; defaults to
            :func:`context_objective`.
    """
    objective = objective or context_objective
    return bound_check(
        "context distributions",
        seed,
        alpha,
        beta,
        n_perturbations,
        perturb_context,
        objective,
        lambda model, o: float(model.weights[o]),
        "Eq. 3.6, A.1.3",
        "Lower bound for the per-expert context distributions (Section 3.3.3)",
    )


def check_weight_bound(
    seed: int = 0,
    alpha: float = 0.5,
    beta: float = 1.0,
    n_perturbations: int = 6,
    rewards: BoundFn | None = None,
) -> CheckReport:
    """The weight lower bound, Eq. 3.7 / A.5 with both auxiliaries from the old model.

    As :func:`check_expert_bound`, for perturbations of ``pi(o)``; the bound changes exactly
    as Eq. 3.7, ``sum_o pi(o) r_o + beta H[pi(o)]`` with the per-expert rewards ``r_o`` of
    :func:`weight_rewards` (which do not depend on ``pi(o)``). Two extra checks: the maximiser
    of Eq. 3.7, ``softmax(r / beta)``, improves the true objective (Eq. 3.3); and the printed
    form of Eq. A.5, which leaves ``beta H[pi(c|o)]`` unweighted by ``pi(o)``, is not what the
    bound contains (pass it as ``rewards`` to see the report fail).

    Args:
        rewards: candidate ``(problem, model, log_aux_theta, log_aux_context) -> r (K,)``
            such that Eq. 3.7 is ``sum_o pi(o) r_o + beta H[pi(o)]``; defaults to
            :func:`weight_rewards`.

    Returns:
        As :func:`check_expert_bound`, plus ``rewards`` (``r_o``), ``weights_old`` and
        ``weights_softmax``.
    """
    rewards = rewards or weight_rewards

    def surrogate(problem, model, aux_t, aux_c, o):
        r = np.asarray(rewards(problem, model, aux_t, aux_c), dtype=float)
        return weight_objective(model.weights, r, problem.beta)

    report = bound_check(
        "weights",
        seed,
        alpha,
        beta,
        n_perturbations,
        perturb_weights,
        surrogate,
        lambda model, o: 1.0,
        "Eq. 3.7, A.5",
        "Lower bound for the expert weights (Section 3.3.3)",
    )
    problem = ToyProblem(alpha=alpha, beta=beta)
    old = random_toy_moe(seed)
    aux = responsibilities(problem, old)
    r = np.asarray(rewards(problem, old, *aux), dtype=float)
    w_soft = softmax(r / beta) if beta > 0 else np.eye(r.size)[np.argmax(r)]
    w_soft = np.clip(w_soft, 1e-300, None)
    w_soft = w_soft / w_soft.sum()
    better = old.replace(weights=w_soft)
    j_old = maxent_curriculum_objective(problem, old)
    j_soft = maxent_curriculum_objective(problem, better)
    lb_soft = lower_bound(problem, better, *aux)
    tol = quadrature_tol(j_old, j_soft)
    extra = (
        Check(
            "bound at softmax(r / beta) = Eq. 3.7 there + beta log p(c)",
            "Eq. 3.7",
            lb_soft,
            weight_objective(w_soft, r, beta) + beta * problem.log_p,
            tol,
        ),
        Check(
            "J(old) <= J(softmax(r / beta)) (the maximiser of Eq. 3.7 improves Eq. 3.3)",
            "Eqs. 3.3, 3.7",
            j_old,
            j_soft,
            tol,
            "<=",
        ),
    )
    data = dict(report.data)
    data.update(rewards=r, weights_old=old.weights.copy(), weights_softmax=w_soft)
    return CheckReport(report.title, report.checks + extra, data)


def svsl_checks(seed: int = 0) -> list[CheckReport]:
    """Run every Chapter 3 derivation check with default settings."""
    return [
        check_objective_decomposition(seed),
        check_expert_bound(seed),
        check_context_bound(seed),
        check_weight_bound(seed),
        check_reps_weights(seed),
    ]

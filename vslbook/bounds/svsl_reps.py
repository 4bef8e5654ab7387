"""Numerical check of the REPS update of SVSL's weights π(o) (Section 3.3.3, Eq. 3.7 with a
KL trust region, Appendix A.1.4): the closed form against a brute-force optimiser.

Re-exported by :mod:`vslbook.bounds.svsl`.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from scipy.special import softmax

from vslbook.bounds import Check, CheckReport
from vslbook.bounds.svsl_decomposition import (
    brute_force_reps,
    reps_categorical,
    reps_dual,
    reps_solution,
    weight_objective,
)
from vslbook.bounds.toy_numerics import (
    check_count,
    check_finite,
    discrete_kl,
    seeded_rng,
    worst_check,
)

__all__ = ["check_reps_weights"]


def check_reps_weights(
    seed: int = 0,
    n_components: int = 6,
    beta: float = 0.5,
    epsilons: tuple[float, ...] = (0.01, 0.05, 0.2, 0.5, 2.0, 50.0),
    update: Callable[[np.ndarray, np.ndarray, float, float], np.ndarray] | None = None,
) -> CheckReport:
    """REPS update of the weights (Eq. 3.7 with a KL trust region) against brute force.

    For a random categorical ``p_old`` and rewards ``r``: the closed form
    ``p ∝ p_old^(eta/(eta+beta)) exp(r/(eta+beta))`` (``eta`` from the 1-D dual) attains the
    optimum of the primal found by SLSQP over the simplex, stays inside ``KL <= eps``, its
    dual value equals the primal value (strong duality), and for ``eps`` large enough
    (``eps >= KL(softmax(r/beta) || p_old)``) it *is* ``softmax(r / beta)``, the unconstrained
    maximiser of Eq. 3.7.

    Args:
        update: candidate ``(p_old, r, beta, eps) -> p_new``; defaults to
            :func:`reps_categorical` (its first output).

    Returns:
        Report with data ``eps_path``, ``kl_path`` (``KL(p_eps || p_old)``) and
        ``distance_to_softmax`` (``max |p_eps - softmax(r/beta)|``) over a log-spaced range of
        ``eps``, and ``kl_softmax``.
    """
    k = check_count("n_components", n_components, 2)
    beta = check_finite("beta", beta, 0.0, strict=True)
    if not epsilons or any(not (e > 0 and math.isfinite(e)) for e in epsilons):
        raise ValueError(f"epsilons must be positive finite numbers, got {epsilons!r}")
    update = update or (lambda p, r, b, e: reps_categorical(p, r, b, e)[0])
    rng = seeded_rng(seed, 4)
    p_old = rng.dirichlet(np.full(k, 2.0))
    r = rng.normal(0.0, 1.0, k)
    target = softmax(r / beta)
    kl_soft = discrete_kl(target, p_old)
    obj_cand, obj_brute, kls, primal, dual = [], [], [], [], []
    for eps in epsilons:
        p = np.asarray(update(p_old, r, beta, eps), dtype=float)
        if p.shape != (k,):
            raise ValueError(f"update must return shape {(k,)}, got {p.shape}")
        brute = brute_force_reps(p_old, r, beta, eps)
        obj_cand.append(weight_objective(p, r, beta))
        obj_brute.append(weight_objective(brute, r, beta))
        kls.append(discrete_kl(p, p_old))
        _, eta = reps_categorical(p_old, r, beta, eps)
        dual.append(reps_dual(eta, p_old, r, beta, eps))
        primal.append(weight_objective(reps_solution(eta, p_old, r, beta), r, beta))
    large = [e for e in epsilons if e >= kl_soft]
    if large:
        p_large = np.asarray(update(p_old, r, beta, max(large)), dtype=float)
        softmax_gap = float(np.max(np.abs(p_large - target)))
    else:
        softmax_gap = math.nan
    eps_path = np.geomspace(1e-3, max(10.0, 2 * kl_soft), 20)
    p_path = np.array([np.asarray(update(p_old, r, beta, e), dtype=float) for e in eps_path])
    checks = (
        worst_check(
            "closed form attains the SLSQP optimum of the primal",
            "Eq. 3.7 (REPS)",
            obj_cand,
            obj_brute,
            1e-7,
        ),
        worst_check("KL(p_new || p_old) <= eps", "Eq. 3.7 (REPS)", kls, list(epsilons), 1e-9, "<="),
        worst_check(
            "dual value = primal value (strong duality)", "Eq. 3.7 (REPS)", dual, primal, 1e-9
        ),
        Check(
            f"eps >= KL(softmax(r/beta) || p_old) = {kl_soft:.3g}: update = softmax(r / beta)",
            "Eq. 3.7",
            softmax_gap,
            0.0,
            1e-12,
        ),
    )
    data = {
        "eps_path": eps_path,
        "kl_path": np.array([discrete_kl(p, p_old) for p in p_path]),
        "distance_to_softmax": np.max(np.abs(p_path - target), axis=1),
        "kl_softmax": np.array(kl_soft),
        "p_old": p_old,
        "rewards": r,
    }
    return CheckReport("REPS update of the expert weights (Section 3.3.3)", checks, data)

"""Numerical checks of Di-SkilL's sample forms (Section 4.4): Eqs. 4.6 and 4.8 and the gating.

In practice π(c | o) of Eq. 4.6 is a categorical over a batch of contexts drawn from p(c):

* :func:`check_sample_context_objective`: Eq. 4.8 (categorical over ``N`` contexts from
  ``p(c)``) against Eq. 4.5 (density, quadrature): equal up to ``beta log(N / V)``;
* :func:`check_energy_normaliser`: the Monte-Carlo normaliser of Eq. 4.6 and the
  self-normalised expectations under the batch categorical, in 1-D and 2-D;
* :func:`check_gating`: the gating ``pi(o|c)`` of Algorithm 3 / B.3.1 from batch-normalised
  categoricals, same batch against different batches (sizes 75 and 5000).

They run on the toy of :mod:`vslbook.bounds.diskill_toy`; :mod:`vslbook.bounds.diskill`
re-exports them with the checks of the bounds themselves.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from scipy.special import log_softmax, softmax

from vslbook.bounds import Check, CheckReport, relative_tol
from vslbook.bounds.diskill_toy import (
    ebm_context_objective,
    ebm_log_normaliser,
    ebm_responsibilities,
    energy_fn,
    expert_context_values,
    integrate_quad,
    mc_normaliser,
    random_energy_moe,
    sample_context_objective,
    self_normalised_expectation,
    uniform_prior_gating,
)
from vslbook.bounds.svsl_toy import (
    ToyProblem,
)
from vslbook.bounds.toy_numerics import check_count, seeded_rng, worst_check

__all__ = [
    "GatingFn",
    "NormaliserFn",
    "SampleObjectiveFn",
    "check_energy_normaliser",
    "check_gating",
    "check_sample_context_objective",
]


SampleObjectiveFn = Callable[[np.ndarray, np.ndarray, np.ndarray, float, float], float]
"""``(log q (N,), L_c (N,), log aux(o|c_i) (N,), alpha, beta) -> Eq. 4.8``."""


def check_sample_context_objective(
    seed: int = 0,
    alpha: float = 0.5,
    beta: float = 1.0,
    sizes: tuple[int, ...] = (1_000, 10_000, 100_000),
    objective: SampleObjectiveFn | None = None,
) -> CheckReport:
    """Eq. 4.8 (categorical over samples of ``p(c)``) against Eq. 4.5 (density, quadrature).

    Draw ``c_1..c_N ~ p(c) = U[low, high]`` (length ``V``) and let ``q_i = softmax_i phi_o(c_i)``.
    With ``w_i = exp(phi_o(c_i))`` and the Monte-Carlo normaliser ``Z^ = (V/N) sum_i w_i``,
    ``q_i = w_i / sum_j w_j = (V/N) pi^(c_i|o)`` where ``pi^ = exp(phi_o) / Z^`` is the density
    of Eq. 4.6 with the estimated normaliser. Then

    * ``sum_i q_i g(c_i) -> E_pi(c|o)[g]`` for any ``g`` (self-normalised importance sampling
      with proposal ``p(c)``), so the first sum and the ``log aux`` sum of Eq. 4.8 tend to
      their counterparts in Eq. 4.5;
    * ``-sum_i q_i log q_i = -sum_i q_i log pi^(c_i|o) + log(N/V) -> H[pi(c|o)] + log(N/V)``:
      the entropy of the categorical over ``N`` points exceeds the differential entropy by
      ``log(N/V)`` (each point carries mass ``~ pi(c_i|o) V/N``).

    Hence ``Eq. 4.8 - beta log(N/V) -> Eq. 4.5``; the constant depends on ``N`` and ``V`` only,
    not on ``phi_o``, so maximising Eq. 4.8 maximises Eq. 4.5. For every expert (each with its
    own ``phi_o``, the model's own responsibilities as auxiliaries) and every ``N`` in
    ``sizes`` (nested batches of one seeded draw), the check compares
    ``Eq. 4.8 - beta log(N/V)`` with Eq. 4.5 within four delta-method standard errors of the
    estimator ``sum_i q_i h_i + beta log Z^`` (``h = L_c + (beta-alpha) log aux - beta phi``),
    checks that this tolerance shrinks like ``1/sqrt(N)``, and that the offsets
    ``Eq. 4.8 - Eq. 4.5`` of the experts agree (no dependence on ``phi``).

    Args:
        sizes: increasing batch sizes ``N``.
        objective: candidate for Eq. 4.8, ``(log q (N,), L_c (N,), log aux(o|c_i) (N,), alpha,
            beta)``; defaults to :func:`sample_context_objective`.

    Returns:
        Report with data ``sizes``, ``offset`` (K, len(sizes): Eq. 4.8 - Eq. 4.5),
        ``predicted_offset`` (``beta log(N/V)``), ``standard_error`` (K, len(sizes)) and
        ``continuous`` (Eq. 4.5 per expert).
    """
    objective = objective or sample_context_objective
    sizes = tuple(check_count("sizes[i]", n, 2) for n in sizes)
    if len(sizes) < 2 or list(sizes) != sorted(set(sizes)):
        raise ValueError(f"sizes must be at least two increasing batch sizes, got {sizes!r}")
    problem = ToyProblem(alpha=alpha, beta=beta)
    model = random_energy_moe(seed)
    k = model.n_components
    volume = problem.high - problem.low
    log_rt, log_rc = ebm_responsibilities(problem, model)
    continuous = np.array(
        [ebm_context_objective(problem, model, log_rt, log_rc, o) for o in range(k)]
    )
    rng = seeded_rng(seed, 14)
    c = rng.uniform(problem.low, problem.high, sizes[-1])
    l_c, log_gate = expert_context_values(problem, model, c)
    phi = model.energy(c)
    offset = np.empty((k, len(sizes)))
    se = np.empty((k, len(sizes)))
    for j, n in enumerate(sizes):
        for o in range(k):
            log_q = log_softmax(phi[o, :n])
            offset[o, j] = (
                float(objective(log_q, l_c[o, :n], log_gate[o, :n], alpha, beta)) - continuous[o]
            )
            # delta method for  sum_i q_i h_i + beta log((V/N) sum_i w_i)
            w = np.exp(phi[o, :n] - phi[o, :n].max())
            h = l_c[o, :n] + (beta - alpha) * log_gate[o, :n] - beta * phi[o, :n]
            h_bar = float(w @ h / w.sum())
            psi = w * (h - h_bar + beta) / w.mean()
            se[o, j] = float(np.std(psi, ddof=1) / math.sqrt(n))
    predicted = beta * np.log(np.array(sizes) / volume)
    tol = 4.0 * se + 1e-9
    spread = offset[:, -1].max() - offset[:, -1].min()
    checks = (
        worst_check(
            f"Eq. 4.8 - Eq. 4.5 = beta log(N/V) within 4 s.e., N in {sizes}, {k} experts",
            "Eqs. 4.5, 4.6, 4.8",
            offset,
            np.broadcast_to(predicted, offset.shape),
            tol,
        ),
        Check(
            f"the 4 s.e. tolerance shrinks like 1/sqrt(N) (N = {sizes[0]} -> {sizes[-1]})",
            "Eq. 4.8",
            float(tol[:, -1].max() * math.sqrt(sizes[-1] / sizes[0])),
            float(tol[:, 0].max()),
            float(0.5 * tol[:, 0].max()),
        ),
        Check(
            f"offset does not depend on phi: spread over {k} experts at N = {sizes[-1]}",
            "Eq. 4.8",
            float(spread),
            0.0,
            float(2.0 * tol[:, -1].max()),
        ),
    )
    data = {
        "sizes": np.array(sizes),
        "offset": offset,
        "predicted_offset": predicted,
        "standard_error": se,
        "continuous": continuous,
    }
    return CheckReport(
        "Sample form of the context objective, Eq. 4.8 vs Eq. 4.5 (Section 4.4.2)", checks, data
    )


NormaliserFn = Callable[[np.ndarray, float], float]
"""``(phi(c_i) (N,), volume) -> estimate of Z``."""


def _energy_2d(rng: np.random.Generator, n_features: int = 5):
    a = rng.normal(0.0, 0.8, n_features)
    w = rng.normal(0.0, 1.5, (n_features, 2))
    b = rng.normal(0.0, 1.0, n_features)
    return lambda c1, c2: (
        np.tanh(np.multiply.outer(c1, w[:, 0]) + np.multiply.outer(c2, w[:, 1]) + b) @ a
    )


def _gauss_legendre_2d(fn, box, n: int) -> float:
    x, w = np.polynomial.legendre.leggauss(n)
    (l1, h1), (l2, h2) = box
    c1, c2 = l1 + 0.5 * (h1 - l1) * (x + 1), l2 + 0.5 * (h2 - l2) * (x + 1)
    w1, w2 = 0.5 * (h1 - l1) * w, 0.5 * (h2 - l2) * w
    g1, g2 = np.meshgrid(c1, c2, indexing="ij")
    return float(w1 @ fn(g1, g2) @ w2)


def check_energy_normaliser(
    seed: int = 0,
    n_samples: int = 20_000,
    estimator: NormaliserFn | None = None,
) -> CheckReport:
    """The Monte-Carlo normaliser of Eq. 4.6 and self-normalised expectations, 1-D and 2-D.

    ``Z = int_box exp(phi(c)) dc ~ (V/N) sum_i exp(phi(c_i))`` with ``c_i ~ U(box)``: compared
    with ``scipy.integrate.quad`` (1-D, ``phi`` = the first energy of a random
    :class:`EnergyMoE` on the toy interval) and with a tensor-product Gauss-Legendre rule
    (2-D, a random tanh-feature energy on ``[-1, 1] x [0, 1.5]``, converged between 64 and 96
    nodes per axis), within four standard errors estimated from the sample. The
    self-normalised expectation ``sum_i softmax_i(phi(c_i)) f(c_i)`` (the categorical over the
    batch) is compared with ``E_pi(c)[f]`` by quadrature, within four delta-method standard
    errors ``sqrt(sum_i q_i^2 (f_i - f^)^2)``.

    Args:
        n_samples: contexts drawn from the box.
        estimator: candidate ``(phi(c_i) (N,), V) -> Z^``; defaults to :func:`mc_normaliser`.

    Returns:
        Report with data ``normaliser`` and ``normaliser_estimate`` (1-D, 2-D),
        ``expectation``, ``expectation_estimate`` and ``contexts_2d`` (N, 2) with ``phi_2d``.
    """
    estimator = estimator or mc_normaliser
    n = check_count("n_samples", n_samples, 10)
    rng = seeded_rng(seed, 15)
    problem = ToyProblem()
    model = random_energy_moe(seed)
    phi1 = energy_fn(model, 0)
    lo, hi = problem.low, problem.high

    def f1(c):
        return np.sin(3.0 * c) + c**2

    z1 = integrate_quad(lambda c: math.exp(phi1(c)), lo, hi)
    e1 = integrate_quad(lambda c: f1(c) * math.exp(phi1(c)), lo, hi) / z1
    c1 = rng.uniform(lo, hi, n)
    p1 = model.energy(c1)[0]
    box = ((-1.0, 1.0), (0.0, 1.5))
    v2 = (box[0][1] - box[0][0]) * (box[1][1] - box[1][0])
    phi2 = _energy_2d(rng)

    def f2(a, b):
        return a * b + np.cos(2.0 * a)

    z2 = _gauss_legendre_2d(lambda a, b: np.exp(phi2(a, b)), box, 96)
    z2_coarse = _gauss_legendre_2d(lambda a, b: np.exp(phi2(a, b)), box, 64)
    e2 = _gauss_legendre_2d(lambda a, b: f2(a, b) * np.exp(phi2(a, b)), box, 96) / z2
    c2 = np.column_stack([rng.uniform(*box[0], n), rng.uniform(*box[1], n)])
    p2 = phi2(c2[:, 0], c2[:, 1])

    z_hat, z_se, e_hat, e_se = [], [], [], []
    for phi, v, fv in ((p1, hi - lo, f1(c1)), (p2, v2, f2(c2[:, 0], c2[:, 1]))):
        z_hat.append(float(estimator(phi, v)))
        z_se.append(float(v * np.std(np.exp(phi), ddof=1) / math.sqrt(n)))
        q = softmax(phi)
        e_hat.append(self_normalised_expectation(phi, fv))
        e_se.append(float(math.sqrt(np.sum(q**2 * (fv - q @ fv) ** 2))))
    z_true, e_true = np.array([z1, z2]), np.array([e1, e2])
    checks = (
        worst_check(
            f"Z^ = (V/N) sum exp(phi) vs quad (1-D) / Gauss-Legendre (2-D), 4 s.e., N = {n}",
            "Eq. 4.6",
            z_hat,
            z_true,
            4.0 * np.array(z_se),
        ),
        worst_check(
            "sum softmax(phi) f = E_pi(c)[f] within 4 s.e. (1-D, 2-D)",
            "Eqs. 4.6, 4.8",
            e_hat,
            e_true,
            4.0 * np.array(e_se),
        ),
        Check(
            "2-D Gauss-Legendre normaliser converged (64 vs 96 nodes per axis)",
            "Eq. 4.6",
            z2_coarse,
            z2,
            relative_tol(z2, rtol=1e-10),
        ),
    )
    data = {
        "normaliser": z_true,
        "normaliser_estimate": np.array(z_hat),
        "normaliser_standard_error": np.array(z_se),
        "expectation": e_true,
        "expectation_estimate": np.array(e_hat),
        "contexts_2d": c2,
        "phi_2d": p2,
    }
    return CheckReport("Monte-Carlo normaliser of the energy-based model (Eq. 4.6)", checks, data)


GatingFn = Callable[[np.ndarray], np.ndarray]
"""``log pi(c|o) (K, M) -> pi(o|c) (K, M)``."""


def check_gating(
    seed: int = 0,
    batch_sizes: tuple[int, int] = (75, 5000),
    n_repeats: int = 100,
    gating: GatingFn | None = None,
) -> CheckReport:
    """The gating of Algorithm 3 / B.3.1 from batch-normalised categoricals.

    With uniform ``pi(o)``, ``pi(o|c) = pi(c|o) / sum_o' pi(c|o')``. If every expert's
    categorical is normalised over the *same* batch of ``N`` contexts, each categorical is
    ``(V/N) pi^(c|o)`` with the density ``pi^`` of Eq. 4.6 normalised by that batch's
    Monte-Carlo ``Z^_o``; the common factor ``V/N`` cancels and the gating equals the one from
    the normalised densities (identity, checked on a batch of the larger size). In general,
    with expert ``o`` normalised by ``S_o = sum_{c in B_o} exp(phi_o(c))`` over its own batch
    ``B_o``, the gating is the exact one reweighted by ``Z_o / S_o``:
    ``g(o|c) ∝ g_exact(o|c) Z_o / S_o``; checked for experts normalised on batches of
    alternating sizes, where the factor ``N_o / V`` no longer cancels. Finally the size of the
    error on a common batch (root-mean-square over ``p(c)`` and the experts, averaged over
    ``n_repeats`` batches) is reported for both batch sizes; it shrinks like ``1/sqrt(N)``
    (checked to within 50 %), which is why the normaliser should be computed once on a
    large batch from ``p(c)`` and reused.

    Args:
        batch_sizes: the small and the large batch size.
        n_repeats: batches drawn per size for the error estimate.
        gating: candidate ``log pi(c|o) (K, M) -> pi(o|c) (K, M)``; defaults to
            :func:`uniform_prior_gating`.

    Returns:
        Report with data ``batch_sizes``, ``rms_error_same_batch`` (per size),
        ``rms_error_mixed_batches``, ``contexts`` and ``exact_gating`` (K, n_c).
    """
    gating = gating or uniform_prior_gating
    if len(batch_sizes) != 2:
        raise ValueError(f"batch_sizes must be two sizes (small, large), got {batch_sizes!r}")
    small, large = (check_count("batch size", n, 2) for n in batch_sizes)
    if not small < large:
        raise ValueError(f"batch_sizes must be increasing, got {batch_sizes!r}")
    repeats = check_count("n_repeats", n_repeats, 2)
    problem = ToyProblem()
    model = random_energy_moe(seed)
    k = model.n_components
    volume = problem.high - problem.low
    rng = seeded_rng(seed, 16)
    log_z = ebm_log_normaliser(problem, model)
    c_eval, c_w = problem.contexts
    phi_eval = model.energy(c_eval)
    dens = np.exp(phi_eval - log_z[:, None]) / k  # pi(c|o) pi(o)
    g_exact = dens / dens.sum(axis=0)

    # one batch, every expert normalised on it: categorical gating = density gating
    c = rng.uniform(problem.low, problem.high, large)
    phi = model.energy(c)
    g_cat = np.asarray(gating(log_softmax(phi, axis=1)), dtype=float)
    z_hat = volume / large * np.exp(phi).sum(axis=1)
    dens_hat = np.exp(phi) / z_hat[:, None] / k
    g_dens = dens_hat / dens_hat.sum(axis=0)

    # experts normalised on their own batches of different sizes
    own = [small if o % 2 == 0 else large for o in range(k)]
    s_own = np.array(
        [
            np.exp(model.energy(rng.uniform(problem.low, problem.high, own[o]))[o]).sum()
            for o in range(k)
        ]
    )
    g_mixed = np.asarray(gating(phi_eval - np.log(s_own)[:, None]), dtype=float)
    reweighted = g_exact * (np.exp(log_z) / s_own)[:, None]
    reweighted /= reweighted.sum(axis=0)

    def rms(g: np.ndarray) -> float:
        return float(math.sqrt(np.sum((g - g_exact) ** 2 * c_w[None, :]) / volume))

    errors = []
    for n in (small, large):
        sq = 0.0
        for _ in range(repeats):
            s = np.exp(model.energy(rng.uniform(problem.low, problem.high, n))).sum(axis=1)
            sq += rms(np.asarray(gating(phi_eval - np.log(s)[:, None]), dtype=float)) ** 2
        errors.append(math.sqrt(sq / repeats))
    err_mixed = rms(g_mixed)
    ratio = errors[0] / errors[1] / math.sqrt(large / small)
    checks = (
        worst_check(
            f"same batch (N = {large}): categorical gating = density gating with that batch's Z^",
            "Alg. 3, B.3.1",
            g_cat,
            g_dens,
            1e-12,
        ),
        worst_check(
            f"batches of sizes {own}: gating = exact gating reweighted by Z_o / S_o",
            "Alg. 3, Eq. 4.6",
            g_mixed,
            reweighted,
            1e-12,
        ),
        Check(
            f"error(N={small}) / error(N={large}) / sqrt({large}/{small}) = 1 (1/sqrt(N) decay)",
            "Eq. 4.6",
            ratio,
            1.0,
            0.5,
        ),
        Check(
            f"batches of different sizes bias the gating more than a common batch of {small}",
            "Alg. 3",
            errors[0],
            err_mixed,
            0.0,
            "<=",
        ),
    )
    data = {
        "batch_sizes": np.array([small, large]),
        "rms_error_same_batch": np.array(errors),
        "rms_error_mixed_batches": np.array(err_mixed),
        "contexts": c_eval,
        "exact_gating": g_exact,
    }
    return CheckReport("Gating from batch-normalised energy-based models (Alg. 3)", checks, data)

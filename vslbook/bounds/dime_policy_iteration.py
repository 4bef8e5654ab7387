"""Numerical checks of Section 5.4.2 (DIME): diffusion-based policy iteration with ``ℓ``.

Propositions 5.4.1-5.4.3 (policy evaluation with the Bellman operator of Eq. 5.21, policy
improvement by the joint KL of Eq. 5.22, policy iteration) with the diffusion policies of
Section 5.4.1 and the entropy lower bound ``ℓ`` in place of the entropy, on a linear-quadratic
problem where the chains are linear-Gaussian and both sides of every proposition are
computable (:func:`check_diffusion_policy_iteration`). The tabular version with exact
entropies, SAC's soft policy iteration, is in :mod:`vslbook.bounds.dime_tabular`.

Import from :mod:`vslbook.bounds.dime`, which re-exports everything public here.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from scipy.optimize import minimize

from vslbook.bounds import Check, CheckReport, relative_tol
from vslbook.bounds.dime_linear_chain import linear_gaussian_chain, linear_gaussian_policy
from vslbook.bounds.dime_lq import (
    ChainFamily,
    Marginal,
    Target,
    evaluate_policy,
    expected_q,
    improve_exact,
    joint_kls,
    log_partition,
    lq_backup,
    lq_features,
    lq_objective,
    lq_problem,
    lq_quadratic,
)
from vslbook.bounds.toy_numerics import (
    check_count,
    check_positive,
    seeded_rng,
    to_numpy,
    worst_check,
)

__all__ = ["check_diffusion_policy_iteration"]


def check_diffusion_policy_iteration(
    seed: int = 0,
    n_steps: int = 4,
    sigma0: float = 1.5,
    total_time: float = 1.0,
    noise_var: float = 1.0,
    gamma: float = 0.9,
    alpha: float = 0.5,
    n_iter: int = 8,
    n_backups: int = 300,
    n_pairs: int = 24,
    n_random: int = 30,
    entropy_sign: float = 1.0,
    improve: Callable[[np.ndarray, Callable[[np.ndarray], np.ndarray]], np.ndarray] | None = None,
) -> CheckReport:
    """Propositions 5.4.1-5.4.3 with diffusion policies and ``ℓ``, where both sides are computable.

    **Problem.** One-dimensional linear-quadratic control: ``s' = A s + B a + w`` with
    ``w ~ N(0, W)``, reward ``r(s, a) = -(k_s (s - goal)^2 + k_a a^2) / 2``, discount ``gamma``
    and start state ``s_0 ~ N(0, 1)`` (``A, B, W, k_s, k_a, goal`` seeded). A bandit (one state
    with a self-loop) would not do: there ``Q^pi - r`` is a constant, the target
    ``exp(Q / alpha) / Z`` never changes and policy iteration stops after one improvement. Here
    the next state depends on the action, so every evaluation moves the target.

    **Family** ``Π̃``. The linear-Gaussian chains of Section 5.4.1 (:func:`linear_gaussian_chain`)
    with the released cosine step sizes of :func:`linear_gaussian_policy` (scaled to
    ``total_time``), a fixed noise scale ``noise_var``, the prior ``N(0, sigma0^2)`` and DIME's
    OU noising kernels; the score of step ``k`` (sampling order) is
    ``f_k(x, s) = slope x + c_k + g_k s``, so ``theta = (slope, c_1..c_N, g_1..g_N)``: one slope
    shared by steps and states, offsets per step and affine in the state. Every member has the
    marginal ``pi_0(a|s) = N(m_c + m_g s, v)`` and a bound ``ℓ(s)`` (Eq. 5.15) quadratic in
    ``s``: ``ℓ`` depends on the state through the mean, because the noising chain pulls towards
    0. Per-step offsets make Eq. 5.22 solvable at every state at once: for a fixed slope the
    joint KL is quadratic in the offsets, which can put the generative means of ``x^{N-1..0}``
    anywhere; what remains depends on the state only through a term free of the slope, so all
    states share the optimal slope and their optimal offsets are affine in ``s``. (With one
    offset shared by the steps the states' optimal slopes differ and no member of the family
    solves Eq. 5.22 at every state; the tests show both.)

    **alpha** is explicit, as in SAC and DIME's implementation (Section 5.4.4): the bonus in
    Eqs. 5.16, 5.17 and 5.21 is ``alpha ℓ`` and the target of Eqs. 5.23/5.27 is
    ``exp(Q / alpha) / Z``. The thesis's equations (alpha absorbed in the reward) are this with
    ``r / alpha`` and ``Q / alpha``.

    **Closed forms** (the evaluation side). With ``pi_0(a|s) = N(m_c + m_g s, v)`` and
    ``ℓ(s) = l_2 s^2 + l_1 s + l_0``, Eq. 5.17 reads ``Q^pi(s, a) = r(s, a) + gamma
    E[V^pi(s') | s, a]`` with ``V^pi(s) = b(s) + gamma E[V^pi(s') | s]`` and
    ``b(s) = E_pi[r(s, a)] + alpha ℓ(s) = b_2 s^2 + b_1 s + b_0``. Under ``pi``,
    ``s' | s ~ N(F s + e, B^2 v + W)`` with ``F = A + B m_g``, ``e = B m_c``, and matching the
    powers of ``s`` in ``V = v_2 s^2 + v_1 s + v_0`` gives, when ``gamma F^2 < 1``,

        v_2 = b_2 / (1 - gamma F^2),   v_1 = (b_1 + 2 gamma v_2 F e) / (1 - gamma F),
        v_0 = (b_0 + gamma (v_2 (e^2 + B^2 v + W) + v_1 e)) / (1 - gamma),

    (otherwise ``V = -inf``), and ``J̄`` of Eq. 5.16 is ``E[V^pi(s_0)]``.

    **Checks.** Prop. 5.4.1 (for the initial policy ``pi_0``): the backup ``T^pi`` of Eq. 5.21,
    with its expectation over ``w`` and ``a' ~ pi_0(.|s')`` by Gauss-Hermite quadrature, leaves
    the closed-form ``Q^pi`` unchanged on an ``(s, a)`` grid; ``n_backups`` backups from a
    random quadratic ``Q^0`` (each refitted in the quadratic basis, exactly, since ``T^pi`` maps
    quadratics to quadratics) reach it; ``||T Q1 - T Q2||_inf <= gamma ||Q1 - Q2||_inf`` for
    ``n_pairs`` pairs with a bounded difference ``shift + amp cos(.)`` (its sup is exactly
    ``|shift| + |amp|``; the left side is a maximum over a grid, which can only be smaller; two
    different quadratics differ by an unbounded function), and constant shifts attain
    ``gamma``. Prop. 5.4.2, at every iteration: the improvement minimises over ``theta`` the
    summed joint KL of Eq. 5.22 between the generative chain and the noising chain started at
    ``exp(Q^pi_old(s, .) / alpha) / Z(s)`` at 9 states (all joints Gaussian;
    :func:`scipy.optimize.minimize_scalar` on the slope, least squares on the offsets). The
    joint KL, from Section 5.4.1's joints and :func:`vslbook.dists.gaussian_kl`, equals
    ``-ℓ(s) - E[Q(s, a)] / alpha + log Z(s)`` from the evaluation side (Eqs. 5.27, C.11); it
    does not increase at any state (Eq. C.16, what the proof uses of the minimisation); and
    ``Q^pi_new >= Q^pi_old`` on the grid. Prop. 5.4.3: ``J̄(pi_i)`` is non-decreasing; after
    ``n_iter`` iterations it equals the maximum of ``J̄`` over ``Π̃`` found independently by
    BFGS on ``theta`` from ``pi_0``; ``Q`` of the limit equals ``Q`` of that maximiser and
    dominates ``Q^pi`` of ``n_random`` random stable members of ``Π̃`` about it. Finally
    ``ℓ(s) <= H`` at the limit, and the family's ``ℓ(s)`` and marginal equal
    :func:`linear_gaussian_chain`'s (whose agreement with :class:`~vslbook.srl.DiffusionPolicy`
    :func:`~vslbook.bounds.dime_entropy.check_entropy_lower_bound` checks).

    **What this shows and what it does not.** The limit of policy iteration maximises the
    *bound* ``J̄`` (with ``ℓ``) within ``Π̃``; it is not the maximiser of the exact objective of
    Eq. 5.11 (with ``H``) within ``Π̃``, which ``data["j_exact_entropy"]`` shows, and ``H - ℓ(s)``
    stays positive at the limit (``data["bound"]``, ``data["entropy"]``). The setting is
    linear-quadratic with a one-dimensional action and a family in which the improvement is
    solved exactly at every state: neither the finite action spaces the proofs of Section 5.4.2
    assume, nor DIME's neural score network improved by stochastic gradients. The maximum over
    ``Π̃`` comes from a local optimiser, so the agreement is evidence, not proof, that the limit
    is the global maximiser.

    Args:
        n_steps, sigma0, total_time, noise_var: the chain, as in :func:`linear_gaussian_policy`.
        n_iter: policy-iteration steps (evaluation plus improvement).
        n_backups: backups of the Prop. 5.4.1 iteration.
        n_pairs, n_random: contraction pairs; random members of ``Π̃`` for Prop. 5.4.3.
        entropy_sign: sign of ``alpha ℓ`` in the backup of Eq. 5.21 used by the Prop. 5.4.1
            checks (the closed form keeps ``+``); a test hands in ``-1``.
        improve: candidate improvement ``(theta_old, kl) -> theta_new``, where ``kl(theta)``
            returns the joint KLs of Eq. 5.22 at the 9 states for the current target; defaults
            to the exact minimiser.

    Returns:
        Report with data ``j_bar`` (n_iter+1,: ``J̄(pi_i)``, ``-inf`` for a policy whose value
        diverges and ``nan`` after it), ``j_bar_direct`` (the BFGS maximum), ``j_exact_entropy``
        (2,: the exact objective ``J`` of the limit and its maximum over ``Π̃``), ``theta``
        (n_iter+1, 2N+1), ``theta_direct``, ``states`` (9,), ``bound`` (``ℓ(s)`` of the limit at
        ``states``), ``entropy`` (its ``H``), ``s_axis`` (21,), ``a_axis`` (25,), ``q_iterates``
        (n_iter+1, 21, 25: ``Q^pi_i`` on the grid), ``q_old`` and ``q_new`` (its first two
        entries), ``q_direct``, ``kl`` (improvements, 2, 9: the KL of Eq. 5.22 at each state
        before and after), ``backup_errors`` (n_backups+1,: ``max |Q^k - Q^pi|`` on the grid),
        ``contraction_ratios`` (n_pairs,), ``pair_kind`` (0 cosine plus constant, 1 constant,
        2 cosine) and ``etas`` (N,: the step sizes).
    """
    gamma = check_positive("gamma", gamma)
    if not gamma < 1:
        raise ValueError(f"gamma must lie in (0, 1), got {gamma}")
    alpha = check_positive("alpha", alpha)
    n_iter, n_backups = check_count("n_iter", n_iter), check_count("n_backups", n_backups)
    n_pairs, n_random = check_count("n_pairs", n_pairs), check_count("n_random", n_random)
    rng = seeded_rng(seed, 3)
    problem = lq_problem(rng, gamma, alpha)
    policy = linear_gaussian_policy(n_steps, sigma0, total_time, [noise_var], [0.0], [0.0], seed)
    eta = to_numpy(policy.step_sizes)[:, 0].astype(float)
    family = ChainFamily(eta, float(sigma0))
    n = family.n
    theta0 = np.r_[rng.uniform(-0.3, 0.3), rng.normal(scale=0.3, size=n), np.zeros(n)]
    for _ in range(1000):  # a small state feedback g with |F| = |A + B m_g| <= 1 (A <= 0.95)
        theta0[n + 1 :] = rng.normal(scale=0.1, size=n)
        if abs(problem.A + problem.B * family.marginal(theta0).mean_g) <= 1:
            break
    states = np.linspace(-2.0, 2.0, 9)
    s_axis, a_axis = np.linspace(-2.5, 2.5, 21), np.linspace(-3.0, 3.0, 25)
    grid_s, grid_a = np.meshgrid(s_axis, a_axis, indexing="ij")
    grid = lq_features(grid_s, grid_a)

    def evaluate(theta: np.ndarray, exact_entropy: bool = False):
        pi = family.marginal(theta)
        bonus = np.array([0.0, 0.0, pi.entropy]) if exact_entropy else pi.bound
        return pi, evaluate_policy(problem, pi, bonus)

    # ---- Prop. 5.4.1: the backup of Eq. 5.21 for pi_0, against the closed form of Eq. 5.17
    pi0, evaluated = evaluate(theta0)
    assert evaluated is not None  # gamma F^2 <= gamma < 1; the slowest mode of T^pi is gamma
    q_pi = evaluated[1]
    q_pi_grid = grid @ q_pi
    scale = float(np.abs(q_pi_grid).max())
    tol_q = relative_tol(scale)

    def backup(q: Callable[[np.ndarray, np.ndarray], np.ndarray], s, a, n_nodes: int):
        return lq_backup(problem, pi0, q, s, a, n_nodes, entropy_sign)

    fixed_point = backup(lambda s, a: lq_features(s, a) @ q_pi, grid_s, grid_a, 4)
    fit_s, fit_a = (x.ravel() for x in np.meshgrid(*2 * [np.linspace(-2, 2, 4)]))
    fit = lq_features(fit_s, fit_a)
    q = rng.normal(scale=scale, size=6)  # an arbitrary Q^0
    errors = [np.abs(grid @ q - q_pi_grid).max()]
    for _ in range(n_backups):
        q = np.linalg.lstsq(fit, backup(lambda s, a, q=q: lq_features(s, a) @ q, fit_s, fit_a, 4))[
            0
        ]
        errors.append(np.abs(grid @ q - q_pi_grid).max())
    errors = np.array(errors)

    coarse_s, coarse_a = (x[::2, ::2] for x in (grid_s, grid_a))
    ratios, kinds = [], []
    for i in range(n_pairs):
        q1 = rng.normal(size=6)
        kind = i % 3  # 0: cosine plus constant, 1: constant shift, 2: cosine
        shift = rng.normal(scale=3.0) if kind < 2 else 0.0
        amp = rng.normal(scale=3.0) if kind != 1 else 0.0
        freq, phase = rng.uniform(-1.5, 1.5, 2), rng.uniform(0, 2 * math.pi)

        def q2(s, a, q1=q1, shift=shift, amp=amp, freq=freq, phase=phase):
            bump = shift + amp * np.cos(freq[0] * s + freq[1] * a + phase)
            return lq_features(s, a) @ q1 + bump

        t1 = backup(lambda s, a, q1=q1: lq_features(s, a) @ q1, coarse_s, coarse_a, 20)
        t2 = backup(q2, coarse_s, coarse_a, 20)
        # sup over (s, a) of |shift + amp cos(.)| is |shift| + |amp| (the phase takes all values)
        ratios.append(np.abs(t1 - t2).max() / (abs(shift) + abs(amp)))
        kinds.append(kind)
    ratios, kinds = np.array(ratios), np.array(kinds)

    # ---- Props. 5.4.2-5.4.3: evaluation (closed form) and improvement (Eq. 5.22), alternated
    thetas, objectives, q_grids, kls, c11 = [], [], [], [], []
    theta = last = theta0  # last: the last iterate with a finite value
    for i in range(n_iter + 1):
        thetas.append(theta)
        pi, evaluated = evaluate(theta)
        if evaluated is None:  # a candidate improvement left the stable policies: V = -inf
            objectives.append(-math.inf)
            q_grids.append(np.full(grid.shape[:-1], -math.inf))
            break
        last, (value, q) = theta, evaluated
        objectives.append(lq_objective(problem, value))
        q_grids.append(grid @ q)
        # Q is concave in a for every stable policy of the family, so the target exists
        target = Target.of(q, alpha, eta, family.sigma0) if i < n_iter else None
        if target is None:
            break

        def kl(th: np.ndarray, target: Target = target) -> np.ndarray:
            return joint_kls(family, np.asarray(th, dtype=float), target, states)

        if improve is None:
            new = improve_exact(family, target, states, theta)
        else:
            new = np.asarray(improve(theta.copy(), kl), dtype=float)
        kls.append([kl(theta), kl(new)])
        rhs = -lq_quadratic(pi.bound, states) - expected_q(q, pi, states) / alpha
        c11.append([kls[-1][0], rhs + log_partition(q, alpha, states)])
        theta = new
    pad = n_iter + 1 - len(objectives)
    objectives = np.array(objectives + [math.nan] * pad)
    q_grids = np.array(q_grids + [np.full(grid.shape[:-1], math.nan)] * pad)
    thetas = np.array(thetas + [np.full(theta0.shape, math.nan)] * pad)
    kls, c11 = np.array(kls), np.array(c11)  # the improvements that were made (at least one)

    def negative_objective(theta: np.ndarray, exact_entropy: bool = False) -> float:
        return -lq_objective(problem, (evaluate(theta, exact_entropy)[1] or (None,))[0])

    def negative_exact(x: np.ndarray) -> float:
        """``-J`` with the exact entropy; it sees only the marginal ``(slope, mean_c, mean_g)``,
        and the offsets reach every affine mean."""
        var = family.maps(x[0])[1][-1, -1]
        pi = Marginal(float(x[1]), float(x[2]), float(var), np.zeros(3))
        return -lq_objective(
            problem, (evaluate_policy(problem, pi, [0, 0, pi.entropy]) or (None,))[0]
        )

    with np.errstate(invalid="ignore", over="ignore"):  # -J = inf past the stable policies
        direct = minimize(negative_objective, theta0, method="BFGS", options={"gtol": 1e-9})
        start = family.marginal(direct.x)
        exact_opt = minimize(
            negative_exact, [direct.x[0], start.mean_c, start.mean_g], method="BFGS"
        )
    _, direct_eval = evaluate(direct.x)
    q_direct = grid @ direct_eval[1]
    j_exact = np.array([-negative_objective(last, True), -exact_opt.fun])

    q_random = []  # stable policies of the family about the direct maximiser
    for _ in range(100 * n_random):
        candidate = evaluate(direct.x + rng.normal(scale=0.3, size=direct.x.size))[1]
        if candidate is not None:
            q_random.append(grid @ candidate[1])
        if len(q_random) == n_random:
            break
    q_random = np.array(q_random)

    pi_last = family.marginal(last)
    bound_last = lq_quadratic(pi_last.bound, states)
    chains = [
        linear_gaussian_chain(eta[:, None], family.sigma0, last[0], off[:, None])
        for off in family.offsets(last, states)
    ]
    chain_bound = np.array([c.bound[0] for c in chains])
    chain_mean = np.array([c.marginal_mean[0] for c in chains])
    chain_var = np.array([c.marginal_var[0] for c in chains])
    family_mean = pi_last.mean_c + pi_last.mean_g * states

    # Tolerances. Closed forms, Gauss-Hermite quadrature (exact for the quadratics, and to
    # rounding for the cosines with 20 nodes at these frequencies) and the refitted backups agree
    # to rounding: 1e-9 relative to the largest |Q| on the grid, 1e-9 on the ratios. The backup
    # iteration's slowest mode contracts by gamma, so after 300 backups its error is ~1e-14 of
    # the initial one. The PI limit and the BFGS maximiser locate theta to ~1e-6
    # (finite-difference gradients), but J̄ and Q^theta are stationary at the maximiser (V^theta(s)
    # is maximal at every state), so their values agree to ~1e-12: 1e-8 relative.
    j_scale = float(np.nanmax(np.abs(objectives[np.isfinite(objectives)]), initial=1.0))
    checks = (
        worst_check(
            "T Q^pi = Q^pi: the closed form of Eq. 5.17 (with ℓ) is the backup's fixed point",
            "Eqs. 5.17, 5.21",
            fixed_point,
            q_pi_grid,
            tol_q,
        ),
        Check(
            f"Q^k = T Q^(k-1) from a random Q^0 -> closed-form Q^pi after {n_backups} backups",
            "Prop. 5.4.1",
            errors[-1],
            0.0,
            tol_q,
        ),
        Check(
            f"||TQ1 - TQ2|| <= gamma ||Q1 - Q2|| (sup norm) for {n_pairs} bounded differences",
            "Eq. 5.21, Prop. 5.4.1",
            ratios.max(),
            gamma,
            1e-9,
            "<=",
        ),
        worst_check(
            "constant shifts: ||TQ1 - TQ2|| = gamma ||Q1 - Q2|| (the modulus is attained)",
            "Eq. 5.21",
            ratios[kinds == 1],
            gamma,
            1e-9,
        ),
        worst_check(
            "joint KL of Eq. 5.22 = -ℓ(s) - E[Q(s, a)] / alpha + log Z(s), every iterate",
            "Eqs. 5.18-5.19, 5.27, C.11",
            c11[:, 0],
            c11[:, 1],
            relative_tol(*np.abs(c11).max((0, 2)).tolist()),
        ),
        worst_check(
            "improvement: KL to the target does not increase, at every state",
            "Eq. 5.22, C.16",
            kls[:, 1],
            kls[:, 0],
            relative_tol(float(np.nanmax(np.abs(kls), initial=0.0))),
            "<=",
        ),
        worst_check(
            "improvement: Q^pi_new >= Q^pi_old on the (s, a) grid, every iteration",
            "Prop. 5.4.2, Eqs. C.16-C.28",
            q_grids[:-1],
            q_grids[1:],
            tol_q,
            "<=",
        ),
        worst_check(
            "iteration: J̄(pi_i) is non-decreasing",
            "Eq. 5.16, Prop. 5.4.3",
            objectives[:-1],
            objectives[1:],
            relative_tol(j_scale),
            "<=",
        ),
        Check(
            f"iteration: J̄(pi_{n_iter}) = max of J̄ over Π̃ (BFGS on theta from pi_0)",
            "Eq. 5.16, Prop. 5.4.3",
            objectives[-1],
            -direct.fun,
            relative_tol(objectives[-1], direct.fun, rtol=1e-8),
        ),
        worst_check(
            f"iteration: Q^pi_{n_iter} = Q of the direct maximiser of J̄",
            "Prop. 5.4.3",
            q_grids[-1],
            q_direct,
            relative_tol(float(np.abs(q_direct).max()), rtol=1e-8),
        ),
        worst_check(
            f"iteration: Q^pi_{n_iter} >= Q^pi of {n_random} random policies in Π̃",
            "Prop. 5.4.3",
            q_random,
            q_grids[-1][None],
            tol_q,
            "<=",
        ),
        worst_check(
            "ℓ(s) <= H(pi_0(.|s)) for the limit policy",
            "Eq. 5.15",
            bound_last,
            pi_last.entropy,
            relative_tol(pi_last.entropy),
            "<=",
        ),
        worst_check(
            "the family's ℓ(s), marginal mean and variance = linear_gaussian_chain (Sec. 5.4.1)",
            "Eqs. 5.14-5.15",
            np.r_[bound_last, family_mean, np.full_like(states, pi_last.var)],
            np.r_[chain_bound, chain_mean, chain_var],
            relative_tol(*np.abs(chain_bound).tolist(), *np.abs(chain_mean).tolist()),
        ),
    )
    data = {
        "j_bar": objectives,
        "j_bar_direct": np.array(-direct.fun),
        "j_exact_entropy": j_exact,
        "theta": thetas,
        "theta_direct": direct.x,
        "states": states,
        "bound": bound_last,
        "entropy": np.array(pi_last.entropy),
        "s_axis": s_axis,
        "a_axis": a_axis,
        "q_iterates": q_grids,
        "q_old": q_grids[0],
        "q_new": q_grids[1],
        "q_direct": q_direct,
        "kl": kls,
        "backup_errors": errors,
        "contraction_ratios": ratios,
        "pair_kind": kinds,
        "etas": eta,
    }
    return CheckReport(
        "Diffusion-based policy iteration with ℓ on a linear-quadratic problem (Section 5.4.2)",
        checks,
        data,
    )

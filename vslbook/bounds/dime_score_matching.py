"""Numerical checks of Section 5.3.2 (DIME): denoising score matching, Eq. 5.9.

The forward process of Eq. 5.7 is an Ornstein-Uhlenbeck process whose conditional law given
the action is Gaussian in closed form (:class:`OUProcess`), so the regression target of the
denoising score-matching loss of Eq. 5.9 (:func:`score_matching_loss`) is explicit. Why a
regression onto the *conditional* score learns the *marginal* score, and what the learned
score is then used for (the denoising process of Eq. 5.10), is checked by
:func:`check_score_matching` against quadrature and closed forms on a one-dimensional
Gaussian-mixture target, whose noised marginals are Gaussian mixtures again.

Import from :mod:`vslbook.bounds.dime`, which re-exports everything public here.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from vslbook.bounds import Check, CheckReport, relative_tol
from vslbook.bounds.toy_numerics import check_count, check_positive, seeded_rng, worst_check

__all__ = [
    "OUProcess",
    "check_score_matching",
    "mixture_log_density_and_score",
    "score_matching_loss",
]

Score = Callable[[np.ndarray, float], np.ndarray]


@dataclass(frozen=True)
class OUProcess:
    """The noising process of Eq. 5.7, ``da = -beta_t a dt + eta sqrt(2 beta_t) dB_t``.

    The diffusion coefficient rises linearly from ``beta_start`` at ``t = 0`` to ``beta_end``
    at ``t = horizon`` (the usual variance-preserving schedule), so
    ``B(t) = int_0^t beta_s ds`` is a quadratic and the conditional law of ``a_t`` given
    ``a_0`` is (solve the linear SDE with the integrating factor ``e^{B(t)}``)

        ->pi_{t|0}(a_t | a_0) = N(a_t; e^{-B(t)} a_0, eta^2 (1 - e^{-2 B(t)})),

    which tends to the stationary ``N(0, eta^2)`` as ``B(t)`` grows.
    """

    beta_start: float = 0.1
    beta_end: float = 8.0
    horizon: float = 1.0
    eta: float = 1.0

    def __post_init__(self) -> None:
        for name in ("beta_start", "beta_end", "horizon", "eta"):
            check_positive(name, getattr(self, name))

    def beta(self, t: np.ndarray | float) -> np.ndarray:
        """``beta_t``, linear in ``t``."""
        t = np.asarray(t, dtype=float)
        return self.beta_start + (self.beta_end - self.beta_start) * t / self.horizon

    def integral(self, t: np.ndarray | float) -> np.ndarray:
        """``B(t) = int_0^t beta_s ds``."""
        t = np.asarray(t, dtype=float)
        return self.beta_start * t + (self.beta_end - self.beta_start) * t**2 / (2 * self.horizon)

    def conditional(
        self, a0: np.ndarray | float, t: np.ndarray | float
    ) -> tuple[np.ndarray, np.ndarray]:
        """Mean and variance of ``->pi_{t|0}(. | a0)`` (Eq. 5.7 solved in closed form)."""
        decay = np.exp(-self.integral(t))
        return decay * np.asarray(a0, dtype=float), self.eta**2 * (1 - decay**2)

    def conditional_score(
        self, a_t: np.ndarray, a0: np.ndarray, t: np.ndarray | float
    ) -> np.ndarray:
        """``grad log ->pi_{t|0}(a_t | a_0) = -(a_t - e^{-B(t)} a_0) / (eta^2 (1 - e^{-2B(t)}))``,
        the regression target of Eq. 5.9."""
        mean, var = self.conditional(a0, t)
        return -(np.asarray(a_t, dtype=float) - mean) / var

    def noised_mixture(
        self, t: float, means: np.ndarray, variances: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Component means and variances of ``->pi_t`` when ``->pi_0`` is a Gaussian mixture.

        Each component ``N(m_k, v_k)`` is pushed through the linear-Gaussian conditional:
        ``N(e^{-B} m_k, e^{-2B} v_k + eta^2 (1 - e^{-2B}))``; the weights are unchanged.
        """
        decay = math.exp(-float(self.integral(t)))
        means, variances = np.asarray(means, dtype=float), np.asarray(variances, dtype=float)
        return decay * means, decay**2 * variances + self.eta**2 * (1 - decay**2)


def mixture_log_density_and_score(
    x: np.ndarray, weights: np.ndarray, means: np.ndarray, variances: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``log p(x)`` and ``d/dx log p(x)`` of a one-dimensional Gaussian mixture, elementwise.

    The score is the responsibility-weighted component score,
    ``sum_k r_k(x) (-(x - m_k) / v_k)`` (computed stably in log space).
    """
    x = np.asarray(x, dtype=float)[..., None]
    log_comp = np.log(weights) - 0.5 * (
        (x - means) ** 2 / variances + np.log(2 * np.pi * variances)
    )
    top = log_comp.max(-1, keepdims=True)
    rel = np.exp(log_comp - top)
    total = rel.sum(-1, keepdims=True)
    resp = rel / total
    return (np.log(total) + top)[..., 0], (resp * (-(x - means) / variances)).sum(-1)


def score_matching_loss(
    score: Score,
    a0: np.ndarray,
    a_t: np.ndarray,
    t: np.ndarray | float,
    process: OUProcess,
    conditional_score: Callable[[np.ndarray, np.ndarray, np.ndarray | float], np.ndarray]
    | None = None,
) -> np.ndarray:
    """Per-sample terms of the denoising score-matching loss of Eq. 5.9.

        beta_t || f(a_t, t) - grad log ->pi_{t|0}(a_t | a_0) ||^2

    with ``a_0 ~ ->pi_0`` and ``a_t ~ ->pi_{t|0}(. | a_0)``; the loss is their mean over
    samples (and over ``t``). Arrays are ``(...,)`` for a one-dimensional action, or
    ``(..., d)`` with the squared norm over the last axis when ``score`` returns that shape.

    Args:
        score: the candidate score ``f(a_t, t)``.
        conditional_score: the regression target ``(a_t, a_0, t) -> grad log ->pi_{t|0}``;
            defaults to :meth:`OUProcess.conditional_score`.
    """
    target = (conditional_score or process.conditional_score)(a_t, a0, t)
    residual = np.asarray(score(a_t, t), dtype=float) - target
    return process.beta(t) * residual**2


def _em_conditional_moments(
    process: OUProcess, a0: float, n_fine: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact moments of the Euler-Maruyama recursion of Eq. 5.7 from a fixed ``a0``."""
    dt = process.horizon / n_fine
    times = dt * np.arange(n_fine + 1)
    mean, var = np.empty(n_fine + 1), np.empty(n_fine + 1)
    mean[0], var[0] = a0, 0.0
    for k in range(n_fine):
        c = 1 - process.beta(times[k]) * dt
        mean[k + 1] = c * mean[k]
        var[k + 1] = c**2 * var[k] + 2 * process.eta**2 * process.beta(times[k]) * dt
    return times, mean, var


def _simulate_forward(
    process: OUProcess, a0: float, n_fine: int, n_samples: int, rng: np.random.Generator
) -> np.ndarray:
    """Euler-Maruyama paths ``(n_fine + 1, n_samples)`` of Eq. 5.7 from a fixed ``a0``."""
    dt = process.horizon / n_fine
    paths = np.empty((n_fine + 1, n_samples))
    paths[0] = a0
    for k in range(n_fine):
        b = float(process.beta(k * dt))
        noise = process.eta * math.sqrt(2 * b * dt) * rng.standard_normal(n_samples)
        paths[k + 1] = paths[k] - b * paths[k] * dt + noise
    return paths


def _denoise_on_grid(
    process: OUProcess, score: Score, n_steps: int, grid: np.ndarray
) -> np.ndarray:
    """Density of ``a^0`` after ``n_steps`` Euler-Maruyama steps of Eq. 5.10, on ``grid``.

    Starts from ``N(0, eta^2)`` and applies the Gaussian kernel of each step
    ``a^{n-1} = a^n + (beta_n a^n + 2 eta^2 beta_n f(a^n, t_n)) delta + N(0, 2 eta^2 beta_n delta)``
    as a matrix on the grid (the trapezoid rule), so no sampling is involved.
    """
    h = grid[1] - grid[0]
    delta = process.horizon / n_steps
    eta2 = process.eta**2
    p = np.exp(-0.5 * grid**2 / eta2) / math.sqrt(2 * math.pi * eta2)
    for n in range(n_steps, 0, -1):
        t = n * delta
        b = float(process.beta(t))
        mean = grid + (b * grid + 2 * eta2 * b * score(grid, t)) * delta
        var = 2 * eta2 * b * delta
        kernel = np.exp(-0.5 * (grid[:, None] - mean[None, :]) ** 2 / var)
        p = kernel @ p * (h / math.sqrt(2 * math.pi * var))
    return p


def check_score_matching(
    seed: int = 0,
    n_samples: int = 20_000,
    n_fine: int = 400,
    check_times: tuple[float, ...] = (0.1, 0.3, 0.6, 1.0),
    denoise_steps: tuple[int, ...] = (16, 32, 64, 128),
    conditional_score: Callable[[np.ndarray, np.ndarray, np.ndarray | float], np.ndarray]
    | None = None,
) -> CheckReport:
    """Denoising score matching (Eq. 5.9) on a Gaussian-mixture target, in five checks.

    The target ``->pi_0`` is a seeded two-component mixture in one dimension and the forward
    process is :class:`OUProcess` (Eq. 5.7, ``horizon = 1``), so every noised marginal
    ``->pi_t`` is a mixture with a closed-form score (:meth:`OUProcess.noised_mixture`).

    1. *The conditional law.* Euler-Maruyama paths of Eq. 5.7 from a fixed ``a_0`` have the
       closed-form mean and variance of :meth:`OUProcess.conditional` (5 standard errors plus
       the exact bias of the discretisation).
    2. *Why the regression works.* ``E[grad log ->pi_{t|0}(a_t | a_0) | a_t] = grad log
       ->pi_t(a_t)``: the posterior mean of the conditional score, by quadrature over
       ``a_0``, equals the marginal score on a grid of ``a_t`` and ``t``.
    3. *Same minimiser.* For several functions ``f`` (zero, the true score, an affine map, a
       sine), Eq. 5.9 at fixed ``t`` minus the explicit loss
       ``beta_t E||f - grad log ->pi_t||^2`` is one constant ``C(t)``, by 2-D quadrature over
       ``(a_0, a_t)``; so the true score minimises Eq. 5.9 and the loss there is ``C(t)``.
    4. *Learning from samples.* For a Gaussian target the marginal score is affine; least
       squares of the conditional score on ``(1, a_t)`` over samples ``a_0 ~ ->pi_0``
       (the sample form of Eq. 5.9 over affine ``f``) recovers its slope and intercept
       (5 standard errors).
    5. *Eq. 5.10.* The denoising chain driven by the minimiser of Eq. 5.9 (the exact score)
       and started at ``N(0, eta^2)`` ends at the target: the L1 distance of its ``a^0``
       density (propagated on a grid, no sampling) to ``->pi_0`` falls as the number of steps
       grows and halves over the last doubling (first order in ``delta``).

    Args:
        conditional_score: candidate regression target ``(a_t, a_0, t) -> grad log
            ->pi_{t|0}``; defaults to :meth:`OUProcess.conditional_score`.

    Returns:
        Report with data ``weights``, ``means``, ``variances`` (the target), ``grid``,
        ``check_times``, ``posterior_score`` and ``marginal_score`` (``len(check_times)``,
        grid), ``loss_offsets`` (times x functions: Eq. 5.9 minus the explicit loss),
        ``fit`` and ``fit_stderr`` (per fitted time: intercept, slope) and ``fit_exact``,
        ``denoise_steps``, ``denoise_l1``, ``denoise_density`` (finest) and
        ``target_density`` on ``denoise_grid``.
    """
    n_samples = check_count("n_samples", n_samples, 10)
    n_fine = check_count("n_fine", n_fine, 10)
    target_of = conditional_score
    process = OUProcess()
    rng = seeded_rng(seed, 11)
    weights = np.array([0.35, 0.65]) + rng.uniform(-0.05, 0.05) * np.array([1, -1])
    means = np.array([-1.5, 1.0]) + rng.uniform(-0.2, 0.2, 2)
    variances = (np.array([0.4, 0.6]) * rng.uniform(0.9, 1.1, 2)) ** 2
    times = np.asarray(check_times, dtype=float)
    if np.any(times <= 0) or np.any(times > process.horizon):
        raise ValueError(f"check_times must lie in (0, {process.horizon}], got {check_times}")
    cond = target_of or process.conditional_score

    def marginal_score(x: np.ndarray, t: float) -> np.ndarray:
        m, v = process.noised_mixture(t, means, variances)
        return mixture_log_density_and_score(x, weights, m, v)[1]

    # 1. the conditional law of Eq. 5.7 against an Euler-Maruyama simulation
    a_fixed = 1.7
    paths = _simulate_forward(process, a_fixed, n_fine, n_samples, rng)
    em_times, em_mean, em_var = _em_conditional_moments(process, a_fixed, n_fine)
    idx = np.rint(times * n_fine / process.horizon).astype(int)
    cf_mean, cf_var = process.conditional(a_fixed, em_times[idx])
    s_mean, s_var = paths[idx].mean(1), paths[idx].var(1, ddof=1)
    tol_mean = 5 * np.sqrt(s_var / n_samples) + np.abs(em_mean[idx] - cf_mean)
    tol_var = 5 * s_var * math.sqrt(2 / (n_samples - 1)) + np.abs(em_var[idx] - cf_var)

    # 2. posterior mean of the conditional score = marginal score (quadrature over a_0)
    a0_grid = np.linspace(-7.0, 7.0, 4001)
    prior_0 = np.exp(mixture_log_density_and_score(a0_grid, weights, means, variances)[0])
    grid = np.linspace(-3.5, 3.5, 57)
    posterior, exact = [], []
    for t in times:
        m, v = process.conditional(a0_grid, t)
        joint = prior_0 * np.exp(-0.5 * (grid[:, None] - m) ** 2 / v)  # (grid, a0)
        scores = cond(grid[:, None], a0_grid[None, :], t)
        posterior.append(
            np.trapezoid(joint * scores, a0_grid, axis=1) / np.trapezoid(joint, a0_grid, axis=1)
        )
        exact.append(marginal_score(grid, t))
    posterior, exact = np.array(posterior), np.array(exact)

    # 3. Eq. 5.9 minus the explicit loss is the same constant for every f (2-D quadrature)
    candidates: dict[str, Score] = {
        "zero": lambda x, t: np.zeros_like(x),
        "true score": marginal_score,
        "affine": lambda x, t: 0.5 - 0.8 * x,
        "sine": lambda x, t: np.sin(2 * x),
    }
    at_grid = np.linspace(-7.0, 7.0, 1401)
    offsets = np.empty((times.size, len(candidates)))
    losses = np.empty_like(offsets)
    a0_coarse = np.linspace(-7.0, 7.0, 1401)
    p0_coarse = np.exp(mixture_log_density_and_score(a0_coarse, weights, means, variances)[0])
    for i, t in enumerate(times):
        m, v = process.conditional(a0_coarse, t)
        cond_density = np.exp(-0.5 * (at_grid[:, None] - m) ** 2 / v) / np.sqrt(2 * np.pi * v)
        weight = cond_density * p0_coarse  # (a_t, a_0)
        mt, vt = process.noised_mixture(t, means, variances)
        p_t = np.exp(mixture_log_density_and_score(at_grid, weights, mt, vt)[0])
        for j, f in enumerate(candidates.values()):
            dsm = score_matching_loss(
                f, a0_coarse[None, :], at_grid[:, None], t, process, target_of
            )
            dsm = np.trapezoid(np.trapezoid(weight * dsm, a0_coarse, axis=1), at_grid)
            esm = np.trapezoid(
                p_t * process.beta(t) * (f(at_grid, t) - marginal_score(at_grid, t)) ** 2, at_grid
            )
            losses[i, j], offsets[i, j] = dsm, dsm - esm

    # 4. least squares over samples recovers the affine marginal score of a Gaussian target
    g_mean, g_var = float(means @ weights), 0.8**2
    fit, fit_se, fit_exact = [], [], []
    for t in times:
        a0 = g_mean + math.sqrt(g_var) * rng.standard_normal(n_samples)
        m, v = process.conditional(a0, t)
        a_t = m + np.sqrt(v) * rng.standard_normal(n_samples)
        y = cond(a_t, a0, t)
        design = np.stack([np.ones(n_samples), a_t], 1)
        coef, *_ = np.linalg.lstsq(design, y, rcond=None)
        resid = y - design @ coef
        cov = np.linalg.inv(design.T @ design) * resid.var(ddof=2)
        mt, vt = process.noised_mixture(t, np.array([g_mean]), np.array([g_var]))
        fit.append(coef)
        fit_se.append(np.sqrt(np.diag(cov)))
        fit_exact.append([mt[0] / vt[0], -1 / vt[0]])  # score -(a - m_t)/v_t
    fit, fit_se, fit_exact = np.array(fit), np.array(fit_se), np.array(fit_exact)

    # 5. Eq. 5.10 with the exact score: the a^0 density converges to the target (first order)
    steps = [check_count("denoise_steps entry", n) for n in denoise_steps]
    d_grid = np.linspace(-5.0, 5.0, 401)
    target = np.exp(mixture_log_density_and_score(d_grid, weights, means, variances)[0])
    l1, density = [], None
    for n in steps:
        density = _denoise_on_grid(process, marginal_score, n, d_grid)
        l1.append(np.trapezoid(np.abs(density - target), d_grid))
    l1 = np.array(l1)
    ratios = l1[1:] / l1[:-1]

    spread = offsets.max(1) - offsets.min(1)
    checks = (
        worst_check(
            "sample mean of a_t | a_0 = e^{-B(t)} a_0 (5 SE + EM bias)",
            "Eq. 5.7",
            s_mean,
            cf_mean,
            tol_mean,
        ),
        worst_check(
            "sample var of a_t | a_0 = eta^2 (1 - e^{-2B(t)}) (5 SE + EM bias)",
            "Eq. 5.7",
            s_var,
            cf_var,
            tol_var,
        ),
        worst_check(
            "E[grad log ->pi_{t|0}(a_t|a_0) | a_t] = grad log ->pi_t(a_t) (quadrature)",
            "Eq. 5.9",
            posterior,
            exact,
            1e-6 * np.maximum(1, np.abs(exact)),
        ),
        worst_check(
            "Eq. 5.9 - explicit score loss = C(t), the same for every f (quadrature)",
            "Eq. 5.9",
            spread,
            0.0,
            1e-7 * np.maximum(1, np.abs(offsets).max(1)),
        ),
        worst_check(
            "the true score minimises Eq. 5.9 among the candidates",
            "Eq. 5.9",
            losses[:, 1],
            losses.min(1),
            relative_tol(*losses.ravel(), rtol=1e-9),
        ),
        worst_check(
            "least squares on samples = slope and intercept of the marginal score (5 SE)",
            "Eq. 5.9",
            fit,
            fit_exact,
            5 * fit_se,
        ),
        worst_check(
            f"Eq. 5.10 with the exact score: L1(a^0 density, target) falls (N = {steps})",
            "Eqs. 5.8, 5.10",
            np.diff(l1),
            0.0,
            0.0,
            "<=",
        ),
        Check(
            f"... and halves when the steps double (N = {steps[-2]} -> {steps[-1]})",
            "Eqs. 5.8, 5.10",
            float(ratios[-1]),
            0.5,
            0.05,
        ),
        Check(
            f"Eq. 5.10 at N = {steps[-1]} steps: L1 distance to the target < 0.02",
            "Eqs. 5.8, 5.10",
            float(l1[-1]),
            0.02,
            0.0,
            "<=",
        ),
    )
    data = {
        "weights": weights,
        "means": means,
        "variances": variances,
        "grid": grid,
        "check_times": times,
        "posterior_score": posterior,
        "marginal_score": exact,
        "loss_offsets": offsets,
        "losses": losses,
        "fit": fit,
        "fit_stderr": fit_se,
        "fit_exact": fit_exact,
        "denoise_steps": np.array(steps),
        "denoise_l1": l1,
        "denoise_grid": d_grid,
        "denoise_density": density,
        "target_density": target,
    }
    return CheckReport("Denoising score matching (Section 5.3.2, Eq. 5.9)", checks, data)

"""HiREPS: hierarchical relative entropy policy search (Daniel, Neumann, Peters 2012).

The first Chapter 3 baseline (Section 3.2, "Versatile Skill Learning"; Section 3.4.2;
hyper-parameters Table A.2). A contextual mixture of N linear-Gaussian experts over the
task's FIXED context distribution p(c) (no curriculum), all N experts present from the start:

    π(θ|c) = Σ_o π(o|c) π(θ|c,o),   π(θ|c,o) = N(θ | K_o c + k_o, Σ_o),
    π(o|c) = π(o) N(c|μ_o, S_o) / Σ_o' π(o') N(c|μ_o', S_o').

One iteration is episode-based REPS over the joint (c, θ, o), solved on the samples:

    max_p  Σ p(c,θ,o) R(c,θ)
    s.t.   KL(p(c,θ) ‖ q(c,θ)) ≤ ε                      (trust region)
           Σ p(c,θ) φ(c) = φ̂                             (context marginal = p(c))
           E_p(c,θ)[H(p(o|c,θ))] ≤ κ_abs                  (responsibilities stay crisp)

with q the distribution of the samples. Replacing p(o|c,θ) inside the KL and entropy terms
by the responsibilities of the current mixture, p̃(o|c,θ) ∝ π(o|c) π(θ|c,o) (the EM lower
bound of the paper), gives the closed form

    p(c,θ,o) ∝ q(c,θ) p̃(o|c,θ)^{1+ξ/η} exp((R(c,θ) − V(c)) / η),   V(c) = vᵀφ(c),

and, on n samples (q = 1/n), the convex dual minimised over η > 0, ξ ≥ 0, v

    g(η, ξ, v) = η ε + ξ κ_abs + vᵀφ̂
                 + η log (1/n) Σ_i Σ_o p̃_io^{1+ξ/η} exp((R_i − vᵀφ_i) / η),

with ∂g/∂η = ε − KL̃, ∂g/∂ξ = κ_abs − H̃, ∂g/∂v = φ̂ − E_p[φ], where KL̃ = Σ p_io
log(p_io / (q_i p̃_io)) and H̃ = −Σ p_io log p̃_io are the bounds' relaxed forms. Both are
upper bounds (log-sum inequality; cross-entropy ≥ entropy) of the true KL of the (c, θ)
marginal and of the true expected entropy of the new responsibilities p_io / Σ_o p_io, so
the solution satisfies the original constraints (:func:`hireps_weights`).

The policy is then refitted by weighted maximum likelihood with the weights p_io
(:func:`fit_gating`, :func:`fit_linear_gaussian`).

The mixture itself (densities, responsibilities, sampling, the weighted ML fits and the
initial mixture) is shared with LaDiPS and lives in :mod:`vslbook.erl.mixture_baseline`; this
module holds HiREPS's configuration, its dual and its iteration.

What had to be inferred (no public code; the papers' full text was not at hand)
    * κ of Table A.2 (0.99 / 0.9) is read as a *relative* bound: κ_abs = κ · H_old, H_old the
      mean entropy of the current responsibilities on the samples (the absolute bound would
      need a value per task and N). The EM relaxation above follows the paper's derivation.
    * The gating is the generative ("Bayes") gating written above: Gaussian context models
      N(c|μ_o, S_o) and priors π(o). Its weighted ML fit is closed form (weighted moments),
      and it is the gating SVSL uses (π(o|c) = π(c|o)π(o)/π(c)), so the two compare directly.
    * V(c) features φ(c): linear and quadratic monomials of the context scaled to the
      task's box, φ̂ their sample mean (the empirical p(c)).
    * Samples: the last ``reuse_iterations`` batches are kept and treated as samples of q
      (the usual REPS sample reuse); responsibilities are recomputed under the current
      mixture each iteration.
    * Weighted ML: ridge ``ridge`` on the gain K (not on the offset k), ``cov_reg``·I added
      to every covariance; an expert (and its gating component) whose weights have an
      effective sample size below ``min_ess`` keeps its old parameters, its prior π(o)
      still takes the new mass. Prior masses are floored at 1e-20.
    * Samples per iteration (not in the thesis): 10 episodes per expert (600 / 700 / 500),
      with ``reuse_iterations`` = 3; ``iterations`` is set so the episode budget is of the
      order of SVSL's on the task (K·(N+1) iterations of its per-expert samples, §3.5 of the
      design facts): planar 350·61·81 ≈ 1.7M, beer pong 750·71·24 ≈ 1.3M, table tennis
      800·51·226 ≈ 9.2M episodes.
    * Initial mixture: expert offsets k_o = init_mean + init_mean_std·N(0, I) (random, to
      break the symmetry), K_o = 0, Σ_o = diag(init_cov); gating means uniform in the
      context box, S_o the box's uniform covariance, π(o) = 1/N.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import minimize
from scipy.special import logsumexp

from vslbook.erl.mixture_baseline import (
    MixtureAlgorithm,
    MixtureState,
    context_features,
    expert_log_density,
    fit_gating,
    fit_linear_gaussian,
    gating_log_probs,
    gaussian_log_pdf,
    log_responsibilities,
    mixture_update,
    run_iterations,
)

__all__ = [
    "HIREPS_PRESETS",
    "HiREPS",
    "HiREPSConfig",
    "MixtureState",
    "RepsWeights",
    "context_features",
    "expert_log_density",
    "fit_gating",
    "fit_linear_gaussian",
    "gating_log_probs",
    "gaussian_log_pdf",
    "hireps_weights",
    "log_responsibilities",
    "train",
]

_LOW, _HIGH = 1e-8, 1e8


# --------------------------------------------------------------------------------------
# configuration (Table A.2)
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class HiREPSConfig:
    """HiREPS hyper-parameters. Table A.2 (ε, κ, N); the rest are this implementation's.

    =========================  =====  =====  ===
    Task                        ε      κ      N
    =========================  =====  =====  ===
    Planar reacher (ablation)   0.5    0.99   60
    Beer pong                   0.3    0.9    70
    Table tennis                0.3    0.9    50
    =========================  =====  =====  ===

    Attributes:
        eps: KL bound ε of the joint update.
        kappa: relative bound on the responsibilities' entropy, κ_abs = κ · H_old (module
            docstring, "What had to be inferred").
        n_experts: N, all present from the start.
        samples_per_iteration: episodes drawn per iteration.
        reuse_iterations: batches kept as the REPS sample set (1: only the newest).
        iterations: full-run iteration count (used by :func:`train` when not overridden).
        init_mean: initial expert offset k (length n_params), or () for zeros.
        init_cov: initial expert covariance diagonal (length n_params), or one value.
        init_mean_std: spread of the random initial offsets.
        ridge: ridge on the expert gains K in the weighted ML fit.
        cov_reg: added to the diagonal of every fitted covariance.
        min_ess: an expert with fewer effective samples keeps its parameters.
    """

    eps: float = 0.5
    kappa: float = 0.99
    n_experts: int = 60
    samples_per_iteration: int = 600
    reuse_iterations: int = 3
    iterations: int = 2900
    init_mean: tuple[float, ...] = ()
    init_cov: tuple[float, ...] | float = 0.19
    init_mean_std: float = 0.5
    ridge: float = 1e-6
    cov_reg: float = 1e-6
    min_ess: float = 3.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.eps) and self.eps > 0):
            raise ValueError(f"eps must be a positive number, got {self.eps!r}")
        if not (np.isfinite(self.kappa) and self.kappa > 0):
            raise ValueError(f"kappa must be a positive number, got {self.kappa!r}")
        for name in ("n_experts", "samples_per_iteration", "reuse_iterations", "iterations"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {v!r}")
        cov = np.atleast_1d(np.asarray(self.init_cov, dtype=np.float64))
        if not np.all(np.isfinite(cov) & (cov > 0)):
            raise ValueError(f"init_cov must be positive, got {self.init_cov!r}")
        for name in ("init_mean_std", "ridge", "cov_reg", "min_ess"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a number >= 0, got {v!r}")

    @classmethod
    def for_task(cls, name: str, **overrides: Any) -> HiREPSConfig:
        """The preset of task ``name`` (:data:`HIREPS_PRESETS`) with ``overrides``."""
        if name not in HIREPS_PRESETS:
            raise ValueError(f"no HiREPS preset for task {name!r}; have {sorted(HIREPS_PRESETS)}")
        return _replace(HIREPS_PRESETS[name], overrides)


def _replace(cfg: Any, overrides: dict[str, Any]) -> Any:
    from dataclasses import replace

    return replace(cfg, **overrides)


_PLANAR_COV = (5.0,) + (0.19,) * 9  # SVSL's planar expert covariance (Σ₁₁ = 5)
_BP_MEAN = (0.7,) + (0.0,) * 14  # duration in the middle of [0.1, 1.3] s
_BP_COV = (0.25,) + (0.25, 5.0) * 7  # SVSL's beer pong expert covariance
_TT_MEAN = (1.03, 0.325) + (0.0,) * 21  # τ, delay in the middle of their bounds
_TT_COV = (0.02, 0.01) + (1.0,) * 21
# Chapter 3 table tennis (θ = [l, 21 ProMP weights]): the duration l starts at 1 s with
# variance 0.1 (std ≈ 0.32 s; roughly the flight time of the served ball at 2.5 m/s to the
# robot, and l < 0.1 s, which is rejected, is three standard deviations away); the weights
# start at 0 (the rest posture) with SVSL's unit variance. 28,007 iterations × 500
# episodes match SVSL's 14,003,100 episodes at N = 50, K = 800.
_TT3_MEAN = (1.0,) + (0.0,) * 21
_TT3_COV = (0.1,) + (1.0,) * 21

#: Per-task presets (task names of :mod:`vslbook.envs.robot`).
HIREPS_PRESETS: dict[str, HiREPSConfig] = {
    "planar-reacher": HiREPSConfig(
        eps=0.5, kappa=0.99, n_experts=60, samples_per_iteration=600, iterations=2900,
        init_cov=_PLANAR_COV, init_mean_std=0.5,
    ),
    "beer-pong": HiREPSConfig(
        eps=0.3, kappa=0.9, n_experts=70, samples_per_iteration=700, iterations=1800,
        init_mean=_BP_MEAN, init_cov=_BP_COV, init_mean_std=0.2,
    ),
    "table-tennis-4d": HiREPSConfig(
        eps=0.3, kappa=0.9, n_experts=50, samples_per_iteration=500, iterations=18400,
        init_mean=_TT_MEAN, init_cov=_TT_COV, init_mean_std=0.1,
    ),
    "table-tennis-ch3": HiREPSConfig(
        eps=0.3, kappa=0.9, n_experts=50, samples_per_iteration=500, iterations=28007,
        init_mean=_TT3_MEAN, init_cov=_TT3_COV, init_mean_std=0.1,
    ),
}  # fmt: skip


# --------------------------------------------------------------------------------------
# the REPS step (the dual)
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class RepsWeights:
    """Solution of the HiREPS dual (:func:`hireps_weights`).

    Attributes:
        weights: (n, N) p(c_i, θ_i, o), summing to 1.
        eta, xi: the multipliers η (KL) and ξ (entropy), in the units of the returns.
        v: (m,) the V(c) coefficients (returns' units).
        kl: the relaxed KL̃ (≥ the true KL of the (c, θ) marginal).
        entropy: the relaxed H̃ (≥ the true expected entropy of the new responsibilities).
        success: the constraints hold (KL̃ ≤ ε(1 + 1e-3), H̃ ≤ κ_abs + 1e-3·|κ_abs| + 1e-6,
            feature means within 1e-3 of φ̂ relative to their scale).
    """

    weights: np.ndarray
    eta: float
    xi: float
    v: np.ndarray
    kl: float
    entropy: float
    success: bool


def hireps_weights(
    returns: np.ndarray,
    log_resp: np.ndarray,
    features: np.ndarray,
    *,
    eps: float,
    kappa: float | None,
) -> RepsWeights:
    """Solve the HiREPS dual on n samples and return p(c_i, θ_i, o) (module docstring).

    Args:
        returns: (n,) returns R_i.
        log_resp: (n, N) log p̃(o|c_i, θ_i) of the current mixture (rows normalised).
        features: (n, m) context features φ(c_i) of V(c) (m may be 0); φ̂ = their mean.
        eps: KL bound ε > 0.
        kappa: absolute bound κ_abs on the expected responsibility entropy, or None.

    Returns:
        :class:`RepsWeights`. The dual is minimised with L-BFGS-B on the returns scaled to
        unit standard deviation (the weights are invariant to that scaling; η, ξ and v are
        reported back in return units).
    """
    r = np.asarray(returns, dtype=np.float64)
    lr = np.asarray(log_resp, dtype=np.float64)
    phi = np.asarray(features, dtype=np.float64)
    n = len(r)
    if r.ndim != 1 or lr.ndim != 2 or len(lr) != n or phi.ndim != 2 or len(phi) != n:
        raise ValueError(
            "need returns (n,), log_resp (n, N) and features (n, m); "
            f"got {r.shape}, {lr.shape}, {phi.shape}"
        )
    if not (np.all(np.isfinite(r)) and np.all(np.isfinite(phi)) and np.all(lr < np.inf)):
        raise ValueError("returns, features must be finite and log_resp must not hold +inf")
    if not (np.isfinite(eps) and eps > 0):
        raise ValueError(f"eps must be a positive number, got {eps!r}")
    if kappa is not None and not np.isfinite(kappa):
        raise ValueError(f"kappa must be a finite number or None, got {kappa!r}")
    lr = np.maximum(lr, -1e4)
    scale = float(np.std(r)) or 1.0
    rs = (r - r.mean()) / scale
    phi_hat = phi.mean(axis=0)
    m = phi.shape[1]
    constrained = kappa is not None
    kap = float(kappa) if constrained else 0.0

    def parts(x: np.ndarray) -> tuple[np.ndarray, float, np.ndarray]:
        eta = x[0]
        xi = x[1] if constrained else 0.0
        v = x[2:] if constrained else x[1:]
        delta = rs - phi @ v
        a = (1 + xi / eta) * lr + (delta / eta)[:, None]
        lse = logsumexp(a)
        return delta, lse, np.exp(a - lse)

    def dual(x: np.ndarray) -> tuple[float, np.ndarray]:
        eta = x[0]
        xi = x[1] if constrained else 0.0
        v = x[2:] if constrained else x[1:]
        delta, lse, p = parts(x)
        log_z = lse - np.log(n)
        g = eta * eps + xi * kap + v @ phi_hat + eta * log_z
        pl = float(np.sum(p * lr))
        d_eta = eps + log_z - (xi * pl + float(p.sum(1) @ delta)) / eta
        grad = [d_eta] + ([kap + pl] if constrained else []) + list(phi_hat - p.sum(1) @ phi)
        return float(g), np.asarray(grad)

    x0 = np.concatenate([[1.0], [1.0] if constrained else [], np.zeros(m)])
    bounds = [(_LOW, _HIGH)] + ([(0.0, _HIGH)] if constrained else []) + [(None, None)] * m
    res = minimize(
        dual, x0, jac=True, method="L-BFGS-B", bounds=bounds,
        options={"ftol": 1e-14, "gtol": 1e-9, "maxiter": 2000, "maxcor": 30},
    )  # fmt: skip
    x = res.x
    _, _, p = parts(x)
    kl = float(np.sum(p * (np.log(np.maximum(p, 1e-300)) + np.log(n) - lr)))
    ent = float(-np.sum(p * lr))
    phi_err = np.abs(p.sum(1) @ phi - phi_hat) / (phi.std(axis=0) + 1e-12)
    ok = bool(
        kl <= eps * (1 + 1e-3)
        and (not constrained or ent <= kap + 1e-3 * abs(kap) + 1e-6)
        and (m == 0 or phi_err.max() < 1e-3)
    )
    xi = float(x[1]) * scale if constrained else 0.0
    v = (x[2:] if constrained else x[1:]) * scale
    return RepsWeights(p, float(x[0]) * scale, xi, v, kl, ent, ok)


# --------------------------------------------------------------------------------------
# the algorithm object and loop
# --------------------------------------------------------------------------------------
class HiREPS(MixtureAlgorithm):
    """HiREPS on an episodic task (module docstring). ``workers`` is passed to
    ``task.evaluate``."""

    config: HiREPSConfig

    def __init__(self, task: Any, config: HiREPSConfig, seed: int, workers: int | None = 0) -> None:
        if not isinstance(config, HiREPSConfig):
            raise TypeError(f"config must be a HiREPSConfig, got {type(config).__name__}")
        super().__init__(task, config, seed, workers)

    def iteration(self) -> dict[str, float]:
        """Sample, solve the HiREPS dual, refit gating and experts by weighted ML."""
        cfg = self.config
        _, _, r_new, n_exec = self._collect()  # 1. episodes from the current mixture
        c, th, r = self._buffer_arrays()
        log_resp = log_responsibilities(c, th, self.mix)  # 2. p̃(o|c,θ) (EM step)
        h_old = float(-np.mean(np.sum(np.exp(log_resp) * log_resp, axis=1)))
        phi = context_features(c, self.task.context_low, self.task.context_high)
        sol = hireps_weights(r, log_resp, phi, eps=cfg.eps, kappa=cfg.kappa * h_old)  # 3.
        if sol.success or np.isfinite(sol.weights).all():  # 4. weighted ML (M step)
            self.mix = mixture_update(
                self.mix, c, th, sol.weights,
                ridge=cfg.ridge, cov_reg=cfg.cov_reg, min_ess=cfg.min_ess,
            )  # fmt: skip
        self.iterations_done += 1
        prior = np.exp(self.mix.log_prior)
        return {
            "iteration": float(self.iterations_done),
            "samples": float(n_exec),
            "total_samples": float(self.total_samples),
            "mean_return": float(np.mean(r_new)),
            "kl": sol.kl,
            "entropy_resp": sol.entropy,
            "entropy_bound": cfg.kappa * h_old,
            "eta": sol.eta,
            "xi": sol.xi,
            "dual_success": float(sol.success),
            "active_experts": float(np.sum(prior > 1e-3)),
        }


def train(
    task: Any,
    config: HiREPSConfig,
    seed: int,
    iterations: int | None = None,
    callback: Callable[[int, dict[str, float]], None] | None = None,
    workers: int | None = 0,
) -> HiREPS:
    """Run ``iterations`` (default ``config.iterations``) HiREPS iterations; ``callback(i,
    metrics)`` after each."""
    algo = HiREPS(task, config, seed, workers)
    n = config.iterations if iterations is None else iterations
    run_iterations(algo, n, callback)
    return algo

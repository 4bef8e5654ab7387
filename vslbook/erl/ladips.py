"""LaDiPS: layered direct policy search (End, Akrour, Peters, Neumann 2017).

The second Chapter 3 baseline (Section 3.2; Section 3.4.2; hyper-parameters Table A.3). The
policy is the same contextual mixture as HiREPS (:mod:`vslbook.erl.mixture_baseline`: N
linear-Gaussian experts π(θ|c,o) = N(K_o c + k_o, Σ_o), Bayes gating π(o|c) ∝ π(o) N(c|μ_o,
S_o), the task's fixed p(c), all N experts from the start), but the layers are updated
separately:

1. **Experts** (lower layer): each expert by contextual MORE (Eq. 3.5 without the SVSL
   reward augmentation; :func:`vslbook.erl.more.cmore_update`) on a quadratic surrogate of
   R(c, θ), every sample of the buffer weighted by the responsibility
   p̃(o|c,θ) ∝ π(o|c) π(θ|c,o) of the current mixture. The responsibility is the importance
   weight of the option's joint p(c) π(o|c) π(θ|c,o) against the sampling mixture, so every
   expert learns from every sample (LaDiPS's intra-option learning / experience sharing,
   A.3.2.1):

       max E_{p(c)π(o|c)} E_{π(θ|c,o)}[R̂_o(c,θ)]  s.t.  E[KL(π(·|c,o) ‖ π_old(·|c,o))] ≤ ε,
                                                      H(π(·|c,o)) ≥ H_min.

2. **Gating** (upper layer): a REPS step on the categorical π(o|c) of every sample context
   (:func:`gating_update`):

       max E_c Σ_o π(o|c) Q(c,o)  s.t.  E_c KL(π(·|c) ‖ π_old(·|c)) ≤ ε_gating,
                                         E_c H(π(·|c)) ≥ α,

   with the closed form log π(o|c) ∝ (η log π_old(o|c) + Q(c,o)) / (η + ω) and the dual

       g(η, ω) = η ε_gating − ω α + (1/n) Σ_i (η + ω) log Σ_o exp((η log π_old(o|c_i)
                 + Q(c_i,o)) / (η + ω)),

   ∂g/∂η = ε_gating − E KL, ∂g/∂ω = E H − α. Q(c,o) = E[R | c, o] is a weighted
   least-squares fit of the returns on quadratic context features with the responsibilities
   of o as weights. The new π(o|c_i) are then projected on the Bayes gating by weighted ML
   (:func:`vslbook.erl.mixture_baseline.fit_gating` with weights π_new(o|c_i)/n).

α = log 30 (Table A.3) is the lower bound on the gating's entropy ("the entropy of the gating
is lower bounded with a constant value", Section 3.2): log 30 nats is the entropy of a
uniform choice among 30 experts, so the gating keeps at least that much spread.

What had to be inferred (no public code; the paper's full text was not at hand)
    * α bounds the *expected per-context* entropy E_c H(π(o|c)) (rather than the entropy of
      the marginal Σ_c π(o|c) p(c)); it must not exceed log N (checked).
    * Q(c,o) is a responsibility-weighted regression of the returns on [1, φ(c)] (φ as in
      HiREPS's V(c)), ridge ``q_ridge`` on the non-constant features.
    * The experts' MORE step keeps MORE's entropy-loss bound H_min = γ(H_old − H₀) + H₀
      (γ = ``entropy_gamma``, H₀ = −75; None switches it off) and no entropy bonus.
    * Sample reuse, sample counts, initial mixture, ``min_ess`` and ``cov_reg`` as in HiREPS
      (see :mod:`vslbook.erl.hireps`): experts whose responsibility weights have an effective
      sample size below ``min_ess`` are not updated in that iteration.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy.optimize import minimize
from scipy.special import logsumexp

from vslbook.erl.mixture_baseline import (
    MixtureAlgorithm,
    context_features,
    effective_sample_size,
    fit_gating,
    gating_log_probs,
    log_responsibilities,
    run_iterations,
)
from vslbook.erl.more import cmore_update, entropy_loss_bound, fit_quadratic, joint_whitening

__all__ = [
    "LADIPS_PRESETS",
    "GatingResult",
    "LaDiPS",
    "LaDiPSConfig",
    "fit_option_values",
    "gating_update",
    "train",
]

_LOW, _HIGH = 1e-8, 1e8


@dataclass(frozen=True)
class LaDiPSConfig:
    """LaDiPS hyper-parameters. Table A.3 (ε, ε_gating, α, N); the rest are inferred.

    ===============  =====  ==========  ========  ===
    Task              ε      ε_gating    α         N
    ===============  =====  ==========  ========  ===
    Beer pong         0.1    0.05        log 30    70
    Table tennis      0.01   0.02        log 30    50
    ===============  =====  ==========  ========  ===

    Attributes:
        eps: KL bound of every expert's contextual MORE step.
        eps_gating: KL bound of the gating step.
        alpha: lower bound on E_c H(π(o|c)) (nats); at most log N.
        n_experts, samples_per_iteration, reuse_iterations, iterations, init_mean,
        init_cov, init_mean_std, cov_reg, min_ess: as in
            :class:`vslbook.erl.hireps.HiREPSConfig`.
        entropy_gamma: MORE's entropy-loss factor γ for the experts, or None.
        q_ridge: ridge of the Q(c,o) regression.
    """

    eps: float = 0.1
    eps_gating: float = 0.05
    alpha: float = math.log(30)
    n_experts: int = 70
    samples_per_iteration: int = 700
    reuse_iterations: int = 3
    iterations: int = 1800
    init_mean: tuple[float, ...] = ()
    init_cov: tuple[float, ...] | float = 1.0
    init_mean_std: float = 0.2
    entropy_gamma: float | None = 0.99
    q_ridge: float = 1e-3
    cov_reg: float = 1e-6
    min_ess: float = 3.0

    def __post_init__(self) -> None:
        for name in ("eps", "eps_gating"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive number, got {v!r}")
        for name in ("n_experts", "samples_per_iteration", "reuse_iterations", "iterations"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {v!r}")
        if not (np.isfinite(self.alpha) and 0 <= self.alpha <= math.log(self.n_experts) + 1e-12):
            raise ValueError(
                f"alpha must lie in [0, log n_experts = {math.log(self.n_experts):.4g}], "
                f"got {self.alpha!r}"
            )
        if self.entropy_gamma is not None and not (0 < self.entropy_gamma <= 1):
            raise ValueError(f"entropy_gamma must be in (0, 1] or None, got {self.entropy_gamma!r}")
        cov = np.atleast_1d(np.asarray(self.init_cov, dtype=np.float64))
        if not np.all(np.isfinite(cov) & (cov > 0)):
            raise ValueError(f"init_cov must be positive, got {self.init_cov!r}")
        for name in ("init_mean_std", "q_ridge", "cov_reg", "min_ess"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a number >= 0, got {v!r}")

    @classmethod
    def for_task(cls, name: str, **overrides: Any) -> LaDiPSConfig:
        """The preset of task ``name`` (:data:`LADIPS_PRESETS`) with ``overrides``."""
        if name not in LADIPS_PRESETS:
            raise ValueError(f"no LaDiPS preset for task {name!r}; have {sorted(LADIPS_PRESETS)}")
        return replace(LADIPS_PRESETS[name], **overrides)


#: Per-task presets (Table A.3 has no planar-reacher row).
LADIPS_PRESETS: dict[str, LaDiPSConfig] = {
    "beer-pong": LaDiPSConfig(
        eps=0.1, eps_gating=0.05, alpha=math.log(30), n_experts=70,
        samples_per_iteration=700, iterations=1800,
        init_mean=(0.7,) + (0.0,) * 14, init_cov=(0.25,) + (0.25, 5.0) * 7, init_mean_std=0.2,
    ),
    "table-tennis-4d": LaDiPSConfig(
        eps=0.01, eps_gating=0.02, alpha=math.log(30), n_experts=50,
        samples_per_iteration=500, iterations=18400,
        init_mean=(1.03, 0.325) + (0.0,) * 21, init_cov=(0.02, 0.01) + (1.0,) * 21,
        init_mean_std=0.1,
    ),
    # Chapter 3 table tennis, θ = [l, 21 ProMP weights]: the initial mixture of HiREPS's
    # "table-tennis-ch3" preset (l from 1 s with variance 0.1, weights 0 with variance 1)
    "table-tennis-ch3": LaDiPSConfig(
        eps=0.01, eps_gating=0.02, alpha=math.log(30), n_experts=50,
        samples_per_iteration=500, iterations=28007,
        init_mean=(1.0,) + (0.0,) * 21, init_cov=(0.1,) + (1.0,) * 21, init_mean_std=0.1,
    ),
}  # fmt: skip


# --------------------------------------------------------------------------------------
# the gating layer
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class GatingResult:
    """The new per-context gating of :func:`gating_update`.

    Attributes:
        log_p: (n, N) new log π(o|c_i); eta, omega: multipliers (Q's units);
        kl: mean KL(new ‖ old) over the contexts; entropy: mean H(new);
        success: KL ≤ ε(1 + 1e-3) and (if bounded) entropy ≥ h_min − 1e-6.
    """

    log_p: np.ndarray
    eta: float
    omega: float
    kl: float
    entropy: float
    success: bool


def gating_update(
    log_q: np.ndarray, q_values: np.ndarray, *, eps: float, h_min: float | None
) -> GatingResult:
    """REPS step of the categorical gating on n contexts (module docstring, layer 2).

    Args:
        log_q: (n, N) log π_old(o|c_i), rows normalised.
        q_values: (n, N) Q(c_i, o).
        eps: bound on the mean KL, > 0.
        h_min: lower bound on the mean entropy, or None.

    Returns:
        :class:`GatingResult`; on a failed solve the old gating is returned (success False).
    """
    lq = np.asarray(log_q, dtype=np.float64)
    qv = np.asarray(q_values, dtype=np.float64)
    if lq.ndim != 2 or qv.shape != lq.shape:
        raise ValueError(f"log_q and q_values must have the same (n, N) shape, got "
                         f"{lq.shape} and {qv.shape}")  # fmt: skip
    if not (np.all(np.isfinite(qv)) and np.all(lq < np.inf)):
        raise ValueError("q_values must be finite and log_q must not hold +inf")
    if not (np.isfinite(eps) and eps > 0):
        raise ValueError(f"eps must be a positive number, got {eps!r}")
    if h_min is not None and h_min > math.log(lq.shape[1]) + 1e-12:
        raise ValueError(f"h_min = {h_min} exceeds log N = {math.log(lq.shape[1]):.4g}")
    lq = np.maximum(lq, -700.0)
    lq = lq - logsumexp(lq, axis=1, keepdims=True)
    scale = float(np.std(qv)) or 1.0
    qs = (qv - qv.mean()) / scale
    bounded = h_min is not None

    def new_log_p(eta: float, omega: float) -> tuple[np.ndarray, np.ndarray]:
        s = (eta * lq + qs) / (eta + omega)
        z = logsumexp(s, axis=1, keepdims=True)
        return s - z, z[:, 0]

    def stats(log_p: np.ndarray) -> tuple[float, float]:
        p = np.exp(log_p)
        return float(np.mean(np.sum(p * (log_p - lq), 1))), float(np.mean(-np.sum(p * log_p, 1)))

    def dual(x: np.ndarray) -> tuple[float, np.ndarray]:
        eta, omega = x[0], (x[1] if bounded else 0.0)
        log_p, z = new_log_p(eta, omega)
        kl, ent = stats(log_p)
        g = eta * eps + (eta + omega) * float(np.mean(z))
        grad = [eps - kl]
        if bounded:
            g -= omega * h_min
            grad.append(ent - h_min)
        return g, np.asarray(grad)

    x0 = np.array([1.0, 1.0] if bounded else [1.0])
    bnds = [(_LOW, _HIGH)] + ([(0.0, _HIGH)] if bounded else [])
    res = minimize(dual, x0, jac=True, method="L-BFGS-B", bounds=bnds,
                   options={"ftol": 1e-14, "gtol": 1e-10, "maxiter": 2000})  # fmt: skip
    eta, omega = float(res.x[0]), (float(res.x[1]) if bounded else 0.0)
    log_p, _ = new_log_p(eta, omega)
    kl, ent = stats(log_p)
    ok = bool(kl <= eps * (1 + 1e-3) and (not bounded or ent >= h_min - 1e-6))
    if not ok:
        log_p = lq.copy()
        kl, ent = stats(log_p)
    return GatingResult(log_p, eta * scale, omega * scale, kl, ent, ok)


def fit_option_values(
    features: np.ndarray, returns: np.ndarray, weights: np.ndarray, *, ridge: float = 1e-3
) -> np.ndarray:
    """Q(c,o) coefficients: weighted ridge of the returns on [1, φ(c)] per option.

    Args:
        features: (n, m) φ(c_i); returns: (n,); weights: (n, N) non-negative.

    Returns:
        (N, m + 1) coefficients β_o with Q(c, o) = [1, φ(c)] β_o; the ridge (scaled by each
        option's total weight) is not applied to the constant.
    """
    x = np.concatenate([np.ones((len(features), 1)), features], axis=1)
    w = np.asarray(weights, dtype=np.float64)
    mass = w.sum(axis=0)
    reg = ridge * np.diag(np.r_[0.0, np.ones(features.shape[1])])
    xtwx = np.einsum("no,ni,nj->oij", w, x, x) + mass[:, None, None] * reg
    xtwx[~(mass > 0)] = np.eye(x.shape[1])
    xtwy = np.einsum("no,ni,n->oi", w, x, returns)
    return np.linalg.solve(xtwx, xtwy[..., None])[..., 0]


# --------------------------------------------------------------------------------------
# the algorithm
# --------------------------------------------------------------------------------------
class LaDiPS(MixtureAlgorithm):
    """LaDiPS on an episodic task (module docstring). ``workers`` goes to ``task.evaluate``."""

    config: LaDiPSConfig

    def __init__(self, task: Any, config: LaDiPSConfig, seed: int, workers: int | None = 0) -> None:
        if not isinstance(config, LaDiPSConfig):
            raise TypeError(f"config must be a LaDiPSConfig, got {type(config).__name__}")
        super().__init__(task, config, seed, workers)

    def iteration(self) -> dict[str, float]:
        """Sample; contextual MORE per expert; REPS step of the gating; ML projection."""
        cfg, mix = self.config, self.mix
        _, _, r_new, n_exec = self._collect()  # 1. episodes from the current mixture
        c, th, r = self._buffer_arrays()
        n, n_exp = len(c), cfg.n_experts
        resp = np.exp(log_responsibilities(c, th, mix))  # (n, N) importance weights
        ok = effective_sample_size(resp) >= max(cfg.min_ess, 1e-12)

        # 2. experts: contextual MORE on responsibility-weighted samples (Eq. 3.5 form)
        w = (resp / np.maximum(resp.sum(0), 1e-300)).T  # (N, n), rows sum to 1
        ctx = np.broadcast_to(c, (n_exp, n, c.shape[1]))
        x = np.broadcast_to(np.concatenate([c, th], axis=1), (n_exp, n, c.shape[1] + th.shape[1]))
        y = np.broadcast_to(r, (n_exp, n))
        mean, chol = joint_whitening(ctx, mix.K, mix.k, mix.cov)
        quad = fit_quadratic(x, y, mean=mean, chol=chol, weights=w)
        h_old = 0.5 * np.linalg.slogdet(2 * np.pi * np.e * mix.cov)[1]
        h_min = (
            None
            if cfg.entropy_gamma is None
            else entropy_loss_bound(h_old, gamma=cfg.entropy_gamma)
        )
        res = cmore_update(mix.K, mix.k, mix.cov, ctx, quad, eps=cfg.eps, entropy_coef=0.0,
                           h_min=h_min, weights=w)  # fmt: skip
        upd = ok & np.asarray(res.success, dtype=bool)
        new = mix.copy()
        new.K[upd], new.k[upd] = res.K[upd], res.k[upd]
        new.cov[upd] = res.cov[upd] + cfg.cov_reg * np.eye(th.shape[1])

        # 3. gating: Q(c,o), REPS step per context with E_c H ≥ α, then weighted ML
        phi = context_features(c, self.task.context_low, self.task.context_high)
        beta = fit_option_values(phi, r, resp, ridge=cfg.q_ridge)
        q_values = np.concatenate([np.ones((n, 1)), phi], axis=1) @ beta.T
        log_q = gating_log_probs(c, mix)
        gate = gating_update(log_q, q_values, eps=cfg.eps_gating, h_min=cfg.alpha)
        if gate.success:
            log_prior, mu, s = fit_gating(c, np.exp(gate.log_p) / n, cov_reg=cfg.cov_reg)
            g_ok = effective_sample_size(np.exp(gate.log_p)) >= max(cfg.min_ess, 1e-12)
            new.log_prior = log_prior
            new.ctx_mean[g_ok], new.ctx_cov[g_ok] = mu[g_ok], s[g_ok]
        self.mix = new
        self.iterations_done += 1
        prior = np.exp(new.log_prior)
        return {
            "iteration": float(self.iterations_done),
            "samples": float(n_exec),
            "total_samples": float(self.total_samples),
            "mean_return": float(np.mean(r_new)),
            "kl": float(np.mean(np.asarray(res.kl)[upd])) if upd.any() else 0.0,
            "experts_updated": float(upd.sum()),
            "kl_gating": gate.kl,
            "entropy_gating": gate.entropy,
            "gating_success": float(gate.success),
            "active_experts": float(np.sum(prior > 1e-3)),
        }


def train(
    task: Any,
    config: LaDiPSConfig,
    seed: int,
    iterations: int | None = None,
    callback: Callable[[int, dict[str, float]], None] | None = None,
    workers: int | None = 0,
) -> LaDiPS:
    """Run ``iterations`` (default ``config.iterations``) LaDiPS iterations; ``callback(i,
    metrics)`` after each."""
    algo = LaDiPS(task, config, seed, workers)
    n = config.iterations if iterations is None else iterations
    run_iterations(algo, n, callback)
    return algo

"""REPS for a categorical distribution and the Nadaraya–Watson value V(c) (Eqs. 3.7, A.5–A.7).

SVSL's last stage (Algorithm 1, line 17) updates the expert weights π(o) by the maximum-entropy
objective A.7 under a trust region,

    max_p  Σ_o p_o r_o + β_w H(p)   s.t.  KL(p ‖ q) ≤ ε,   H(p) ≥ H_min,   Σ_o p_o = 1,

with q = π_old(o). The Lagrangian with multipliers η (KL) and ω_d (entropy) is stationary at

    log p_o = (η log q_o + r_o) / (η + ω) − log Σ_o' exp((η log q_o' + r_o') / (η + ω)),
    ω = ω_d + β_w,

and inserting it gives the convex dual

    g(η, ω_d) = η ε − ω_d H_min + (η + ω) log Σ_o exp((η log q_o + r_o) / (η + ω)),

with ∂g/∂η = ε − KL(p ‖ q) and ∂g/∂ω_d = H(p) − H_min. Without the entropy constraint and
with ε → ∞ (η → 0) the update is the softmax softmax(r / β_w) — the "expected softmax" of
the maximum-entropy objective; with β_w → 0 it is REPS (Peters et al. 2010).

V(c) of Eq. A.6 is the mean task return in context c over the experts that cover it; SVSL
estimates it with a Nadaraya–Watson kernel regression on importance-weighted samples and
subtracts it from the weights' rewards (A.7) so that an expert alone in a hard context region
is not starved of weight.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize
from scipy.special import logsumexp

__all__ = ["CategoricalResult", "nadaraya_watson", "reps_categorical_update"]

#: Multipliers are searched in [LOW, HIGH] (as the authors' NLopt set-up).
_LOW, _HIGH = 1e-8, 1e8
#: Probabilities are kept at or above this value (the authors' clip).
_P_MIN = 1e-20


@dataclass(frozen=True)
class CategoricalResult:
    """The new categorical of :func:`reps_categorical_update` and the dual's solution."""

    log_p: np.ndarray  #: (K,) new log-probabilities (normalised)
    eta: float  #: KL multiplier η
    omega: float  #: entropy multiplier ω_d (0 without the entropy constraint)
    kl: float  #: KL(new ‖ old)
    entropy: float  #: H(new)
    success: bool  #: the constraints hold (KL ≤ ε(1 + 1e-3), H ≥ H_min − 1e-6)


def _entropy(log_p: np.ndarray) -> float:
    return float(-np.sum(np.exp(log_p) * log_p))


def reps_categorical_update(
    log_p_old: np.ndarray,
    rewards: np.ndarray,
    *,
    eps: float,
    entropy_coef: float,
    h_min: float | None = None,
) -> CategoricalResult:
    """One trust-region update of a categorical distribution (Eq. 3.7 / A.7; module doc).

    Args:
        log_p_old: (K,) log-probabilities of q = π_old(o).
        rewards: (K,) the reward r_o of each category.
        eps: the KL bound ε > 0.
        entropy_coef: β_w ≥ 0, the entropy bonus.
        h_min: lower bound on the new entropy, or None (no entropy constraint).

    Returns:
        :class:`CategoricalResult`; on a failed dual solve the old distribution is kept
        (``success`` False).
    """
    log_q = np.asarray(log_p_old, dtype=np.float64)
    r = np.asarray(rewards, dtype=np.float64)
    if log_q.ndim != 1 or r.shape != log_q.shape:
        raise ValueError(
            f"log_p_old and rewards must both have shape (K,), got {log_q.shape} and {r.shape}"
        )
    if not (np.all(np.isfinite(r)) and np.all(log_q < np.inf)):
        raise ValueError("rewards must be finite and log_p_old must not contain +inf")
    if not abs(logsumexp(log_q)) < 1e-6:
        raise ValueError(f"log_p_old must be normalised, its logsumexp is {logsumexp(log_q):g}")
    if not (np.isfinite(eps) and eps > 0):
        raise ValueError(f"eps must be a positive number, got {eps!r}")
    if not (np.isfinite(entropy_coef) and entropy_coef >= 0):
        raise ValueError(f"entropy_coef must be >= 0, got {entropy_coef!r}")
    log_q = np.maximum(log_q, np.log(_P_MIN))
    log_q = log_q - logsumexp(log_q)
    constrained = h_min is not None

    def new_log_p(eta: float, omega_d: float) -> tuple[np.ndarray, float]:
        s = (eta * log_q + r) / (eta + omega_d + entropy_coef)
        z = logsumexp(s)
        return s - z, z

    def dual(x: np.ndarray) -> tuple[float, np.ndarray]:
        eta, omega_d = x[0], (x[1] if constrained else 0.0)
        log_p, z = new_log_p(eta, omega_d)
        p = np.exp(log_p)
        kl = float(np.sum(p * (log_p - log_q)))
        g = eta * eps + (eta + omega_d + entropy_coef) * z
        grad = [eps - kl]
        if constrained:
            g -= omega_d * h_min
            grad.append(_entropy(log_p) - h_min)
        return g, np.asarray(grad)

    x0 = np.array([1.0, 1.0] if constrained else [1.0])
    res = minimize(
        dual, x0, jac=True, method="L-BFGS-B", bounds=[(_LOW, _HIGH)] * len(x0),
        options={"ftol": 1e-12, "gtol": 1e-10, "maxiter": 1000},
    )  # fmt: skip
    eta = float(res.x[0])
    omega = float(res.x[1]) if constrained else 0.0
    log_p, _ = new_log_p(eta, omega)
    p = np.exp(log_p)
    kl = float(np.sum(p * (log_p - log_q)))
    ent = _entropy(log_p)
    ok = bool(kl <= eps * (1 + 1e-3) and (not constrained or ent >= h_min - 1e-6))
    if not ok:
        log_p, kl, ent = log_q.copy(), 0.0, _entropy(log_q)
    return CategoricalResult(log_p, eta, omega, kl, ent, ok)


def nadaraya_watson(
    train_x: np.ndarray,
    train_y: np.ndarray,
    query: np.ndarray,
    *,
    weights: np.ndarray | None = None,
    scale: float = 0.5,
    chunk: int = 2048,
) -> np.ndarray:
    """Kernel regression V(c) = Σ_i w_i k(c_i, c) y_i / Σ_i w_i k(c_i, c) (Eq. A.6).

    k(c_i, c) = exp(−‖c − c_i‖² / scale) (the authors' ``rbf_scale`` = 0.5). Computed in
    log space, so a query far from every training point gets the value of the nearest ones
    instead of 0/0.

    Args:
        train_x: (n, d) training contexts; train_y: (n,) their returns.
        query: (m, d) contexts to predict at.
        weights: (n,) non-negative importance weights (default uniform).
        scale: kernel scale > 0.
        chunk: queries per block (memory).
    """
    x = np.asarray(train_x, dtype=np.float64)
    y = np.asarray(train_y, dtype=np.float64)
    q = np.asarray(query, dtype=np.float64)
    if x.ndim != 2 or y.shape != (len(x),) or q.ndim != 2 or q.shape[1] != x.shape[1]:
        raise ValueError(
            f"need train_x (n, d), train_y (n,), query (m, d); got {x.shape}, {y.shape}, {q.shape}"
        )
    if len(x) == 0:
        raise ValueError("nadaraya_watson needs at least one training point")
    if not (np.isfinite(scale) and scale > 0):
        raise ValueError(f"scale must be a positive number, got {scale!r}")
    w = np.ones(len(x)) if weights is None else np.asarray(weights, dtype=np.float64)
    if w.shape != (len(x),) or np.any(w < 0) or not np.any(w > 0):
        raise ValueError("weights must be (n,), non-negative and not all zero")
    log_w = np.log(np.maximum(w, 1e-300))
    x2 = np.einsum("ij,ij->i", x, x)
    out = np.empty(len(q))
    for s in range(0, len(q), chunk):
        qb = q[s : s + chunk]
        # ‖q − x‖² = ‖q‖² + ‖x‖² − 2 q·x: one matrix product per block
        d2 = np.maximum(np.einsum("ij,ij->i", qb, qb)[:, None] + x2[None] - 2 * qb @ x.T, 0.0)
        logits = log_w[None] - d2 / scale
        logits -= logits.max(axis=1, keepdims=True)
        k = np.exp(logits)
        out[s : s + chunk] = (k @ y) / k.sum(axis=1)
    return out

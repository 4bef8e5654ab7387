"""The batched solver of MORE's convex dual in (η, ω_d) (Eqs. 3.5, 3.6; ``vslbook.erl.more``).

Notation as in :mod:`vslbook.erl.more` (the dual g(η, ω_d), F, Q, A, ε, H_min). The
duals of all E experts are solved in one vectorised loop, with no loop over experts. Each
expert's dual is a smooth convex function of two variables with bounds η ∈ [1e-8, 1e8],
ω_d ∈ [0, 1e8], and its Hessian has a closed form: with S = F⁻¹, δ = μ_old − μ,
M = QS − I and λ = η + ω,

    ∂²g/∂η² = (δᵀQSQδ + ½ tr M²)/λ,   ∂²g/∂η∂ω = −tr M/(2λ),   ∂²g/∂ω² = d/(2λ)

(the dual is the perspective of a log-partition function, whose Hessian is a covariance of
quadratic forms under the new Gaussian). We therefore run a projected Newton method
(Bertsekas, 1982) with an Armijo line search, independently per expert but in lock-step as
array operations. Compared with L-BFGS-B on the sum of the E duals this (i) converges in a
few iterations to the tight tolerance that the constraint check needs, (ii) lets every
expert backtrack on its own, so an η too small for a positive-definite ηQ + A (treated as
g = +∞) only shortens that expert's step and never poisons the others' line searches, and
(iii) stops each expert on its own KKT test. The dual value is evaluated in the
cancellation-free form g = η(ε − KL) + ω_d(H − H_min) + (β/σ_R) H + E_π[R̃], which equals
the expression above at the Lagrangian solution. The start is η = max(40, 2η_min + 1)
(η_min: smallest η with ηQ + A ⪰ 0), ω_d = 0.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

__all__ = ["ETA_BOUNDS", "OMEGA_MAX", "DualEval", "chol_inverse", "cholesky_ok", "eta_min",
           "newton_dual"]  # fmt: skip

ETA_BOUNDS = (1e-8, 1e8)  #: bounds of η
OMEGA_MAX = 1e8  #: upper bound of ω_d (lower bound 0)


def cholesky_ok(P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Batched Cholesky of P; slots that are not (numerically) positive definite or not
    finite get the identity and ok False, so one bad expert never stops the batch."""
    ok = np.all(np.isfinite(P), axis=(-2, -1))
    P = np.where(ok[:, None, None], P, np.eye(P.shape[-1]))
    for _ in range(4):
        try:
            chol = np.linalg.cholesky(P)
            diag = np.diagonal(chol, axis1=1, axis2=2)
            good = np.all(diag > 1e-150, axis=1)
            if np.all(good):
                return chol, ok
            ok &= good
        except np.linalg.LinAlgError:
            eig = np.linalg.eigvalsh(P)
            ok &= eig[:, 0] > 1e-14 * np.abs(eig).max(axis=1)
        P = np.where(ok[:, None, None], P, np.eye(P.shape[-1]))
    raise FloatingPointError("batched Cholesky failed repeatedly")  # pragma: no cover


def chol_inverse(chol: np.ndarray) -> np.ndarray:
    l_inv = np.linalg.inv(chol)
    return np.swapaxes(l_inv, 1, 2) @ l_inv


def eta_min(cov_old: np.ndarray, A: np.ndarray) -> np.ndarray:
    """Smallest η ≥ 0 with ηΣ_old⁻¹ + A ⪰ 0: −λ_min(LᵀA L) for Σ_old = L Lᵀ."""
    chol = np.linalg.cholesky(cov_old)
    return np.maximum(0.0, -np.linalg.eigvalsh(np.swapaxes(chol, 1, 2) @ A @ chol)[:, 0])


@dataclass
class DualEval:
    """Dual value, gradient parts and Hessian at (η, ω_d) for a subset of experts."""

    ok: np.ndarray
    g: np.ndarray
    kl: np.ndarray
    ent: np.ndarray
    hee: np.ndarray
    heo: np.ndarray
    hoo: np.ndarray
    params: tuple[np.ndarray, ...]

    def put(self, idx: np.ndarray, other: DualEval, sel: np.ndarray) -> None:
        for name in ("ok", "g", "kl", "ent", "hee", "heo", "hoo"):
            getattr(self, name)[idx] = getattr(other, name)[sel]
        for mine, theirs in zip(self.params, other.params, strict=True):
            mine[idx] = theirs[sel]


def newton_dual(
    evaluate: Callable[[np.ndarray, np.ndarray, np.ndarray], DualEval],
    eta0: np.ndarray,
    eps: np.ndarray,
    h_min: np.ndarray,
    max_iter: int = 200,
) -> tuple[np.ndarray, np.ndarray, DualEval]:
    """Projected Newton on the E separable duals g(η, ω_d) at once (see module docstring).

    h_min entries of −inf mark experts without entropy constraint (ω_d fixed at 0).
    """
    n_exp = len(eta0)
    con = np.isfinite(h_min)
    hm = np.where(con, h_min, 0.0)
    eta = np.clip(eta0, *ETA_BOUNDS)
    om = np.zeros(n_exp)
    every = np.arange(n_exp)
    cur = evaluate(every, eta, om)
    for _ in range(8):  # make the start feasible (ηQ + A positive definite)
        if np.all(cur.ok):
            break
        bad = np.flatnonzero(~cur.ok)
        eta[bad] = np.minimum(eta[bad] * 10.0, ETA_BOUNDS[1])
        cur.put(bad, evaluate(bad, eta[bad], om[bad]), np.arange(len(bad)))
    stalled = ~cur.ok
    for _ in range(max_iter):
        ge = eps - cur.kl
        go = np.where(con, cur.ent - hm, 0.0)
        lo_e = (eta <= ETA_BOUNDS[0] * (1 + 1e-12)) & (ge > 0)
        lo_o = ~con | ((om <= 0.0) & (go > 0))
        conv_e = lo_e | (np.abs(ge) <= 1e-9 * eps)
        conv_o = lo_o | (np.abs(go) <= 1e-9) | ((om >= OMEGA_MAX) & (go < 0))
        active = ~(stalled | (conv_e & conv_o))
        if not np.any(active):
            break
        # Newton direction on the free variables (active-set handling of the bounds)
        hee = cur.hee * (1 + 1e-12) + 1e-300
        hoo = cur.hoo * (1 + 1e-12) + 1e-300
        det = hee * hoo - cur.heo**2
        both = ~lo_e & ~lo_o & (det > 1e-12 * hee * hoo)
        de = np.where(lo_e, 0.0, -ge / hee)
        do = np.where(lo_o, 0.0, -go / hoo)
        de = np.where(both, -(hoo * ge - cur.heo * go) / np.where(both, det, 1.0), de)
        do = np.where(both, -(hee * go - cur.heo * ge) / np.where(both, det, 1.0), do)
        # Armijo backtracking per expert along the projected path
        alpha = np.ones(n_exp)
        pending = active.copy()
        for _ in range(60):
            idx = np.flatnonzero(pending)
            if len(idx) == 0:
                break
            eta_t = np.clip(eta[idx] + alpha[idx] * de[idx], *ETA_BOUNDS)
            om_t = np.clip(om[idx] + alpha[idx] * do[idx], 0.0, OMEGA_MAX)
            trial = evaluate(idx, eta_t, om_t)
            step = ge[idx] * (eta_t - eta[idx]) + go[idx] * (om_t - om[idx])
            g_old = cur.g[idx]
            armijo = trial.g <= g_old + 1e-4 * step
            # at round-off level the dual value cannot rank the points: use the gradient
            flat = np.abs(trial.g - g_old) <= 1e-12 * (1.0 + np.abs(g_old))
            pg_old = np.abs(ge[idx]) / eps[idx] + np.abs(go[idx])
            go_t = np.where(con[idx], trial.ent - hm[idx], 0.0)
            pg_new = np.abs(eps[idx] - trial.kl) / eps[idx] + np.abs(go_t)
            acc = trial.ok & np.isfinite(trial.g) & (armijo | (flat & (pg_new < pg_old)))
            moved = (eta_t != eta[idx]) | (om_t != om[idx])
            acc &= moved
            sel = np.flatnonzero(acc)
            eta[idx[sel]], om[idx[sel]] = eta_t[sel], om_t[sel]
            cur.put(idx[sel], trial, sel)
            pending[idx[sel]] = False
            alpha[idx[~acc]] *= 0.5
            pending[idx[~moved]] = False
            stalled[idx[~moved]] = True
        stalled |= pending
    return eta, om, cur

"""MORE and contextual MORE, batched over experts (Section 3.3, Eq. 3.5 and 3.6, App. A.2).

SVSL updates every mixture component with a trust-region step on a quadratic surrogate
R̃ of its augmented reward (``vslbook.erl.surrogate``, units of σ_R):

* ``more_update``: the per-expert context distribution π(c|o) = N(μ, Σ) (Eq. 3.6), MORE
  (Abdolmaleki et al., 2015) in the variant of Arenz et al. (2020),

      max_π E_π[R̃] + β H(π)   s.t.  KL(π‖π_old) ≤ ε,  H(π) ≥ H_min;

* ``cmore_update``: the linear-Gaussian expert π(θ|c,o) = N(K c + k, Σ) (Eq. 3.5),
  contextual MORE (Tangkaratt et al., 2017) in the variant of Becker et al. (2020), with the
  KL averaged over the given contexts.

The Lagrangian solution is π ∝ π_old^{η/(η+ω)} exp(R̃/(η+ω)) with ω = ω_d + β/σ_R, i.e.
precision F = (ηQ + A)/(η+ω) and linear term f = (ηq + a)/(η+ω) (Q = Σ_old⁻¹, q = Qμ_old),
and the multipliers (η, ω_d) minimise the convex dual

    g(η, ω_d) = η ε − ω_d H_min + (η+ω) log ∫ π_old^{η/(η+ω)} exp(R̃/(η+ω)),
    ∂g/∂η = ε − KL(π‖π_old),   ∂g/∂ω_d = H(π) − H_min.

The dual is solved for all experts at once by :func:`vslbook.erl.more_dual.newton_dual`
(a projected Newton method with closed-form Hessians, explained in that module's docstring).

Success per expert: KL ≤ ε(1 + 1e-3) and, when constrained, H ≥ H_min − 1e-6. An expert
whose dual fails keeps its old distribution (success False, KL 0); nothing raises.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from vslbook.erl.more_dual import (
    DualEval,
    chol_inverse,
    cholesky_ok,
    eta_min,
    newton_dual,
)
from vslbook.erl.surrogate import (
    Quadratic,
    fit_quadratic,
    joint_whitening,
    normalised_weights,
    whitening_gaussian,
)

__all__ = [
    "CMoreResult",
    "MoreResult",
    "Quadratic",
    "cmore_update",
    "entropy_loss_bound",
    "fit_quadratic",
    "gaussian_entropy",
    "joint_whitening",
    "more_update",
    "whitening_gaussian",
]

LOG_2PI = float(np.log(2.0 * np.pi))


@dataclass(frozen=True)
class MoreResult:
    """New Gaussians N(mean, cov) of ``more_update``; eta, omega are the dual variables
    (omega = ω_d, without the entropy temperature); kl = KL(new‖old), entropy = H(new)."""

    mean: np.ndarray  # (E, d)
    cov: np.ndarray  # (E, d, d)
    eta: np.ndarray  # (E,)
    omega: np.ndarray  # (E,)
    kl: np.ndarray  # (E,)
    entropy: np.ndarray  # (E,)
    success: np.ndarray  # (E,) bool


@dataclass(frozen=True)
class CMoreResult:
    """New experts N(K c + k, cov) of ``cmore_update``; kl is E_c KL over the given contexts."""

    K: np.ndarray  # (E, dθ, dc)
    k: np.ndarray  # (E, dθ)
    cov: np.ndarray  # (E, dθ, dθ)
    eta: np.ndarray  # (E,)
    omega: np.ndarray  # (E,)
    kl: np.ndarray  # (E,)
    entropy: np.ndarray  # (E,)
    success: np.ndarray  # (E,) bool


def entropy_loss_bound(entropy: np.ndarray, gamma: float = 0.99, h0: float = -75.0) -> np.ndarray:
    """H_min = γ (H_old − H₀) + H₀: the entropy may shrink by a fraction 1 − γ of its
    distance to H₀ per update (the H_min rule of the MORE variant used for Eq. 3.5/3.6)."""
    return gamma * (np.asarray(entropy, dtype=np.float64) - h0) + h0


def gaussian_entropy(cov: np.ndarray) -> np.ndarray:
    """H[N(·, Σ)] = ½ (d log 2πe + log|Σ|), batched."""
    d = cov.shape[-1]
    return 0.5 * (d * (LOG_2PI + 1.0) + np.linalg.slogdet(cov)[1])


def _check_eps_coef(eps, entropy_coef, n_exp: int) -> tuple[np.ndarray, np.ndarray]:
    eps_arr = np.asarray(eps, dtype=np.float64)
    if eps_arr.ndim == 0:
        eps_arr = np.full(n_exp, float(eps_arr))
    if eps_arr.shape != (n_exp,) or not np.all(np.isfinite(eps_arr) & (eps_arr > 0)):
        raise ValueError(f"eps must be a positive scalar or shape ({n_exp},), got {eps}")
    coef = np.asarray(entropy_coef, dtype=np.float64)
    if coef.shape not in ((), (n_exp,)) or not np.all(np.isfinite(coef) & (coef >= 0)):
        raise ValueError(
            f"entropy_coef must be >= 0, a scalar or shape ({n_exp},), got {entropy_coef}"
        )
    return eps_arr, np.broadcast_to(coef, (n_exp,)).copy()


def _check_h_min(h_min, n_exp: int) -> np.ndarray:
    if h_min is None:
        return np.full(n_exp, -np.inf)
    h = np.asarray(h_min, dtype=np.float64)
    if h.shape != (n_exp,) or np.any(np.isnan(h)) or np.any(h == np.inf):
        raise ValueError(
            f"h_min must be None or shape ({n_exp},) without nan/+inf (−inf: none), got {h_min}"
        )
    return h


def _check_cov(cov: np.ndarray, name: str) -> np.ndarray:
    if not np.all(np.isfinite(cov)) or not np.allclose(cov, np.swapaxes(cov, 1, 2)):
        raise ValueError(f"{name} must be finite and symmetric")
    eig_min = np.linalg.eigvalsh(cov)[:, 0]
    if np.any(eig_min <= 0):
        raise ValueError(
            f"{name} must be positive definite; smallest eigenvalues per expert: {eig_min}"
        )
    return 0.5 * (cov + np.swapaxes(cov, 1, 2))


def _check_quad(quad: Quadratic, n_exp: int, d: int) -> None:
    if not isinstance(quad, Quadratic):
        raise ValueError(f"quad must be a Quadratic, got {type(quad).__name__}")
    if np.shape(quad.A) != (n_exp, d, d):
        raise ValueError(f"quad.A must have shape {(n_exp, d, d)}, got {np.shape(quad.A)}")


# --------------------------------------------------------------------------- Eq. 3.6


def _more_dual(mean, cov, A, a, beta, eps_arr, hmin) -> Callable[..., DualEval]:
    """Dual of Eq. 3.6 for all experts: evaluate(idx, η, ω_d) → value, gradient, Hessian."""
    d = mean.shape[1]
    Q = np.linalg.inv(cov)
    q = np.einsum("eij,ej->ei", Q, mean)
    logdet_old = np.linalg.slogdet(cov)[1]
    eye = np.eye(d)

    def evaluate(idx: np.ndarray, eta: np.ndarray, om: np.ndarray) -> DualEval:
        lam = eta + om + beta[idx]
        chol, ok = cholesky_ok(eta[:, None, None] * Q[idx] + A[idx])  # λF = ηQ + A
        p_inv = chol_inverse(chol)
        m = np.einsum("eij,ej->ei", p_inv, eta[:, None] * q[idx] + a[idx])
        S = lam[:, None, None] * p_inv
        logdet_s = d * np.log(lam) - 2.0 * np.log(np.diagonal(chol, axis1=1, axis2=2)).sum(1)
        QS = Q[idx] @ S
        delta = mean[idx] - m
        kl = 0.5 * (
            np.trace(QS, axis1=1, axis2=2)
            - d
            + logdet_old[idx]
            - logdet_s
            + np.einsum("ei,eij,ej->e", delta, Q[idx], delta)
        )
        ent = 0.5 * (d * (LOG_2PI + 1.0) + logdet_s)
        e_r = (
            -0.5 * np.einsum("ei,eij,ej->e", m, A[idx], m)
            - 0.5 * np.einsum("eij,eji->e", A[idx], S)
            + np.einsum("ei,ei->e", a[idx], m)
        )
        hm = np.where(np.isfinite(hmin[idx]), hmin[idx], 0.0)
        g = eta * (eps_arr[idx] - kl) + om * (ent - hm) + beta[idx] * ent + e_r
        Qd = np.einsum("eij,ej->ei", Q[idx], delta)
        M = QS - eye
        hee = (np.einsum("ei,eij,ej->e", Qd, S, Qd) + 0.5 * np.einsum("eij,eji->e", M, M)) / lam
        heo = -0.5 * np.trace(M, axis1=1, axis2=2) / lam
        hoo = 0.5 * d / lam
        g = np.where(ok, g, np.inf)
        return DualEval(ok, g, kl, ent, hee, heo, hoo, (m, S))

    return evaluate


def more_update(
    mean: np.ndarray,
    cov: np.ndarray,
    quad: Quadratic,
    *,
    eps: float | np.ndarray,
    entropy_coef: float | np.ndarray,
    h_min: np.ndarray | None = None,
    eig_clip: tuple[float, float] | None = None,
) -> MoreResult:
    """MORE step for E Gaussians N(mean, cov) on the surrogate ``quad`` (Eq. 3.6).

    max E_π[R̃] + (entropy_coef/σ_R) H(π) s.t. KL(π‖π_old) ≤ eps, H(π) ≥ h_min, where R̃ is
    ``quad`` in units of σ_R = quad.scale, so entropy_coef (β of Eq. 3.6) is in reward
    units. eps: scalar or (E,); h_min: None or (E,) (−inf entries: unconstrained);
    eig_clip: None or (lo, hi), bounds on the new covariance's eigenvalues applied after the
    step (the reported kl/entropy are those of the clipped Gaussian).
    """
    mean = np.asarray(mean, dtype=np.float64)
    cov = np.asarray(cov, dtype=np.float64)
    if mean.ndim != 2 or cov.shape != (*mean.shape, mean.shape[1]):
        raise ValueError(f"mean must be (E, d) and cov (E, d, d), got {mean.shape} and {cov.shape}")
    n_exp, d = mean.shape
    cov = _check_cov(cov, "cov")
    _check_quad(quad, n_exp, d)
    eps_arr, coef = _check_eps_coef(eps, entropy_coef, n_exp)
    hmin = _check_h_min(h_min, n_exp)
    if eig_clip is not None and not (0 < eig_clip[0] < eig_clip[1] < np.inf):
        raise ValueError(f"eig_clip must be (lo, hi) with 0 < lo < hi, got {eig_clip}")

    A, a = np.asarray(quad.A, dtype=np.float64), np.asarray(quad.a, dtype=np.float64)
    beta = coef / np.asarray(quad.scale, dtype=np.float64)  # entropy temperature in σ_R units
    evaluate = _more_dual(mean, cov, A, a, beta, eps_arr, hmin)
    eta0 = np.maximum(40.0, 2.0 * eta_min(cov, A) + 1.0)
    eta, om, sol = newton_dual(evaluate, eta0, eps_arr, hmin)
    success = sol.ok & np.isfinite(sol.kl) & (sol.kl <= eps_arr * (1 + 1e-3))
    success &= ~np.isfinite(hmin) | (sol.ent >= hmin - 1e-6)
    new_mean = np.where(success[:, None], sol.params[0], mean)
    new_cov = np.where(success[:, None, None], sol.params[1], cov)
    new_cov = 0.5 * (new_cov + np.swapaxes(new_cov, 1, 2))
    if eig_clip is not None:
        w, V = np.linalg.eigh(new_cov)
        new_cov = (V * np.clip(w, *eig_clip)[:, None, :]) @ np.swapaxes(V, 1, 2)
    kl = _gauss_kl(new_mean, new_cov, mean, np.linalg.inv(cov), np.linalg.slogdet(cov)[1])
    return MoreResult(
        mean=new_mean,
        cov=new_cov,
        eta=eta,
        omega=om,
        kl=kl,
        entropy=gaussian_entropy(new_cov),
        success=success,
    )


def _gauss_kl(mean, cov, mean_old, Q_old, logdet_old) -> np.ndarray:
    """KL(N(mean, cov) ‖ N(mean_old, Q_old⁻¹)), batched."""
    delta = mean - mean_old
    return 0.5 * (
        np.einsum("eij,eji->e", Q_old, cov)
        - cov.shape[-1]
        + logdet_old
        - np.linalg.slogdet(cov)[1]
        + np.einsum("ei,eij,ej->e", delta, Q_old, delta)
    )


# --------------------------------------------------------------------------- Eq. 3.5


def _expect_bilinear(U, u, B, V, v, c1, c2) -> np.ndarray:
    """E_c[(U c + u)ᵀ B (V c + v)] from the context moments c1 = E[c], c2 = E[c cᵀ]."""
    UB = np.swapaxes(U, 1, 2) @ B  # (E, dc, dθ)
    return (
        np.einsum("eij,eji->e", UB @ V, c2)
        + np.einsum("ei,eij,ej->e", u, B @ V, c1)
        + np.einsum("ei,eij,ej->e", c1, UB, v)
        + np.einsum("ei,eij,ej->e", u, B, v)
    )


def _cmore_dual(K, k, cov, contexts, w, A, a, beta, eps_arr, hmin) -> Callable[..., DualEval]:
    """Dual of Eq. 3.5 for all experts: evaluate(idx, η, ω_d) → value, gradient, Hessian."""
    dt, dc = K.shape[1:]
    A_tt, A_tc = A[:, dc:, dc:], A[:, dc:, :dc]
    a_t = a[:, dc:]
    Q = np.linalg.inv(cov)
    QK, Qk = Q @ K, np.einsum("eij,ej->ei", Q, k)
    logdet_old = np.linalg.slogdet(cov)[1]
    eye = np.eye(dt)
    # everything below is quadratic in c: the weighted context moments suffice
    c_mean = np.einsum("en,eni->ei", w, contexts)
    c_second = np.swapaxes(contexts * w[..., None], 1, 2) @ contexts  # E_c[c cᵀ]

    def evaluate(idx: np.ndarray, eta: np.ndarray, om: np.ndarray) -> DualEval:
        lam = eta + om + beta[idx]
        chol, ok = cholesky_ok(eta[:, None, None] * Q[idx] + A_tt[idx])
        p_inv = chol_inverse(chol)
        K_new = p_inv @ (eta[:, None, None] * QK[idx] - A_tc[idx])
        k_new = np.einsum("eij,ej->ei", p_inv, eta[:, None] * Qk[idx] + a_t[idx])
        S = lam[:, None, None] * p_inv
        logdet_s = dt * np.log(lam) - 2.0 * np.log(np.diagonal(chol, axis1=1, axis2=2)).sum(1)
        QS = Q[idx] @ S
        c1, c2 = c_mean[idx], c_second[idx]
        D, e = K[idx] - K_new, k[idx] - k_new  # μ_old(c) − μ(c) = D c + e
        kl = 0.5 * (
            np.trace(QS, axis1=1, axis2=2)
            - dt
            + logdet_old[idx]
            - logdet_s
            + _expect_bilinear(D, e, Q[idx], D, e, c1, c2)
        )
        ent = 0.5 * (dt * (LOG_2PI + 1.0) + logdet_s)
        # E_c E_π[R̃] up to c-only terms: E_c[−½ μᵀA_θθ μ + (a_θ − A_θc c)ᵀμ] − ½ tr(A_θθ S)
        e_r = (
            -0.5 * _expect_bilinear(K_new, k_new, A_tt[idx], K_new, k_new, c1, c2)
            + _expect_bilinear(
                -A_tc[idx], a_t[idx], np.broadcast_to(eye, S.shape), K_new, k_new, c1, c2
            )
            - 0.5 * np.einsum("eij,eji->e", A_tt[idx], S)
        )
        hm = np.where(np.isfinite(hmin[idx]), hmin[idx], 0.0)
        g = eta * (eps_arr[idx] - kl) + om * (ent - hm) + beta[idx] * ent + e_r
        M = QS - eye
        quad_d = _expect_bilinear(D, e, QS @ Q[idx], D, e, c1, c2)
        hee = (quad_d + 0.5 * np.einsum("eij,eji->e", M, M)) / lam
        heo = -0.5 * np.trace(M, axis1=1, axis2=2) / lam
        hoo = 0.5 * dt / lam
        g = np.where(ok, g, np.inf)
        return DualEval(ok, g, kl, ent, hee, heo, hoo, (K_new, k_new, S))

    return evaluate


def cmore_update(
    K: np.ndarray,
    k: np.ndarray,
    cov: np.ndarray,
    contexts: np.ndarray,
    quad: Quadratic,
    *,
    eps: float | np.ndarray,
    entropy_coef: float | np.ndarray,
    h_min: np.ndarray | None = None,
    weights: np.ndarray | None = None,
) -> CMoreResult:
    """Contextual MORE step for E experts N(θ | K c + k, cov) (Eq. 3.5).

    ``quad`` is the joint surrogate over x = [c; θ] (d = dc + dθ); the step solves
    max E_c E_π[R̃] + (entropy_coef/σ_R) H(π) s.t. E_c KL(π(·|c)‖π_old(·|c)) ≤ eps,
    H(π) ≥ h_min, with E_c the (weighted) average over ``contexts`` (E, n, dc). Closed form:
    with P = ηQ + A_θθ, Σ = (η+ω) P⁻¹, K = P⁻¹(ηQK_old − A_θc), k = P⁻¹(ηQk_old + a_θ).
    """
    K, k, cov = (np.asarray(v, dtype=np.float64) for v in (K, k, cov))
    contexts = np.asarray(contexts, dtype=np.float64)
    if K.ndim != 3:
        raise ValueError(f"K must have shape (E, dθ, dc), got {K.shape}")
    n_exp, dt, dc = K.shape
    if k.shape != (n_exp, dt) or cov.shape != (n_exp, dt, dt):
        raise ValueError(
            f"k and cov must have shapes {(n_exp, dt)} and {(n_exp, dt, dt)}, "
            f"got {k.shape} and {cov.shape}"
        )
    if contexts.ndim != 3 or contexts.shape[0] != n_exp or contexts.shape[2] != dc:
        raise ValueError(f"contexts must have shape ({n_exp}, n, {dc}), got {contexts.shape}")
    if not np.all(np.isfinite(contexts)):
        raise ValueError("contexts must be finite")
    n = contexts.shape[1]
    cov = _check_cov(cov, "cov")
    _check_quad(quad, n_exp, dc + dt)
    eps_arr, coef = _check_eps_coef(eps, entropy_coef, n_exp)
    hmin = _check_h_min(h_min, n_exp)
    w = normalised_weights(weights, n_exp, n)

    A, a = np.asarray(quad.A, dtype=np.float64), np.asarray(quad.a, dtype=np.float64)
    beta = coef / np.asarray(quad.scale, dtype=np.float64)  # entropy temperature in σ_R units
    evaluate = _cmore_dual(K, k, cov, contexts, w, A, a, beta, eps_arr, hmin)
    A_tt = A[:, dc:, dc:]
    eta0 = np.maximum(40.0, 2.0 * eta_min(cov, A_tt) + 1.0)
    eta, om, sol = newton_dual(evaluate, eta0, eps_arr, hmin)
    success = sol.ok & np.isfinite(sol.kl) & (sol.kl <= eps_arr * (1 + 1e-3))
    success &= ~np.isfinite(hmin) | (sol.ent >= hmin - 1e-6)
    new_cov = np.where(success[:, None, None], sol.params[2], cov)
    return CMoreResult(
        K=np.where(success[:, None, None], sol.params[0], K),
        k=np.where(success[:, None], sol.params[1], k),
        cov=0.5 * (new_cov + np.swapaxes(new_cov, 1, 2)),
        eta=eta,
        omega=om,
        kl=np.where(success, sol.kl, 0.0),
        entropy=gaussian_entropy(new_cov),
        success=success,
    )

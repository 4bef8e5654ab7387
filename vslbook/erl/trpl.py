"""KL trust-region projection layers for Gaussian policies (Otto et al., 2021).

Di-SkilL updates each expert π(θ | c, o) on Eq. 4.7 under a per-context bound
KL(π(·|c, o) ‖ π_old(·|c, o)) ≤ ε, and BBRL does the same for its single Gaussian; both
enforce the bound the way TRPL does for Eq. 2.25 (Otto et al. 2021, "Differentiable trust
region layers for deep reinforcement learning", ICLR): the network proposes a Gaussian
N(μ, Σ) and a differentiable layer maps it to the closest Gaussian N(μ̃, Σ̃) inside the
trust region around the old one N(μ_o, Σ_o).

The KL between Gaussians splits into a mean part and a covariance part,

    m(μ) = ½ (μ − μ_o)ᵀ Σ_o⁻¹ (μ − μ_o),
    C(Σ) = ½ [tr(Σ_o⁻¹ Σ) − d + log|Σ_o| − log|Σ|],

each with its own bound (ε_μ, ε_Σ); :func:`kl_parts` evaluates both.

Mean (:func:`project_mean`). μ̃ minimises (μ̃ − μ)ᵀ Σ_o⁻¹ (μ̃ − μ) subject to m(μ̃) ≤ ε_μ.
Setting the gradient of the Lagrangian to zero puts μ̃ on the segment between μ and μ_o,
μ̃ = (μ + ω μ_o)/(1 + ω), where m(μ̃) = m(μ)/(1 + ω)²; an active bound therefore gives
ω = √(m(μ)/ε_μ) − 1. This is a closed form, differentiated by ordinary autograd.

Covariance (:func:`project_cov`). Σ̃ minimises KL(N(0, Σ̃) ‖ N(0, Σ)), the divergence from
the projected covariance to the proposed one, subject to C(Σ̃) ≤ ε_Σ. The derivative of
½[tr(Σ⁻¹Σ̃) − log|Σ̃|] + η ½[tr(Σ_o⁻¹Σ̃) − log|Σ̃|] in Σ̃ vanishes at

    Σ̃(η)⁻¹ = (η Σ_o⁻¹ + Σ⁻¹) / (η + 1),

a precision-space interpolation between the proposal (η = 0) and the old covariance
(η → ∞). The multiplier η* ≥ 0 minimises the convex dual, whose derivative is
g'(η) = ε_Σ − C(Σ̃(η)); since C(Σ̃(η)) falls monotonically from C(Σ) to 0, η* is the single
root of C(Σ̃(η)) = ε_Σ whenever C(Σ) > ε_Σ. Whitening with Σ_o turns this into a scalar
equation: if λ_i are the eigenvalues of Σ_o^{-½} Σ Σ_o^{-½}, the whitened Σ̃(η) has
eigenvalues 1 + u_i with u_i = (λ_i − 1)/(η λ_i + 1), and

    C(η) = ½ Σ_i [u_i − log(1 + u_i)],   dC/dη = −½ Σ_i (λ_i − 1)² / ((η + 1)(η λ_i + 1)²).

The root is found in float64 by Newton's method on log C − log ε_Σ as a function of log η,
safeguarded by bisection on the bracket η ∈ [1e-20, 1e20], batched over all leading
dimensions, until |log C − log ε_Σ| ≤ 1e-12 (at most 100 steps; an entry that stops early
returns the feasible end of its bracket). It starts at η = √(C(Σ)/ε_Σ) − 1, the root when Σ
is close to Σ_o (then C(Σ̃(η)) ≈ C(Σ)/(η + 1)²), so inside a trust region a few steps
suffice. The layer's gradient follows from the implicit function theorem applied to
C(Σ̃(η*; Σ, Σ_o)) = ε_Σ: dη*/dx = −(∂C/∂x)/(∂C/∂η) for every input x (Σ and Σ_o alike).
It is realised as L̃(η*) + (dL̃/dη)·(η − sg(η)) with η = η* − (C − sg(C))/sg(∂C/∂η)
(sg: stop-gradient): the value is L̃(η*), and autograd adds the implicit term to the
derivative of L̃(η*) at fixed η*, where C is evaluated from the interpolation's own factors
and dL̃/dη in closed form (dΣ̃/dη = (Σ̃ − Σ̃Σ_o⁻¹Σ̃)/(η + 1) through the derivative of the
Cholesky factorisation). This is the same gradient as the authors' hand-written backward
pass.

Where a bound already holds the layer is the identity, in value and in gradient. Where the
covariance solve fails (no feasible η in the bracket, a non-finite value, or a failed
Cholesky factorisation) the old covariance Σ_o is returned for that entry and a
``RuntimeWarning`` says how many entries failed.

Conventions. A Gaussian is (mean, chol) with chol the lower Cholesky factor of Σ. ``mean``
has shape (..., n, d): n vectors (e.g. B contexts) that share the covariance ``chol`` of
shape (..., d, d), and the leading dimensions "..." broadcast, so the Di-SkilL layout is
``mean`` (K, B, d) with ``chol`` (K, d, d) for K experts; a 1-D ``mean`` is one vector. The
covariance projection works in float64 internally and returns the input dtype.

:func:`trust_region_loss` is the regression term of the expert loss that pulls the network's
mean towards its projection (α_TR · m(π ‖ sg(π̃)), mean part only).
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np
import torch
from torch import Tensor

__all__ = ["kl_parts", "project", "project_cov", "project_mean", "trust_region_loss"]

_LOG_ETA_MIN = math.log(1e-20)  # bracket of the multiplier η* in log space
_LOG_ETA_MAX = math.log(1e20)
_ROOT_TOL = 1e-12  # |log C(Σ̃) − log ε_Σ| at convergence
_MAX_ITER = 100


# ------------------------------------------------------------------------------ validation


def _check_eps(eps: float, name: str) -> float:
    try:
        value = float(eps)
    except (TypeError, ValueError, RuntimeError) as err:
        raise ValueError(f"{name} must be a positive finite number, got {eps!r}") from err
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a positive finite number, got {eps!r}")
    return value


def _check_tensor(x: Tensor, name: str, min_ndim: int) -> None:
    if not isinstance(x, Tensor):
        raise ValueError(f"{name} must be a torch.Tensor, got {type(x).__name__}")
    if not x.is_floating_point():
        raise ValueError(f"{name} must be a floating-point tensor, got dtype {x.dtype}")
    if x.ndim < min_ndim or x.shape[-1] == 0:
        raise ValueError(
            f"{name} must have at least {min_ndim} dimension(s) and a non-empty last one, "
            f"got shape {tuple(x.shape)}"
        )
    if not bool(torch.isfinite(x.detach()).all()):
        raise ValueError(f"{name} must be finite, got non-finite entries")


def _check_mean(mean: Tensor, name: str) -> None:
    _check_tensor(mean, name, 1)


def _check_chol(chol: Tensor, name: str) -> None:
    _check_tensor(chol, name, 2)
    if chol.shape[-1] != chol.shape[-2]:
        raise ValueError(f"{name} must be square in its last two dims, got {tuple(chol.shape)}")
    c = chol.detach()
    if bool((torch.triu(c, 1) != 0).any()):
        raise ValueError(f"{name} must be lower-triangular (a Cholesky factor)")
    if not bool((torch.diagonal(c, dim1=-2, dim2=-1) > 0).all()):
        raise ValueError(f"{name} must have a positive diagonal (a Cholesky factor)")


def _check_same(named: dict[str, Tensor]) -> int:
    """Same dtype and the same event size d for all; returns d."""
    dtypes = {n: t.dtype for n, t in named.items()}
    if len(set(dtypes.values())) > 1:
        raise ValueError(f"all tensors must share one dtype, got {dtypes}")
    dims = {n: t.shape[-1] for n, t in named.items()}
    if len(set(dims.values())) > 1:
        raise ValueError(f"all tensors must share the event size d (last dim), got {dims}")
    return next(iter(dims.values()))


def _broadcast(named: dict[str, torch.Size]) -> torch.Size:
    try:
        return torch.broadcast_shapes(*named.values())
    except RuntimeError as err:
        shapes = {n: tuple(s) for n, s in named.items()}
        raise ValueError(f"leading dimensions do not broadcast: {shapes}") from err


# ------------------------------------------------------------------------------ KL parts


def _phi(u: Any, xp: Any = torch) -> Any:
    """u − log(1 + u) ≥ 0 for u > −1, accurate also for small |u| (series below 1e-2);
    ``u`` a tensor (``xp`` torch) or a numpy array (``xp`` numpy)."""
    small = abs(u) < 1e-2
    us = xp.where(small, u, 0.0)
    series = (
        us
        * us
        * (
            1 / 2
            - us * (1 / 3 - us * (1 / 4 - us * (1 / 5 - us * (1 / 6 - us * (1 / 7 - us / 8)))))
        )
    )
    ul = xp.where(small, 1.0, u)
    return xp.where(small, series, ul - xp.log1p(ul))


def _mean_part(mean: Tensor, old_mean: Tensor, old_chol: Tensor) -> Tensor:
    """m(μ) = ½ (μ − μ_o)ᵀ Σ_o⁻¹ (μ − μ_o) by a triangular solve; shape (..., n)."""
    diff = mean - old_mean
    single = diff.ndim == 1
    if single:
        diff = diff.unsqueeze(0)
    d = diff.shape[-1]
    batch = _broadcast({"mean": diff.shape[:-2], "old_chol": old_chol.shape[:-2]})
    rhs = diff.expand(*batch, *diff.shape[-2:]).mT  # (..., d, n)
    z = torch.linalg.solve_triangular(old_chol.expand(*batch, d, d), rhs, upper=False)
    m = 0.5 * z.square().sum(-2)
    return m.squeeze(-1) if single else m


def _cov_part(chol: Tensor, old_chol: Tensor) -> Tensor:
    """C(Σ) with M = L_o⁻¹ L: ½[Σ_{i≠j} M_ij² + Σ_i (M_ii² − 1 − log M_ii²)]."""
    d = chol.shape[-1]
    batch = _broadcast({"chol": chol.shape[:-2], "old_chol": old_chol.shape[:-2]})
    M = torch.linalg.solve_triangular(
        old_chol.expand(*batch, d, d), chol.expand(*batch, d, d), upper=False
    )
    diag_sq = torch.diagonal(M, dim1=-2, dim2=-1).square()
    off = torch.tril(M, -1).square().sum((-2, -1))
    return 0.5 * (off + _phi(diag_sq - 1).sum(-1))


def kl_parts(
    mean: Tensor, chol: Tensor, old_mean: Tensor, old_chol: Tensor
) -> tuple[Tensor, Tensor]:
    """Mean and covariance parts of KL(N(μ, Σ) ‖ N(μ_o, Σ_o)); their sum is the full KL.

    Args:
        mean: μ, shape (..., n, d) (or (d,)).
        chol: lower Cholesky factor of Σ, shape (..., d, d).
        old_mean: μ_o, broadcastable with ``mean``.
        old_chol: lower Cholesky factor of Σ_o, shape (..., d, d).

    Returns:
        ``m`` of shape (..., n) (``mean.shape[:-1]`` when the leading dims of the factors
        broadcast into those of ``mean``) and ``C`` of shape (...,) (``chol.shape[:-2]``
        broadcast with ``old_chol.shape[:-2]``).
    """
    for name, x in (("mean", mean), ("old_mean", old_mean)):
        _check_mean(x, name)
    _check_chol(chol, "chol")
    _check_chol(old_chol, "old_chol")
    _check_same({"mean": mean, "chol": chol, "old_mean": old_mean, "old_chol": old_chol})
    _broadcast({"mean": mean.shape, "old_mean": old_mean.shape})
    return _mean_part(mean, old_mean, old_chol), _cov_part(chol, old_chol)


# ------------------------------------------------------------------------------ mean projection


def project_mean(
    mean: Tensor, old_mean: Tensor, old_chol: Tensor, eps_mean: float, *, check: bool = True
) -> Tensor:
    """Project μ onto {μ̃ : m(μ̃) ≤ ε_μ} in the Σ_o-metric (closed form, plain autograd).

    Where m(μ) > ε_μ: ω = √(m(μ)/ε_μ) − 1 and μ̃ = (μ + ω μ_o)/(1 + ω), so that m(μ̃) = ε_μ;
    elsewhere μ̃ = μ exactly (identity gradient).

    Args:
        mean: μ, shape (..., n, d) (or (d,)).
        old_mean: μ_o, broadcastable with ``mean``.
        old_chol: lower Cholesky factor of Σ_o, shape (..., d, d), shared by the n rows.
        eps_mean: ε_μ > 0, a bound on the ½-scaled Mahalanobis distance m.
        check: validate the inputs (False: the caller vouches for them, e.g. an update loop
            whose inputs come from its own networks).

    Returns:
        μ̃ with the broadcast shape of ``mean`` and ``old_mean``.
    """
    eps = _check_eps(eps_mean, "eps_mean") if check else float(eps_mean)
    if check:
        _check_mean(mean, "mean")
        _check_mean(old_mean, "old_mean")
        _check_chol(old_chol, "old_chol")
        _check_same({"mean": mean, "old_mean": old_mean, "old_chol": old_chol})
        _broadcast({"mean": mean.shape, "old_mean": old_mean.shape})
    m = _mean_part(mean, old_mean, old_chol)
    active = m > eps
    omega = torch.sqrt(torch.where(active, m, torch.full_like(m, eps)) / eps) - 1
    projected = (mean + omega.unsqueeze(-1) * old_mean) / (1 + omega.unsqueeze(-1))
    return torch.where(active.unsqueeze(-1), projected, mean)


# ------------------------------------------------------------------------------ covariance


def _whitened_eigenvalues(chol: Tensor, old_chol: Tensor) -> Tensor:
    """Eigenvalues λ of Σ_o^{-½} Σ Σ_o^{-½}: squared singular values of L_o⁻¹ L."""
    M = torch.linalg.solve_triangular(old_chol, chol, upper=False)
    return torch.linalg.svdvals(M).square()


def _cov_part_eta(eta: np.ndarray, lam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """C(Σ̃(η)) and dC/dη from the whitened eigenvalues λ (shapes (N,) and (N, d))."""
    e = eta[:, None]
    den = e * lam + 1
    a = lam - 1
    c = 0.5 * _phi(a / den, np).sum(-1)
    dc = -0.5 * (a * a / ((e + 1) * den * den)).sum(-1)
    return c, dc


def _solve_eta(lam: np.ndarray, eps: float, c0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Root η* of C(Σ̃(η)) = ε per row of λ; returns (η*, ok).

    In numpy, float64: a few dozen elementwise operations on (N, d) per step, which numpy
    does at a fraction of PyTorch's cost per operation. ``c0`` = C(Σ) (η = 0). The
    iteration starts at η = √(C(Σ)/ε) − 1, the root where Σ ≈ Σ_o (u_i ≈ (λ_i − 1)/(η + 1),
    so C(Σ̃(η)) ≈ C(Σ)/(η + 1)², as for the mean), which is where a trust region keeps the
    iterates.
    """
    log_eps = math.log(eps)

    def h(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # log C − log ε, d/dt, t = log η
        eta = np.exp(t)
        c, dc = _cov_part_eta(eta, lam)
        return np.log(c) - log_eps, eta * dc / c

    n = lam.shape[0]
    with np.errstate(all="ignore"):
        lo = np.full(n, _LOG_ETA_MIN)
        hi = np.full(n, _LOG_ETA_MAX)
        h_hi, _ = h(hi)
        ok = np.isfinite(h_hi) & (h_hi <= 0)  # a feasible η exists in the bracket
        t = np.clip(np.log(np.maximum(np.sqrt(c0 / eps) - 1, 1e-12)), lo, hi)
        t = np.where(np.isfinite(t), t, 0.0)
        done = ~ok
        for _ in range(_MAX_ITER):
            hv, dh = h(t)
            done = done | (np.abs(hv) <= _ROOT_TOL) | (hi - lo <= _ROOT_TOL)
            if done.all():
                break
            run = ~done
            lo = np.where(run & (hv > 0), t, lo)  # C too large: η must grow
            hi = np.where(run & (hv < 0), t, hi)
            newton = t - hv / dh
            inside = np.isfinite(newton) & (newton > lo) & (newton < hi)
            t = np.where(run, np.where(inside, newton, 0.5 * (lo + hi)), t)
        hv, _ = h(t)
        t = np.where(hv <= _ROOT_TOL, t, hi)  # otherwise the feasible end of the bracket
        eta = np.exp(t)
    return eta, ok & np.isfinite(eta)


def _interpolate(
    eta: Tensor, prec: Tensor, old_prec: Tensor
) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """Σ̃(η) = (η + 1)(η Σ_o⁻¹ + Σ⁻¹)⁻¹: its lower Cholesky factor, Σ̃ itself, the factor of
    Σ̃⁻¹ and a failure flag."""
    e = eta[..., None, None]
    prec_chol, info1 = torch.linalg.cholesky_ex((e * old_prec + prec) / (e + 1))
    cov = torch.cholesky_inverse(prec_chol)
    chol, info2 = torch.linalg.cholesky_ex(cov)
    return chol, cov, prec_chol, (info1 != 0) | (info2 != 0)


def _cov_part_from(cov: Tensor, prec_chol: Tensor, old_prec: Tensor, old_chol: Tensor) -> Tensor:
    """C(Σ̃) = ½[tr(Σ_o⁻¹Σ̃) − d + log|Σ_o| − log|Σ̃|] from Σ̃ and the factor of Σ̃⁻¹."""
    log_diag = torch.log(torch.diagonal(prec_chol, dim1=-2, dim2=-1)).sum(-1)  # −½ log|Σ̃|
    old_log_diag = torch.log(torch.diagonal(old_chol, dim1=-2, dim2=-1)).sum(-1)  # ½ log|Σ_o|
    trace = (old_prec * cov).sum((-2, -1))
    return 0.5 * (trace - cov.shape[-1]) + old_log_diag + log_diag


def _chol_slope(chol: Tensor, cov: Tensor, old_prec: Tensor, eta: Tensor) -> Tensor:
    """dL̃/dη of L̃ = chol(Σ̃(η)) at fixed Σ, Σ_o (no grad).

    dΣ̃/dη = (Σ̃ − Σ̃ Σ_o⁻¹ Σ̃)/(η + 1), and a Cholesky factor moves as
    dL̃ = L̃ Φ(L̃⁻¹ dΣ̃ L̃⁻ᵀ), Φ = the lower triangle with the diagonal halved.
    """
    dcov = (cov - cov @ old_prec @ cov) / (eta[..., None, None] + 1)
    half = torch.linalg.solve_triangular(chol, dcov, upper=False)
    x = torch.linalg.solve_triangular(chol, half.mT, upper=False)
    phi = torch.tril(x, -1) + 0.5 * torch.diag_embed(torch.diagonal(x, dim1=-2, dim2=-1))
    return chol @ phi


def project_cov(chol: Tensor, old_chol: Tensor, eps_cov: float, *, check: bool = True) -> Tensor:
    """Project Σ onto {Σ̃ : C(Σ̃) ≤ ε_Σ}, minimising KL(N(0, Σ̃) ‖ N(0, Σ)); returns chol(Σ̃).

    Where C(Σ) ≤ ε_Σ the output is ``chol`` itself (identity, also for gradients); elsewhere
    Σ̃⁻¹ = (η* Σ_o⁻¹ + Σ⁻¹)/(η* + 1) with C(Σ̃) = ε_Σ (the root to 1e-12 relative, the
    returned factor up to rounding that grows with the condition number of Σ_o⁻¹Σ), η*
    found by a safeguarded Newton iteration in log η, and the gradient (with respect to ``chol`` and
    ``old_chol``) includes the implicit term dη*/dΣ. Where the solve fails (no η ≤ 1e20
    reaches the bound, non-finite values, failed Cholesky) the old factor ``old_chol`` is
    returned for that entry and a ``RuntimeWarning`` is issued.

    Args:
        chol: lower Cholesky factor of Σ, shape (..., d, d).
        old_chol: lower Cholesky factor of Σ_o, shape (..., d, d) (broadcasts with ``chol``).
        eps_cov: ε_Σ > 0, the bound on the covariance part C of the KL.
        check: validate the inputs (see :func:`project_mean`).

    Returns:
        The projected lower Cholesky factor, broadcast shape, dtype of ``chol``.
    """
    eps = _check_eps(eps_cov, "eps_cov") if check else float(eps_cov)
    d = chol.shape[-1]
    if check:
        _check_chol(chol, "chol")
        _check_chol(old_chol, "old_chol")
        d = _check_same({"chol": chol, "old_chol": old_chol})
    batch = _broadcast({"chol": chol.shape[:-2], "old_chol": old_chol.shape[:-2]})
    dtype = chol.dtype
    L = chol.to(torch.float64).expand(*batch, d, d)
    L_old = old_chol.to(torch.float64).expand(*batch, d, d)

    with torch.no_grad():  # the multiplier, in numpy on the whitened eigenvalues (N, d)
        lam = _whitened_eigenvalues(L, L_old).reshape(-1, d).cpu().numpy()
        c0, _ = _cov_part_eta(np.zeros(len(lam)), lam)
        active_np = c0 > eps
    if not active_np.any():
        return chol.expand(*batch, d, d).clone()
    with np.errstate(all="ignore"):
        eta_np, ok_np = np.zeros(len(lam)), np.zeros(len(lam), dtype=bool)
        eta_np[active_np], ok_np[active_np] = _solve_eta(lam[active_np], eps, c0[active_np])
        eta_np = np.where(active_np & ok_np, eta_np, 0.0)
        _, slope_np = _cov_part_eta(eta_np, lam)

    def tensor(x: np.ndarray) -> Tensor:
        return torch.from_numpy(x).to(L.device).reshape(batch)

    active, eta, slope = tensor(active_np), tensor(eta_np), tensor(slope_np)
    use = active & tensor(ok_np)
    prec, old_prec = torch.cholesky_inverse(L), torch.cholesky_inverse(L_old)
    root, cov, prec_chol, failed = _interpolate(eta, prec, old_prec)
    with torch.no_grad():
        finite = torch.isfinite(root).all(-1).all(-1)
        good = use & ~failed & finite & torch.isfinite(slope) & (slope < 0)
        redo = bool((good != use).any())
        use = good
        eta = torch.where(use, eta, torch.zeros_like(eta))
        slope = torch.where(use, slope, -torch.ones_like(slope))
        n_failed = int((active & ~use).sum())
    if redo:  # entries whose factorisation failed: evaluated at η = 0 (then discarded)
        root, cov, prec_chol, _ = _interpolate(eta, prec, old_prec)
    if n_failed:
        warnings.warn(
            f"project_cov: {n_failed} of {active.numel()} covariance projections failed; "
            "the old covariance was kept for them",
            RuntimeWarning,
            stacklevel=2,
        )

    # L̃(η*) + dL̃/dη · (η − sg(η)) with η = η* − (C − sg(C))/(∂C/∂η): the value of L̃(η*),
    # the derivative ∂L̃/∂x + ∂L̃/∂η · dη*/dx with dη*/dx = −(∂C/∂x)/(∂C/∂η) (implicit
    # function theorem), C = C(Σ̃(η*)) as a function of the inputs x at fixed η*
    c_root = _cov_part_from(cov, prec_chol, old_prec, L_old)
    with torch.no_grad():
        chol_slope = _chol_slope(root, cov, old_prec, eta)
        chol_slope = torch.where(use[..., None, None], chol_slope, torch.zeros_like(chol_slope))
    d_eta = (c_root.detach() - c_root) / slope  # value 0
    projected = root + chol_slope * d_eta[..., None, None]
    keep = torch.where((active & ~use)[..., None, None], L_old, L)
    return torch.where(use[..., None, None], projected, keep).to(dtype)


# ------------------------------------------------------------------------------ both + loss


def project(
    mean: Tensor,
    chol: Tensor,
    old_mean: Tensor,
    old_chol: Tensor,
    eps_mean: float,
    eps_cov: float,
    *,
    check: bool = True,
) -> tuple[Tensor, Tensor]:
    """Project N(μ, LLᵀ) into the trust region around N(μ_o, L_o L_oᵀ): (μ̃, L̃).

    The mean and covariance parts are projected independently (:func:`project_mean`,
    :func:`project_cov`), so m(μ̃) ≤ ε_μ and C(Σ̃) ≤ ε_Σ hold per entry.
    Shapes as in :func:`kl_parts`, e.g. ``mean`` (K, B, d) and ``chol`` (K, d, d).
    """
    return (
        project_mean(mean, old_mean, old_chol, eps_mean, check=check),
        project_cov(chol, old_chol, eps_cov, check=check),
    )


def trust_region_loss(
    mean: Tensor, proj_mean: Tensor, proj_chol: Tensor, *, check: bool = True
) -> Tensor:
    """Trust-region regression term of the expert loss, mean part: mean_n m(μ ‖ sg(μ̃)).

    ½ (μ − sg(μ̃))ᵀ Σ̃⁻¹ (μ − sg(μ̃)) with Σ̃ = sg(L̃ L̃ᵀ), averaged over the batch axis −2 of
    ``mean``; only ``mean`` receives gradients.

    Args:
        mean: the network's mean μ, shape (..., n, d).
        proj_mean: the projected mean μ̃, broadcastable with ``mean``.
        proj_chol: the projected Cholesky factor L̃, shape (..., d, d).
        check: validate the inputs (see :func:`project_mean`).

    Returns:
        Shape ``mean.shape[:-2]`` (one value per expert for ``mean`` (K, B, d)).
    """
    if check:
        _check_mean(mean, "mean")
        _check_mean(proj_mean, "proj_mean")
        _check_chol(proj_chol, "proj_chol")
        _check_same({"mean": mean, "proj_mean": proj_mean, "proj_chol": proj_chol})
        _broadcast({"mean": mean.shape, "proj_mean": proj_mean.shape})
    m = _mean_part(mean, proj_mean.detach(), proj_chol.detach())
    return m if mean.ndim == 1 else m.mean(-1)

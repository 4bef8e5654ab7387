"""Multivariate Gaussians with full covariance, batched over leading dimensions.

Gaussians are the building block of every policy in the thesis: the experts of a mixture
(Eq. 2.49), the kernels of a discretised diffusion (Eqs. 2.53-2.54) and the closed-form KLs of
the variational objectives (Eqs. 2.56-2.60). Everything here works through the Cholesky factor
``cov = L L^T``, never through an explicit inverse.

Shape conventions: a mean has shape ``(..., d)`` and a covariance ``(..., d, d)``; leading
dimensions broadcast against each other like ordinary torch operations. float32 and float64
are supported; mixed inputs are promoted to the wider floating dtype.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import torch

Tensor = torch.Tensor
TensorLike = Tensor | np.ndarray | Sequence[float] | float
Indices = Sequence[int] | Tensor | np.ndarray


def as_floats(**named: TensorLike) -> list[Tensor]:
    """Convert inputs to tensors sharing one floating dtype.

    Tensors keep their dtype; lists, scalars and integer input become float64, numpy arrays
    keep their floating dtype. Mixed dtypes are promoted to the widest one.
    """
    tensors = {
        k: v if isinstance(v, Tensor) else torch.as_tensor(np.asarray(v)) for k, v in named.items()
    }
    dtype = None
    for t in tensors.values():
        tdt = t.dtype if t.is_floating_point() else torch.float64
        dtype = tdt if dtype is None else torch.promote_types(dtype, tdt)
    if dtype not in (torch.float32, torch.float64):
        dtype = torch.float64
    return [t.to(dtype) for t in tensors.values()]


def dtype_tolerance(dtype: torch.dtype) -> float:
    """The validation tolerance of ``dtype``: the square root of its machine epsilon."""
    return math.sqrt(torch.finfo(dtype).eps)


def check_mean_cov(mean: Tensor, cov: Tensor, mean_name: str, cov_name: str) -> int:
    """Validate shapes ``(..., d)`` and ``(..., d, d)`` and return ``d``."""
    if mean.ndim < 1:
        raise ValueError(f"{mean_name} must have shape (..., d), got a scalar")
    d = mean.shape[-1]
    if cov.ndim < 2 or cov.shape[-2:] != (d, d):
        raise ValueError(
            f"{cov_name} must have shape (..., {d}, {d}) to match {mean_name} of shape "
            f"{tuple(mean.shape)}, got {tuple(cov.shape)}"
        )
    _broadcast_batch(mean.shape[:-1], cov.shape[:-2], mean_name, cov_name)
    return d


def _broadcast_batch(a: Sequence[int], b: Sequence[int], a_name: str, b_name: str) -> tuple:
    try:
        return tuple(np.broadcast_shapes(tuple(a), tuple(b)))
    except ValueError as err:
        raise ValueError(
            f"batch shapes of {a_name} {tuple(a)} and {b_name} {tuple(b)} do not broadcast"
        ) from err


def cholesky(cov: Tensor, name: str = "cov") -> Tensor:
    """Lower Cholesky factor of a batch of symmetric positive-definite matrices.

    Raises:
        ValueError: if ``cov`` is not square, not symmetric, or not positive definite.
    """
    if cov.ndim < 2 or cov.shape[-1] != cov.shape[-2]:
        raise ValueError(f"{name} must have shape (..., d, d), got {tuple(cov.shape)}")
    scale = cov.abs().amax() if cov.numel() else cov.new_tensor(0.0)
    asym = (cov - cov.mT).abs().amax() if cov.numel() else cov.new_tensor(0.0)
    if asym > dtype_tolerance(cov.dtype) * max(float(scale), 1.0):
        raise ValueError(f"{name} must be symmetric, but max |{name} - {name}^T| = {asym:.3g}")
    chol, info = torch.linalg.cholesky_ex(cov)
    if bool((info > 0).any()):
        bad = tuple(int(i) for i in (info > 0).nonzero()[0]) if info.ndim else ()
        raise ValueError(
            f"{name} must be positive definite, but the Cholesky factorisation failed "
            f"(batch index {bad}, leading minor of order {int(info[bad])} is not positive)"
        )
    return chol


def _logdet_from_chol(chol: Tensor) -> Tensor:
    return 2.0 * torch.diagonal(chol, dim1=-2, dim2=-1).log().sum(-1)


def _solve_lower(chol: Tensor, rhs: Tensor) -> Tensor:
    """``L^{-1} rhs`` for ``rhs`` of shape ``(..., d)``; batch dimensions broadcast."""
    return torch.linalg.solve_triangular(chol, rhs.unsqueeze(-1), upper=False).squeeze(-1)


def gaussian_log_prob(x: TensorLike, mean: TensorLike, cov: TensorLike) -> Tensor:
    """Log density ``log N(x | mean, cov)`` with full covariance.

    ``log N = -1/2 (x - mu)^T cov^{-1} (x - mu) - 1/2 log det(2 pi cov)``, evaluated with the
    Cholesky factor (the expert density of Eq. 2.49).

    Args:
        x: points, shape ``(..., d)``.
        mean: means, shape ``(..., d)``.
        cov: covariances, shape ``(..., d, d)``, symmetric positive definite.

    Returns:
        Log densities of shape ``broadcast(x.shape[:-1], mean.shape[:-1], cov.shape[:-2])``.
    """
    x, mean, cov = as_floats(x=x, mean=mean, cov=cov)
    d = check_mean_cov(mean, cov, "mean", "cov")
    if x.ndim < 1 or x.shape[-1] != d:
        raise ValueError(f"x must have shape (..., {d}) to match mean, got {tuple(x.shape)}")
    _broadcast_batch(x.shape[:-1], mean.shape[:-1], "x", "mean")
    chol = cholesky(cov)
    z = _solve_lower(chol, x - mean)
    return -0.5 * (z * z).sum(-1) - 0.5 * _logdet_from_chol(chol) - 0.5 * d * math.log(2 * math.pi)


def gaussian_entropy(cov: TensorLike) -> Tensor:
    """Differential entropy ``H = 1/2 log det(2 pi e cov)`` of a Gaussian, shape ``(...)``."""
    (cov,) = as_floats(cov=cov)
    chol = cholesky(cov)
    d = cov.shape[-1]
    return 0.5 * _logdet_from_chol(chol) + 0.5 * d * (1.0 + math.log(2 * math.pi))


def gaussian_kl(
    mean_p: TensorLike, cov_p: TensorLike, mean_q: TensorLike, cov_q: TensorLike
) -> Tensor:
    """Closed-form ``KL(p || q)`` between two Gaussians (the divergence of Eqs. 2.56 and 2.60).

    ``KL = 1/2 [tr(S_q^{-1} S_p) + (m_q - m_p)^T S_q^{-1} (m_q - m_p) - d + log det S_q
    - log det S_p]``.

    Returns:
        Non-negative KLs of the broadcast batch shape.
    """
    mean_p, cov_p, mean_q, cov_q = as_floats(mean_p=mean_p, cov_p=cov_p, mean_q=mean_q, cov_q=cov_q)
    d = check_mean_cov(mean_p, cov_p, "mean_p", "cov_p")
    d_q = check_mean_cov(mean_q, cov_q, "mean_q", "cov_q")
    if d_q != d:
        raise ValueError(f"p has dimension {d} but q has dimension {d_q}; they must agree")
    _broadcast_batch(mean_p.shape[:-1], mean_q.shape[:-1], "mean_p", "mean_q")
    _broadcast_batch(cov_p.shape[:-2], cov_q.shape[:-2], "cov_p", "cov_q")
    chol_p = cholesky(cov_p, "cov_p")
    chol_q = cholesky(cov_q, "cov_q")
    m = torch.linalg.solve_triangular(chol_q, chol_p, upper=False)
    trace = (m * m).sum((-2, -1))
    z = _solve_lower(chol_q, mean_q - mean_p)
    maha = (z * z).sum(-1)
    logdet = _logdet_from_chol(chol_q) - _logdet_from_chol(chol_p)
    return 0.5 * (trace + maha - d + logdet)


def _check_indices(idx: Indices, d: int, name: str) -> list[int]:
    values = np.asarray(idx.cpu() if isinstance(idx, Tensor) else idx)
    if values.ndim != 1 or (values.size and not np.issubdtype(values.dtype, np.integer)):
        raise ValueError(f"{name} must be a 1-D sequence of integers, got {idx!r}")
    out = [int(i) for i in values]
    if any(i < 0 or i >= d for i in out):
        raise ValueError(f"{name} must hold indices in [0, {d}), got {out}")
    if len(set(out)) != len(out):
        raise ValueError(f"{name} must not repeat an index, got {out}")
    return out


def marginal_gaussian(mean: TensorLike, cov: TensorLike, idx: Indices) -> tuple[Tensor, Tensor]:
    """Marginal of the dimensions ``idx``: ``(mean[..., idx], cov[..., idx, idx])``."""
    mean, cov = as_floats(mean=mean, cov=cov)
    d = check_mean_cov(mean, cov, "mean", "cov")
    keep = _check_indices(idx, d, "idx")
    if not keep:
        raise ValueError("idx must select at least one dimension, got an empty selection")
    sel = torch.tensor(keep, device=mean.device)
    return mean[..., sel], cov[..., sel, :][..., :, sel]


def condition_gaussian(
    mean: TensorLike, cov: TensorLike, idx_obs: Indices, x_obs: TensorLike
) -> tuple[Tensor, Tensor]:
    """Gaussian of the unobserved block given observed values (Schur complement).

    With ``u`` the unobserved and ``o`` the observed indices:
    ``mean_u|o = mean_u + S_uo S_oo^{-1} (x_o - mean_o)`` and
    ``cov_u|o = S_uu - S_uo S_oo^{-1} S_ou``. This is the posterior ``p(z | x)`` that appears in
    the expected KL of Eq. 2.60 when ``p(x, z)`` is jointly Gaussian.

    Args:
        mean: joint means, shape ``(..., d)``.
        cov: joint covariances, shape ``(..., d, d)``.
        idx_obs: indices of the observed dimensions (``k`` of them, ``0 < k < d``).
        x_obs: observed values, shape ``(..., k)``, in the order of ``idx_obs``.

    Returns:
        ``(mean_u, cov_u)`` of shapes ``(..., d - k)`` and ``(..., d - k, d - k)``; the
        unobserved dimensions keep their original (ascending) order.
    """
    mean, cov, x_obs = as_floats(mean=mean, cov=cov, x_obs=x_obs)
    d = check_mean_cov(mean, cov, "mean", "cov")
    obs = _check_indices(idx_obs, d, "idx_obs")
    if not 0 < len(obs) < d:
        raise ValueError(
            f"idx_obs must observe between 1 and {d - 1} of the {d} dimensions, got {obs}"
        )
    if x_obs.ndim < 1 or x_obs.shape[-1] != len(obs):
        raise ValueError(
            f"x_obs must have shape (..., {len(obs)}) to match idx_obs={obs}, "
            f"got {tuple(x_obs.shape)}"
        )
    _broadcast_batch(x_obs.shape[:-1], mean.shape[:-1], "x_obs", "mean")
    unobs = [i for i in range(d) if i not in set(obs)]
    o = torch.tensor(obs, device=mean.device)
    u = torch.tensor(unobs, device=mean.device)
    s_oo = cov[..., o, :][..., :, o]
    s_ou = cov[..., o, :][..., :, u]
    s_uu = cov[..., u, :][..., :, u]
    chol = cholesky(s_oo, "cov[idx_obs, idx_obs]")
    gain = torch.cholesky_solve(s_ou, chol)  # S_oo^{-1} S_ou, shape (..., k, d - k)
    resid = (x_obs - mean[..., o]).unsqueeze(-1)
    cond_mean = mean[..., u] + (gain.mT @ resid).squeeze(-1)
    cond_cov = s_uu - s_ou.mT @ gain
    return cond_mean, 0.5 * (cond_cov + cond_cov.mT)

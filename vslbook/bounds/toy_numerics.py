"""Small numerical helpers shared by the checks of :mod:`vslbook.bounds`.

Seeded random streams, argument validation, the worst element of an element-wise comparison,
Monte Carlo means with their standard errors,
NumPy/PyTorch conversion, random covariances and linear-Gaussian joints, and the entropy, KL
and log-sum-exp of discrete distributions that the toy problems of the bound checks use.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from vslbook.bounds import Check, relative_tol

__all__ = [
    "check_count",
    "check_distribution",
    "check_finite",
    "check_positive",
    "discrete_entropy",
    "discrete_kl",
    "linear_gaussian_joint",
    "logsumexp0",
    "mc_mean_stderr",
    "quadrature_tol",
    "random_spd",
    "seeded_rng",
    "to_numpy",
    "to_tensor",
    "worst_check",
]


# ------------------------------------------------------------------ streams and validation


def seeded_rng(seed: int, stream: int = 0) -> np.random.Generator:
    """The generator of stream ``stream`` of ``seed`` (a non-negative integer)."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    return np.random.default_rng([int(seed), stream])


def check_count(name: str, value: int, minimum: int = 1) -> int:
    """``value`` as an int; ValueError unless it is an integer ``>= minimum``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def check_positive(name: str, value: float) -> float:
    """``value`` as a float; ValueError unless it is a positive finite number."""
    if not (isinstance(value, (int, float, np.floating)) and value > 0 and math.isfinite(value)):
        raise ValueError(f"{name} must be a positive finite number, got {value!r}")
    return float(value)


def check_finite(
    name: str, value: float, minimum: float = -math.inf, strict: bool = False
) -> float:
    """``value`` as a float; ValueError unless it is finite and ``>= minimum`` (``>`` if strict)."""
    ok = isinstance(value, (int, float, np.floating, np.integer)) and not isinstance(value, bool)
    ok = ok and math.isfinite(value) and (value > minimum if strict else value >= minimum)
    if not ok:
        bound = f"> {minimum}" if strict else f">= {minimum}"
        raise ValueError(f"{name} must be a finite number {bound}, got {value!r}")
    return float(value)


def check_distribution(name: str, probs: np.ndarray, shape: tuple[int, ...], axis: int = -1):
    """``probs`` as a float array; ValueError unless it has ``shape`` and sums to 1 on ``axis``."""
    probs = np.asarray(probs, dtype=float)
    if probs.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {probs.shape}")
    if np.any(probs < 0) or not np.allclose(probs.sum(axis), 1.0, atol=1e-8):
        raise ValueError(
            f"{name} must be non-negative and sum to 1 along axis {axis}; sums are "
            f"{np.round(probs.sum(axis), 6)}"
        )
    return probs


# ------------------------------------------------------------------------- comparisons


def worst_check(
    name: str,
    equation: str,
    lhs: np.ndarray | float,
    rhs: np.ndarray | float,
    tol: np.ndarray | float,
    relation: str = "==",
) -> Check:
    """The :class:`Check` of the worst element of an element-wise comparison."""
    lhs, rhs, tol = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (lhs, rhs, tol)))
    excess = np.abs(lhs - rhs) - tol if relation == "==" else lhs - rhs - tol
    excess = np.where(np.isnan(excess), np.inf, excess)
    i = np.unravel_index(np.argmax(excess), excess.shape) if excess.ndim else ()
    return Check(name, equation, lhs[i], rhs[i], tol[i], relation)


def mc_mean_stderr(x: np.ndarray) -> tuple[float, float]:
    """The Monte Carlo mean of the samples ``x`` and its standard error."""
    return float(x.mean()), float(x.std(ddof=1) / math.sqrt(x.size))


def quadrature_tol(*values: float) -> float:
    """The tolerance of identities computed by quadrature: :func:`relative_tol` at ``1e-8``."""
    return relative_tol(*values, rtol=1e-8)


# ---------------------------------------------------------------------- conversions


def to_tensor(x: np.ndarray | float) -> torch.Tensor:
    """``x`` as a float64 tensor."""
    return torch.as_tensor(np.asarray(x, dtype=float), dtype=torch.float64)


def to_numpy(x: torch.Tensor | np.ndarray | float) -> np.ndarray:
    """``x`` (a tensor, array or number) as a NumPy array."""
    if isinstance(x, torch.Tensor):
        return x.detach().cpu().numpy()
    return np.asarray(x, dtype=float)


# ------------------------------------------------------------------ Gaussian helpers


def random_spd(rng: np.random.Generator, d: int, scale: float = 1.0) -> np.ndarray:
    """A random symmetric positive-definite ``(d, d)`` matrix (eigenvalues ``>= scale / 2``)."""
    a = rng.normal(size=(d, d)) / math.sqrt(d)
    return scale * (a @ a.T + 0.5 * np.eye(d))


def linear_gaussian_joint(
    coupling: np.ndarray, offset: np.ndarray, std: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Mean and covariance of ``x = M x + m + diag(std) eps`` with ``M`` nilpotent."""
    a = np.linalg.inv(np.eye(offset.size) - coupling)
    s = a * std[None, :]
    return a @ offset, s @ s.T


# -------------------------------------------------------------- discrete distributions


def logsumexp0(a: np.ndarray, keepdims: bool = False) -> np.ndarray:
    """``log sum exp`` over axis 0 (the experts); scipy's version is slow on these sizes."""
    m = a.max(axis=0, keepdims=True)
    out = m + np.log(np.exp(a - m).sum(axis=0, keepdims=True))
    return out if keepdims else out[0]


def discrete_entropy(p: np.ndarray) -> float:
    """``H[p] = -sum p log p`` of a discrete distribution (``0 log 0 = 0``)."""
    p = np.asarray(p, dtype=float)
    nz = p > 0
    return float(-np.sum(p[nz] * np.log(p[nz])))


def discrete_kl(p: np.ndarray, q: np.ndarray) -> float:
    """``KL(p || q) = sum p (log p - log q)`` of two discrete distributions (over ``p > 0``)."""
    p, q = np.asarray(p, dtype=float), np.asarray(q, dtype=float)
    nz = p > 0
    return float(np.sum(p[nz] * (np.log(p[nz]) - np.log(q[nz]))))

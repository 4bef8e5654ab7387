"""Small helpers shared by the numerical checks of :mod:`vslbook.bounds`: seeded streams,
argument validation, the worst element of an element-wise comparison."""

from __future__ import annotations

import math

import numpy as np
import torch

from vslbook.bounds import Check


def _rng(seed: int, stream: int = 0) -> np.random.Generator:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    return np.random.default_rng([int(seed), stream])


def _worst(
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


def _positive(name: str, value: float) -> float:
    if not (isinstance(value, (int, float, np.floating)) and value > 0 and math.isfinite(value)):
        raise ValueError(f"{name} must be a positive finite number, got {value!r}")
    return float(value)


def _count(name: str, value: int, minimum: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def _t(x: np.ndarray | float) -> torch.Tensor:
    return torch.as_tensor(np.asarray(x, dtype=float), dtype=torch.float64)


def _np(x: torch.Tensor | np.ndarray | float) -> np.ndarray:
    if isinstance(x, torch.Tensor):
        return x.detach().cpu().numpy()
    return np.asarray(x, dtype=float)


def _random_spd(rng: np.random.Generator, d: int, scale: float = 1.0) -> np.ndarray:
    a = rng.normal(size=(d, d)) / math.sqrt(d)
    return scale * (a @ a.T + 0.5 * np.eye(d))


def _check_distribution(name: str, probs: np.ndarray, shape: tuple[int, ...], axis: int = -1):
    probs = np.asarray(probs, dtype=float)
    if probs.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {probs.shape}")
    if np.any(probs < 0) or not np.allclose(probs.sum(axis), 1.0, atol=1e-8):
        raise ValueError(
            f"{name} must be non-negative and sum to 1 along axis {axis}; sums are "
            f"{np.round(probs.sum(axis), 6)}"
        )
    return probs


def _linear_gaussian_joint(
    coupling: np.ndarray, offset: np.ndarray, std: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Mean and covariance of ``x = M x + m + diag(std) eps`` with ``M`` nilpotent."""
    a = np.linalg.inv(np.eye(offset.size) - coupling)
    s = a * std[None, :]
    return a @ offset, s @ s.T

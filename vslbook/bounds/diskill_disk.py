"""An energy-based context distribution on the 5-link reacher's goal disk (Section 4.3, Eq. 4.6).

Chapter 4 draws contexts from ``pi(c|o) ∝ exp phi(c)`` by resampling a batch of environment
resets with ``softmax_i phi(c_i)``. On the disk of radius 0.5 the exact masses of that
density are integrals in polar coordinates; :func:`polar_integral` computes them by
Gauss–Legendre quadrature, so the categorical's masses can be checked against them.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

RADIUS = 0.5  # the goal disk of the 5-link reacher (vslbook.envs.robot.reacher5)


def two_mode_energy(c: np.ndarray) -> np.ndarray:
    """A hand-made energy phi(c) with two modes, one on the disk's edge; defined everywhere,
    also outside the disk (Eq. 4.6 needs it only on the support of p(c))."""
    c = np.asarray(c, dtype=float)
    edge = 3.0 * np.exp(-np.sum((c - [0.42, 0.28]) ** 2, axis=-1) / (2 * 0.12**2))
    inner = 2.0 * np.exp(-np.sum((c - [-0.22, -0.25]) ** 2, axis=-1) / (2 * 0.1**2))
    return edge + inner - 1.0 * c[..., 1]


def polar_integral(
    f: Callable[[np.ndarray], np.ndarray],
    t_low: float,
    t_high: float,
    radius: float = RADIUS,
    n: int = 128,
) -> float:
    """∫ f over the sector {r <= radius, t_low <= t <= t_high}: Gauss–Legendre with ``n``
    nodes in r and in t, and the Jacobian r of polar coordinates."""
    x, w = np.polynomial.legendre.leggauss(n)
    r, wr = 0.5 * radius * (x + 1), 0.5 * radius * w
    t, wt = t_low + 0.5 * (t_high - t_low) * (x + 1), 0.5 * (t_high - t_low) * w
    rr, tt = np.meshgrid(r, t, indexing="ij")
    pts = np.stack([rr * np.cos(tt), rr * np.sin(tt)], axis=-1)
    return float(np.sum(wr[:, None] * wt[None, :] * rr * f(pts)))


def categorical_mass(q: np.ndarray, inside: np.ndarray) -> tuple[float, float]:
    """Mass ``sum_i q_i 1[c_i in A]`` of a self-normalised categorical over a batch, and its
    delta-method standard error ``sqrt(sum_i q_i² (1[c_i in A] − mass)²)``."""
    mass = float(q @ inside)
    return mass, float(np.sqrt(np.sum(q**2 * (inside - mass) ** 2)))


def moment_matched_gaussian(q: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and covariance of the categorical with probabilities ``q`` over the points ``c``."""
    mean = q @ c
    return mean, (c - mean).T @ ((c - mean) * q[:, None])

"""Gaussian Markov chains in closed form, for the diffusion KL of Section 2.6 (Eqs. 2.65, 2.66).

A chain whose every step is linear-Gaussian is one joint Gaussian over all its states;
:func:`chain_joint` gives its moments, so the KL between two chains (Eq. 2.65) is a KL
between two Gaussians. :func:`expected_log_normal` gives the per-step terms of Eq. 2.66.
"""

from __future__ import annotations

import math

import numpy as np


def expected_log_normal(mean_diff_sq: float, v: float) -> float:
    """E[log N(y | mu, v)] when E[(y − mu)²] = ``mean_diff_sq``:
    −½ log(2π v) − mean_diff_sq / (2 v)."""
    return -0.5 * math.log(2 * math.pi * v) - mean_diff_sq / (2 * v)


def chain_joint(B: np.ndarray, b: np.ndarray, std: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and covariance of x = B x + b + diag(std) eps, eps ~ N(0, I), for a nilpotent B
    (each state depends linearly on earlier ones): x = (I − B)⁻¹ (b + diag(std) eps)."""
    inv = np.linalg.inv(np.eye(len(b)) - B)
    return inv @ b, (inv * std) @ (inv * std).T


def log_normal(x: np.ndarray, mean: np.ndarray | float, var: np.ndarray | float) -> np.ndarray:
    """log N(x | mean, var) elementwise, for scalar variables: the log density of one
    Gaussian kernel of a chain."""
    return -0.5 * ((x - mean) ** 2 / var + np.log(2 * np.pi * var))

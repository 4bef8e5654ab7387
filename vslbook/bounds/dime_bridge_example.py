"""The one-dimensional linear bridge of Chapter 5's general-bridge check (Section 5.6).

Drift and controls are affine in the action, so every kernel of Eqs. 5.32–5.36 is
Gaussian and Eq. 5.37 has a closed form against a Gaussian target
(`vslbook.bounds.dime_bridges_linear.linear_bridge_closed_form`). The notebook runs the
chain with these functions by hand and compares with the package's estimator.
"""

from __future__ import annotations

import numpy as np


def reference_drift(a: np.ndarray, n: int) -> np.ndarray:
    """f(a, n) = −a/2: the reference (OU) drift of Eq. 5.29."""
    return -0.5 * a


def forward_control(a: np.ndarray, n: int) -> np.ndarray:
    """u(a, n) = 0.4 a + 0.2: the learned control of the noising process (Eq. 5.35)."""
    return 0.4 * a + 0.2


def backward_control(a: np.ndarray, n: int) -> np.ndarray:
    """v(a, n) = −1.2 a + 0.1 n: the learned control of the denoising process (Eq. 5.36)."""
    return -1.2 * a + 0.1 * n


def gaussian_target_q(mu: float, s: float):
    """Q(a) = −(a − mu)² / (2 s²) on actions of shape (B, 1): the target of Eq. 5.38 is then
    N(mu, s²), with log Z = ½ log(2π s²)."""

    def q(a: np.ndarray) -> np.ndarray:
        return -((a[:, 0] - mu) ** 2) / (2 * s**2)

    return q

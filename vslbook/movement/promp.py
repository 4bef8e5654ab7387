"""Probabilistic Movement Primitives (Paraschos et al., 2013; thesis Eq. 2.46).

A ProMP writes the trajectory of each degree of freedom (dof) as a linear function of its
weights, ``tau = Phi^T theta`` (Eq. 2.46), where ``Phi`` holds normalised RBFs over the phase
``s = t / duration``. Because the map is linear, a Gaussian over the weights gives a Gaussian
over trajectories in closed form, and conditioning on a via-point is a Kalman update.

Layout conventions:

* weights ``w`` have shape ``(..., n_dof * n_basis)``, dof-major: ``w[..., d * n_basis + i]``
  multiplies basis ``i`` of dof ``d``;
* trajectories have shape ``(..., T, n_dof)``;
* the full trajectory covariance is over the flattened ``(T, n_dof)`` array, index
  ``t * n_dof + d``.
"""

from __future__ import annotations

import numpy as np
import torch

from vslbook.movement.basis import (
    Array,
    as_float_tensor,
    check_gaussian,
    check_int,
    check_last_dim,
    check_positive,
    check_square,
    normalized_rbf,
    normalized_rbf_np,
    time_grid_np,
)


class ProMP:
    """ProMP with ``n_basis`` normalised RBFs per degree of freedom (thesis Eq. 2.46).

    Args:
        n_basis: basis functions per dof (>= 1).
        n_dof: degrees of freedom (>= 1).
        duration: length of the movement in seconds; the phase is ``s = t / duration``.
        dt: time step of the output grid :attr:`times`.
        width: RBF width in phase units; ``None`` uses the spacing of the centres.
        dtype: floating dtype of all returned tensors.
    """

    def __init__(
        self,
        n_basis: int,
        n_dof: int,
        duration: float = 1.0,
        dt: float = 0.01,
        width: float | None = None,
        *,
        dtype: torch.dtype = torch.float64,
    ) -> None:
        self.n_basis = check_int("n_basis", n_basis)
        self.n_dof = check_int("n_dof", n_dof)
        self.duration = check_positive("duration", duration)
        self.dt = check_positive("dt", dt)
        self.width = None if width is None else check_positive("width", width)
        self.dtype = dtype
        self.n_params = self.n_dof * self.n_basis
        t = time_grid_np(self.duration, self.dt)
        self.times = torch.from_numpy(t).to(dtype)
        # The basis and its time derivative, computed once in float64 numpy
        # (see basis.normalized_rbf_np); trajectory_numpy reads them as they are.
        s = t / self.duration
        phi = normalized_rbf_np(s, self.n_basis, self.width)
        dphi = normalized_rbf_np(s, self.n_basis, self.width, derivative=True) / self.duration
        self._np = (phi, dphi)
        self._phi, self._dphi = (torch.from_numpy(v).to(dtype) for v in self._np)
        for arr in self._np:  # shared with the float64 tensors: neither is ever written
            arr.flags.writeable = False

    def _basis_at(self, t: torch.Tensor, derivative: bool = False) -> torch.Tensor:
        """Basis (or its time derivative) at times ``t``, shape ``(*t.shape, n_basis)``."""
        psi = normalized_rbf(t / self.duration, self.n_basis, self.width, derivative=derivative)
        return psi / self.duration if derivative else psi

    def basis_matrix(self, derivative: bool = False) -> torch.Tensor:
        """``Phi`` of Eq. 2.46 on :attr:`times`, shape ``(T, n_basis)``; ``d Phi / dt`` if asked."""
        return (self._dphi if derivative else self._phi).clone()

    def _weights(self, w: Array) -> torch.Tensor:
        w = check_last_dim(
            "w", as_float_tensor("w", w, self.dtype), self.n_params, "n_dof * n_basis"
        )
        return w.reshape(*w.shape[:-1], self.n_dof, self.n_basis)

    def trajectory(self, w: Array) -> torch.Tensor:
        """Positions ``Phi^T theta`` (Eq. 2.46) for weights ``(..., n_dof * n_basis)``.

        Returns a tensor of shape ``(..., T, n_dof)``.
        """
        return torch.einsum("ti,...di->...td", self._phi, self._weights(w))

    def velocity(self, w: Array) -> torch.Tensor:
        """Velocities ``(dPhi/dt)^T theta`` for weights ``(..., n_dof * n_basis)``.

        Returns a tensor of shape ``(..., T, n_dof)``.
        """
        return torch.einsum("ti,...di->...td", self._dphi, self._weights(w))

    def trajectory_numpy(self, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Positions and velocities (:meth:`trajectory`, :meth:`velocity`) for float64 numpy
        weights ``(..., n_dof * n_basis)``, without torch: what a simulator that builds a
        ProMP for every parameter vector (a learned duration) calls."""
        w = np.asarray(w, dtype=np.float64)
        if w.ndim < 1 or w.shape[-1] != self.n_params:
            raise ValueError(f"w must have shape (..., {self.n_params}), got {w.shape}")
        w = w.reshape(*w.shape[:-1], self.n_dof, self.n_basis).swapaxes(-1, -2)
        phi, dphi = self._np
        return phi @ w, dphi @ w

    def _observation_matrix(self, phi: torch.Tensor) -> torch.Tensor:
        """Map from weights to the flattened ``(len(phi), n_dof)`` positions, ``(len * n_dof, P)``.

        Row ``t * n_dof + d`` holds ``phi[t]`` in the columns of dof ``d``.
        """
        eye = torch.eye(self.n_dof, dtype=self.dtype)
        block = torch.einsum("ti,de->tdei", phi, eye)
        return block.reshape(phi.shape[0] * self.n_dof, self.n_params)

    def _gaussian(self, mean_w: Array, cov_w: Array) -> tuple[torch.Tensor, torch.Tensor]:
        mean_w = as_float_tensor("mean_w", mean_w, self.dtype)
        cov_w = as_float_tensor("cov_w", cov_w, self.dtype)
        return check_gaussian(mean_w, cov_w, self.n_params, "n_dof * n_basis", ("mean_w", "cov_w"))

    def distribution(self, mean_w: Array, cov_w: Array) -> tuple[torch.Tensor, torch.Tensor]:
        """Trajectory distribution for weights ``theta ~ N(mean_w, cov_w)`` (Eq. 2.46 is linear).

        Args:
            mean_w: shape ``(..., n_dof * n_basis)``.
            cov_w: shape ``(..., n_dof * n_basis, n_dof * n_basis)``, broadcast against mean_w.

        Returns:
            ``(mean, cov)`` with mean ``(..., T, n_dof)`` and the full covariance
            ``A cov_w A^T`` of shape ``(..., T * n_dof, T * n_dof)`` (index ``t * n_dof + d``).
            Use :meth:`marginal_std` when only the per-time spread is needed.
        """
        mean_w, cov_w = self._gaussian(mean_w, cov_w)
        a = self._observation_matrix(self._phi)
        return self.trajectory(mean_w), a @ cov_w @ a.T

    def marginal_std(self, cov_w: Array) -> torch.Tensor:
        """Per-time standard deviation of the positions, shape ``(..., T, n_dof)``.

        Only the diagonal blocks of ``cov_w`` (the within-dof covariances) enter, so this costs
        ``O(T n_dof n_basis^2)`` instead of forming the full trajectory covariance.
        """
        cov_w = as_float_tensor("cov_w", cov_w, self.dtype)
        check_square("cov_w", cov_w, self.n_params, "n_dof * n_basis")
        blocks = cov_w.reshape(*cov_w.shape[:-2], self.n_dof, self.n_basis, self.n_dof, -1)
        blocks = torch.diagonal(blocks, dim1=-4, dim2=-2).movedim(-1, -3)
        var = torch.einsum("ti,...dij,tj->...td", self._phi, blocks, self._phi)
        return var.clamp_min(0.0).sqrt()

    def condition(
        self,
        mean_w: Array,
        cov_w: Array,
        t: float,
        y: Array,
        y_std: float | Array,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Condition the weight Gaussian on passing through ``y`` at time ``t`` (a via-point).

        The observation model is ``y = A_t theta + eps`` with ``A_t`` the basis at ``t`` for each
        dof and ``eps ~ N(0, diag(y_std^2))``. The Kalman update reads

        ``S = A_t cov A_t^T + R``, ``K = cov A_t^T S^-1``,
        ``mean' = mean + K (y - A_t mean)``, ``cov' = cov - K A_t cov``.

        Args:
            mean_w: ``(..., n_dof * n_basis)``.
            cov_w: ``(..., n_dof * n_basis, n_dof * n_basis)``.
            t: time of the via-point in ``[0, duration]`` (need not lie on :attr:`times`).
            y: desired position ``(..., n_dof)``.
            y_std: observation noise, a positive number or ``(n_dof,)`` positive values.

        Returns:
            The conditioned ``(mean_w, cov_w)``, batch shapes broadcast together (the new
            covariance does not depend on ``y``).
        """
        mean_w, cov_w = self._gaussian(mean_w, cov_w)
        real = isinstance(t, (int, float, np.integer, np.floating)) and not isinstance(t, bool)
        if not real or not 0.0 <= t <= self.duration:
            raise ValueError(f"t must be a time in [0, duration={self.duration}], got {t!r}")
        y = check_last_dim("y", as_float_tensor("y", y, self.dtype), self.n_dof, "n_dof")
        y_std = as_float_tensor("y_std", y_std, self.dtype)
        if y_std.dim() > 1 or (y_std.dim() == 1 and y_std.shape[0] != self.n_dof):
            raise ValueError(
                f"y_std must be a number or have shape ({self.n_dof},), got shape "
                f"{tuple(y_std.shape)}"
            )
        if not bool(torch.all(y_std > 0)) or not bool(torch.all(torch.isfinite(y_std))):
            raise ValueError(f"y_std must be finite and positive, got {y_std.tolist()}")

        a = self._observation_matrix(self._basis_at(torch.tensor([float(t)], dtype=self.dtype)))
        noise = torch.diag_embed(y_std.expand(self.n_dof) ** 2)
        cov_at = cov_w @ a.T
        s = a @ cov_at + noise
        chol, info = torch.linalg.cholesky_ex(s)
        if bool(torch.any(info != 0)):
            raise ValueError("cov_w must be positive semi-definite; A cov_w A^T + R is not PD")
        gain = torch.cholesky_solve(cov_at.mT, chol).mT
        residual = y - torch.einsum("ep,...p->...e", a, mean_w)
        new_mean = mean_w + torch.einsum("...pe,...e->...p", gain, residual)
        new_cov = cov_w - gain @ cov_at.mT
        new_cov = 0.5 * (new_cov + new_cov.mT)
        return new_mean, new_cov.expand(*new_mean.shape[:-1], self.n_params, self.n_params)

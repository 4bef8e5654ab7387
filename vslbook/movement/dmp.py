"""Dynamic Movement Primitives (Schaal, 2006; Ijspeert et al., 2013; thesis Eq. 2.45).

Each degree of freedom (dof) follows the second-order system of Eq. 2.45,

    tau^2 y'' = alpha (beta (g - y) - tau y') + f(x),    f(x) = x phi(x)^T theta,

with the canonical phase ``x(t) = exp(-alpha_x t / tau)`` (``tau`` is written gamma in the
thesis). The default ``beta = alpha / 4`` makes the spring-damper critically damped, so the
system converges to ``g`` without overshoot once the forcing term has decayed.

Forcing convention: ``f(x) = x phi(x)^T theta`` exactly as in Eq. 2.45, *without* the common
extra factor ``(g - y0)``. The system is then linear in ``(theta, g)``, which is what
:class:`~vslbook.movement.prodmp.ProDMP` exploits, and it is well defined when ``g = y0``.

Weights have shape ``(..., n_dof * n_basis)``, dof-major (``w[..., d * n_basis + i]``).
"""

from __future__ import annotations

import torch

from vslbook.movement.basis import (
    Array,
    as_float_tensor,
    check_int,
    check_last_dim,
    check_positive,
    dmp_forcing_basis,
    time_grid,
)


class DMP:
    """DMP of Eq. 2.45 integrated numerically with semi-implicit Euler.

    Args:
        n_basis: forcing basis functions per dof (>= 1).
        n_dof: degrees of freedom (>= 1).
        duration: length of the rollout in seconds.
        dt: time step of the output grid :attr:`times`.
        alpha: spring-damper constant ``alpha`` (> 0).
        beta: spring constant ``beta`` (> 0); ``None`` means ``alpha / 4`` (critical damping).
        tau: temporal scaling (gamma in the thesis, > 0).
        alpha_x: decay rate of the canonical phase (> 0).
        bandwidth_factor: scales the bandwidths of the phase-space Gaussians (Eq. B2).
        rule: how the last Gaussian's bandwidth is set, ``"di-skill"`` or
            ``"mp_pytorch-0.1.3"`` (:func:`~vslbook.movement.basis.phase_rbf_centres`).
        substeps: Euler steps per output step ``dt`` (>= 1).
        dtype: floating dtype of all returned tensors.
    """

    def __init__(
        self,
        n_basis: int,
        n_dof: int,
        duration: float = 1.0,
        dt: float = 0.01,
        alpha: float = 25.0,
        beta: float | None = None,
        tau: float = 1.0,
        alpha_x: float = 3.0,
        bandwidth_factor: float = 3.0,
        substeps: int = 10,
        *,
        rule: str = "di-skill",
        dtype: torch.dtype = torch.float64,
    ) -> None:
        self.n_basis = check_int("n_basis", n_basis)
        self.n_dof = check_int("n_dof", n_dof)
        self.duration = check_positive("duration", duration)
        self.dt = check_positive("dt", dt)
        self.alpha = check_positive("alpha", alpha)
        self.beta = self.alpha / 4.0 if beta is None else check_positive("beta", beta)
        self.tau = check_positive("tau", tau)
        self.alpha_x = check_positive("alpha_x", alpha_x)
        self.bandwidth_factor = check_positive("bandwidth_factor", bandwidth_factor)
        self.rule = rule
        self.substeps = check_int("substeps", substeps)
        self.dtype = dtype
        self.n_params = self.n_dof * self.n_basis
        self.times = time_grid(self.duration, self.dt, dtype=dtype)
        # Forcing basis x phi(x) at every Euler step k * dt / substeps, shape (K, n_basis).
        n_fine = (len(self.times) - 1) * self.substeps
        fine_times = torch.arange(n_fine, dtype=dtype) * (self.dt / self.substeps)
        self._forcing_basis = dmp_forcing_basis(
            fine_times, self.n_basis, self.alpha_x, self.tau, self.bandwidth_factor, rule
        )

    def forcing(self, w: Array) -> torch.Tensor:
        """Forcing ``f = x phi(x)^T theta`` (Eq. 2.45) on :attr:`times`, ``(..., T, n_dof)``."""
        w = check_last_dim(
            "w", as_float_tensor("w", w, self.dtype), self.n_params, "n_dof * n_basis"
        )
        w = w.reshape(*w.shape[:-1], self.n_dof, self.n_basis)
        basis = dmp_forcing_basis(
            self.times, self.n_basis, self.alpha_x, self.tau, self.bandwidth_factor, self.rule
        )
        return torch.einsum("ti,...di->...td", basis, w)

    def rollout(
        self, w: Array, y0: Array, dy0: Array, goal: Array
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Integrate Eq. 2.45 from ``(y0, dy0)`` towards ``goal``.

        Each output step ``dt`` is split into :attr:`substeps` semi-implicit Euler steps of
        size ``h``: ``v <- v + h y''(y, v, t)``, then ``y <- y + h v``.

        Args:
            w: forcing weights ``(..., n_dof * n_basis)``.
            y0: initial positions ``(..., n_dof)``.
            dy0: initial velocities ``(..., n_dof)``.
            goal: goal attractors ``(..., n_dof)``.

        Returns:
            ``(positions, velocities)``, each ``(..., T, n_dof)`` with all batch shapes
            broadcast together; index 0 holds ``(y0, dy0)``.
        """
        w = check_last_dim(
            "w", as_float_tensor("w", w, self.dtype), self.n_params, "n_dof * n_basis"
        )
        y = check_last_dim("y0", as_float_tensor("y0", y0, self.dtype), self.n_dof, "n_dof")
        v = check_last_dim("dy0", as_float_tensor("dy0", dy0, self.dtype), self.n_dof, "n_dof")
        g = check_last_dim("goal", as_float_tensor("goal", goal, self.dtype), self.n_dof, "n_dof")
        batch = torch.broadcast_shapes(w.shape[:-1], y.shape[:-1], v.shape[:-1], g.shape[:-1])
        y, v = y.expand(*batch, self.n_dof), v.expand(*batch, self.n_dof)

        w = w.reshape(*w.shape[:-1], self.n_dof, self.n_basis)
        force = torch.einsum("ki,...di->...kd", self._forcing_basis, w)
        h, a, b, tau = self.dt / self.substeps, self.alpha, self.beta, self.tau
        positions, velocities = [y], [v]
        for k in range(self._forcing_basis.shape[0]):
            acc = (a * (b * (g - y) - tau * v) + force[..., k, :]) / tau**2
            v = v + h * acc
            y = y + h * v
            if (k + 1) % self.substeps == 0:
                positions.append(y)
                velocities.append(v)
        return torch.stack(positions, dim=-2), torch.stack(velocities, dim=-2)

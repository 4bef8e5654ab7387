"""Probabilistic Dynamic Movement Primitives (Li et al., 2023, "ProDMP: A Unified Perspective
on Dynamic and Probabilistic Movement Primitives"; thesis Sec. 2.6.1).

A ProDMP solves the DMP of Eq. 2.45 in closed form instead of integrating it for every
parameter vector. With the critically damped choice ``beta = alpha / 4`` and
``a = alpha / (2 tau)``, Eq. 2.45 divided by ``tau^2`` reads

    y'' + 2 a y' + a^2 y = a^2 g + f(t) / tau^2,    f(t) = x(t) phi(x(t))^T w.

Its homogeneous solutions are ``y1 = exp(-a t)`` and ``y2 = t exp(-a t)`` (Wronskian
``exp(-2 a t)``), and variation of parameters gives the particular solution (Li et al., 2023)

    y_p(t) = y2(t) p2(t)^T w - y1(t) p1(t)^T w + g,
    p1(t) = int_0^t s exp(a s) x phi(x) / tau^2 ds,   p2(t) = int_0^t exp(a s) x phi(x) / tau^2 ds.

The position basis ``Phi(t) = [y2 p2 - y1 p1, 1]`` is linear in the parameters
``w_g = [w, g]`` of each dof and is integrated numerically once, at construction. Its time
derivative is ``[y2' p2 - y1' p1, 0]`` (the terms with ``p1'`` and ``p2'`` cancel). A trajectory
is then

    y(t) = c1 y1(t) + c2 y2(t) + Phi(t)^T w_g,

with ``c1, c2`` solved from ``y(t0) = y0`` and ``y'(t0) = dy0`` at ``t0 = 0`` (a 2x2 system
whose determinant is the Wronskian), so the initial conditions hold exactly for any ``w_g``.

Parameters have shape ``(..., n_dof * (n_basis + 1))``, one block ``[w_1..w_n, g]`` per dof.
The forcing convention is the one of :class:`~vslbook.movement.dmp.DMP` (no ``(g - y0)`` factor).
"""

from __future__ import annotations

import torch

from vslbook.movement.basis import (
    Array,
    _as_tensor,
    _check_gaussian,
    _check_int,
    _check_last_dim,
    _check_positive,
    dmp_forcing_basis,
    time_grid,
)


def _cumulative_trapezoid(values: torch.Tensor, h: float) -> torch.Tensor:
    """``int_0^{t_k} values dt`` along dim 0 for samples spaced ``h`` apart (trapezoid rule)."""
    steps = 0.5 * h * (values[1:] + values[:-1])
    return torch.cat([torch.zeros_like(values[:1]), torch.cumsum(steps, dim=0)])


class ProDMP:
    """ProDMP: the DMP of Eq. 2.45 with positions linear in ``[w, g]`` (Li et al., 2023).

    Args:
        n_basis: forcing basis functions per dof (>= 1).
        n_dof: degrees of freedom (>= 1).
        duration: length of the trajectory in seconds.
        dt: time step of the output grid :attr:`times`.
        alpha: spring-damper constant (> 0); ``beta = alpha / 4`` (critical damping).
        tau: temporal scaling (gamma in the thesis, > 0).
        alpha_x: decay rate of the canonical phase (> 0).
        width: RBF width in units of ``t / tau``; ``None`` uses the spacing of the centres.
        substeps: trapezoid steps per output step ``dt`` when precomputing the basis (>= 1).
        dtype: floating dtype of all returned tensors (the basis is computed in float64).
    """

    def __init__(
        self,
        n_basis: int,
        n_dof: int,
        duration: float = 1.0,
        dt: float = 0.01,
        alpha: float = 25.0,
        tau: float = 1.0,
        alpha_x: float = 3.0,
        width: float | None = None,
        substeps: int = 10,
        *,
        dtype: torch.dtype = torch.float64,
    ) -> None:
        self.n_basis = _check_int("n_basis", n_basis)
        self.n_dof = _check_int("n_dof", n_dof)
        self.duration = _check_positive("duration", duration)
        self.dt = _check_positive("dt", dt)
        self.alpha = _check_positive("alpha", alpha)
        self.beta = self.alpha / 4.0
        self.tau = _check_positive("tau", tau)
        self.alpha_x = _check_positive("alpha_x", alpha_x)
        self.width = None if width is None else _check_positive("width", width)
        self.substeps = _check_int("substeps", substeps)
        self.dtype = dtype
        self.n_params = self.n_dof * (self.n_basis + 1)
        self.times = time_grid(self.duration, self.dt, dtype=dtype)

        a = self.alpha / (2.0 * self.tau)
        if a * float(self.times[-1]) > 600.0:
            raise ValueError(
                f"alpha * duration / (2 tau) must be at most 600 so that exp(a t) stays finite, "
                f"got {a * float(self.times[-1]):.1f}"
            )
        t = time_grid(self.duration, self.dt, dtype=torch.float64)
        y1, y2 = torch.exp(-a * t), t * torch.exp(-a * t)
        dy1, dy2 = -a * y1, (1.0 - a * t) * torch.exp(-a * t)

        # p1, p2 on a grid `substeps` times finer than `times`, then read off at `times`.
        h = self.dt / self.substeps
        fine = torch.arange((len(t) - 1) * self.substeps + 1, dtype=torch.float64) * h
        forcing = dmp_forcing_basis(fine, self.n_basis, self.alpha_x, self.tau, self.width)
        forcing = forcing / self.tau**2
        grow = torch.exp(a * fine).unsqueeze(-1)
        p1 = _cumulative_trapezoid(fine.unsqueeze(-1) * grow * forcing, h)[:: self.substeps]
        p2 = _cumulative_trapezoid(grow * forcing, h)[:: self.substeps]

        ones, zeros = torch.ones_like(t).unsqueeze(-1), torch.zeros_like(t).unsqueeze(-1)
        phi = torch.cat([y2[:, None] * p2 - y1[:, None] * p1, ones], dim=-1)
        dphi = torch.cat([dy2[:, None] * p2 - dy1[:, None] * p1, zeros], dim=-1)
        homogeneous = torch.stack([y1, y2], dim=-1)
        d_homogeneous = torch.stack([dy1, dy2], dim=-1)

        self._phi, self._dphi = phi.to(dtype), dphi.to(dtype)
        self._y, self._dy = homogeneous.to(dtype), d_homogeneous.to(dtype)

        # Positions as one linear map of (w_g, y0, dy0): with M = [[y1, y2], [y1', y2']](t0)
        # and B0 = [Phi(t0), Phi'(t0)], c = M^-1 ([y0, dy0] - B0 w_g), hence
        # y(t) = (Phi(t)^T - [y1, y2](t) M^-1 B0) w_g + [y1, y2](t) M^-1 [y0, dy0].
        m_inv = torch.linalg.inv(torch.stack([homogeneous[0], d_homogeneous[0]]))
        init = homogeneous @ m_inv
        self._param_map = (phi - init @ torch.stack([phi[0], dphi[0]])).to(dtype)

    def basis_matrix(self, derivative: bool = False) -> torch.Tensor:
        """Position basis ``Phi(t) = [y2 p2 - y1 p1, 1]`` on :attr:`times`, ``(T, n_basis + 1)``.

        The last column multiplies the goal ``g``. ``derivative=True`` returns ``d Phi / dt``.
        This is the particular-solution basis; the initial conditions enter through ``c1, c2``.
        """
        return (self._dphi if derivative else self._phi).clone()

    def _check_state(self, y0: Array, dy0: Array) -> tuple[torch.Tensor, torch.Tensor]:
        y0 = _check_last_dim("y0", _as_tensor("y0", y0, self.dtype), self.n_dof, "n_dof")
        dy0 = _check_last_dim("dy0", _as_tensor("dy0", dy0, self.dtype), self.n_dof, "n_dof")
        return y0, dy0

    def _params(self, params: Array, name: str = "params") -> torch.Tensor:
        params = _as_tensor(name, params, self.dtype)
        return _check_last_dim(name, params, self.n_params, "n_dof * (n_basis + 1)")

    def trajectory(self, params: Array, y0: Array, dy0: Array) -> tuple[torch.Tensor, torch.Tensor]:
        """Positions and velocities for parameters ``(..., n_dof * (n_basis + 1))``.

        Args:
            params: per dof ``[w_1, ..., w_n, g]``.
            y0: initial positions ``(..., n_dof)`` at ``t0 = 0``.
            dy0: initial velocities ``(..., n_dof)`` at ``t0 = 0``.

        Returns:
            ``(positions, velocities)``, each ``(..., T, n_dof)`` with the batch shapes
            broadcast together; ``positions[..., 0, :] == y0`` and
            ``velocities[..., 0, :] == dy0`` up to rounding.
        """
        params = self._params(params)
        y0, dy0 = self._check_state(y0, dy0)
        w_g = params.reshape(*params.shape[:-1], self.n_dof, self.n_basis + 1)
        pos_p = torch.einsum("tp,...dp->...td", self._phi, w_g)
        vel_p = torch.einsum("tp,...dp->...td", self._dphi, w_g)

        # Solve [[y1, y2], [y1', y2']](t0) [c1, c2] = [y0 - y_p(t0), dy0 - y_p'(t0)] by Cramer.
        (y1, y2), (dy1, dy2) = self._y[0], self._dy[0]
        wronskian = y1 * dy2 - y2 * dy1
        r0, r1 = y0 - pos_p[..., 0, :], dy0 - vel_p[..., 0, :]
        c1 = (dy2 * r0 - y2 * r1) / wronskian
        c2 = (y1 * r1 - dy1 * r0) / wronskian
        c = torch.stack([c1, c2], dim=-2)  # (..., 2, n_dof)
        positions = torch.einsum("tj,...jd->...td", self._y, c) + pos_p
        velocities = torch.einsum("tj,...jd->...td", self._dy, c) + vel_p
        return positions, velocities

    def distribution(
        self, mean_params: Array, cov_params: Array, y0: Array, dy0: Array
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Mean and per-time std of the positions for ``params ~ N(mean_params, cov_params)``.

        Positions are affine in the parameters for fixed ``(y0, dy0)``,
        ``y(t) = H(t)^T w_g + const`` with ``H(t) = Phi(t) - [y1, y2](t) M^-1 [Phi, Phi'](t0)``,
        so the distribution is Gaussian with mean ``trajectory(mean_params)`` and variance
        ``H(t)^T Sigma_dd H(t)`` for dof ``d`` (``Sigma_dd`` the dof's diagonal block).

        Args:
            mean_params: ``(..., n_dof * (n_basis + 1))``.
            cov_params: ``(..., P, P)`` with ``P = n_dof * (n_basis + 1)``.
            y0, dy0: deterministic initial state ``(..., n_dof)``.

        Returns:
            ``(mean, std)``, each ``(..., T, n_dof)``; the std is zero at ``t0``.
        """
        mean = self._params(mean_params, "mean_params")
        cov = _as_tensor("cov_params", cov_params, self.dtype)
        what, names = "n_dof * (n_basis + 1)", ("mean_params", "cov_params")
        mean, cov = _check_gaussian(mean, cov, self.n_params, what, names)
        mean_pos, _ = self.trajectory(mean, y0, dy0)
        n = self.n_basis + 1
        blocks = cov.reshape(*cov.shape[:-2], self.n_dof, n, self.n_dof, n)
        blocks = torch.diagonal(blocks, dim1=-4, dim2=-2).movedim(-1, -3)
        var = torch.einsum("tp,...dpq,tq->...td", self._param_map, blocks, self._param_map)
        std = var.clamp_min(0.0).sqrt()
        return mean_pos, std.expand_as(mean_pos)

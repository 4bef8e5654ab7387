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

from typing import TypeVar

import numpy as np
import torch

from vslbook.movement.basis import (
    Array,
    _as_tensor,
    _check_gaussian,
    _check_int,
    _check_last_dim,
    _check_positive,
    dmp_forcing_basis_np,
    time_grid_np,
)

_A = TypeVar("_A", torch.Tensor, np.ndarray)


def _cumulative_trapezoid(values: np.ndarray, h: float) -> np.ndarray:
    """``int_0^{t_k} values dt`` along the last axis for samples spaced ``h`` apart
    (trapezoid rule)."""
    out = np.empty_like(values)
    out[..., 0] = 0.0
    np.cumsum(0.5 * h * (values[..., 1:] + values[..., :-1]), axis=-1, out=out[..., 1:])
    return out


def _solve_initial(phi: _A, dphi: _A, y: _A, dy: _A, w_g: _A, y0: _A, dy0: _A) -> tuple[_A, _A]:
    """Positions and velocities ``(..., T, n_dof)`` of parameters ``w_g (..., n_dof, P)``
    from the bases ``Phi, Phi' (T, P)`` and ``[y1, y2], [y1', y2'] (T, 2)``: the particular
    solution plus ``c1 y1 + c2 y2`` with ``c1, c2`` from ``y(t0) = y0``, ``y'(t0) = dy0``
    (a 2x2 system solved by Cramer's rule; its determinant is the Wronskian). The same
    expression for torch tensors (differentiable) and numpy arrays."""
    pos_p = phi @ w_g.swapaxes(-1, -2)
    vel_p = dphi @ w_g.swapaxes(-1, -2)
    (y1, y2), (dy1, dy2) = y[0], dy[0]
    wronskian = y1 * dy2 - y2 * dy1
    r0, r1 = y0 - pos_p[..., 0, :], dy0 - vel_p[..., 0, :]
    c1 = ((dy2 * r0 - y2 * r1) / wronskian)[..., None, :]
    c2 = ((y1 * r1 - dy1 * r0) / wronskian)[..., None, :]
    positions = y[:, :1] * c1 + y[:, 1:] * c2 + pos_p
    velocities = dy[:, :1] * c1 + dy[:, 1:] * c2 + vel_p
    return positions, velocities


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
        a = self.alpha / (2.0 * self.tau)
        t = time_grid_np(self.duration, self.dt)
        if a * float(t[-1]) > 600.0:
            raise ValueError(
                f"alpha * duration / (2 tau) must be at most 600 so that exp(a t) stays finite, "
                f"got {a * float(t[-1]):.1f}"
            )
        self.times = torch.from_numpy(t).to(dtype)
        # The bases are computed once, in float64 numpy (see basis.normalized_rbf_np).
        decay = np.exp(-a * t)
        y1, y2 = decay, t * decay
        dy1, dy2 = -a * y1, (1.0 - a * t) * decay

        # p1, p2 on a grid `substeps` times finer than `times`, then read off at `times`.
        h = self.dt / self.substeps
        fine = np.arange((len(t) - 1) * self.substeps + 1, dtype=np.float64) * h
        # (basis, time) layout: the integrals run along contiguous rows
        forcing = dmp_forcing_basis_np(
            fine, self.n_basis, self.alpha_x, self.tau, self.width, basis_first=True
        )
        integrand = np.exp(a * fine) * forcing / self.tau**2
        p2 = _cumulative_trapezoid(integrand, h)[:, :: self.substeps].T
        p1 = _cumulative_trapezoid(fine * integrand, h)[:, :: self.substeps].T

        ones, zeros = np.ones((len(t), 1)), np.zeros((len(t), 1))
        phi = np.concatenate([y2[:, None] * p2 - y1[:, None] * p1, ones], axis=1)
        dphi = np.concatenate([dy2[:, None] * p2 - dy1[:, None] * p1, zeros], axis=1)
        homogeneous = np.stack([y1, y2], axis=-1)
        d_homogeneous = np.stack([dy1, dy2], axis=-1)
        self._np = (phi, dphi, homogeneous, d_homogeneous)  # float64, for trajectory_numpy
        self._phi, self._dphi = (torch.from_numpy(v).to(dtype) for v in (phi, dphi))
        self._y, self._dy = (torch.from_numpy(v).to(dtype) for v in self._np[2:])
        for arr in self._np:  # shared with the float64 tensors: neither is ever written
            arr.flags.writeable = False

        # Positions as one linear map of (w_g, y0, dy0): with M = [[y1, y2], [y1', y2']](t0)
        # and B0 = [Phi(t0), Phi'(t0)], c = M^-1 ([y0, dy0] - B0 w_g), hence
        # y(t) = (Phi(t)^T - [y1, y2](t) M^-1 B0) w_g + [y1, y2](t) M^-1 [y0, dy0].
        m_inv = np.linalg.inv(np.stack([homogeneous[0], d_homogeneous[0]]))
        init = homogeneous @ m_inv
        self._param_map = torch.from_numpy(phi - init @ np.stack([phi[0], dphi[0]])).to(dtype)

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
        return _solve_initial(self._phi, self._dphi, self._y, self._dy, w_g, y0, dy0)

    def trajectory_numpy(
        self, params: np.ndarray, y0: np.ndarray, dy0: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`trajectory` for float64 numpy arrays, without torch (no gradient): what a
        simulator that builds a primitive for every parameter vector calls. The same
        shapes, and the same numbers up to rounding."""
        params = np.asarray(params, dtype=np.float64)
        y0, dy0 = np.asarray(y0, dtype=np.float64), np.asarray(dy0, dtype=np.float64)
        for name, value, size in (
            ("params", params, self.n_params), ("y0", y0, self.n_dof), ("dy0", dy0, self.n_dof)
        ):  # fmt: skip
            if value.ndim < 1 or value.shape[-1] != size:
                raise ValueError(f"{name} must have shape (..., {size}), got {value.shape}")
        w_g = params.reshape(*params.shape[:-1], self.n_dof, self.n_basis + 1)
        return _solve_initial(*self._np, w_g, y0, dy0)

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

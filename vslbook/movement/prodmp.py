"""Probabilistic Dynamic Movement Primitives (Li et al., 2023, "ProDMP: A Unified Perspective
on Dynamic and Probabilistic Movement Primitives"; thesis Sec. 2.6.1).

A ProDMP solves the DMP of Eq. 2.45 in closed form instead of integrating it for every
parameter vector. Positions and velocities are affine in the parameters
``w_g = [w_1, ..., w_n, g]`` of each degree of freedom (dof) and in the initial state
(Eqs. P1-P3 of :mod:`vslbook.movement.prodmp_basis`, which derives them):

    y(t)  = xi1(s) y0 + xi2(s) tau dy0 + G(s)^T (c * w_g) [+ G_g(s) y0],     s = (t - delay) / tau,
    y'(t) = (xi1'(s) y0 + xi2'(s) tau dy0 + G'(s)^T (c * w_g) [+ G_g'(s) y0]) / tau,

with ``s`` clipped at 0 (the trajectory holds ``y0`` until ``delay``), ``G`` the position basis
made to start at rest at zero, ``c`` the per-column scales (``weights_scale`` for the weights,
``goal_scale`` for the goal, each times ``1 / max G`` under ``auto_scale_basis``), and the
bracket only with ``relative_goal`` (then the goal is ``y0 + c_g g``). The initial conditions
``y(0) = y0`` and ``y'(0) = dy0`` hold exactly for any ``w_g``.

This is the construction of MP_PyTorch (which fancy-gym and the authors' Di-SkilL code use):
the forcing Gaussians live in the exponential phase (:func:`~vslbook.movement.basis.
phase_rbf_centres`), the basis is integrated on a grid of scaled time built for ``basis_tau``
and read by linear interpolation. Parameters have shape ``(..., n_dof * (n_basis + 1))``, one
block ``[w_1..w_n, g]`` per dof, mp_pytorch's layout. The forcing convention is the one of
:class:`~vslbook.movement.dmp.DMP` (no ``(g - y0)`` factor).
"""

from __future__ import annotations

from typing import TypeVar

import numpy as np
import torch

from vslbook.movement.basis import (
    Array,
    as_float_tensor,
    check_gaussian,
    check_int,
    check_last_dim,
    check_positive,
    time_grid_np,
)
from vslbook.movement.prodmp_basis import initial_value_maps, prodmp_basis

_A = TypeVar("_A", torch.Tensor, np.ndarray)


def _affine(phi: _A, dphi: _A, init: _A, d_init: _A, w_g: _A, y0: _A, dy0: _A) -> tuple[_A, _A]:
    """Positions and velocities ``(..., T, n_dof)`` of parameters ``w_g (..., n_dof, P)`` from
    the bases ``phi, dphi (T, P)`` and the initial-state maps ``init, d_init (T, 2)`` (Eq. P3).
    The same expression for torch tensors (differentiable) and numpy arrays."""
    y0, dy0 = y0[..., None, :], dy0[..., None, :]
    positions = init[:, :1] * y0 + init[:, 1:] * dy0 + phi @ w_g.swapaxes(-1, -2)
    velocities = d_init[:, :1] * y0 + d_init[:, 1:] * dy0 + dphi @ w_g.swapaxes(-1, -2)
    return positions, velocities


class ProDMP:
    """ProDMP: the DMP of Eq. 2.45 with positions linear in ``[w, g]`` (Li et al., 2023).

    Args:
        n_basis: forcing basis functions per dof (>= 1).
        n_dof: degrees of freedom (>= 1).
        duration: length of the trajectory in seconds (the grid ``0, dt, ..., duration``).
        dt: time step of the output grid :attr:`times`.
        alpha: spring-damper constant (> 0); ``beta = alpha / 4`` (critical damping).
        tau: temporal scaling (gamma in the thesis, > 0).
        alpha_x: decay rate of the canonical phase (> 0).
        bandwidth_factor: bandwidth factor of the phase-space Gaussians (Eq. B2).
        delay: start time (>= 0): the trajectory holds ``y0`` (velocity ``dy0``) before it.
        basis_tau: the τ the basis grid is built for (MP_PyTorch's construction-time τ);
            ``None`` uses ``tau``.
        basis_dt: MP_PyTorch's basis step (0.01 s, which fancy-gym never changes).
        length_factor: the grid covers scaled times ``[0, length_factor]``; ``None``: 6
            under the Di-SkilL rule, 5 under mp_pytorch 0.1.3's (their defaults).
        rule: ``"di-skill"`` or ``"mp_pytorch-0.1.3"``, the last Gaussian's bandwidth.
        auto_scale_basis: divide each basis column by its largest value on the grid.
        weights_scale, goal_scale: multiply the weights' and the goal's columns.
        relative_goal: the goal is ``y0 + goal parameter`` instead of the parameter itself.
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
        bandwidth_factor: float = 3.0,
        *,
        delay: float = 0.0,
        basis_tau: float | None = None,
        basis_dt: float = 0.01,
        length_factor: int | None = None,
        rule: str = "di-skill",
        auto_scale_basis: bool = False,
        weights_scale: float = 1.0,
        goal_scale: float = 1.0,
        relative_goal: bool = False,
        dtype: torch.dtype = torch.float64,
    ) -> None:
        self.n_basis = check_int("n_basis", n_basis)
        self.n_dof = check_int("n_dof", n_dof)
        self.duration = check_positive("duration", duration)
        self.dt = check_positive("dt", dt)
        self.alpha = check_positive("alpha", alpha)
        self.beta = self.alpha / 4.0
        self.tau = check_positive("tau", tau)
        self.alpha_x = check_positive("alpha_x", alpha_x)
        self.bandwidth_factor = check_positive("bandwidth_factor", bandwidth_factor)
        if not (isinstance(delay, (int, float, np.floating)) and 0 <= delay < float("inf")):
            raise ValueError(f"delay must be a finite number >= 0, got {delay!r}")
        self.delay = float(delay)
        self.basis_tau = self.tau if basis_tau is None else check_positive("basis_tau", basis_tau)
        self.relative_goal = bool(relative_goal)
        self.dtype = dtype
        self.n_params = self.n_dof * (self.n_basis + 1)
        t = time_grid_np(self.duration, self.dt)
        self.times = torch.from_numpy(t).to(dtype)
        basis = prodmp_basis(
            self.n_basis, self.alpha, self.alpha_x, self.bandwidth_factor, rule,
            self.basis_tau, basis_dt,
            length_factor or (5 if rule == "mp_pytorch-0.1.3" else 6),
        )  # fmt: skip
        # Eq. P3 with the initial conditions at t0 = 0, i.e. s0 = 0 (before any delay)
        s = np.maximum((t - self.delay) / self.tau, 0.0)
        xi, dxi, g, dg = initial_value_maps(basis, s, 0.0)
        scale = np.full(self.n_basis + 1, float(weights_scale))
        scale[-1] = float(goal_scale)
        if auto_scale_basis:
            scale = scale * basis.scale
        phi, dphi = g * scale, dg * scale / self.tau
        rel = 1.0 if self.relative_goal else 0.0
        # y = init[:, 0] y0 + init[:, 1] dy0 + phi w_g (velocities: d_init, dphi)
        init = np.stack([xi[:, 0] + rel * g[:, -1], xi[:, 1] * self.tau], 1)
        d_init = np.stack([(dxi[:, 0] + rel * dg[:, -1]) / self.tau, dxi[:, 1]], 1)
        self._np = (phi, dphi, init, d_init)  # float64, for trajectory_numpy
        self._phi, self._dphi, self._init, self._d_init = (
            torch.from_numpy(v).to(dtype) for v in self._np
        )
        for arr in self._np:  # shared with the float64 tensors: neither is ever written
            arr.flags.writeable = False
        self._param_map = self._phi

    def basis_matrix(self, derivative: bool = False) -> torch.Tensor:
        """Position basis ``c * G(s(t))`` on :attr:`times`, ``(T, n_basis + 1)`` (Eq. P3).

        The last column multiplies the goal. Every column starts at zero with zero slope (the
        initial conditions enter through ``xi1, xi2``). ``derivative=True`` returns the
        time derivative ``d/dt`` (the scaled-time derivative divided by τ).
        """
        return (self._dphi if derivative else self._phi).clone()

    def _check_state(self, y0: Array, dy0: Array) -> tuple[torch.Tensor, torch.Tensor]:
        y0 = check_last_dim("y0", as_float_tensor("y0", y0, self.dtype), self.n_dof, "n_dof")
        dy0 = check_last_dim("dy0", as_float_tensor("dy0", dy0, self.dtype), self.n_dof, "n_dof")
        return y0, dy0

    def _params(self, params: Array, name: str = "params") -> torch.Tensor:
        params = as_float_tensor(name, params, self.dtype)
        return check_last_dim(name, params, self.n_params, "n_dof * (n_basis + 1)")

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
        return _affine(self._phi, self._dphi, self._init, self._d_init, w_g, y0, dy0)

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
        return _affine(*self._np, w_g, y0, dy0)

    def distribution(
        self, mean_params: Array, cov_params: Array, y0: Array, dy0: Array
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Mean and per-time std of the positions for ``params ~ N(mean_params, cov_params)``.

        Positions are affine in the parameters for fixed ``(y0, dy0)``,
        ``y(t) = H(t)^T w_g + const`` with ``H`` the scaled basis :meth:`basis_matrix` (Eq. P3),
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
        cov = as_float_tensor("cov_params", cov_params, self.dtype)
        what, names = "n_dof * (n_basis + 1)", ("mean_params", "cov_params")
        mean, cov = check_gaussian(mean, cov, self.n_params, what, names)
        mean_pos, _ = self.trajectory(mean, y0, dy0)
        n = self.n_basis + 1
        blocks = cov.reshape(*cov.shape[:-2], self.n_dof, n, self.n_dof, n)
        blocks = torch.diagonal(blocks, dim1=-4, dim2=-2).movedim(-1, -3)
        var = torch.einsum("tp,...dpq,tq->...td", self._param_map, blocks, self._param_map)
        std = var.clamp_min(0.0).sqrt()
        return mean_pos, std.expand_as(mean_pos)

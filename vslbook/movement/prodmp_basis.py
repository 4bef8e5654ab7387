"""The ProDMP's position and velocity bases, precomputed on a grid of scaled time (Li et al.,
2023, "ProDMP"; the construction of MP_PyTorch, which fancy-gym and the authors' Di-SkilL code
use, rederived here).

In scaled time ``s = (t - delay) / tau`` (clipped at 0 before the delay) the DMP of Eq. 2.45
with ``beta = alpha / 4`` reads, with ``a = alpha / 2`` and ``' = d/ds``,

    y'' + 2 a y' + a^2 y = a^2 g + x(s) phi(x(s))^T w,    x(s) = exp(-alpha_x s).     (Eq. P1)

Its homogeneous solutions are ``y1 = exp(-a s)`` and ``y2 = s exp(-a s)`` (Wronskian
``W = exp(-2 a s)``); variation of parameters from ``s = 0`` gives the particular solution

    y_p(s) = y2(s) p2(s)^T w - y1(s) p1(s)^T w + (q2(s) y2(s) - q1(s) y1(s)) g,       (Eq. P2)
    p1(s) = int_0^s u exp(a u) x(u) phi(x(u)) du,   p2(s) = int_0^s exp(a u) x(u) phi(x(u)) du,
    q1(s) = int_0^s u exp(a u) a^2 du = (a s - 1) exp(a s) + 1,
    q2(s) = int_0^s exp(a u) a^2 du = a (exp(a s) - 1),

which starts at rest at zero. Its ``s``-derivative is ``y2' p2 - y1' p1`` (and
``q2 y2' - q1 y1'`` for ``g``): the terms with ``p1'``, ``p2'`` cancel since
``y2 p2' - y1 p1' = 0``. The position basis of one degree of freedom is therefore
``H(s) = [y2 p2 - y1 p1 (n columns), q2 y2 - q1 y1]`` and the velocity basis ``H'(s)``.

Numerics, as MP_PyTorch does them (these fix the numbers to ~1e-12, not only to the
discretisation error):

* one grid ``s_j = j L / (N - 1)``, ``N = L round(tau0 / dt0) + 1`` with the construction-time
  ``tau0`` (the task's fixed or initial τ), the library's default step ``dt0 = 0.01 s`` and
  ``L`` = ``length_factor`` (6; 5 in mp_pytorch 0.1.3);
* ``p1, p2`` by the cumulative trapezoid rule on that grid; ``y1, y2, y1', y2'``, ``q1, q2``
  in closed form on it;
* a query at scaled time ``s`` reads the grid by linear interpolation at the fractional
  index ``s tau0 / dt0``, also when a learned τ differs from ``tau0``;
* ``auto_scale_basis`` divides each column of ``H`` by its largest (signed) value on the grid.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from vslbook.movement.basis import (
    check_int,
    check_positive,
    dmp_forcing_basis_np,
)


@dataclass(frozen=True, eq=False)
class ProDMPBasis:
    """The bases of Eq. P2 on the grid of scaled time (read-only arrays).

    Attributes:
        n_basis: forcing basis functions per degree of freedom.
        alpha: spring-damper constant (in scaled time); ``a = alpha / 2``.
        scaled_dt: ``dt0 / tau0``, the step that maps a scaled time to a grid index.
        length: the grid covers ``s`` in ``[0, length]``.
        pos, vel: ``H`` and ``H'`` (d/ds), ``(N, n_basis + 1)``; the last column is the goal's.
        y, dy: ``[y1, y2]`` and ``[y1', y2']``, ``(N, 2)``.
        scale: ``1 / max_j H[j]`` per column, ``(n_basis + 1,)`` (for ``auto_scale_basis``).
    """

    n_basis: int
    alpha: float
    scaled_dt: float
    length: float
    pos: np.ndarray
    vel: np.ndarray
    y: np.ndarray
    dy: np.ndarray
    scale: np.ndarray

    def read(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(H, H', [y1, y2], [y1', y2'])`` at scaled times ``s`` (``(T,)``, each ``(T, ...)``),
        linearly interpolated at the fractional grid index ``s / scaled_dt``."""
        s = np.asarray(s, dtype=np.float64)
        if s.size and (np.min(s) < 0 or np.max(s) > self.length):
            raise ValueError(
                f"scaled time (t - delay) / tau must lie in [0, {self.length:g}] (the precomputed "
                f"range, length_factor), got [{np.min(s):.4g}, {np.max(s):.4g}]"
            )
        index = s / self.scaled_dt
        lo = np.clip(np.floor(index).astype(np.int64), 0, len(self.y) - 2)
        frac = (index - lo)[:, None]
        return tuple(_lerp(a[lo], a[lo + 1], frac) for a in (self.pos, self.vel, self.y, self.dy))


def _lerp(a: np.ndarray, b: np.ndarray, w: np.ndarray) -> np.ndarray:
    """``a + w (b - a)``, written from the nearer end (as torch.lerp does)."""
    return np.where(w < 0.5, a + w * (b - a), b - (b - a) * (1.0 - w))


def _cumulative_trapezoid(values: np.ndarray, h: float) -> np.ndarray:
    """``int_0^{s_j} values ds`` along axis 0 for samples spaced ``h`` apart (trapezoid rule)."""
    out = np.zeros_like(values)
    np.cumsum(0.5 * h * (values[1:] + values[:-1]), axis=0, out=out[1:])
    return out


@lru_cache(maxsize=64)
def prodmp_basis(
    n_basis: int,
    alpha: float = 25.0,
    alpha_x: float = 3.0,
    bandwidth_factor: float = 3.0,
    rule: str = "di-skill",
    basis_tau: float = 1.0,
    basis_dt: float = 0.01,
    length_factor: int = 6,
) -> ProDMPBasis:
    """Precompute the bases of Eq. P2 (see the module docstring for the grid and numerics).

    Args:
        n_basis: forcing basis functions per degree of freedom (>= 1).
        alpha: DMP spring-damper constant (> 0).
        alpha_x: decay of the phase ``x = exp(-alpha_x s)`` (> 0).
        bandwidth_factor, rule: the phase-space Gaussians (Eqs. B1-B3 of
            :mod:`vslbook.movement.basis`).
        basis_tau: ``tau0``, the τ the grid is built for (> 0).
        basis_dt: ``dt0``, MP_PyTorch's basis-generator time step (0.01 s unless set).
        length_factor: the grid covers ``s`` in ``[0, length_factor]`` (>= 1).

    Cached: tasks share one grid per setting; the returned arrays are read-only.
    """
    n_basis = check_int("n_basis", n_basis)
    alpha = check_positive("alpha", alpha)
    basis_tau = check_positive("basis_tau", basis_tau)
    basis_dt = check_positive("basis_dt", basis_dt)
    length_factor = check_int("length_factor", length_factor)
    scaled_dt = basis_dt / basis_tau
    steps = round(1.0 / scaled_dt)
    if steps < 1:
        raise ValueError(f"basis_dt must not exceed basis_tau={basis_tau}, got {basis_dt}")
    s = np.linspace(0.0, float(length_factor), length_factor * steps + 1)
    a = 0.5 * alpha
    if a * length_factor > 600.0:
        raise ValueError(
            f"alpha * length_factor / 2 must be at most 600 so that exp(a s) stays finite, "
            f"got {a * length_factor:.1f}"
        )
    y1 = np.exp(-a * s)
    y2 = s * y1
    dy1, dy2 = -a * y1, -a * y2 + y1
    grow = np.exp(a * s)
    q1 = (a * s - 1.0) * grow + 1.0
    q2 = a * (grow - 1.0)
    # x phi(x) as a function of s (tau = 1 in dmp_forcing_basis_np's t / tau)
    forcing = dmp_forcing_basis_np(s, n_basis, alpha_x, 1.0, bandwidth_factor, rule)
    h = s[1] - s[0]
    p2 = _cumulative_trapezoid(grow[:, None] * forcing, h)
    p1 = _cumulative_trapezoid((s * grow)[:, None] * forcing, h)
    pos = np.concatenate([y2[:, None] * p2 - y1[:, None] * p1, (q2 * y2 - q1 * y1)[:, None]], 1)
    vel = np.concatenate([dy2[:, None] * p2 - dy1[:, None] * p1, (q2 * dy2 - q1 * dy1)[:, None]], 1)
    arrays = dict(
        pos=pos, vel=vel, y=np.stack([y1, y2], 1), dy=np.stack([dy1, dy2], 1),
        scale=1.0 / pos.max(axis=0),
    )  # fmt: skip
    for arr in arrays.values():
        arr.flags.writeable = False
    return ProDMPBasis(n_basis, alpha, scaled_dt, float(length_factor), **arrays)


def initial_value_maps(
    basis: ProDMPBasis, s: np.ndarray, s0: float = 0.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The trajectory's maps from ``(y0, tau dy0)`` and from the parameters, at scaled times
    ``s`` for initial conditions at scaled time ``s0`` (Eq. P3).

    A trajectory is ``y = y_p + c1 y1 + c2 y2`` with ``c1, c2`` fixed by ``y(s0) = y0`` and
    ``y'(s0) = tau dy0`` (the velocity in scaled time). Solving the 2x2 system (its
    determinant ``D = y1 y2' - y2 y1'`` at ``s0``, the Wronskian) gives

        y(s)  = xi1(s) y0 + xi2(s) tau dy0 + [H(s) + xi3(s) H(s0) + xi4(s) H'(s0)] w_g,
        xi1 = (y2'0 y1 - y1'0 y2) / D,   xi2 = (y1_0 y2 - y2_0 y1) / D,            (Eq. P3)
        xi3 = (y1'0 y2 - y2'0 y1) / D,   xi4 = (y2_0 y1 - y1_0 y2) / D,

    and ``y'(s)`` the same with ``y1, y2, H`` replaced by their derivatives. Returns
    ``(xi, dxi, G, dG)``: ``xi, dxi`` ``(T, 2)`` (columns xi1, xi2), ``G, dG`` ``(T, n + 1)``
    the bracket above (unscaled) and its derivative.
    """
    pos, vel, y, dy = basis.read(np.asarray(s, dtype=np.float64))
    pos0, vel0, y_0, dy_0 = (v[0] for v in basis.read(np.array([s0])))
    (y10, y20), (dy10, dy20) = y_0, dy_0
    det = y10 * dy20 - y20 * dy10

    def maps(u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        u1, u2 = u[:, 0], u[:, 1]
        return (
            (dy20 * u1 - dy10 * u2) / det, (y10 * u2 - y20 * u1) / det,
            (dy10 * u2 - dy20 * u1) / det, (y20 * u1 - y10 * u2) / det,
        )  # fmt: skip

    x1, x2, x3, x4 = maps(y)
    d1, d2, d3, d4 = maps(dy)
    g = pos + x3[:, None] * pos0 + x4[:, None] * vel0
    dg = vel + d3[:, None] * pos0 + d4[:, None] * vel0
    return np.stack([x1, x2], 1), np.stack([d1, d2], 1), g, dg

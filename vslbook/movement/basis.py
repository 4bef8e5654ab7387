"""Basis functions and phase variables shared by the movement primitives (thesis Sec. 2.6.1).

Two ingredients are used throughout:

* normalised radial basis functions (RBFs) ``psi_i(s)`` over a phase ``s`` in ``[0, 1]``:
  Gaussian bumps ``b_i(s) = exp(-(s - c_i)^2 / (2 h^2))`` with centres ``c_i`` spaced evenly
  over ``[0, 1]`` and width ``h``, divided by their sum so that ``sum_i psi_i(s) = 1``.
  ProMPs (Eq. 2.46) use them directly with ``s = t / duration``.
* the DMP canonical system ``x(t) = exp(-alpha_x t / tau)`` (Eq. 2.45) and the DMP forcing
  basis ``x phi(x)``, whose Gaussians are functions of the phase ``x`` (not of ``t / tau``),
  centred at the phases of times spaced evenly over ``[0, tau]`` (Eqs. B1-B3 below; the
  basis of MP_PyTorch, which the authors' code uses).

The module also holds the small input checks used by ``promp``, ``dmp`` and ``prodmp``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch

Array = torch.Tensor | np.ndarray | float | list


# --------------------------------------------------------------------------- input checks
def check_int(name: str, value: Any, minimum: int = 1) -> int:
    """Return ``value`` as an int, or raise ValueError unless it is an integer >= ``minimum``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def check_positive(name: str, value: Any) -> float:
    """Return ``value`` as a float, or raise ValueError unless it is a finite number > 0."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"{name} must be a finite positive number, got {value!r}")
    if not math.isfinite(value) or value <= 0:
        raise ValueError(f"{name} must be a finite positive number, got {value!r}")
    return float(value)


def as_float_tensor(name: str, value: Array, dtype: torch.dtype | None = None) -> torch.Tensor:
    """Convert a numpy array, list, number or tensor to a floating tensor.

    ``dtype=None`` keeps the dtype of a floating tensor and uses float64 otherwise.
    """
    if dtype is None:
        floating = torch.is_tensor(value) and value.is_floating_point()
        dtype = value.dtype if floating else torch.float64
    try:
        return torch.as_tensor(value, dtype=dtype)
    except (TypeError, ValueError, RuntimeError) as err:
        raise ValueError(f"{name} must be array-like of numbers, got {value!r}") from err


def check_last_dim(name: str, value: torch.Tensor, size: int, what: str) -> torch.Tensor:
    """Raise ValueError unless ``value`` has shape ``(..., size)``."""
    if value.dim() < 1 or value.shape[-1] != size:
        raise ValueError(
            f"{name} must have shape (..., {size}) ({what}), got shape {tuple(value.shape)}"
        )
    return value


def check_square(name: str, value: torch.Tensor, size: int, what: str) -> torch.Tensor:
    """Raise ValueError unless ``value`` has shape ``(..., size, size)``."""
    if value.dim() < 2 or value.shape[-2:] != (size, size):
        raise ValueError(
            f"{name} must have shape (..., {size}, {size}) ({what}), got shape {tuple(value.shape)}"
        )
    return value


def check_gaussian(
    mean: torch.Tensor, cov: torch.Tensor, size: int, what: str, names: tuple[str, str]
) -> tuple[torch.Tensor, torch.Tensor]:
    """Check a Gaussian ``N(mean, cov)`` over ``size`` parameters and broadcast its batch."""
    check_last_dim(names[0], mean, size, what)
    check_square(names[1], cov, size, what)
    batch = torch.broadcast_shapes(mean.shape[:-1], cov.shape[:-2])
    return mean.expand(*batch, size), cov.expand(*batch, size, size)


# --------------------------------------------------------------------------- time and phase
def time_grid(duration: float, dt: float, dtype: torch.dtype = torch.float64) -> torch.Tensor:
    """Time steps ``0, dt, 2 dt, ..., n dt`` with ``n = round(duration / dt)``, shape ``(n + 1,)``.

    The step is exactly ``dt``; the last time is the multiple of ``dt`` closest to ``duration``.
    """
    return torch.from_numpy(time_grid_np(duration, dt)).to(dtype)


def time_grid_np(duration: float, dt: float) -> np.ndarray:
    """:func:`time_grid` as a float64 numpy array."""
    duration = check_positive("duration", duration)
    dt = check_positive("dt", dt)
    if dt > duration:
        raise ValueError(f"dt must not exceed duration={duration}, got dt={dt}")
    return np.arange(round(duration / dt) + 1, dtype=np.float64) * dt


def canonical_phase(t: Array, alpha_x: float = 3.0, tau: float = 1.0) -> torch.Tensor:
    """DMP canonical system ``x(t) = exp(-alpha_x t / tau)`` (thesis Eq. 2.45), same shape as t.

    The phase starts at ``x(0) = 1`` and decays to zero; ``tau`` is the temporal scaling
    (written gamma in the thesis).
    """
    alpha_x = check_positive("alpha_x", alpha_x)
    tau = check_positive("tau", tau)
    t = as_float_tensor("t", t)
    return torch.exp(-alpha_x * t / tau)


# --------------------------------------------------------------------------- radial basis
def default_width(n_basis: int) -> float:
    """Default bump width: the distance between neighbouring centres (1 for a single bump)."""
    n_basis = check_int("n_basis", n_basis)
    return 1.0 / (n_basis - 1) if n_basis > 1 else 1.0


def normalized_rbf(
    phase: Array, n_basis: int, width: float | None = None, *, derivative: bool = False
) -> torch.Tensor:
    """Normalised Gaussian RBFs ``psi_i(s) = b_i(s) / sum_j b_j(s)``, shape ``(*phase.shape, n)``.

    Args:
        phase: phase values ``s`` (usually in ``[0, 1]``; values outside are allowed).
        n_basis: number of bumps, centred evenly over ``[0, 1]``.
        width: standard deviation ``h`` of each bump in phase units; ``None`` uses
            :func:`default_width`.
        derivative: return ``d psi_i / d s`` instead of ``psi_i``.

    The normalisation is a softmax over the log-bumps, so it stays finite far from all centres.
    With ``u_i = -(s - c_i) / h^2`` the derivative is ``psi_i (u_i - sum_j psi_j u_j)``.
    The basis is a constant of a primitive (no gradient flows through the phase): it is
    computed in float64 by :func:`normalized_rbf_np` and returned in the phase's dtype.
    """
    phase = as_float_tensor("phase", phase)
    psi = normalized_rbf_np(phase.detach().cpu().numpy(), n_basis, width, derivative=derivative)
    return torch.from_numpy(psi).to(phase.dtype)


def normalized_rbf_np(
    phase: np.ndarray,
    n_basis: int,
    width: float | None = None,
    *,
    derivative: bool = False,
    basis_first: bool = False,
) -> np.ndarray:
    """:func:`normalized_rbf` in numpy, float64; ``basis_first`` puts the basis index first,
    ``(n, *phase.shape)``.

    The primitives' bases are computed here once per primitive; a robot task builds one
    primitive per parameter vector (its duration or start time is learned), and on these small
    arrays numpy's per-call cost is a fraction of torch's.
    """
    n_basis = check_int("n_basis", n_basis)
    width = default_width(n_basis) if width is None else check_positive("width", width)
    phase = np.asarray(phase, dtype=np.float64)
    centers = np.linspace(0.0, 1.0, n_basis).reshape(n_basis, *[1] * phase.ndim)
    # basis index first: the softmax reduces over a short leading axis
    diff = phase[None] - centers
    logits = -0.5 * (diff / width) ** 2
    psi = np.exp(logits - logits.max(axis=0))
    psi /= psi.sum(axis=0)
    if derivative:
        u = -diff / width**2
        psi = psi * (u - (psi * u).sum(axis=0))
    return psi if basis_first else np.moveaxis(psi, 0, -1)


BANDWIDTH_RULES = ("di-skill", "mp_pytorch-0.1.3")


def phase_rbf_centres(
    n_basis: int, alpha_x: float = 3.0, bandwidth_factor: float = 3.0, rule: str = "di-skill"
) -> tuple[np.ndarray, np.ndarray]:
    """Centres ``c_i`` and bandwidths ``h_i`` of the DMP forcing basis in phase space (Eq. B1).

    The centres are spaced evenly in *time* over ``[0, tau]`` and mapped to the exponential
    phase ``x = exp(-alpha_x t / tau)`` of Eq. 2.45:

        c_i = exp(-alpha_x i / (n - 1)),  i = 0, ..., n - 1,                         (Eq. B1)

    (one bump: ``c_0 = exp(-alpha_x / 2)``), so they crowd towards ``x = 0``. The bandwidth
    of bump ``i`` is the inverse square of its distance to the next centre times
    ``bandwidth_factor``,

        h_i = bandwidth_factor / (c_{i+1} - c_i)^2.                                    (Eq. B2)

    The last bump has no successor; the two rules differ only there:

    * ``"di-skill"`` (the MP_PyTorch copy that the authors' Di-SkilL code runs, as in
      mp_pytorch's later releases): ``c_n`` is one more centre one time spacing after the
      last, ``exp(-alpha_x n / (n - 1))``; with exactly two bumps this last distance is doubled.
    * ``"mp_pytorch-0.1.3"`` (the release fancy-gym 0.3.0 pins): the last bump repeats the
      previous distance, ``h_{n-1} = h_{n-2}``.

    A single bump has bandwidth ``bandwidth_factor`` (distance 1). Returns ``(c, h)``, each
    ``(n,)``; the basis does not depend on tau or on a start delay (they only map t to x).
    """
    n_basis = check_int("n_basis", n_basis)
    alpha_x = check_positive("alpha_x", alpha_x)
    bandwidth_factor = check_positive("bandwidth_factor", bandwidth_factor)
    if rule not in BANDWIDTH_RULES:
        raise ValueError(f"rule must be one of {BANDWIDTH_RULES}, got {rule!r}")
    if n_basis == 1:
        return np.array([math.exp(-0.5 * alpha_x)]), np.array([bandwidth_factor])
    # centres at the times linspace(0, tau, n) (in units of tau), one more for the last gap
    steps = np.linspace(0.0, 1.0, n_basis)
    if rule == "di-skill":
        steps = np.append(steps, steps[-1] + (steps[1] - steps[0]))
        centres = np.exp(-alpha_x * steps)
        gaps = np.diff(centres)
        if n_basis == 2:
            gaps[-1] *= 2.0
        centres = centres[:-1]
    else:
        centres = np.exp(-alpha_x * steps)
        gaps = np.diff(centres)
        gaps = np.append(gaps, gaps[-1])
    return centres, bandwidth_factor / gaps**2


def phase_rbf_np(
    x: np.ndarray,
    n_basis: int,
    alpha_x: float = 3.0,
    bandwidth_factor: float = 3.0,
    rule: str = "di-skill",
    *,
    basis_first: bool = False,
) -> np.ndarray:
    """Normalised Gaussians in the phase, ``phi_i(x) = b_i(x) / sum_j b_j(x)`` (Eq. B3), with
    ``b_i(x) = exp(-h_i (x - c_i)^2 / 2)`` and ``(c, h)`` of :func:`phase_rbf_centres`.

    Float64, shape ``(*x.shape, n)`` (``basis_first``: ``(n, *x.shape)``). A single bump is not
    normalised. The sum carries a ``1e-15`` guard under the Di-SkilL rule, as that code does.
    """
    centres, bandwidths = phase_rbf_centres(n_basis, alpha_x, bandwidth_factor, rule)
    x = np.asarray(x, dtype=np.float64)
    shape = (len(centres), *[1] * x.ndim)
    psi = np.exp(-0.5 * bandwidths.reshape(shape) * (x[None] - centres.reshape(shape)) ** 2)
    if len(centres) > 1:
        psi /= psi.sum(axis=0) + (1e-15 if rule == "di-skill" else 0.0)
    return psi if basis_first else np.moveaxis(psi, 0, -1)


def dmp_forcing_basis(
    t: Array,
    n_basis: int,
    alpha_x: float = 3.0,
    tau: float = 1.0,
    bandwidth_factor: float = 3.0,
    rule: str = "di-skill",
) -> torch.Tensor:
    """The DMP forcing basis ``x(t) phi(x(t))`` of Eq. 2.45, shape ``(*t.shape, n_basis)``.

    ``phi`` are the phase-space Gaussians of :func:`phase_rbf_np` (Eqs. B1-B3), evaluated at
    ``x = exp(-alpha_x max(t, 0) / tau)``; the forcing term of one degree of freedom is
    ``f(x) = x phi(x)^T theta``. Computed in float64 by :func:`dmp_forcing_basis_np`,
    returned in the dtype of ``t``.
    """
    t = as_float_tensor("t", t)
    basis = dmp_forcing_basis_np(
        t.detach().cpu().numpy(), n_basis, alpha_x, tau, bandwidth_factor, rule
    )
    return torch.from_numpy(basis).to(t.dtype)


def dmp_forcing_basis_np(
    t: np.ndarray,
    n_basis: int,
    alpha_x: float = 3.0,
    tau: float = 1.0,
    bandwidth_factor: float = 3.0,
    rule: str = "di-skill",
    *,
    basis_first: bool = False,
) -> np.ndarray:
    """:func:`dmp_forcing_basis` in numpy, float64; ``basis_first`` puts the basis index
    first, ``(n_basis, *t.shape)``."""
    alpha_x = check_positive("alpha_x", alpha_x)
    tau = check_positive("tau", tau)
    x = np.exp(-alpha_x * np.maximum(np.asarray(t, dtype=np.float64), 0.0) / tau)
    psi = phase_rbf_np(x, n_basis, alpha_x, bandwidth_factor, rule, basis_first=True)
    return x * psi if basis_first else np.moveaxis(x * psi, 0, -1)

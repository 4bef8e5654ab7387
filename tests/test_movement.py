"""Tests for vslbook.movement: ProMP (Eq. 2.46), DMP (Eq. 2.45) and ProDMP (Li et al., 2023)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from vslbook.movement import DMP, ProDMP, ProMP
from vslbook.movement.basis import (
    canonical_phase,
    dmp_forcing_basis,
    dmp_forcing_basis_np,
    normalized_rbf,
    normalized_rbf_np,
    time_grid,
)


def _random_cov(gen: torch.Generator, size: int, scale: float = 1.0) -> torch.Tensor:
    root = torch.randn(size, size, generator=gen, dtype=torch.float64)
    return scale * (root @ root.T / size + 0.1 * torch.eye(size, dtype=torch.float64))


def _prodmp_params(w: torch.Tensor, goal: torch.Tensor, n_dof: int, n_basis: int) -> torch.Tensor:
    """Stack DMP weights ``(..., n_dof * n_basis)`` and goals ``(..., n_dof)`` into ``[w, g]``."""
    w = w.reshape(*w.shape[:-1], n_dof, n_basis)
    return torch.cat([w, goal.unsqueeze(-1)], dim=-1).reshape(*w.shape[:-2], -1)


# --------------------------------------------------------------------------- basis
def test_normalized_rbf_sums_to_one_and_derivative_matches_finite_difference() -> None:
    s = torch.linspace(-0.2, 1.2, 57, dtype=torch.float64)
    psi = normalized_rbf(s, 6)
    assert psi.shape == (57, 6)
    torch.testing.assert_close(psi.sum(-1), torch.ones(57, dtype=torch.float64))
    eps = 1e-6
    numeric = (normalized_rbf(s + eps, 6) - normalized_rbf(s - eps, 6)) / (2 * eps)
    torch.testing.assert_close(normalized_rbf(s, 6, derivative=True), numeric, atol=1e-7, rtol=0)
    # Far outside [0, 1] the softmax normalisation stays finite.
    assert torch.isfinite(normalized_rbf(torch.tensor([50.0]), 10, width=0.01)).all()


def test_canonical_phase_and_forcing_basis() -> None:
    t = np.array([0.0, 0.5, 1.0])
    x = canonical_phase(t, alpha_x=3.0, tau=2.0)
    torch.testing.assert_close(x, torch.exp(torch.tensor([0.0, -0.75, -1.5], dtype=torch.float64)))
    forcing = dmp_forcing_basis(t, 4, alpha_x=3.0, tau=2.0)
    torch.testing.assert_close(forcing.sum(-1), x)  # x * sum_i phi_i(x) = x
    assert time_grid(1.0, 0.25).tolist() == [0.0, 0.25, 0.5, 0.75, 1.0]


# --------------------------------------------------------------------------- ProMP
def test_promp_shapes_batching_and_numpy_input() -> None:
    promp = ProMP(n_basis=5, n_dof=3, duration=2.0, dt=0.02)
    assert promp.times.shape == (101,)
    assert promp.basis_matrix().shape == (101, 5)
    assert promp.basis_matrix(derivative=True).shape == (101, 5)
    w = np.random.default_rng(0).normal(size=(4, 2, 15))
    pos, vel = promp.trajectory(w), promp.velocity(w)
    assert pos.shape == vel.shape == (4, 2, 101, 3)
    assert pos.dtype == torch.float64
    # Eq. 2.46 per dof, and the batch entries are independent.
    phi = promp.basis_matrix()
    torch.testing.assert_close(pos[1, 0, :, 2], phi @ torch.as_tensor(w[1, 0, 10:15]))
    # Velocities are the time derivative of positions.
    central = (pos[..., 2:, :] - pos[..., :-2, :]) / (2 * promp.dt)
    torch.testing.assert_close(vel[..., 1:-1, :], central, atol=2e-3, rtol=2e-3)


def test_promp_distribution_matches_monte_carlo() -> None:
    gen = torch.Generator().manual_seed(1)
    promp = ProMP(n_basis=6, n_dof=2, dt=0.05)
    mean_w = torch.randn(12, generator=gen, dtype=torch.float64)
    cov_w = _random_cov(gen, 12)
    mean, cov = promp.distribution(mean_w, cov_w)
    std = promp.marginal_std(cov_w)
    t_len = len(promp.times)
    assert mean.shape == std.shape == (t_len, 2)
    assert cov.shape == (t_len * 2, t_len * 2)
    torch.testing.assert_close(cov.diagonal().reshape(t_len, 2).sqrt(), std)

    chol = torch.linalg.cholesky(cov_w)
    samples = mean_w + torch.randn(40_000, 12, generator=gen, dtype=torch.float64) @ chol.T
    trajs = promp.trajectory(samples)
    torch.testing.assert_close(trajs.mean(0), mean, atol=0.03, rtol=0)
    torch.testing.assert_close(trajs.std(0), std, atol=0, rtol=0.03)
    flat = trajs.reshape(len(samples), -1)
    torch.testing.assert_close(torch.cov(flat.T), cov, atol=0.03, rtol=0.05)


def test_promp_condition_on_via_point() -> None:
    gen = torch.Generator().manual_seed(2)
    promp = ProMP(n_basis=8, n_dof=2)
    mean_w = torch.zeros(16, dtype=torch.float64)
    cov_w = _random_cov(gen, 16)
    k = 37
    via = torch.tensor([0.5, -0.3], dtype=torch.float64)
    new_mean, new_cov = promp.condition(mean_w, cov_w, float(promp.times[k]), via, y_std=1e-4)
    assert new_mean.shape == (16,) and new_cov.shape == (16, 16)
    torch.testing.assert_close(promp.trajectory(new_mean)[k], via, atol=1e-6, rtol=0)
    before, after = promp.marginal_std(cov_w), promp.marginal_std(new_cov)
    assert torch.all(after[k] < 1e-3 * before[k])
    assert torch.all(after <= before + 1e-12)  # conditioning never adds variance
    torch.testing.assert_close(new_cov, new_cov.T)
    assert torch.linalg.eigvalsh(new_cov).min() > -1e-9

    # Off-grid times, batched via-points and per-dof noise broadcast against one prior.
    vias = torch.randn(3, 2, generator=gen, dtype=torch.float64)
    means, covs = promp.condition(mean_w, cov_w, 0.555, vias, y_std=[1e-4, 1e-4])
    assert means.shape == (3, 16) and covs.shape == (3, 16, 16)
    exact = ProMP(n_basis=8, n_dof=2, dt=0.005)
    torch.testing.assert_close(exact.trajectory(means)[:, 111], vias, atol=1e-6, rtol=0)

    # A large y_std barely moves the prior.
    loose_mean, _ = promp.condition(mean_w, cov_w, 0.5, via, y_std=1e3)
    assert loose_mean.abs().max() < 1e-4


# --------------------------------------------------------------------------- DMP
@pytest.mark.parametrize("weight_scale", [0.0, 200.0])
def test_dmp_converges_to_goal(weight_scale: float) -> None:
    gen = torch.Generator().manual_seed(3)
    dmp = DMP(n_basis=10, n_dof=3, duration=3.0, dt=0.01, substeps=4)
    w = weight_scale * torch.randn(5, 30, generator=gen, dtype=torch.float64)
    y0 = torch.randn(5, 3, generator=gen, dtype=torch.float64)
    goal = torch.randn(5, 3, generator=gen, dtype=torch.float64)
    pos, vel = dmp.rollout(w, y0, torch.zeros(3), goal)
    assert pos.shape == vel.shape == (5, 301, 3)
    torch.testing.assert_close(pos[:, 0], y0, atol=0, rtol=0)
    torch.testing.assert_close(pos[:, -1], goal, atol=1e-3, rtol=0)
    assert vel[:, -1].abs().max() < 1e-2
    if weight_scale == 0.0:  # critically damped and starting at rest: no overshoot
        progress = (pos - goal[:, None]) / (y0 - goal)[:, None]
        assert progress.min() > -1e-9 and progress.max() <= 1.0 + 1e-12


def test_dmp_forcing_and_broadcasting() -> None:
    dmp = DMP(n_basis=4, n_dof=2, alpha=16.0, beta=2.0, tau=0.5)
    assert dmp.beta == 2.0
    w = torch.ones(7, 1, 8, dtype=torch.float64)
    pos, vel = dmp.rollout(w, y0=np.zeros(2), dy0=np.zeros((3, 2)), goal=[1.0, -1.0])
    assert pos.shape == vel.shape == (7, 3, 101, 2)
    # With all weights 1 the forcing is the phase itself (the RBFs sum to one).
    x = canonical_phase(dmp.times, dmp.alpha_x, dmp.tau)
    torch.testing.assert_close(dmp.forcing(w)[0, 0, :, 1], x)


# --------------------------------------------------------------------------- ProDMP
def test_prodmp_meets_initial_conditions_exactly() -> None:
    gen = torch.Generator().manual_seed(4)
    prodmp = ProDMP(n_basis=7, n_dof=3, duration=1.5, dt=0.01, tau=0.8)
    params = 100.0 * torch.randn(4, 5, 24, generator=gen, dtype=torch.float64)
    y0 = torch.randn(4, 5, 3, generator=gen, dtype=torch.float64)
    dy0 = 10.0 * torch.randn(4, 1, 3, generator=gen, dtype=torch.float64)
    pos, vel = prodmp.trajectory(params, y0, dy0)
    assert pos.shape == vel.shape == (4, 5, 151, 3)
    torch.testing.assert_close(pos[..., 0, :], y0, atol=1e-10, rtol=0)
    torch.testing.assert_close(vel[..., 0, :], dy0.expand(4, 5, 3), atol=1e-10, rtol=0)

    # Velocities are the time derivative of positions (checked on a finer grid; the basis
    # grid is made as fine too, since by default it is read by linear interpolation between
    # points 0.01 s apart, as mp_pytorch does).
    fine = ProDMP(n_basis=7, n_dof=3, duration=1.5, dt=0.001, tau=0.8, basis_dt=0.001)
    pos, vel = fine.trajectory(params[0], y0[0], dy0[0])
    central = (pos[..., 2:, :] - pos[..., :-2, :]) / (2 * fine.dt)
    assert (vel[..., 1:-1, :] - central).abs().max() < 1e-3 * vel.abs().max()


def test_prodmp_matches_dmp_integration() -> None:
    gen = torch.Generator().manual_seed(5)
    kwargs = dict(n_basis=8, n_dof=2, duration=1.2, dt=0.01, alpha=30.0, tau=0.9, alpha_x=2.5)
    prodmp = ProDMP(**kwargs, basis_dt=0.001)  # a fine basis grid: its own error stays small
    w = 150.0 * torch.randn(6, 16, generator=gen, dtype=torch.float64)
    goal = torch.randn(6, 2, generator=gen, dtype=torch.float64)
    y0 = torch.randn(6, 2, generator=gen, dtype=torch.float64)
    dy0 = torch.randn(6, 2, generator=gen, dtype=torch.float64)
    pos, vel = prodmp.trajectory(_prodmp_params(w, goal, 2, 8), y0, dy0)

    pos_errors, vel_errors = [], []
    for substeps in (10, 40):
        dmp_pos, dmp_vel = DMP(**kwargs, substeps=substeps).rollout(w, y0, dy0, goal)
        pos_errors.append((dmp_pos - pos).abs().max() / pos.abs().max())
        vel_errors.append((dmp_vel - vel).abs().max() / vel.abs().max())
    assert pos_errors[1] < 5e-3 and vel_errors[1] < 5e-3
    # The gap is first-order Euler error, not a mismatch: 4x smaller steps, ~4x smaller gap.
    assert pos_errors[1] < pos_errors[0] / 3 and vel_errors[1] < vel_errors[0] / 3


def test_prodmp_distribution_matches_monte_carlo() -> None:
    gen = torch.Generator().manual_seed(6)
    prodmp = ProDMP(n_basis=5, n_dof=2, dt=0.02)
    mean_params = 20.0 * torch.randn(12, generator=gen, dtype=torch.float64)
    cov_params = _random_cov(gen, 12, scale=50.0)
    y0, dy0 = torch.tensor([0.3, -0.2]), torch.tensor([1.0, 0.0])
    mean, std = prodmp.distribution(mean_params, cov_params, y0, dy0)
    assert mean.shape == std.shape == (51, 2)
    torch.testing.assert_close(mean, prodmp.trajectory(mean_params, y0, dy0)[0])
    assert std[0].max() < 1e-10  # the start is pinned by the initial conditions

    chol = torch.linalg.cholesky(cov_params)
    samples = mean_params + torch.randn(40_000, 12, generator=gen, dtype=torch.float64) @ chol.T
    trajs, _ = prodmp.trajectory(samples, y0, dy0)
    torch.testing.assert_close(trajs.mean(0), mean, atol=0.05 * std.max().item(), rtol=0)
    torch.testing.assert_close(trajs.std(0)[1:], std[1:], atol=1e-9, rtol=0.03)

    batched_mean, batched_std = prodmp.distribution(mean_params.expand(3, 12), cov_params, y0, dy0)
    assert batched_mean.shape == batched_std.shape == (3, 51, 2)


def test_prodmp_basis_matrix() -> None:
    prodmp = ProDMP(n_basis=4, n_dof=1)
    phi, dphi = prodmp.basis_matrix(), prodmp.basis_matrix(derivative=True)
    assert phi.shape == dphi.shape == (101, 5)
    # the goal's column starts at rest at zero: 1 - (1 + a s) exp(-a s), a = alpha / 2 (Eq. P2)
    a, s = 12.5, prodmp.times
    torch.testing.assert_close(phi[:, -1], 1 - (1 + a * s) * torch.exp(-a * s))
    torch.testing.assert_close(dphi[:, -1], a**2 * s * torch.exp(-a * s))
    assert phi[0].abs().max() == 0 and dphi[0].abs().max() == 0


def test_gradients_flow_to_parameters() -> None:
    params = torch.zeros(2 * 5, dtype=torch.float64, requires_grad=True)
    pos, _ = ProDMP(n_basis=4, n_dof=2).trajectory(params, [0.1, 0.2], [0.0, 0.0])
    pos[-1].sum().backward()
    assert params.grad is not None and torch.isfinite(params.grad).all()
    assert params.grad[4] > 0.9  # the goal pulls the end point
    w = torch.zeros(6, dtype=torch.float64, requires_grad=True)
    ProMP(n_basis=3, n_dof=2).trajectory(w).sum().backward()
    assert w.grad is not None and torch.isfinite(w.grad).all()


def test_float32_dtype() -> None:
    prodmp = ProDMP(n_basis=3, n_dof=1, dtype=torch.float32)
    pos, vel = prodmp.trajectory(np.ones(4), [0.0], [0.0])
    assert pos.dtype == vel.dtype == torch.float32
    assert ProMP(3, 1, dtype=torch.float32).trajectory(np.ones(3)).dtype == torch.float32


# --------------------------------------------------------------------------- bad input
@pytest.mark.parametrize("cls", [ProMP, DMP, ProDMP])
@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (dict(n_basis=0, n_dof=1), r"n_basis must be an integer >= 1, got 0"),
        (dict(n_basis=2.5, n_dof=1), r"n_basis must be an integer >= 1, got 2.5"),
        (dict(n_basis=3, n_dof=0), r"n_dof must be an integer >= 1, got 0"),
        (dict(n_basis=3, n_dof=1, duration=0.0), r"duration must be a finite positive .* 0.0"),
        (dict(n_basis=3, n_dof=1, duration=-1.0), r"duration must be a finite positive .* -1.0"),
        (dict(n_basis=3, n_dof=1, dt=float("nan")), r"dt must be a finite positive .* nan"),
        (dict(n_basis=3, n_dof=1, dt=2.0), r"dt must not exceed duration=1.0, got dt=2.0"),
    ],
)
def test_constructors_reject_bad_input(cls: type, kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        cls(**kwargs)


def test_basis_widths_reject_bad_values() -> None:
    with pytest.raises(ValueError, match=r"width must be a finite positive .* -0.1"):
        ProMP(3, 1, width=-0.1)
    for cls in (DMP, ProDMP):
        with pytest.raises(ValueError, match=r"bandwidth_factor must be a finite positive .* -0.1"):
            cls(3, 1, bandwidth_factor=-0.1)
        with pytest.raises(ValueError, match=r"rule must be one of .*, got 'fancy'"):
            cls(3, 1, rule="fancy")


@pytest.mark.parametrize("cls", [DMP, ProDMP])
@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (dict(alpha=0.0), r"alpha must be a finite positive number, got 0.0"),
        (dict(tau=-2.0), r"tau must be a finite positive number, got -2.0"),
        (dict(alpha_x=float("inf")), r"alpha_x must be a finite positive number, got inf"),
        (dict(bandwidth_factor=0), r"bandwidth_factor must be a finite positive number, got 0"),
    ],
)
def test_dynamic_primitives_reject_bad_constants(cls: type, kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        cls(n_basis=3, n_dof=2, **kwargs)


def test_dmp_rejects_bad_beta_and_substeps() -> None:
    with pytest.raises(ValueError, match=r"beta must be a finite positive number, got -1.0"):
        DMP(3, 2, beta=-1.0)
    with pytest.raises(ValueError, match=r"substeps must be an integer >= 1, got 0"):
        DMP(3, 2, substeps=0)


def test_prodmp_rejects_a_horizon_beyond_its_basis_grid() -> None:
    # the basis grid covers (t - delay) / tau in [0, 6] (mp_pytorch's length factor)
    with pytest.raises(ValueError, match=r"scaled time \(t - delay\) / tau must lie in \[0, 6\]"):
        ProDMP(3, 1, duration=100.0, dt=0.5)
    with pytest.raises(ValueError, match=r"delay must be a finite number >= 0, got -0.1"):
        ProDMP(3, 1, delay=-0.1)


def test_promp_rejects_bad_shapes() -> None:
    promp = ProMP(n_basis=3, n_dof=2)
    with pytest.raises(ValueError, match=r"w must have shape \(\.\.\., 6\) .* got shape \(5,\)"):
        promp.trajectory(np.zeros(5))
    with pytest.raises(ValueError, match=r"w must have shape \(\.\.\., 6\) .* got shape \(\)"):
        promp.velocity(0.0)
    with pytest.raises(ValueError, match=r"cov_w must have shape \(\.\.\., 6, 6\) .* \(6, 5\)"):
        promp.distribution(np.zeros(6), np.eye(6)[:, :5])
    with pytest.raises(ValueError, match=r"cov_w must have shape \(\.\.\., 6, 6\) .* \(3, 3\)"):
        promp.marginal_std(np.eye(3))
    with pytest.raises(ValueError, match=r"mean_w must have shape \(\.\.\., 6\) .* \(2, 7\)"):
        promp.distribution(np.zeros((2, 7)), np.eye(6))


def test_promp_condition_rejects_bad_input() -> None:
    promp = ProMP(n_basis=3, n_dof=2)
    mean, cov = np.zeros(6), np.eye(6)
    with pytest.raises(ValueError, match=r"t must be a time in \[0, duration=1.0\], got 1.5"):
        promp.condition(mean, cov, 1.5, [0.0, 0.0], 0.1)
    with pytest.raises(ValueError, match=r"t must be a time in \[0, duration=1.0\], got -0.1"):
        promp.condition(mean, cov, -0.1, [0.0, 0.0], 0.1)
    with pytest.raises(ValueError, match=r"y must have shape \(\.\.\., 2\) .* got shape \(3,\)"):
        promp.condition(mean, cov, 0.5, [0.0, 0.0, 0.0], 0.1)
    with pytest.raises(ValueError, match=r"y_std must be finite and positive, got \[0.1, 0.0\]"):
        promp.condition(mean, cov, 0.5, [0.0, 0.0], [0.1, 0.0])
    with pytest.raises(ValueError, match=r"y_std must be a number or have shape \(2,\)"):
        promp.condition(mean, cov, 0.5, [0.0, 0.0], [0.1, 0.1, 0.1])
    with pytest.raises(ValueError, match=r"cov_w must be positive semi-definite"):
        promp.condition(mean, -np.eye(6), 0.5, [0.0, 0.0], 1e-3)


def test_dmp_and_prodmp_reject_bad_shapes() -> None:
    dmp = DMP(n_basis=3, n_dof=2)
    with pytest.raises(ValueError, match=r"w must have shape \(\.\.\., 6\) .* got shape \(4, 7\)"):
        dmp.rollout(np.zeros((4, 7)), np.zeros(2), np.zeros(2), np.zeros(2))
    with pytest.raises(ValueError, match=r"goal must have shape \(\.\.\., 2\) .* \(3,\)"):
        dmp.rollout(np.zeros(6), np.zeros(2), np.zeros(2), np.zeros(3))
    with pytest.raises(ValueError, match=r"y0 must have shape \(\.\.\., 2\) .* \(1,\)"):
        dmp.rollout(np.zeros(6), np.zeros(1), np.zeros(2), np.zeros(2))

    prodmp = ProDMP(n_basis=3, n_dof=2)
    match = r"params must have shape \(\.\.\., 8\) \(n_dof \* \(n_basis \+ 1\)\), got shape \(6,\)"
    with pytest.raises(ValueError, match=match):
        prodmp.trajectory(np.zeros(6), np.zeros(2), np.zeros(2))
    with pytest.raises(ValueError, match=r"dy0 must have shape \(\.\.\., 2\) .* \(5, 3\)"):
        prodmp.trajectory(np.zeros(8), np.zeros(2), np.zeros((5, 3)))
    with pytest.raises(ValueError, match=r"mean_params must have shape \(\.\.\., 8\)"):
        prodmp.distribution(np.zeros(6), np.eye(8), np.zeros(2), np.zeros(2))
    match = r"cov_params must have shape \(\.\.\., 8, 8\) .* got shape \(6, 6\)"
    with pytest.raises(ValueError, match=match):
        prodmp.distribution(np.zeros(8), np.eye(6), np.zeros(2), np.zeros(2))
    with pytest.raises(ValueError, match=r"w must be array-like of numbers, got 'abc'"):
        ProMP(3, 2).trajectory("abc")


# --------------------------------------------------------------------------- numpy paths
def test_numpy_trajectories_equal_the_torch_ones() -> None:
    """trajectory_numpy (what the robot tasks call) gives the torch path's numbers, batched."""
    rng = np.random.default_rng(7)
    prodmp = ProDMP(n_basis=3, n_dof=7, duration=2.0, dt=0.008, tau=0.9)
    params, y0, dy0 = 50 * rng.normal(size=(5, 28)), rng.normal(size=(5, 7)), rng.normal(size=7)
    pos, vel = prodmp.trajectory_numpy(params, y0, dy0)
    want_pos, want_vel = prodmp.trajectory(params, y0, dy0)
    assert isinstance(pos, np.ndarray) and pos.shape == vel.shape == (5, 251, 7)
    np.testing.assert_allclose(pos, want_pos.numpy(), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(vel, want_vel.numpy(), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(pos[:, 0], y0, atol=1e-12)  # the initial conditions hold
    np.testing.assert_allclose(vel[:, 0], np.broadcast_to(dy0, (5, 7)), atol=1e-12)

    promp = ProMP(n_basis=4, n_dof=3, duration=0.7, dt=0.001, width=0.1)
    w = rng.normal(size=(2, 12))
    pos, vel = promp.trajectory_numpy(w)
    np.testing.assert_allclose(pos, promp.trajectory(w).numpy(), rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(vel, promp.velocity(w).numpy(), rtol=1e-12, atol=1e-12)
    central = (pos[:, 2:] - pos[:, :-2]) / (2 * promp.dt)  # velocities: d/dt of positions
    assert np.abs(vel[:, 1:-1] - central).max() < 1e-3 * np.abs(vel).max()


def test_numpy_trajectories_reject_bad_shapes() -> None:
    prodmp, promp = ProDMP(n_basis=3, n_dof=2), ProMP(n_basis=3, n_dof=2)
    with pytest.raises(ValueError, match=r"params must have shape \(\.\.\., 8\), got \(6,\)"):
        prodmp.trajectory_numpy(np.zeros(6), np.zeros(2), np.zeros(2))
    with pytest.raises(ValueError, match=r"dy0 must have shape \(\.\.\., 2\), got \(3,\)"):
        prodmp.trajectory_numpy(np.zeros(8), np.zeros(2), np.zeros(3))
    with pytest.raises(ValueError, match=r"w must have shape \(\.\.\., 6\), got \(5,\)"):
        promp.trajectory_numpy(np.zeros(5))


def test_basis_first_layouts() -> None:
    s = np.linspace(-0.1, 1.1, 31)
    first = normalized_rbf_np(s, 4, basis_first=True, derivative=True)
    want = normalized_rbf_np(s, 4, derivative=True)
    np.testing.assert_array_equal(np.moveaxis(first, 0, -1), want)
    forcing = dmp_forcing_basis_np(s, 4, 2.0, 0.5, basis_first=True)
    np.testing.assert_array_equal(forcing.T, dmp_forcing_basis(s, 4, 2.0, 0.5).numpy())

"""Tests for Eq. 5.9 (denoising score matching) and Section 5.6 (general bridges, Eqs. 5.29-5.38).

Each formula is compared with a computation written here from the thesis's equations and
independent of the module's code: joint Gaussians assembled by hand and scipy's density,
brute-force integration over a full grid of the chain's variables, the moment ODEs solved in
closed form, Gauss-Hermite quadrature. Each check fails when handed a wrong candidate.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from scipy.stats import multivariate_normal

from vslbook.bounds import CheckReport
from vslbook.bounds import dime as D
from vslbook.bounds import dime_bridges_quadrature as BQ
from vslbook.srl.diffusion_policy import (
    DiffusionPolicy,
    DiffusionPolicyConfig,
    tanh_log_det_jacobian,
)

SEEDS = (0, 1, 2)
CHECKS = (
    D.check_score_matching,
    D.check_general_bridge,
    D.check_bridge_quadrature,
    D.check_dime_as_bridge,
)


def failed_names(report: CheckReport) -> set[str]:
    return {check.name for check in report.failed}


def log_normal(x, mean, var):
    return -0.5 * ((x - mean) ** 2 / var + np.log(2 * np.pi * var))


# ------------------------------------------------------------------ every check passes


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("check", CHECKS, ids=lambda f: f.__name__)
def test_check_passes(check, seed):
    report = check(seed)
    assert isinstance(report, CheckReport) and len(report) >= 6
    report.require()


@pytest.mark.parametrize("check", CHECKS, ids=lambda f: f.__name__)
def test_checks_are_deterministic(check):
    a, b = check(3), check(3)
    assert [c.lhs for c in a] == [c.lhs for c in b]
    for key in a.data:
        np.testing.assert_array_equal(a.data[key], b.data[key])


# ------------------------------------------------------- Eq. 5.9: denoising score matching


def test_ou_conditional_solves_the_moment_odes():
    """Eq. 5.7's conditional law against dm/dt = -beta_t m, dv/dt = -2 beta_t v + 2 eta^2 beta_t,
    integrated here in closed form with the schedule's own antiderivative."""
    process = D.OUProcess(beta_start=0.3, beta_end=5.0, horizon=2.0, eta=1.3)
    t = np.linspace(0.0, 2.0, 9)
    b = 0.3 * t + (5.0 - 0.3) * t**2 / (2 * 2.0)  # int_0^t beta_s ds, by hand
    mean, var = process.conditional(0.8, t)
    np.testing.assert_allclose(mean, 0.8 * np.exp(-b), rtol=1e-14)
    np.testing.assert_allclose(var, 1.3**2 * (1 - np.exp(-2 * b)), rtol=1e-14, atol=1e-16)
    # and by finite differences of the ODEs themselves
    h = 1e-6
    for s in (0.4, 1.1, 1.9):
        (m1, v1), (m0, v0) = process.conditional(0.8, s + h), process.conditional(0.8, s - h)
        m, v = process.conditional(0.8, s)
        beta = process.beta(s)
        assert abs((m1 - m0) / (2 * h) + beta * m) < 1e-7
        assert abs((v1 - v0) / (2 * h) - (-2 * beta * v + 2 * 1.3**2 * beta)) < 1e-7


def test_score_matching_loss_by_hand():
    process = D.OUProcess()
    a0, a_t, t = np.array([0.3, -1.2]), np.array([0.1, 0.4]), 0.5
    b = process.beta_start * t + (process.beta_end - process.beta_start) * t**2 / 2
    var = 1 - math.exp(-2 * b)
    target = -(a_t - math.exp(-b) * a0) / var

    def f(x, s):
        return 2 * x - 1

    expected = (process.beta_start + (process.beta_end - process.beta_start) * t) * (
        f(a_t, t) - target
    ) ** 2
    np.testing.assert_allclose(D.score_matching_loss(f, a0, a_t, t, process), expected, rtol=1e-14)


@pytest.mark.parametrize("t", [0.2, 0.5, 1.0])
def test_minimiser_of_eq_5_9_over_affine_scores_is_the_marginal_score(t):
    """For a Gaussian target, Eq. 5.9 over f(a) = c0 + c1 a is a quadratic in (c0, c1);
    Gauss-Hermite quadrature over (a_0, noise) is exact for it. Its minimiser is the marginal
    score -(a - m_t) / v_t, with m_t, v_t propagated here from the OU solution."""
    process, mu, s2 = D.OUProcess(), 0.7, 0.45
    x, w = np.polynomial.hermite_e.hermegauss(12)
    w = w / w.sum()
    a0 = mu + math.sqrt(s2) * x[:, None]
    m, v = process.conditional(a0, t)
    a_t = m + np.sqrt(v) * x[None, :]
    weight = w[:, None] * w[None, :]

    def loss(c0, c1):
        return np.sum(weight * D.score_matching_loss(lambda y, s: c0 + c1 * y, a0, a_t, t, process))

    # the quadratic's coefficients from 6 evaluations, then its stationary point
    pts = [(0, 0), (1, 0), (-1, 0), (0, 1), (0, -1), (1, 1)]
    vals = [loss(*p) for p in pts]
    design = np.array([[1, c0, c1, c0 * c0, c1 * c1, c0 * c1] for c0, c1 in pts], dtype=float)
    k = np.linalg.solve(design, vals)
    hess = np.array([[2 * k[3], k[5]], [k[5], 2 * k[4]]])
    c_star = np.linalg.solve(hess, -k[1:3])
    decay = math.exp(-float(process.integral(t)))
    m_t, v_t = decay * mu, decay**2 * s2 + (1 - decay**2)
    np.testing.assert_allclose(c_star, [m_t / v_t, -1 / v_t], rtol=1e-9)


def test_wrong_conditional_score_fails():
    process = D.OUProcess()

    def wrong(a_t, a0, t):  # variance 1 - e^{-B} instead of 1 - e^{-2B}
        b = process.integral(t)
        return -(a_t - np.exp(-b) * a0) / (1 - np.exp(-b))

    failed = failed_names(D.check_score_matching(0, conditional_score=wrong))
    assert "E[grad log ->pi_{t|0}(a_t|a_0) | a_t] = grad log ->pi_t(a_t) (quadrature)" in failed
    assert "Eq. 5.9 - explicit score loss = C(t), the same for every f (quadrature)" in failed
    assert any(name.startswith("least squares on samples") for name in failed)


def test_score_matching_report_data():
    report = D.check_score_matching(0, n_samples=2000)
    d = report.data
    assert d["posterior_score"].shape == d["marginal_score"].shape == (4, d["grid"].size)
    assert d["loss_offsets"].shape == d["losses"].shape == (4, 4)
    np.testing.assert_array_equal(d["denoise_steps"], [16, 32, 64, 128])
    assert np.all(np.diff(d["denoise_l1"]) < 0)
    np.testing.assert_allclose(np.trapezoid(d["target_density"], d["denoise_grid"]), 1, atol=1e-6)


# --------------------------------------------- Section 5.6: the bridge and its joints


def _affine_2d(n_steps=3, delta=0.3):
    F = np.array([[-0.4, 0.2], [-0.1, -0.6]])
    U, u0 = np.array([[0.3, -0.2], [0.1, 0.2]]), np.array([0.2, -0.1])
    V, v0 = np.array([[-0.7, 0.1], [0.2, -0.3]]), np.array([-0.3, 0.5])
    beta = np.array([[0.8, 1.3]])
    bridge = D.make_bridge(
        lambda a, n: a @ F.T,
        lambda a, n: a @ (U * (1 + n)).T + u0,
        lambda a, n: a @ (V / (1 + n)).T + v0,
        beta,
        delta,
        n_steps,
        2,
    )
    return bridge, F, U, u0, V, v0, beta[0]


def test_kernels_follow_eqs_5_35_and_5_36():
    bridge, F, U, u0, V, v0, beta = _affine_2d()
    a = np.random.default_rng(0).normal(size=(7, 2))
    for n in range(3):
        expected = a + (a @ F.T + beta * (a @ (U * (1 + n)).T + u0)) * 0.3  # Eq. 5.35
        np.testing.assert_allclose(bridge.forward_mean(a, n), expected, rtol=1e-14)
    for n in range(1, 4):
        expected = a - (a @ F.T - beta * (a @ (V / (1 + n)).T + v0)) * 0.3  # Eq. 5.36
        np.testing.assert_allclose(bridge.backward_mean(a, n), expected, rtol=1e-14)
        np.testing.assert_allclose(bridge.kernel_var(n), 2 * beta * 0.3)


def _scalar_bridge():
    c_f, c_u, c_v, o_u, o_v, beta, delta = -0.5, 0.4, -1.1, 0.3, -0.2, 0.9, 0.25
    bridge = D.make_bridge(
        lambda a, n: c_f * a,
        lambda a, n: c_u * a + o_u,
        lambda a, n: (c_v + 0.1 * n) * a + o_v,
        beta,
        delta,
        3,
        1,
        prior_var=1.0,
    )
    fwd = [(1 + (c_f + beta * c_u) * delta, beta * o_u * delta) for n in range(3)]
    bwd = {n: (1 - (c_f - beta * (c_v + 0.1 * n)) * delta, beta * o_v * delta) for n in (1, 2, 3)}
    return bridge, fwd, bwd, 2 * beta * delta


def _chain_cov(order, start_var, start_mean, steps, var):
    """Mean and covariance of x_0 ~ N(start), x_{k+1} = c_k x_k + e_k + N(0, var), by hand."""
    n = len(order)
    mean, cov = np.zeros(n), np.zeros((n, n))
    mean[0], cov[0, 0] = start_mean, start_var
    for k, (c, e) in enumerate(steps):
        mean[k + 1] = c * mean[k] + e
        cov[k + 1, : k + 1] = c * cov[k, : k + 1]
        cov[: k + 1, k + 1] = cov[k + 1, : k + 1]
        cov[k + 1, k + 1] = c * c * cov[k, k] + var
    perm = np.argsort(order)  # reorder to a^0, ..., a^N
    return mean[perm], cov[np.ix_(perm, perm)]


def test_log_joints_equal_scipy_on_the_hand_built_gaussians():
    """Eqs. 5.33-5.34: the chains' log densities against scipy's joint Gaussian densities."""
    bridge, fwd, bwd, var = _scalar_bridge()
    traj = np.random.default_rng(1).normal(size=(4, 6, 1)) * 1.5
    # backward joint, built from a^3 down to a^0
    mean_b, cov_b = _chain_cov([3, 2, 1, 0], 1.0, 0.0, [bwd[3], bwd[2], bwd[1]], var)
    expected = multivariate_normal(mean_b, cov_b).logpdf(traj[:, :, 0].T)
    np.testing.assert_allclose(D.log_backward_joint(bridge, traj), expected, rtol=1e-12)
    # forward joint started at N(0.4, 0.6), built from a^0 up
    mean_f, cov_f = _chain_cov([0, 1, 2, 3], 0.6, 0.4, fwd, var)
    expected = multivariate_normal(mean_f, cov_f).logpdf(traj[:, :, 0].T)
    got = D.log_forward_conditional(bridge, traj) + log_normal(traj[0, :, 0], 0.4, 0.6)
    np.testing.assert_allclose(got, expected, rtol=1e-12)


def test_closed_form_joints_equal_the_hand_built_gaussians():
    bridge, fwd, bwd, var = _scalar_bridge()
    cf = D.linear_bridge_closed_form(bridge, [0.4], [[0.6]])
    mean_b, cov_b = _chain_cov([3, 2, 1, 0], 1.0, 0.0, [bwd[3], bwd[2], bwd[1]], var)
    mean_f, cov_f = _chain_cov([0, 1, 2, 3], 0.6, 0.4, fwd, var)
    np.testing.assert_allclose(cf.backward_mean, mean_b, atol=1e-14)
    np.testing.assert_allclose(cf.backward_cov, cov_b, rtol=1e-12)
    np.testing.assert_allclose(cf.forward_mean, mean_f, atol=1e-14)
    np.testing.assert_allclose(cf.forward_cov, cov_f, rtol=1e-12)


def _grid_quantities(bridge, q, half_width=9.0, size=151):
    """Brute force over the full 3-D grid of (a^0, a^1, a^2) for a 1-D bridge with N = 2, with
    the kernels of Eqs. 5.35-5.36 written out here from the bridge's drift functions."""
    assert bridge.n_steps == 2 and bridge.dim == 1
    g = np.linspace(-half_width, half_width, size)
    h = g[1] - g[0]
    a0, a1, a2 = np.meshgrid(g, g, g, indexing="ij")
    beta, delta = bridge.beta[:, 0], bridge.delta
    f, u, v = bridge.f, bridge.u, bridge.v

    def back(a, n):  # Eq. 5.36
        return a - (f(a, n) - beta[n - 1] * v(a, n)) * delta

    def forw(a, n):  # Eq. 5.35
        return a + (f(a, n) + beta[n] * u(a, n)) * delta

    var = 2 * beta * delta
    log_b = (
        log_normal(a2, bridge.prior_mean[0], bridge.prior_var[0])
        + log_normal(a1, back(a2, 2), var[1])
        + log_normal(a0, back(a1, 1), var[0])
    )
    log_f = log_normal(a1, forw(a0, 0), var[0]) + log_normal(a2, forw(a1, 1), var[1])
    p = np.exp(log_b)
    cell = h**3
    q_grid = q(g[:, None])
    log_z = math.log(np.sum(np.exp(q_grid)) * h)
    p0 = p.sum((1, 2)) * h * h
    return {
        "mass": p.sum() * cell,
        "bound": np.sum(p * (log_f - log_b)) * cell,
        "kl": np.sum(p * (log_b - (q(a0[..., None]) - log_z) - log_f)) * cell,
        "entropy": -np.sum(np.where(p0 > 0, p0 * np.log(p0), 0.0)) * h,
    }


def test_affine_closed_form_against_brute_force_grid():
    bridge = D.make_bridge(
        lambda a, n: -0.4 * a,
        lambda a, n: 0.5 * a + 0.2 * n,
        lambda a, n: -1.3 * a + 0.4,
        1.0,
        0.5,
        2,
        1,
    )
    mu, s2 = 0.3, 0.5
    cf = D.linear_bridge_closed_form(bridge, [mu], [[s2]])
    grid = _grid_quantities(bridge, lambda a: -((a[..., 0] - mu) ** 2) / (2 * s2))
    assert abs(grid["mass"] - 1) < 1e-10
    assert abs(grid["bound"] - cf.bound) < 1e-10
    assert abs(grid["entropy"] - cf.entropy) < 1e-10
    assert abs(grid["kl"] - cf.kl) < 1e-10


@pytest.mark.parametrize("seed", [0, 4])
def test_transfer_quadrature_against_brute_force_grid(seed):
    """The check's quadrature (marginals propagated step by step) against the full 3-D grid,
    for the nonlinear bridge and the double-well target, at N = 2."""
    report = D.check_bridge_quadrature(seed, n_steps=2, n_samples=200)
    grid = _grid_quantities(BQ._nonlinear_bridge(seed, 2, 1.0), BQ._double_well(seed))
    assert abs(grid["mass"] - 1) < 1e-9
    for key in ("bound", "kl", "entropy"):
        assert abs(float(report.data[key]) - grid[key]) < 1e-10, key


def test_linear_sde_moments_scalar_ou_in_closed_form():
    """dx = (a x + b) dt + sqrt(2 beta) dB: m = e^{aT} m0 + b (e^{aT} - 1) / a,
    P = e^{2aT} P0 + beta (e^{2aT} - 1) / a."""
    a, b, beta, m0, p0, T = -0.7, 0.4, 0.9, 1.5, 0.3, 1.8
    m, P = D.linear_sde_moments(
        lambda t: (np.array([[a]]), np.array([b])), np.array([beta]), [m0], [[p0]], T
    )
    e = math.exp(a * T)
    assert abs(m[0] - (e * m0 + b * (e - 1) / a)) < 1e-10
    assert abs(P[0, 0] - (e * e * p0 + beta * (e * e - 1) / a)) < 1e-10


def test_reversal_controls_drive_the_joint_kl_to_zero():
    """Nelson's relation u + v = 2 grad log ->pi_t: Eq. 5.37 -> 0 like delta (KL * N settles)."""
    d = D.check_general_bridge(0, n_samples=100).data
    kl, steps = d["reversal_kl"], d["reversal_steps"]
    assert np.all(kl[-1] < 0.02)
    scaled = kl * steps[:, None]
    assert np.all(np.abs(scaled[-1] / scaled[-2] - 1) < 0.05)


# ------------------------------------------------------------- DIME as the special case


def test_dime_bridge_estimator_equals_eqs_5_11b_5_12_log_ratio():
    """The bound estimator on DIME's bridge against the log ratio of Eq. 5.15 written with the
    kernels of Eqs. 5.11b-5.12 (eta != 1, a nonlinear score)."""
    beta, delta, eta, n_steps = 0.7, 0.2, 1.6, 4

    def score(a, n):
        return -a / (2 + n) + 0.5 * np.cos(a)

    bridge = D.dime_bridge(beta, delta, n_steps, 1, score, eta)
    traj = D.sample_backward(bridge, 500, seed=3)
    var = 2 * eta**2 * beta * delta
    expected = -log_normal(traj[-1, :, 0], 0.0, eta**2)
    for n in range(1, n_steps + 1):
        x_n, x_prev = traj[n, :, 0], traj[n - 1, :, 0]
        denoise = x_n + (beta * x_n + 2 * eta**2 * beta * score(x_n, n)) * delta  # Eq. 5.12
        noise = x_prev - beta * x_prev * delta  # Eq. 5.11b
        expected += log_normal(x_n, noise, var) - log_normal(x_prev, denoise, var)
    np.testing.assert_allclose(D.entropy_bound_samples(bridge, traj), expected, rtol=1e-12)


@pytest.mark.parametrize("squash", [False, True])
@pytest.mark.parametrize("general_bridges", [False, True])
def test_policy_bridge_reproduces_the_library_entropy_bound(general_bridges, squash):
    """The library's DIME defaults (cosine schedule, 16 steps, per-dimension noise) with
    random networks: its entropy_bound is the bridge's estimator, plus the tanh term of
    Eq. C.30 when the action is squashed."""
    config = DiffusionPolicyConfig(
        n_frequencies=8,
        hidden=32,
        n_layers=2,
        out_init_scale=1.0,
        squash=squash,
        general_bridges=general_bridges,
    )
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(5)
        policy = DiffusionPolicy(obs_dim=4, act_dim=3, config=config).double()
        if policy.noising_net is not None:
            torch.nn.init.normal_(policy.noising_net.out.weight, std=0.5)
    obs = np.array([0.3, -1.0, 0.5, 2.0])
    out = policy.sample(
        torch.as_tensor(np.tile(obs, (300, 1))),
        generator=torch.Generator().manual_seed(2),
        return_trajectory=True,
    )
    traj = out.trajectory.detach().numpy()[::-1]
    bridge = D.policy_bridge(policy, obs)
    expected = D.entropy_bound_samples(bridge, traj)
    if squash:
        expected = expected + tanh_log_det_jacobian(out.latent).detach().numpy()
    np.testing.assert_allclose(out.entropy_bound.detach().numpy(), expected, rtol=1e-10, atol=1e-10)


def _flipped_bound(bridge, traj):
    """The log ratio of Eq. 5.15 with Eq. 5.36's bracket added instead of subtracted."""
    out = -log_normal(traj[-1], bridge.prior_mean, bridge.prior_var).sum(-1)
    for n in range(1, bridge.n_steps + 1):
        var = bridge.kernel_var(n)
        wrong = (
            traj[n]
            + (bridge.f(traj[n], n) - bridge.beta[n - 1] * bridge.v(traj[n], n)) * bridge.delta
        )
        right_forward = bridge.forward_mean(traj[n - 1], n - 1)
        out += log_normal(traj[n], right_forward, var).sum(-1)
        out -= log_normal(traj[n - 1], wrong, var).sum(-1)
    return out


def _flipped_kl(bridge, traj, q, log_z):
    return -_flipped_bound(bridge, traj) - q(traj[0]) + log_z


@pytest.mark.parametrize("check", [D.check_general_bridge, D.check_bridge_quadrature])
def test_wrong_estimators_fail(check):
    failed = failed_names(check(0, kl_estimator=_flipped_kl, bound_estimator=_flipped_bound))
    assert any(name.startswith("Monte Carlo of Eq. 5.37") for name in failed)
    assert any(name.startswith("Monte Carlo of the bound estimator") for name in failed)


@pytest.mark.parametrize("check", [D.check_general_bridge, D.check_bridge_quadrature])
def test_bound_estimator_without_the_forward_kernels_fails(check):
    def no_forward(bridge, traj):  # -log pi~_{0:N}: the joint's entropy, not ℓ
        return -D.log_backward_joint(bridge, traj)

    failed = failed_names(check(0, bound_estimator=no_forward))
    assert any(name.startswith("Monte Carlo of the bound estimator") for name in failed)
    assert not any(name.startswith("Monte Carlo of Eq. 5.37") for name in failed)


def test_policy_mapping_without_the_prior_score_fails():
    def wrong(policy, obs):  # u = g_psi, v = f_theta: forgets grad log p_N in both controls
        right = D.policy_bridge(policy, obs)
        prior = policy.config.sigma0**2
        return D.GeneralBridge(
            right.f,
            lambda a, n: right.u(a, n) + a / prior,
            lambda a, n: right.v(a, n) + a / prior,
            right.beta,
            right.delta,
            right.prior_var,
            right.prior_mean,
        )

    failed = failed_names(D.check_dime_as_bridge(0, bridge_of=wrong))
    assert "DiffusionPolicy entropy_bound = bridge estimator, per chain (GB off, on)" in failed
    assert "affine GB policy: bridge closed form = linear_gaussian_chain (ℓ, H, gap)" in failed
    assert "dime_bridge kernels = Eqs. 5.11b-5.12 written out (max abs difference)" not in failed


# ------------------------------------------------------------------------- bad input


def test_bad_input_is_named():
    with pytest.raises(ValueError, match=r"beta must be a scalar, \(N,\), \(1, d\) or \(N, d\)"):
        D.make_bridge(None, None, None, np.ones(5), 0.1, 4, 2)
    with pytest.raises(ValueError, match="beta must be positive"):
        D.make_bridge(None, None, None, -1.0, 0.1, 4, 2)
    with pytest.raises(ValueError, match="prior_var must be positive"):
        D.make_bridge(None, None, None, 1.0, 0.1, 4, 2, prior_var=0.0)
    with pytest.raises(ValueError, match="delta must be a positive"):
        D.make_bridge(None, None, None, 1.0, 0.0, 4, 2)
    bridge = D.make_bridge(None, None, None, 1.0, 0.1, 4, 2)
    with pytest.raises(ValueError, match="a0 must have shape"):
        D.sample_forward(bridge, np.zeros((3, 1)))
    with pytest.raises(ValueError, match="trajectory must have shape"):
        D.log_backward_joint(bridge, np.zeros((4, 3, 2)))
    nonlinear = D.make_bridge(lambda a, n: np.sin(a), None, None, 1.0, 0.1, 2, 1)
    with pytest.raises(ValueError, match="not affine"):
        D.linear_bridge_closed_form(nonlinear, [0.0], [[1.0]])
    with pytest.raises(ValueError, match="check_times must lie"):
        D.check_score_matching(0, check_times=(0.0, 0.5))
    with pytest.raises(ValueError, match="eta must be a positive"):
        D.OUProcess(eta=0.0)

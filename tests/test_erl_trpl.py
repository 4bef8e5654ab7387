"""KL trust-region projection layers (Otto et al. 2021; Eq. 4.7): closed forms vs brute force."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import minimize
from torch.distributions import MultivariateNormal, kl_divergence

from vslbook.erl.trpl import kl_parts, project, project_cov, project_mean, trust_region_loss

F64 = torch.float64


# ---------------------------------------------------------------- random well-conditioned inputs


def _gen(seed: int) -> torch.Generator:
    return torch.Generator().manual_seed(seed)


def _random_chol(gen: torch.Generator, shape: tuple[int, ...], d: int) -> torch.Tensor:
    off = 0.3 * torch.randn(*shape, d, d, generator=gen, dtype=F64)
    diag = torch.exp(0.3 * torch.randn(*shape, d, generator=gen, dtype=F64))
    return torch.tril(off, -1) + torch.diag_embed(diag)


def _perturbed_chol(gen: torch.Generator, old: torch.Tensor, scale: torch.Tensor) -> torch.Tensor:
    """old @ T with T lower-triangular, positive diagonal; perturbation size ``scale`` (...,)."""
    d = old.shape[-1]
    s = scale[..., None, None]
    off = torch.tril(torch.randn(*old.shape, generator=gen, dtype=F64), -1)
    diag = torch.exp(s[..., 0] * torch.randn(*old.shape[:-1], generator=gen, dtype=F64))
    T = s * off + torch.diag_embed(diag)
    assert T.shape[-1] == d
    return old @ T


def _problem(seed: int, K: int, B: int, d: int):
    """Old and proposed Gaussians whose KL parts range from well inside to far outside."""
    gen = _gen(seed)
    levels = torch.tensor([1e-3, 3e-2, 0.3, 1.0], dtype=F64)
    old_chol = _random_chol(gen, (K,), d)
    scale = levels[torch.randint(0, 4, (K,), generator=gen)]
    chol = _perturbed_chol(gen, old_chol, scale)
    old_mean = torch.randn(K, B, d, generator=gen, dtype=F64)
    step = 10 ** (-2 + 2 * torch.rand(K, B, 1, generator=gen, dtype=F64))
    z = torch.randn(K, B, d, 1, generator=gen, dtype=F64)
    mean = old_mean + step * (old_chol.unsqueeze(1) @ z).squeeze(-1)
    return mean, chol, old_mean, old_chol


# ---------------------------------------------------------------- independent numpy formulas


def _np_kl0(S1: np.ndarray, S0: np.ndarray) -> float:
    """KL(N(0, S1) ‖ N(0, S0)) with explicit inverses and determinants."""
    d = S1.shape[0]
    return 0.5 * (
        np.trace(np.linalg.inv(S0) @ S1) - d + np.linalg.slogdet(S0)[1] - np.linalg.slogdet(S1)[1]
    )


def _np_chol(p: np.ndarray) -> np.ndarray:
    return np.array([[np.exp(p[0]), 0.0], [p[1], np.exp(p[2])]])


# ---------------------------------------------------------------- KL parts


@pytest.mark.parametrize("d", [1, 3])
def test_kl_parts_sum_is_the_gaussian_kl(d):
    mean, chol, old_mean, old_chol = _problem(1, K=2, B=4, d=d)
    m, c = kl_parts(mean, chol, old_mean, old_chol)
    assert m.shape == (2, 4) and c.shape == (2,)
    p = MultivariateNormal(mean, scale_tril=chol[:, None].expand(2, 4, d, d))
    q = MultivariateNormal(old_mean, scale_tril=old_chol[:, None].expand(2, 4, d, d))
    torch.testing.assert_close(m + c[:, None], kl_divergence(p, q), rtol=1e-10, atol=1e-12)
    # a single Gaussian: mean (d,), chol (d, d) -> scalars
    m1, c1 = kl_parts(mean[0, 0], chol[0], old_mean[0, 0], old_chol[0])
    assert m1.shape == () and c1.shape == ()
    torch.testing.assert_close(m1 + c1, kl_divergence(p, q)[0, 0], rtol=1e-10, atol=1e-12)


# ---------------------------------------------------------------- mean projection vs SLSQP


def _slsqp_mean(mu: np.ndarray, mu_o: np.ndarray, S_inv: np.ndarray, eps: float) -> np.ndarray:
    """argmin_x (x − μ)ᵀΣ_o⁻¹(x − μ) s.t. ½(x − μ_o)ᵀΣ_o⁻¹(x − μ_o) ≤ ε, by SLSQP from μ_o."""
    res = minimize(
        lambda x: (x - mu) @ S_inv @ (x - mu),
        mu_o,
        jac=lambda x: 2 * S_inv @ (x - mu),
        method="SLSQP",
        constraints=[
            {
                "type": "ineq",
                "fun": lambda x: eps - 0.5 * (x - mu_o) @ S_inv @ (x - mu_o),
                "jac": lambda x: -S_inv @ (x - mu_o),
            }
        ],
        options={"ftol": 1e-12, "maxiter": 500},
    )
    assert res.success, res.message
    return res.x


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("step", [0.1, 1.0, 3.0])  # inside and outside the bound
def test_project_mean_solves_the_constrained_problem(d, seed, step):
    eps = 0.05
    gen = _gen(seed)
    old_chol = _random_chol(gen, (), d)
    old_mean = torch.randn(d, generator=gen, dtype=F64)
    mean = old_mean + step * old_chol @ torch.randn(d, generator=gen, dtype=F64)
    got = project_mean(mean, old_mean, old_chol, eps).numpy()
    S_inv = np.linalg.inv((old_chol @ old_chol.T).numpy())
    expected = _slsqp_mean(mean.numpy(), old_mean.numpy(), S_inv, eps)
    np.testing.assert_allclose(got, expected, atol=1e-6)


# ---------------------------------------------------------------- covariance vs brute force


def _slsqp(objective, p0, slack):
    """SLSQP from ``p0`` with the constraint ``slack >= 0``, restarted from its own answer
    until it reports success (its line search can stop a hair short at ftol 1e-15, depending
    on the BLAS threads); a feasible point where no descent direction is left (status 8)
    is accepted, the caller compares the optimum itself."""
    x = p0
    for _ in range(5):
        res = minimize(objective, x, method="SLSQP", constraints=[{"type": "ineq", "fun": slack}],
                       options={"ftol": 1e-15, "maxiter": 1000})  # fmt: skip
        x = res.x
        if res.success:
            break
    assert res.success or res.status == 8, res.message
    assert slack(res.x) >= -1e-10
    return res


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_project_cov_minimises_kl_from_projection_to_proposal(seed):
    """Σ̃ = argmin KL(N(0,Σ̃) ‖ N(0,Σ)) s.t. C(Σ̃) ≤ ε, found by SLSQP over a Cholesky factor."""
    eps = 0.01
    gen = _gen(10 + seed)
    old_chol = _random_chol(gen, (), 2)
    chol = _perturbed_chol(gen, old_chol, torch.tensor(0.5, dtype=F64))
    S, S_o = (chol @ chol.T).numpy(), (old_chol @ old_chol.T).numpy()
    assert _np_kl0(S, S_o) > 2 * eps  # the bound is active
    got = project_cov(chol, old_chol, eps)
    got_S = (got @ got.T).numpy()

    def objective(p):
        A = _np_chol(p)
        return _np_kl0(A @ A.T, S)

    def slack(p):
        A = _np_chol(p)
        return eps - _np_kl0(A @ A.T, S_o)

    L0 = old_chol.numpy()
    p0 = np.array([np.log(L0[0, 0]), L0[1, 0], np.log(L0[1, 1])])  # feasible start
    res = _slsqp(objective, p0, slack)
    A = _np_chol(res.x)
    np.testing.assert_allclose(got_S, A @ A.T, atol=2e-5)
    assert objective(res.x) == pytest.approx(_np_kl0(got_S, S), rel=1e-5)


# ---------------------------------------------------------------- bounds, activity, identity


@pytest.mark.parametrize(
    "seed,d,K,B",
    [(s, d, K, B) for s, (d, K, B) in enumerate([(1, 3, 4), (2, 4, 3), (5, 3, 2), (2, 1, 1),
                                                   (5, 5, 1), (1, 2, 6), (2, 2, 2), (5, 4, 4)])],
)  # fmt: skip
def test_bounds_hold_and_are_active_where_violated(seed, d, K, B):
    eps_mean, eps_cov = 0.05, 0.005
    mean, chol, old_mean, old_chol = _problem(100 + seed, K, B, d)
    m0, c0 = kl_parts(mean, chol, old_mean, old_chol)
    p_mean, p_chol = project(mean, chol, old_mean, old_chol, eps_mean, eps_cov)
    m1, c1 = kl_parts(p_mean, p_chol, old_mean, old_chol)
    assert bool((m1 <= eps_mean * (1 + 1e-6)).all()) and bool((c1 <= eps_cov * (1 + 1e-6)).all())
    mv, cv = m0 > eps_mean, c0 > eps_cov
    torch.testing.assert_close(m1[mv], torch.full_like(m1[mv], eps_mean), rtol=1e-9, atol=0)
    torch.testing.assert_close(c1[cv], torch.full_like(c1[cv], eps_cov), rtol=1e-9, atol=0)
    assert torch.equal(p_mean[~mv], mean[~mv]) and torch.equal(p_chol[~cv], chol[~cv])


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    d=st.sampled_from([1, 2, 5]),
    K=st.integers(1, 4),
    B=st.integers(1, 5),
    eps_mean=st.floats(1e-3, 1.0),
    eps_cov=st.floats(1e-4, 0.1),
)
def test_bounds_hold_on_random_gaussians(seed, d, K, B, eps_mean, eps_cov):
    """Property: for any well-conditioned old/new Gaussians and bounds, the projection keeps
    both KL parts within their bounds, meets them where they were exceeded, and leaves the
    rest unchanged."""
    mean, chol, old_mean, old_chol = _problem(seed, K, B, d)
    m0, c0 = kl_parts(mean, chol, old_mean, old_chol)
    p_mean, p_chol = project(mean, chol, old_mean, old_chol, eps_mean, eps_cov)
    m1, c1 = kl_parts(p_mean, p_chol, old_mean, old_chol)
    assert bool((m1 <= eps_mean * (1 + 1e-6)).all()) and bool((c1 <= eps_cov * (1 + 1e-6)).all())
    mv, cv = m0 > eps_mean, c0 > eps_cov
    torch.testing.assert_close(m1[mv], torch.full_like(m1[mv], eps_mean), rtol=1e-8, atol=0)
    torch.testing.assert_close(c1[cv], torch.full_like(c1[cv], eps_cov), rtol=1e-8, atol=0)
    assert torch.equal(p_mean[~mv], mean[~mv]) and torch.equal(p_chol[~cv], chol[~cv])


def test_random_problems_cover_both_cases():
    """The problems above include entries inside and outside both bounds."""
    hits = torch.zeros(4, dtype=torch.bool)
    for seed, (d, K, B) in enumerate([(1, 3, 4), (2, 4, 3), (5, 3, 2), (5, 4, 4)]):
        m0, c0 = kl_parts(*_problem(100 + seed, K, B, d))
        hits |= torch.stack([(m0 > 0.05).any(), (m0 <= 0.05).any(), (c0 > 0.005).any(),
                             (c0 <= 0.005).any()])  # fmt: skip
    assert bool(hits.all())


def test_identity_inside_the_region_in_value_and_gradient():
    mean, chol, old_mean, old_chol = _problem(7, K=3, B=5, d=3)
    eps_mean = float(kl_parts(mean, chol, old_mean, old_chol)[0].median())
    eps_cov = float(kl_parts(mean, chol, old_mean, old_chol)[1].median())
    mean, chol = mean.clone().requires_grad_(), chol.clone().requires_grad_()
    m0, c0 = (x.detach() for x in kl_parts(mean, chol, old_mean, old_chol))
    inside_m, inside_c = m0 <= eps_mean, c0 <= eps_cov
    assert bool(inside_m.any() and (~inside_m).any() and inside_c.any() and (~inside_c).any())
    p_mean, p_chol = project(mean, chol, old_mean, old_chol, eps_mean, eps_cov)
    w_mean, w_chol = torch.randn_like(p_mean), torch.tril(torch.randn_like(p_chol))
    ((w_mean * p_mean).sum() + (w_chol * p_chol).sum()).backward()
    assert torch.equal(p_mean[inside_m], mean[inside_m].detach())
    assert torch.equal(p_chol[inside_c], chol[inside_c].detach())
    assert torch.equal(mean.grad[inside_m], w_mean[inside_m])
    assert torch.equal(chol.grad[inside_c], w_chol[inside_c])
    # all entries inside: the input itself, and an identity gradient
    L = chol.detach()[inside_c].clone().requires_grad_()
    out = project_cov(L, old_chol[inside_c], eps_cov)
    (out * 2.0).sum().backward()
    assert torch.equal(out, L.detach()) and torch.equal(L.grad, torch.full_like(L, 2.0))


# ---------------------------------------------------------------- gradients


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("active", [True, False])
def test_gradcheck_project_mean(d, active):
    mean, chol, old_mean, old_chol = _problem(3, K=2, B=3, d=d)
    m0 = kl_parts(mean, chol, old_mean, old_chol)[0]
    eps = float(m0.min()) / 2 if active else float(m0.max()) * 2
    args = (mean.requires_grad_(), old_mean.requires_grad_(), old_chol.requires_grad_())
    assert torch.autograd.gradcheck(
        lambda a, b, c: project_mean(a, b, torch.tril(c), eps), args, eps=1e-6, atol=1e-6
    )


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("active", [True, False])
def test_gradcheck_project_cov(d, active):
    gen = _gen(20 + d)
    old_chol = _random_chol(gen, (2,), d)
    chol = _perturbed_chol(gen, old_chol, torch.tensor([0.3, 0.5], dtype=F64))
    c0 = kl_parts(torch.zeros(d, dtype=F64), chol, torch.zeros(d, dtype=F64), old_chol)[1]
    eps = float(c0.min()) / 3 if active else float(c0.max()) * 2
    args = (chol.requires_grad_(), old_chol.requires_grad_())
    assert torch.autograd.gradcheck(
        lambda a, b: project_cov(torch.tril(a), torch.tril(b), eps), args, eps=1e-6, atol=1e-6
    )


# ---------------------------------------------------------------- batching, dtype, failure


def test_batched_call_equals_loop_of_unbatched_calls():
    mean, chol, old_mean, old_chol = _problem(4, K=3, B=4, d=3)
    p_mean, p_chol = project(mean, chol, old_mean, old_chol, 0.05, 0.005)
    m_b, c_b = kl_parts(mean, chol, old_mean, old_chol)
    for k in range(3):
        pm_k, pc_k = project(mean[k], chol[k], old_mean[k], old_chol[k], 0.05, 0.005)
        torch.testing.assert_close(pm_k, p_mean[k], rtol=1e-12, atol=1e-12)
        torch.testing.assert_close(pc_k, p_chol[k], rtol=1e-12, atol=1e-12)
        m_k, c_k = kl_parts(mean[k], chol[k], old_mean[k], old_chol[k])
        torch.testing.assert_close(m_k, m_b[k], rtol=1e-12, atol=1e-14)
        torch.testing.assert_close(c_k, c_b[k], rtol=1e-12, atol=1e-14)
        for b in range(4):
            pm_kb = project_mean(mean[k, b], old_mean[k, b], old_chol[k], 0.05)
            torch.testing.assert_close(pm_kb, p_mean[k, b], rtol=1e-12, atol=1e-12)


def test_float32_in_float32_out():
    mean, chol, old_mean, old_chol = (x.float() for x in _problem(5, K=2, B=3, d=3))
    p_mean, p_chol = project(mean, chol, old_mean, old_chol, 0.05, 0.005)
    assert p_mean.dtype == torch.float32 and p_chol.dtype == torch.float32
    m1, c1 = kl_parts(*(x.double() for x in (p_mean, p_chol, old_mean, old_chol)))
    assert bool((m1 <= 0.05 * (1 + 1e-4)).all()) and bool((c1 <= 0.005 * (1 + 1e-4)).all())


def test_failed_solve_keeps_the_old_covariance():
    gen = _gen(6)
    old_chol = _random_chol(gen, (2,), 2)
    chol = _perturbed_chol(gen, old_chol, torch.tensor([0.5, 0.5], dtype=F64))
    with pytest.warns(RuntimeWarning, match="failed"):
        out = project_cov(chol, old_chol, 1e-60)  # no η ≤ 1e20 gets C below 1e-60
    assert torch.equal(out, old_chol)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        project_cov(chol, old_chol, 1e-3)  # a solvable problem warns nothing


# ---------------------------------------------------------------- trust-region regression loss


def test_trust_region_loss_is_the_mean_kl_to_the_detached_projection():
    mean, chol, old_mean, old_chol = _problem(8, K=2, B=5, d=3)
    mean = mean.requires_grad_()
    p_mean, p_chol = project(mean, chol, old_mean, old_chol, 0.05, 0.005)
    loss = trust_region_loss(mean, p_mean, p_chol)
    assert loss.shape == (2,)
    tril = p_chol.detach()[:, None].expand(2, 5, 3, 3)
    # equal covariances: the KL is the mean part alone
    ref = kl_divergence(
        MultivariateNormal(mean.detach(), scale_tril=tril),
        MultivariateNormal(p_mean.detach(), scale_tril=tril),
    ).mean(-1)
    torch.testing.assert_close(loss.detach(), ref, rtol=1e-10, atol=1e-12)
    # the gradient is that of the loss with the projection held fixed
    grad = torch.autograd.grad(loss.sum(), mean)[0]
    S = tril[..., :, :] @ tril.mT
    diff = (mean - p_mean).detach().unsqueeze(-1)
    expected = (torch.linalg.solve(S, diff).squeeze(-1)) / 5
    torch.testing.assert_close(grad, expected, rtol=1e-9, atol=1e-12)


# ---------------------------------------------------------------- bad input


def _ok():
    return _problem(9, K=2, B=3, d=2)


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan"), float("inf"), "a", None])
def test_bad_bounds_raise(bad):
    mean, chol, old_mean, old_chol = _ok()
    with pytest.raises(ValueError, match="eps_mean"):
        project_mean(mean, old_mean, old_chol, bad)
    with pytest.raises(ValueError, match="eps_cov"):
        project_cov(chol, old_chol, bad)
    with pytest.raises(ValueError, match="eps_cov"):
        project(mean, chol, old_mean, old_chol, 0.05, bad)


def test_bad_tensors_raise():
    mean, chol, old_mean, old_chol = _ok()
    upper = chol.clone()
    upper[..., 0, 1] = 0.1
    neg = chol.clone()
    neg[..., 1, 1] = -0.5
    nan_chol = chol.clone()
    nan_chol[0, 0, 0] = float("nan")
    inf_mean = mean.clone()
    inf_mean[0, 0, 0] = float("inf")
    cases = [
        (lambda: project_cov(chol[..., :1], old_chol, 0.01), "chol.*square"),
        (lambda: project_cov(upper, old_chol, 0.01), "chol.*lower-triangular"),
        (lambda: project_cov(chol, neg, 0.01), "old_chol.*positive diagonal"),
        (lambda: project_cov(nan_chol, old_chol, 0.01), "chol.*finite"),
        (lambda: project_mean(inf_mean, old_mean, old_chol, 0.05), "mean.*finite"),
        (lambda: project_mean(mean, old_mean[..., :1], old_chol, 0.05), "event size"),
        (lambda: project_mean(torch.zeros(3, 3, 2, dtype=F64), old_mean, old_chol, 0.05),
         "broadcast"),
        (lambda: kl_parts(mean, chol, old_mean, old_chol.float()), "dtype"),
        (lambda: kl_parts(mean, torch.ones(2, 2, 2, dtype=torch.long), old_mean, old_chol),
         "floating"),
        (lambda: trust_region_loss(mean, old_mean, upper), "proj_chol"),
        (lambda: project_cov(chol.numpy(), old_chol, 0.01), "torch.Tensor"),
    ]  # fmt: skip
    for call, message in cases:
        with pytest.raises(ValueError, match=message):
            call()

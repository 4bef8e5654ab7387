"""MORE / contextual MORE (Eq. 3.5, 3.6): surrogate fit, constraints, dual vs primal."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import minimize

from vslbook.erl.more import (
    Quadratic,
    cmore_update,
    entropy_loss_bound,
    fit_quadratic,
    joint_whitening,
    more_update,
    whitening_gaussian,
)

# ---------------------------------------------------------------- independent closed forms


def _kl(m1, S1, m0, S0):
    """KL(N(m1,S1) ‖ N(m0,S0)) for single Gaussians."""
    d = len(m1)
    S0i = np.linalg.inv(S0)
    dm = m0 - m1
    return 0.5 * (
        np.trace(S0i @ S1) + dm @ S0i @ dm - d + np.log(np.linalg.det(S0) / np.linalg.det(S1))
    )


def _entropy(S):
    return 0.5 * np.log(np.linalg.det(2 * np.pi * np.e * S))


def _expected_reward(m, S, A, a, a0):
    """E_{N(m,S)}[−½xᵀAx + aᵀx + a0] = −½mᵀAm − ½tr(AS) + aᵀm + a0."""
    return -0.5 * m @ A @ m - 0.5 * np.trace(A @ S) + a @ m + a0


def _random_spd(rng, d, lo=0.3, hi=2.0):
    q, _ = np.linalg.qr(rng.normal(size=(d, d)))
    return q @ np.diag(rng.uniform(lo, hi, size=d)) @ q.T


def _unpack_chol(v, d):
    L = np.zeros((d, d))
    L[np.tril_indices(d)] = v
    L[np.diag_indices(d)] = np.exp(np.diag(L))
    return L


def _pack_chol(S):
    L = np.linalg.cholesky(S)
    L[np.diag_indices(len(S))] = np.log(np.diag(L))
    return L[np.tril_indices(len(S))]


# ---------------------------------------------------------------------- 1. surrogate fit


def test_fit_quadratic_recovers_exact_quadratic():
    rng = np.random.default_rng(0)
    n_exp, d, n = 2, 3, 60
    A = np.stack([_random_spd(rng, d) for _ in range(n_exp)])
    A[1] -= 1.5 * np.eye(d)  # second function indefinite
    a = rng.normal(size=(n_exp, d))
    a0 = rng.normal(size=n_exp)
    x = rng.normal(size=(n_exp, n, d)) * np.array([1.0, 3.0])[:, None, None] + 2.0
    y = -0.5 * np.einsum("eni,eij,enj->en", x, A, x) + np.einsum("eni,ei->en", x, a) + a0[:, None]
    mean, chol = whitening_gaussian(x)
    quad = fit_quadratic(x, y, mean=mean, chol=chol)
    s = quad.scale
    np.testing.assert_allclose(quad.A * s[:, None, None], A, atol=1e-6)
    np.testing.assert_allclose(quad.a * s[:, None], a, atol=1e-6)
    np.testing.assert_allclose(quad.a0 * s + quad.offset, a0, atol=1e-6)
    np.testing.assert_allclose(s, y.std(axis=1), rtol=1e-12)
    x_new = rng.normal(size=(n_exp, 7, d))
    y_new = (
        -0.5 * np.einsum("eni,eij,enj->en", x_new, A, x_new)
        + np.einsum("eni,ei->en", x_new, a)
        + a0[:, None]
    )
    np.testing.assert_allclose(quad.predict(x_new), y_new, atol=1e-6)
    # weighted: zero weight on corrupted samples leaves the exact fit intact
    w = np.ones((n_exp, n))
    y_bad = y.copy()
    y_bad[:, :5] += 100.0
    w[:, :5] = 0.0
    quad_w = fit_quadratic(x, y_bad, mean=mean, chol=chol, weights=w)
    np.testing.assert_allclose(quad_w.predict(x_new), y_new, atol=1e-6)


def test_joint_whitening_matches_joint_gaussian():
    rng = np.random.default_rng(1)
    n_exp, n, dc, dt = 2, 50, 2, 3
    c = rng.normal(size=(n_exp, n, dc)) * 2.0 + 1.0
    K = rng.normal(size=(n_exp, dt, dc))
    k = rng.normal(size=(n_exp, dt))
    cov = np.stack([_random_spd(rng, dt) for _ in range(n_exp)])
    mean, chol = joint_whitening(c, K, k, cov)
    for e in range(n_exp):
        Sc = np.cov(c[e].T)
        cm = c[e].mean(axis=0)
        joint = np.block([[Sc, Sc @ K[e].T], [K[e] @ Sc, K[e] @ Sc @ K[e].T + cov[e]]])
        np.testing.assert_allclose(chol[e] @ chol[e].T, joint, atol=1e-10)
        np.testing.assert_allclose(mean[e], np.concatenate([cm, K[e] @ cm + k[e]]), atol=1e-12)
        assert np.allclose(chol[e], np.tril(chol[e]))


# ---------------------------------------------------------------- 2. constraints, optimum


def _problem(rng, n_exp, d):
    mean = rng.normal(size=(n_exp, d))
    cov = np.stack([_random_spd(rng, d) for _ in range(n_exp)])
    A = np.stack([_random_spd(rng, d, 0.5, 3.0) for _ in range(n_exp)])
    opt = rng.normal(size=(n_exp, d)) * 3.0
    a = np.einsum("eij,ej->ei", A, opt)
    quad = Quadratic(A=A, a=a, a0=np.zeros(n_exp), scale=rng.uniform(0.5, 2.0, n_exp))
    return mean, cov, quad, opt


@pytest.mark.parametrize("eps", [1e-3, 1e-2, 0.1, 1.0])
def test_more_respects_kl_and_entropy(eps):
    rng = np.random.default_rng(2)
    n_exp, d = 4, 3
    mean, cov, quad, _ = _problem(rng, n_exp, d)
    h_old = np.array([_entropy(S) for S in cov])
    h_min = entropy_loss_bound(h_old)
    res = more_update(mean, cov, quad, eps=eps, entropy_coef=0.01, h_min=h_min)
    assert res.success.all()
    for e in range(n_exp):
        kl = _kl(res.mean[e], res.cov[e], mean[e], cov[e])
        assert kl <= eps * (1 + 1e-3)
        assert _entropy(res.cov[e]) >= h_min[e] - 1e-6
        assert kl == pytest.approx(eps, rel=1e-3)  # optimum far away: trust region active
        np.testing.assert_allclose([kl, _entropy(res.cov[e])], [res.kl[e], res.entropy[e]])


def test_more_reaches_analytic_optimum_with_large_eps():
    rng = np.random.default_rng(3)
    mean, cov, quad, opt = _problem(rng, 3, 4)
    res = more_update(mean, cov, quad, eps=1e4, entropy_coef=1e-9)
    assert res.success.all()
    np.testing.assert_allclose(res.mean, np.linalg.solve(quad.A, quad.a[..., None])[..., 0])
    np.testing.assert_allclose(res.mean, opt, atol=1e-6)
    # with an entropy bonus β and no trust region the optimum is N(A⁻¹a, (β/σ_R) A⁻¹)
    res = more_update(mean, cov, quad, eps=1e4, entropy_coef=0.3)
    expected = 0.3 / quad.scale[:, None, None] * np.linalg.inv(quad.A)
    np.testing.assert_allclose(res.cov, expected, rtol=1e-6)


def test_eig_clip_bounds_covariance():
    rng = np.random.default_rng(4)
    mean, cov, quad, _ = _problem(rng, 2, 3)
    res = more_update(mean, cov, quad, eps=1e3, entropy_coef=1e-6, eig_clip=(0.01, 2.0))
    eig = np.linalg.eigvalsh(res.cov)
    assert eig.min() >= 0.01 * (1 - 1e-9) and eig.max() <= 2.0 * (1 + 1e-9)


# ---------------------------------------------------------------- 3. dual vs brute force


def _more_cases():
    rng = np.random.default_rng(5)
    d = 2
    mean = rng.normal(size=(3, d))
    cov = np.stack([_random_spd(rng, d, 0.5, 1.5) for _ in range(3)])
    A = np.stack(
        [
            _random_spd(rng, d, 0.5, 2.0),  # KL active, no entropy constraint
            _random_spd(rng, d, 5.0, 9.0),  # sharp reward: entropy constraint binds
            np.array([[1.0, 0.3], [0.3, -0.8]]),  # indefinite reward
        ]
    )
    a = rng.normal(size=(3, d)) * 2.0
    quad = Quadratic(A=A, a=a, a0=np.zeros(3), scale=np.array([1.0, 2.0, 0.5]))
    h_old = np.array([_entropy(S) for S in cov])
    h_min = np.array([-np.inf, h_old[1] - 0.05, entropy_loss_bound(h_old[2])])
    eps = np.array([0.1, 0.5, 0.05])
    coef = 0.2
    return mean, cov, quad, h_min, eps, coef


def _primal_more(m0, S0, A, a, scale, eps, coef, h_min):
    d = len(m0)

    def unpack(v):
        L = _unpack_chol(v[d:], d)
        return v[:d], L @ L.T

    def objective(v):
        m, S = unpack(v)
        return -(scale * _expected_reward(m, S, A, a, 0.0) + coef * _entropy(S))

    cons = [{"type": "ineq", "fun": lambda v: eps - _kl(*unpack(v), m0, S0)}]
    if np.isfinite(h_min):
        cons.append({"type": "ineq", "fun": lambda v: _entropy(unpack(v)[1]) - h_min})
    v0 = np.concatenate([m0, _pack_chol(S0)])
    sol = minimize(
        objective, v0, method="SLSQP", constraints=cons, options={"ftol": 1e-13, "maxiter": 1000}
    )
    # status 8: line search stalled at machine precision; accept when feasible
    assert sol.success or (sol.status == 8 and all(con["fun"](sol.x) > -1e-9 for con in cons))
    return (*unpack(sol.x), -sol.fun)


def test_more_dual_matches_primal_slsqp():
    mean, cov, quad, h_min, eps, coef = _more_cases()
    res = more_update(mean, cov, quad, eps=eps, entropy_coef=coef, h_min=h_min)
    assert res.success.all()
    assert res.omega[1] > 1e-3  # the entropy constraint is active for expert 1
    for e in range(3):
        m, S, obj = _primal_more(
            mean[e], cov[e], quad.A[e], quad.a[e], quad.scale[e], eps[e], coef, h_min[e]
        )
        ours = quad.scale[e] * _expected_reward(
            res.mean[e], res.cov[e], quad.A[e], quad.a[e], 0.0
        ) + coef * _entropy(res.cov[e])
        np.testing.assert_allclose(res.mean[e], m, atol=2e-4)
        np.testing.assert_allclose(res.cov[e], S, atol=2e-4)
        assert ours == pytest.approx(obj, abs=1e-6 * (1 + abs(obj)))


def _cmore_cases():
    rng = np.random.default_rng(6)
    dc, dt, n = 1, 2, 20
    K = rng.normal(size=(3, dt, dc))
    k = rng.normal(size=(3, dt))
    cov = np.stack([_random_spd(rng, dt, 0.5, 1.5) for _ in range(3)])
    c = rng.uniform(-1, 1, size=(3, n, dc))
    A = np.stack(
        [
            _random_spd(rng, dc + dt, 0.5, 2.0),
            _random_spd(rng, dc + dt, 5.0, 9.0),
            np.array([[1.0, 0.2, -0.4], [0.2, 1.0, 0.3], [-0.4, 0.3, -0.7]]),
        ]
    )
    a = rng.normal(size=(3, dc + dt)) * 2.0
    quad = Quadratic(A=A, a=a, a0=np.zeros(3), scale=np.array([1.0, 2.0, 0.5]))
    h_old = np.array([_entropy(S) for S in cov])
    h_min = np.array([-np.inf, h_old[1] - 0.05, entropy_loss_bound(h_old[2])])
    eps = np.array([0.1, 0.5, 0.05])
    return K, k, cov, c, quad, h_min, eps, 0.2


def _primal_cmore(K0, k0, S0, c, A, a, scale, eps, coef, h_min):
    dt, dc = K0.shape

    def unpack(v):
        L = _unpack_chol(v[dt * dc + dt :], dt)
        return v[: dt * dc].reshape(dt, dc), v[dt * dc : dt * dc + dt], L @ L.T

    def mean_kl(v):
        K, k, S = unpack(v)
        return np.mean([_kl(K @ ci + k, S, K0 @ ci + k0, S0) for ci in c])

    def objective(v):
        K, k, S = unpack(v)
        r = [_expected_reward(np.concatenate([ci, K @ ci + k]), _pad(S, dc), A, a, 0.0) for ci in c]
        return -(scale * np.mean(r) + coef * _entropy(S))

    cons = [{"type": "ineq", "fun": lambda v: eps - mean_kl(v)}]
    if np.isfinite(h_min):
        cons.append({"type": "ineq", "fun": lambda v: _entropy(unpack(v)[2]) - h_min})
    v0 = np.concatenate([K0.ravel(), k0, _pack_chol(S0)])
    sol = minimize(
        objective, v0, method="SLSQP", constraints=cons, options={"ftol": 1e-13, "maxiter": 1000}
    )
    # status 8: line search stalled at machine precision; accept when feasible
    assert sol.success or (sol.status == 8 and all(con["fun"](sol.x) > -1e-9 for con in cons))
    return (*unpack(sol.x), -sol.fun)


def _pad(S, dc):
    """Joint covariance of (c, θ) for a fixed c: zeros in the context block."""
    out = np.zeros((dc + len(S), dc + len(S)))
    out[dc:, dc:] = S
    return out


def test_cmore_dual_matches_primal_slsqp():
    K, k, cov, c, quad, h_min, eps, coef = _cmore_cases()
    res = cmore_update(K, k, cov, c, quad, eps=eps, entropy_coef=coef, h_min=h_min)
    assert res.success.all()
    assert res.omega[1] > 1e-3
    for e in range(3):
        Kp, kp, Sp, obj = _primal_cmore(
            K[e],
            k[e],
            cov[e],
            c[e],
            quad.A[e],
            quad.a[e],
            quad.scale[e],
            eps[e],
            coef,
            h_min[e],
        )
        r = [
            _expected_reward(
                np.concatenate([ci, res.K[e] @ ci + res.k[e]]),
                _pad(res.cov[e], 1),
                quad.A[e],
                quad.a[e],
                0.0,
            )
            for ci in c[e]
        ]
        ours = quad.scale[e] * np.mean(r) + coef * _entropy(res.cov[e])
        np.testing.assert_allclose(res.K[e], Kp, atol=3e-4)
        np.testing.assert_allclose(res.k[e], kp, atol=3e-4)
        np.testing.assert_allclose(res.cov[e], Sp, atol=3e-4)
        assert ours == pytest.approx(obj, abs=1e-6 * (1 + abs(obj)))
        kl = np.mean(
            [_kl(res.K[e] @ ci + res.k[e], res.cov[e], K[e] @ ci + k[e], cov[e]) for ci in c[e]]
        )
        assert res.kl[e] == pytest.approx(kl, rel=1e-9)
        assert kl <= eps[e] * (1 + 1e-3)


# ------------------------------------------------------------- 4. batched = separate, failure


def _take(quad, e):
    return Quadratic(
        A=quad.A[e : e + 1], a=quad.a[e : e + 1], a0=quad.a0[e : e + 1], scale=quad.scale[e : e + 1]
    )


def test_batched_equals_separate_and_failure_is_isolated():
    mean, cov, quad, h_min, eps, coef = _more_cases()
    h_min = h_min.copy()
    h_min[0] = _entropy(cov[0]) + 5.0  # infeasible: entropy +5 nats within KL ≤ 0.1
    res = more_update(mean, cov, quad, eps=eps, entropy_coef=coef, h_min=h_min)
    assert res.success.tolist() == [False, True, True]
    np.testing.assert_array_equal(res.mean[0], mean[0])
    np.testing.assert_array_equal(res.cov[0], cov[0])
    for e in range(3):
        one = more_update(
            mean[e : e + 1],
            cov[e : e + 1],
            _take(quad, e),
            eps=eps[e],
            entropy_coef=coef,
            h_min=h_min[e : e + 1],
        )
        assert one.success[0] == res.success[e]
        for name in ("mean", "cov", "eta", "omega", "kl", "entropy"):
            np.testing.assert_allclose(
                getattr(one, name)[0], getattr(res, name)[e], rtol=1e-9, atol=1e-12
            )
    K, k, cov, c, quad, h_min, eps, coef = _cmore_cases()
    res = cmore_update(K, k, cov, c, quad, eps=eps, entropy_coef=coef, h_min=h_min)
    for e in range(3):
        s = slice(e, e + 1)
        one = cmore_update(
            K[s], k[s], cov[s], c[s], _take(quad, e), eps=eps[e], entropy_coef=coef, h_min=h_min[s]
        )
        for name in ("K", "k", "cov", "eta", "omega", "kl", "entropy"):
            np.testing.assert_allclose(
                getattr(one, name)[0], getattr(res, name)[e], rtol=1e-9, atol=1e-12
            )


# ------------------------------------------------------------------------------ 5. bad input


def test_bad_input_raises_value_error():
    mean, cov, quad, h_min, eps, coef = _more_cases()
    with pytest.raises(ValueError, match="eps"):
        more_update(mean, cov, quad, eps=0.0, entropy_coef=coef)
    with pytest.raises(ValueError, match="eps"):
        more_update(mean, cov, quad, eps=np.array([0.1, -1.0, 0.1]), entropy_coef=coef)
    with pytest.raises(ValueError, match="positive definite"):
        bad = cov.copy()
        bad[1] = np.array([[1.0, 2.0], [2.0, 1.0]])
        more_update(mean, bad, quad, eps=0.1, entropy_coef=coef)
    with pytest.raises(ValueError, match="cov"):
        more_update(mean, cov[:, :1, :1], quad, eps=0.1, entropy_coef=coef)
    with pytest.raises(ValueError, match=r"quad\.A"):
        more_update(mean[:2], cov[:2], quad, eps=0.1, entropy_coef=coef)
    with pytest.raises(ValueError, match="entropy_coef"):
        more_update(mean, cov, quad, eps=0.1, entropy_coef=-1.0)
    with pytest.raises(ValueError, match="h_min"):
        more_update(mean, cov, quad, eps=0.1, entropy_coef=coef, h_min=np.zeros(2))
    with pytest.raises(ValueError, match="eig_clip"):
        more_update(mean, cov, quad, eps=0.1, entropy_coef=coef, eig_clip=(1.0, 0.5))
    K, k, cov, c, quad, h_min, eps, coef = _cmore_cases()
    with pytest.raises(ValueError, match="contexts"):
        cmore_update(K, k, cov, c[..., :0], quad, eps=eps, entropy_coef=coef)
    with pytest.raises(ValueError, match="eps"):
        cmore_update(K, k, cov, c, quad, eps=-0.1, entropy_coef=coef)
    with pytest.raises(ValueError, match="weights"):
        cmore_update(K, k, cov, c, quad, eps=0.1, entropy_coef=coef, weights=np.ones((3, 2)))
    with pytest.raises(ValueError, match="y must"):
        fit_quadratic(c, np.zeros((3, 5)), mean=c.mean(1), chol=np.ones((3, 1, 1)))
    with pytest.raises(ValueError, match="scale"):
        Quadratic(A=np.eye(2)[None], a=np.zeros((1, 2)), a0=np.zeros(1), scale=np.zeros(1))


# ------------------------------------------------- dual derivatives, weighted contexts


def _fd_check(evaluate, eps, h_min, eta, om):
    """Gradient (ε − KL, H − H_min) vs finite differences of g; Hessian vs differences of it."""
    idx = np.arange(len(eta))

    def grad(e, o):
        ev = evaluate(idx, e, o)
        return np.stack([eps - ev.kl, ev.ent - h_min], axis=1), ev

    g0, ev0 = grad(eta, om)
    hess = np.stack([[ev0.hee, ev0.heo], [ev0.heo, ev0.hoo]], axis=-1).transpose(1, 0, 2)
    for j, (de, do) in enumerate([(1e-6 * eta, 0 * om), (0 * eta, 1e-6 * (1 + om))]):
        step = de + do
        up, ev_up = grad(eta + de, om + do)
        down, ev_down = grad(eta - de, om - do)
        np.testing.assert_allclose((ev_up.g - ev_down.g) / (2 * step), g0[:, j], rtol=1e-5)
        np.testing.assert_allclose((up - down) / (2 * step[:, None]), hess[:, :, j], rtol=1e-5)


def test_dual_gradient_and_hessian_match_finite_differences():
    from vslbook.erl import more

    mean, cov, quad, h_min, eps, coef = _more_cases()
    h = np.array([0.5, h_min[1], h_min[2]])
    beta = coef / quad.scale
    ev = more._more_dual(mean, cov, quad.A, quad.a, beta, eps, h)
    _fd_check(ev, eps, h, np.array([3.0, 7.0, 20.0]), np.array([0.5, 2.0, 0.1]))
    K, k, cov, c, quad, h_min, eps, coef = _cmore_cases()
    w = np.full(c.shape[:2], 1 / c.shape[1])
    ev = more._cmore_dual(K, k, cov, c, w, quad.A, quad.a, coef / quad.scale, eps, h)
    _fd_check(ev, eps, h, np.array([3.0, 7.0, 20.0]), np.array([0.5, 2.0, 0.1]))


def test_cmore_context_weights_equal_repeated_contexts():
    K, k, cov, c, quad, h_min, eps, coef = _cmore_cases()
    reps = np.arange(c.shape[1]) % 3 + 1  # context i counted 1, 2 or 3 times
    weighted = cmore_update(
        K,
        k,
        cov,
        c,
        quad,
        eps=eps,
        entropy_coef=coef,
        h_min=h_min,
        weights=np.tile(reps, (3, 1)).astype(float),
    )
    repeated = cmore_update(
        K, k, cov, np.repeat(c, reps, axis=1), quad, eps=eps, entropy_coef=coef, h_min=h_min
    )
    for name in ("K", "k", "cov", "kl"):
        np.testing.assert_allclose(getattr(weighted, name), getattr(repeated, name), rtol=1e-8)

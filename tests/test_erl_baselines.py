"""HiREPS and LaDiPS (Chapter 3 baselines): dual solutions, weighted ML, learning, state."""

from __future__ import annotations

import importlib.util
import math

import numpy as np
import pytest
from scipy.optimize import minimize

from vslbook.envs.robot.planar_reacher import PlanarReacherTask
from vslbook.erl import hireps, ladips
from vslbook.erl.hireps import HiREPSConfig, fit_gating, fit_linear_gaussian, hireps_weights
from vslbook.erl.ladips import LaDiPSConfig, gating_update

HAS_MORE = importlib.util.find_spec("vslbook.erl.more") is not None  # ladips needs it


def _batch(seed: int = 0, n: int = 150, n_opt: int = 4, m: int = 3):
    rng = np.random.default_rng(seed)
    returns = rng.normal(size=n) * 3 + rng.normal(size=n) ** 2
    logits = 2.0 * rng.normal(size=(n, n_opt))
    log_resp = logits - np.log(np.exp(logits).sum(1, keepdims=True))
    feats = rng.normal(size=(n, m))
    return returns, log_resp, feats


def _entropy_old(log_resp):
    return float(-np.mean(np.sum(np.exp(log_resp) * log_resp, axis=1)))


# -- HiREPS: the REPS step --------------------------------------------------------------
@pytest.mark.parametrize("eps,rel_kappa", [(0.3, 0.8), (0.5, 0.99), (0.1, 0.9)])
def test_hireps_weights_satisfy_bounds(eps, rel_kappa):
    r, lr, phi = _batch()
    kappa = rel_kappa * _entropy_old(lr)
    sol = hireps_weights(r, lr, phi, eps=eps, kappa=kappa)
    w = sol.weights
    n = len(r)
    assert sol.success
    assert np.all(w >= 0) and abs(w.sum() - 1) < 1e-10
    p = w.sum(1)  # new (c, θ) marginal; q = 1/n
    kl = np.sum(p[p > 0] * np.log(n * p[p > 0]))
    assert kl <= eps * (1 + 1e-3)
    resp_new = w / p[:, None]
    ent = -np.sum(w * np.log(np.maximum(resp_new, 1e-300)))
    assert ent <= kappa + 1e-6
    np.testing.assert_allclose(p @ phi, phi.mean(0), atol=1e-4)
    # the update moved: the KL bound is active when the returns differ
    assert kl > 0.2 * eps


def test_hireps_dual_matches_scipy():
    r, lr, phi = _batch(seed=3)
    n, m = phi.shape
    eps, kappa = 0.4, 0.7 * _entropy_old(lr)
    phi_hat = phi.mean(0)

    def dual(x):  # the same dual, written directly in return units
        eta, xi, v = np.exp(x[0]), np.exp(x[1]), x[2:]
        a = (1 + xi / eta) * lr + ((r - phi @ v) / eta)[:, None]
        amax = a.max()
        return (
            eta * eps + xi * kappa + v @ phi_hat + eta * (amax + np.log(np.exp(a - amax).sum() / n))
        )

    best = None
    for x0 in ([1.0, 0.0], [0.0, 1.0]):
        res = minimize(dual, np.r_[x0, np.zeros(m)], method="Nelder-Mead",
                       options={"xatol": 1e-10, "fatol": 1e-12, "maxiter": 40000,
                                "maxfev": 40000})  # fmt: skip
        best = res if best is None or res.fun < best.fun else best
    eta, xi, v = np.exp(best.x[0]), np.exp(best.x[1]), best.x[2:]
    sol = hireps_weights(r, lr, phi, eps=eps, kappa=kappa)
    assert sol.success
    np.testing.assert_allclose(sol.eta, eta, rtol=2e-3)
    np.testing.assert_allclose(sol.xi, xi, rtol=5e-3, atol=1e-4)
    np.testing.assert_allclose(sol.v, v, rtol=5e-3, atol=1e-3)
    a = (1 + xi / eta) * lr + ((r - phi @ v) / eta)[:, None]
    w = np.exp(a - a.max())
    np.testing.assert_allclose(sol.weights, w / w.sum(), atol=2e-5)


# -- weighted maximum likelihood ---------------------------------------------------------
def test_weighted_ml_equals_weighted_least_squares():
    rng = np.random.default_rng(1)
    n, dc, dt, n_opt = 80, 2, 3, 3
    c = rng.normal(size=(n, dc))
    th = c @ rng.normal(size=(dc, dt)) + rng.normal(size=(n, dt))
    w = rng.random((n, n_opt)) ** 2
    K, k, cov = fit_linear_gaussian(c, th, w)
    log_prior, mu, s = fit_gating(c, w)
    for o in range(n_opt):
        sw = np.sqrt(w[:, o])[:, None]
        x = np.c_[c, np.ones(n)]
        beta, *_ = np.linalg.lstsq(sw * x, sw * th, rcond=None)
        np.testing.assert_allclose(K[o], beta[:dc].T, atol=1e-10)
        np.testing.assert_allclose(k[o], beta[dc], atol=1e-10)
        res = th - x @ beta
        np.testing.assert_allclose(cov[o], np.cov(res.T, aweights=w[:, o], bias=True), atol=1e-10)
        np.testing.assert_allclose(mu[o], np.average(c, axis=0, weights=w[:, o]), atol=1e-12)
        np.testing.assert_allclose(s[o], np.cov(c.T, aweights=w[:, o], bias=True), atol=1e-12)
    np.testing.assert_allclose(np.exp(log_prior), w.sum(0) / w.sum(), atol=1e-12)


# -- LaDiPS gating step ------------------------------------------------------------------
def test_gating_update_bounds_and_primal():
    rng = np.random.default_rng(2)
    n, n_opt = 5, 3
    logits = rng.normal(size=(n, n_opt))
    log_q = logits - np.log(np.exp(logits).sum(1, keepdims=True))
    q_values = 2 * rng.normal(size=(n, n_opt))
    eps, h_min = 0.2, 0.95
    sol = gating_update(log_q, q_values, eps=eps, h_min=h_min)
    p = np.exp(sol.log_p)
    assert sol.success
    assert np.mean(np.sum(p * (sol.log_p - log_q), 1)) <= eps * (1 + 1e-3)
    assert np.mean(-np.sum(p * sol.log_p, 1)) >= h_min - 1e-6

    # the primal with scipy: maximise E_c Σ_o π Q under the two constraints
    def unpack(z):
        lg = z.reshape(n, n_opt)
        return lg - np.log(np.exp(lg).sum(1, keepdims=True))

    def kl(z):
        lp = unpack(z)
        return np.mean(np.sum(np.exp(lp) * (lp - log_q), 1))

    def ent(z):
        lp = unpack(z)
        return np.mean(-np.sum(np.exp(lp) * lp, 1))

    res = minimize(
        lambda z: -np.mean(np.sum(np.exp(unpack(z)) * q_values, 1)), log_q.ravel(),
        method="SLSQP",
        constraints=[{"type": "ineq", "fun": lambda z: eps - kl(z)},
                     {"type": "ineq", "fun": lambda z: ent(z) - h_min}],
        options={"ftol": 1e-12, "maxiter": 1000},
    )  # fmt: skip
    np.testing.assert_allclose(np.exp(unpack(res.x)), p, atol=2e-3)


# -- bad input ---------------------------------------------------------------------------
def test_bad_input():
    r, lr, phi = _batch()
    with pytest.raises(ValueError, match="eps"):
        hireps_weights(r, lr, phi, eps=0.0, kappa=0.5)
    with pytest.raises(ValueError, match="eps"):
        HiREPSConfig(eps=-1.0)
    with pytest.raises(ValueError, match="eps_gating"):
        LaDiPSConfig(eps_gating=0.0)
    with pytest.raises(ValueError, match="alpha"):
        LaDiPSConfig(n_experts=10, alpha=math.log(30))
    with pytest.raises(ValueError, match="need returns"):
        hireps_weights(r[:-1], lr, phi, eps=0.1, kappa=None)
    task = PlanarReacherTask()
    with pytest.raises(ValueError, match="n_params"):
        hireps.HiREPS(task, HiREPSConfig(init_mean=(0.0,) * 7, init_cov=1.0), seed=0)
    algo = hireps.HiREPS(task, HiREPSConfig(n_experts=3, init_cov=1.0), seed=0)
    with pytest.raises(ValueError, match="contexts"):
        algo.sample(np.zeros((4, 3)), np.random.default_rng(0))
    with pytest.raises(ValueError, match="no HiREPS preset"):
        HiREPSConfig.for_task("cartpole")


# -- learning, determinism, state round trip ----------------------------------------------
def _hireps_cfg():
    return HiREPSConfig.for_task("planar-reacher", n_experts=8, samples_per_iteration=150)


def _ladips_cfg():
    return LaDiPSConfig(
        n_experts=4,
        alpha=math.log(2),
        eps=0.5,
        eps_gating=0.2,
        samples_per_iteration=200,
        init_cov=hireps.HIREPS_PRESETS["planar-reacher"].init_cov,
        init_mean_std=0.5,
    )


def _returns(algo, task, n=400):
    rng = np.random.default_rng(123)
    c = task.sample_contexts(n, rng)
    return float(task.evaluate(algo.mean_action(c, rng), c).returns.mean())


def _roundtrip(module, cfg, n_before, n_after):
    task = PlanarReacherTask()
    a = module.train(task, cfg, seed=5, iterations=n_before)
    state = a.state_dict()
    m_a = [a.iteration() for _ in range(n_after)]
    b = module.train(task, cfg, seed=99, iterations=0)
    b.load_state_dict(state)
    m_b = [b.iteration() for _ in range(n_after)]
    assert m_a == m_b
    np.testing.assert_array_equal(a.mix.k, b.mix.k)
    c = module.train(task, cfg, seed=5, iterations=n_before + n_after)
    np.testing.assert_array_equal(a.mix.cov, c.mix.cov)  # same seed, same numbers


def test_hireps_improves_on_planar_reacher():
    task = PlanarReacherTask()
    cfg = _hireps_cfg()
    start = _returns(hireps.HiREPS(task, cfg, seed=0), task)
    log = []
    algo = hireps.train(task, cfg, seed=0, iterations=25, callback=lambda i, m: log.append(m))
    end = _returns(algo, task)
    assert end > start + 50 and end > -30, (start, end)
    assert all(m["samples"] == 150 for m in log)
    assert log[-1]["mean_return"] > log[0]["mean_return"]


def test_hireps_determinism_and_state_roundtrip():
    _roundtrip(hireps, _hireps_cfg(), 3, 3)


@pytest.mark.slow
@pytest.mark.skipif(not HAS_MORE, reason="vslbook.erl.more not available")
def test_ladips_improves_on_planar_reacher():
    task = PlanarReacherTask()
    cfg = _ladips_cfg()
    start = _returns(ladips.LaDiPS(task, cfg, seed=0), task)
    log = []
    algo = ladips.train(task, cfg, seed=0, iterations=25, callback=lambda i, m: log.append(m))
    end = _returns(algo, task)
    assert end > start + 30, (start, end)
    assert all(m["gating_success"] == 1.0 for m in log)
    assert min(m["entropy_gating"] for m in log) >= cfg.alpha - 1e-6


@pytest.mark.slow
@pytest.mark.skipif(not HAS_MORE, reason="vslbook.erl.more not available")
def test_ladips_determinism_and_state_roundtrip():
    _roundtrip(ladips, _ladips_cfg(), 2, 2)

"""REPS on a categorical (Eq. 3.7 / A.7) and the Nadaraya–Watson value (A.6)."""

import numpy as np
import pytest
from scipy.optimize import minimize

from vslbook.erl.reps import nadaraya_watson, reps_categorical_update


def _primal(log_q, r, eps, beta, h_min):
    """The constrained problem over the simplex, solved directly with SLSQP."""
    q = np.exp(log_q)

    def neg_obj(z):
        p = np.exp(z - np.logaddexp.reduce(z))
        return -(p @ r - beta * p @ np.log(p))

    def kl(z):
        lp = z - np.logaddexp.reduce(z)
        return np.exp(lp) @ (lp - np.log(q))

    def ent(z):
        lp = z - np.logaddexp.reduce(z)
        return -np.exp(lp) @ lp

    cons = [{"type": "ineq", "fun": lambda z: eps - kl(z)}]
    if h_min is not None:
        cons.append({"type": "ineq", "fun": lambda z: ent(z) - h_min})
    best = None
    for start in (log_q, log_q + 0.1 * r):
        res = minimize(neg_obj, start, constraints=cons, method="SLSQP",
                       options={"ftol": 1e-14, "maxiter": 2000})  # fmt: skip
        if res.success and (best is None or res.fun < best.fun):
            best = res
    return np.exp(best.x - np.logaddexp.reduce(best.x)), -best.fun


@pytest.mark.parametrize(
    ("eps", "beta", "h_min"),
    [(0.05, 0.5, None), (0.3, 0.0, None), (0.2, 0.1, 1.2), (1.0, 2.0, 1.3)],
)
def test_reps_matches_the_primal_problem(eps, beta, h_min):
    rng = np.random.default_rng(0)
    q = rng.dirichlet(np.ones(5))
    r = rng.normal(0, 2, 5)
    res = reps_categorical_update(np.log(q), r, eps=eps, entropy_coef=beta, h_min=h_min)
    p = np.exp(res.log_p)
    assert res.success
    kl = float(p @ (np.log(p) - np.log(q)))  # recomputed here
    assert kl <= eps * (1 + 1e-3)
    if h_min is not None:
        assert -p @ np.log(p) >= h_min - 1e-6
    p_ref, obj_ref = _primal(np.log(q), r, eps, beta, h_min)
    obj = p @ r - beta * p @ np.log(p)
    assert obj == pytest.approx(obj_ref, abs=1e-6)
    np.testing.assert_allclose(p, p_ref, atol=2e-4)


def test_reps_without_trust_region_is_the_softmax():
    """ε → ∞: the maximum-entropy optimum softmax(r / β_w)."""
    r = np.array([1.0, -0.5, 2.0, 0.3])
    beta = 0.7
    res = reps_categorical_update(np.log(np.full(4, 0.25)), r, eps=50.0, entropy_coef=beta)
    expected = np.exp(r / beta) / np.exp(r / beta).sum()
    np.testing.assert_allclose(np.exp(res.log_p), expected, atol=1e-6)


def test_reps_bad_input():
    lq = np.log(np.full(3, 1 / 3))
    with pytest.raises(ValueError, match="eps"):
        reps_categorical_update(lq, np.zeros(3), eps=0.0, entropy_coef=1.0)
    with pytest.raises(ValueError, match="shape"):
        reps_categorical_update(lq, np.zeros(4), eps=0.1, entropy_coef=1.0)
    with pytest.raises(ValueError, match="normalised"):
        reps_categorical_update(np.zeros(3), np.zeros(3), eps=0.1, entropy_coef=1.0)


def test_nadaraya_watson_against_the_sum():
    rng = np.random.default_rng(1)
    x, y, w = rng.normal(size=(30, 2)), rng.normal(size=30), rng.random(30)
    q = rng.normal(size=(7, 2))
    got = nadaraya_watson(x, y, q, weights=w, scale=0.5, chunk=3)
    for j in range(7):
        k = np.array(
            [wi * np.exp(-np.sum((q[j] - xi) ** 2) / 0.5) for xi, wi in zip(x, w, strict=True)]
        )
        assert got[j] == pytest.approx(k @ y / k.sum(), rel=1e-10)
    with pytest.raises(ValueError, match="scale"):
        nadaraya_watson(x, y, q, scale=-1.0)

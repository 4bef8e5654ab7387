import numpy as np

from vslbook.bounds.dime_one_step_mdp import OneStepDiffusionMDP
from vslbook.bounds.foundations import random_mdp


def make(seed=0):
    n_s, n_a, n_z = 4, 3, 2
    P, R = random_mdp(n_s, n_a, seed=seed)
    rng = np.random.default_rng(seed)
    mdp = OneStepDiffusionMDP(P, R, np.full(n_z, 1 / n_z), rng.dirichlet(np.ones(n_z), size=n_a),
                              0.8, 0.3)  # fmt: skip
    return mdp, rng


def test_bound_by_explicit_sums():
    mdp, rng = make()
    kernel = mdp.random_kernel(rng)
    n_s, n_z, n_a = kernel.shape
    for s in range(n_s):
        total = sum(
            mdp.prior[z] * kernel[s, z, a]
            * (np.log(mdp.noising[a, z]) - np.log(mdp.prior[z]) - np.log(kernel[s, z, a]))
            for z in range(n_z) for a in range(n_a)
        )  # fmt: skip
        assert np.isclose(mdp.bound(kernel)[s], total)
        assert np.allclose(mdp.marginal(kernel)[s], mdp.prior @ kernel[s])


def test_evaluate_is_the_fixed_point_of_the_soft_backup():
    mdp, rng = make(1)
    kernel = mdp.random_kernel(rng)
    q = np.zeros_like(mdp.R)
    for _ in range(400):  # Q ← R + γ P (E_π0[Q] + α ℓ)
        q = mdp.R + mdp.gamma * mdp.P @ mdp.soft_value(kernel, q)
    assert np.allclose(mdp.evaluate(kernel), q, atol=1e-10)


def test_improve_maximises_the_soft_value():
    mdp, rng = make(2)
    q = rng.normal(size=mdp.R.shape)
    best = mdp.soft_value(mdp.improve(q), q)
    for _ in range(200):
        assert np.all(best >= mdp.soft_value(mdp.random_kernel(rng), q) - 1e-12)
    assert np.allclose(mdp.improve(q).sum(-1), 1.0)

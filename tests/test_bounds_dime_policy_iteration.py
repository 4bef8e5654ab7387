"""Tests for vslbook.bounds.dime_policy_iteration: Section 5.4.2 with diffusion policies and ℓ.

The check passes for a few seeds and fails (a failed Check, not an exception) when handed a
wrong ingredient: the wrong sign of ℓ in the backup of Eq. 5.21, an "improvement" that moves
away from the target of Eq. 5.22, or no improvement at all. The claims of its docstring about
the policy family (Eq. 5.22 is solved at every state at once with per-step offsets, not with
shared ones) are shown here independently with scipy.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import approx_fprime, minimize

from vslbook.bounds import CheckReport
from vslbook.bounds import dime as D
from vslbook.bounds import dime_entropy as E
from vslbook.bounds import dime_lq as LQ
from vslbook.bounds import dime_policy_iteration as PI
from vslbook.bounds import dime_tabular as T
from vslbook.bounds.toy_numerics import to_numpy

# check names used below
FIXED_POINT = "T Q^pi = Q^pi: the closed form of Eq. 5.17 (with ℓ) is the backup's fixed point"
BACKUPS = "Q^k = T Q^(k-1) from a random Q^0 -> closed-form Q^pi after 300 backups"
CONTRACTION = "||TQ1 - TQ2|| <= gamma ||Q1 - Q2|| (sup norm) for 24 bounded differences"
SHIFT = "constant shifts: ||TQ1 - TQ2|| = gamma ||Q1 - Q2|| (the modulus is attained)"
C11 = "joint KL of Eq. 5.22 = -ℓ(s) - E[Q(s, a)] / alpha + log Z(s), every iterate"
KL_DOWN = "improvement: KL to the target does not increase, at every state"
Q_UP = "improvement: Q^pi_new >= Q^pi_old on the (s, a) grid, every iteration"
J_UP = "iteration: J̄(pi_i) is non-decreasing"
TO_OPTIMUM = "iteration: J̄(pi_8) = max of J̄ over Π̃ (BFGS on theta from pi_0)"
Q_OPTIMUM = "iteration: Q^pi_8 = Q of the direct maximiser of J̄"
DOMINATES = "iteration: Q^pi_8 >= Q^pi of 30 random policies in Π̃"
EVALUATION = {FIXED_POINT, BACKUPS, CONTRACTION, SHIFT}
IMPROVEMENT = {C11, KL_DOWN, Q_UP, J_UP, TO_OPTIMUM, Q_OPTIMUM, DOMINATES}


def failed_names(report: CheckReport) -> set[str]:
    return {check.name for check in report.failed}


@pytest.fixture(scope="module")
def report0() -> CheckReport:
    return D.check_diffusion_policy_iteration(0)


# ------------------------------------------------------------------ the check passes


@pytest.mark.parametrize("seed", (1, 2))
def test_check_passes(seed):
    report = D.check_diffusion_policy_iteration(seed)
    assert len(report) == 13
    report.require()


def test_report_data_and_determinism(report0):
    report0.require()
    data = report0.data
    j = data["j_bar"]
    assert j.shape == (9,) and np.all(np.diff(j) >= -1e-12)
    assert j[-1] - j[0] > 1.0  # policy iteration does something: the target moves
    assert j[-1] == pytest.approx(float(data["j_bar_direct"]), rel=1e-9)
    assert data["q_iterates"].shape == (9, 21, 25)
    assert data["q_old"].shape == data["q_new"].shape == (21, 25)
    assert np.all(data["q_new"] >= data["q_old"]) and np.any(data["q_new"] > data["q_old"] + 1)
    assert data["kl"].shape == (8, 2, 9) and np.all(data["kl"] >= 0)
    assert data["theta"].shape == (9, 9) and data["theta_direct"].shape == (9,)
    assert data["backup_errors"].shape == (301,)
    assert data["contraction_ratios"].max() <= 0.9 + 1e-12
    # the limit is optimal for the bound within the family, not for the exact entropy
    assert np.all(data["bound"] < data["entropy"] - 1e-2)
    j_exact_limit, j_exact_max = data["j_exact_entropy"]
    assert j_exact_limit > j[-1] and j_exact_max > j_exact_limit + 1e-2
    again = D.check_diffusion_policy_iteration(0)
    assert [c.lhs for c in again] == [c.lhs for c in report0]
    for key in data:
        np.testing.assert_array_equal(again.data[key], data[key])


def test_import_paths():
    assert D.check_diffusion_policy_iteration is PI.check_diffusion_policy_iteration
    for name in ("check_soft_bellman_contraction", "check_soft_policy_iteration", "mirror_step"):
        assert getattr(D, name) is getattr(T, name)
    for name in ("check_entropy_lower_bound", "linear_gaussian_chain", "linear_gaussian_policy"):
        assert getattr(D, name) is getattr(E, name)
    assert all(hasattr(D, name) for name in D.__all__)


# ------------------------------------------------------------ wrong ingredients fail


def test_wrong_sign_of_the_bound_in_the_backup_fails_prop_541():
    report = D.check_diffusion_policy_iteration(0, entropy_sign=-1.0)
    failed = failed_names(report)
    assert {FIXED_POINT, BACKUPS} <= failed
    assert not failed & ({CONTRACTION, SHIFT} | IMPROVEMENT)  # differences cancel the bonus


def _ascent(step: float):
    """An "improvement" that climbs the KL of Eq. 5.22, i.e. moves away from the target."""

    def improve(theta, kl):
        return theta + step * approx_fprime(theta, lambda t: kl(t).sum(), 1e-6)

    return improve


def test_improvement_away_from_the_target_fails_prop_542():
    report = D.check_diffusion_policy_iteration(0, improve=_ascent(0.002))
    failed = failed_names(report)
    assert {KL_DOWN, Q_UP, J_UP, TO_OPTIMUM} <= failed
    assert not failed & EVALUATION
    kl = report.data["kl"]
    assert np.all(kl[0, 1] > kl[0, 0])  # the first step raises the KL at every state
    assert report.data["j_bar"][1] < report.data["j_bar"][0]


def test_no_improvement_is_monotone_but_not_optimal():
    report = D.check_diffusion_policy_iteration(0, improve=lambda theta, kl: theta)
    failed = failed_names(report)
    assert {TO_OPTIMUM, Q_OPTIMUM} <= failed
    assert not failed & {KL_DOWN, Q_UP, J_UP, C11}


# ------------------------------------------- the family: Eq. 5.22 at every state at once


def _family_and_target():
    policy = E.linear_gaussian_policy(4, 1.5, 1.0, [1.0], [0.0], [0.0])
    family = LQ.ChainFamily(to_numpy(policy.step_sizes)[:, 0].astype(float), 1.5)
    # Q(s, a) = -s^2 / 2 + 3 s a - a^2 + 2 a: with alpha = 0.5 the target is N(1 + 1.5 s, 1/4)
    q = np.array([-0.5, 3.0, -1.0, 0.0, 2.0, 0.0])
    return family, LQ.Target.of(q, 0.5, family.eta, family.sigma0)


def test_exact_improvement_minimises_the_kl_at_every_state():
    family, target = _family_and_target()
    states = np.linspace(-2.0, 2.0, 9)
    theta0 = np.r_[0.1, np.zeros(8)]
    theta = LQ.improve_exact(family, target, states, theta0)
    at_theta = LQ.joint_kls(family, theta, target, states)
    for i in (0, 8):  # each state alone, over (slope, offsets at that state), by BFGS

        def kl_alone(x, s=states[i]):
            return LQ.joint_kls(family, np.r_[x, np.zeros(4)], target, np.array([s]))[0]

        best = minimize(kl_alone, np.r_[theta0[:5]], method="BFGS", options={"gtol": 1e-10})
        assert at_theta[i] == pytest.approx(best.fun, rel=1e-8, abs=1e-10)
        assert theta[0] == pytest.approx(best.x[0], abs=1e-4)  # the states share the slope


def test_shared_offsets_cannot_minimise_every_state_at_once():
    """With one offset for all steps the states' optimal slopes differ (docstring claim)."""
    family, target = _family_and_target()
    slopes = []
    for s in (0.0, 2.0):

        def kl_shared(x, s=s):
            theta = np.r_[x[0], np.full(4, x[1]), np.zeros(4)]
            return LQ.joint_kls(family, theta, target, np.array([s]))[0]

        slopes.append(minimize(kl_shared, [0.0, 0.0], method="BFGS").x[0])
    assert abs(slopes[0] - slopes[1]) > 0.1  # -1.14 and -0.71; per-step offsets: both -1.208


def test_family_marginal_and_bound_match_the_chain_closed_forms():
    family, _ = _family_and_target()
    theta = np.random.default_rng(3).normal(size=9)
    pi = family.marginal(theta)
    for s, offsets in zip((-1.0, 0.5), family.offsets(theta, np.array([-1.0, 0.5])), strict=True):
        chain = E.linear_gaussian_chain(family.eta[:, None], 1.5, theta[0], offsets[:, None])
        np.testing.assert_allclose(pi.mean_c + pi.mean_g * s, chain.marginal_mean[0], rtol=1e-12)
        np.testing.assert_allclose(pi.var, chain.marginal_var[0], rtol=1e-12)
        np.testing.assert_allclose(pi.bound @ [s * s, s, 1.0], chain.bound[0], rtol=1e-12)
        np.testing.assert_allclose(chain.entropy - chain.bound, chain.kl, rtol=1e-10)


def test_linear_gaussian_chain_per_step_offsets():
    etas = np.array([[0.3, 0.2], [0.1, 0.4]])
    shared = E.linear_gaussian_chain(etas, 1.2, [-0.4, 0.1], [0.7, -0.2])
    per_step = E.linear_gaussian_chain(
        etas, 1.2, np.full((2, 2), [-0.4, 0.1]), np.full((2, 2), [0.7, -0.2])
    )
    for field in ("marginal_mean", "marginal_var", "bound", "kl"):
        np.testing.assert_array_equal(getattr(shared, field), getattr(per_step, field))
    offsets = np.array([[1.0], [-2.0]])  # two steps, one dimension, by hand
    chain = E.linear_gaussian_chain(etas[:, :1], 1.2, 0.0, offsets)
    a1 = 1 - 0.1 / 1.2**2
    np.testing.assert_allclose(chain.marginal_mean, [a1 * 0.3 * 1.0 + 0.1 * -2.0])

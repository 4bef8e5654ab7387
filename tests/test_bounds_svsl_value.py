"""Tests for vslbook.bounds.svsl_value: SVSL's value baseline V(c) (Eqs. A.6, A.7).

The report passes for two seeds and fails with an estimator that drops the importance
ratios π(o|c)/π̂(o|c). The closed forms it compares against are checked here by Monte Carlo
and scipy densities, and SVSL's estimate by an importance-weighted Nadaraya–Watson
regression written out by hand.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import norm

from vslbook.bounds import CheckReport
from vslbook.bounds import svsl_value as SV
from vslbook.erl.reps import nadaraya_watson

SEEDS = (0, 1)
MOVED = "π(o) moved: the ratios"


def _toy(seed=0):
    return SV.ValueToy(np.random.default_rng(seed))


@pytest.mark.parametrize("seed", SEEDS)
def test_value_baseline_check_passes(seed):
    report = SV.check_value_baseline(seed=seed)
    assert isinstance(report, CheckReport)
    report.require()
    d = report.data
    assert d["err_uniform"][-1] < d["err_uniform"][1]
    # the finding: a non-uniform start biases the estimate, by about max |V_∞ − V|
    assert d["err_skewed"] > 5 * d["err_uniform"][-1]
    assert abs(float(d["err_skewed"]) - float(d["bias_skewed"])) < float(d["tol"])


def test_estimator_without_importance_ratios_fails_after_the_weights_moved():
    def plain(s, query):  # unweighted Nadaraya–Watson: tracks the old V, not the new one
        wp = s.weight_phase
        return nadaraya_watson(
            wp["c"], wp["ret"], np.asarray(query)[:, None], scale=s.config.value_kernel_scale
        )

    report = SV.check_value_baseline(seed=0, estimator=plain)
    assert not report.passed
    failed = [c.name for c in report.failed]
    assert any(name.startswith(MOVED) for name in failed)
    # at π = π̂ the ratios are 1, so the first case cannot tell the two apart
    assert report.checks[0].passed
    with pytest.raises(AssertionError, match="check"):
        report.require()


def test_svsl_estimate_is_the_ratio_weighted_kernel_regression():
    toy = _toy(3)
    k = toy.n_experts
    s = SV.svsl_at_weight_phase(toy, np.full(k, 1 / k), 400, 0.3, seed=5)
    moved = np.array([0.5, 0.3, 0.2])
    s.model.log_w = np.log(moved)
    s.model.changed()
    query = np.linspace(-2.0, 2.0, 9)
    got = SV.svsl_value_at(s, query)
    wp = s.weight_phase
    c, o, ret = wp["c"][:, 0], wp["own"], wp["ret"]
    assert np.bincount(o).tolist() == [400] * k  # equal sample counts per expert

    def gate(w):  # π(o|c_i) of each sample's own expert, from scipy densities
        joint = w * norm.pdf(c[:, None], toy.mu, toy.s)
        return (joint / joint.sum(1, keepdims=True))[np.arange(len(c)), o]

    ratio = gate(moved) / gate(np.full(k, 1 / k))
    kern = np.exp(-((query[:, None] - c[None]) ** 2) / 0.3) * ratio
    np.testing.assert_allclose(got, kern @ ret / kern.sum(1), rtol=1e-10)
    # the buffers are restored after the call
    assert s.buffers.c.shape == (k, 400, 1)


def test_closed_forms_against_monte_carlo():
    toy = _toy(1)
    rng = np.random.default_rng(2)
    c = np.array([-1.0, 0.3, 1.2])
    mc = np.empty((len(c), toy.n_experts))
    for j in range(toy.n_experts):
        theta = toy.gain[j] * c + toy.offset[j] + toy.sigma[j] * rng.standard_normal((200_000, 3))
        mc[:, j] = np.mean(-((theta - SV.goal(c)) ** 2), axis=0)
    np.testing.assert_allclose(SV.expected_returns(toy, c), mc, atol=0.02)
    w = np.array([0.2, 0.5, 0.3])
    joint = w * norm.pdf(c[:, None], toy.mu, toy.s)
    np.testing.assert_allclose(SV.gating(toy, w, c), joint / joint.sum(1, keepdims=True))
    np.testing.assert_allclose(
        SV.true_value(toy, w, c), np.sum(SV.gating(toy, w, c) * SV.expected_returns(toy, c), 1)
    )


def test_limit_is_the_value_exactly_when_the_start_weights_are_uniform():
    toy = _toy(4)
    k = toy.n_experts
    c = np.linspace(-2, 2, 11)
    uniform, w = np.full(k, 1 / k), np.array([0.6, 0.1, 0.3])
    np.testing.assert_allclose(SV.nw_limit(toy, w, uniform, c), SV.true_value(toy, w, c))
    assert np.max(np.abs(SV.nw_limit(toy, w, w, c) - SV.true_value(toy, w, c))) > 1e-2
    # A.6 literally at π = π̂: the K expected returns added up
    np.testing.assert_allclose(
        SV.literal_value(toy, w, w, c), SV.expected_returns(toy, c).sum(1), rtol=1e-12
    )


def test_arguments_are_checked():
    with pytest.raises(ValueError, match="at least three increasing"):
        SV.check_value_baseline(samples=(100, 1000))
    with pytest.raises(ValueError, match="at least three increasing"):
        SV.check_value_baseline(samples=(1000, 100, 10_000))
    with pytest.raises(ValueError, match="tol must be a positive"):
        SV.check_value_baseline(tol=0.0)
    with pytest.raises(ValueError, match="seed must be a non-negative integer"):
        SV.check_value_baseline(seed=-1)

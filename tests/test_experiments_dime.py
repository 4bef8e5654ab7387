import numpy as np
import pytest

from vslbook.experiments.dime_toy import fit_boltzmann


def test_fit_boltzmann_reduces_the_kl_bound():
    fit = fit_boltzmann(1.0, iterations=40, batch=128, n_steps=4, hidden=32)
    assert fit.losses[-5:].mean() < fit.losses[:5].mean()
    assert fit.trajectories.shape == (5, 200, 1)
    assert np.trapezoid(fit.target, fit.grid) == pytest.approx(1.0, abs=1e-6)
    assert fit.kl_upper > -0.05  # an upper bound on a KL cannot be (much) below zero


def test_fit_boltzmann_rejects_bad_alpha():
    with pytest.raises(ValueError, match="alpha must be > 0, got 0"):
        fit_boltzmann(0.0)

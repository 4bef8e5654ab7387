import numpy as np
from scipy import integrate

from vslbook.bounds.diskill_disk import (
    RADIUS,
    categorical_mass,
    moment_matched_gaussian,
    polar_integral,
    two_mode_energy,
)


def test_polar_integral_area_and_moment():
    assert np.isclose(polar_integral(lambda p: np.ones(p.shape[:-1]), 0.0, 2 * np.pi),
                      np.pi * RADIUS**2, rtol=1e-12)  # fmt: skip
    # ∫ y over the upper half disk = 2 R³ / 3
    upper_moment = polar_integral(lambda p: p[..., 1], 0.0, np.pi)
    assert np.isclose(upper_moment, 2 * RADIUS**3 / 3, rtol=1e-12)


def test_polar_integral_matches_cartesian_quadrature():
    def f(p):
        return np.exp(two_mode_energy(p))

    exact, _ = integrate.dblquad(
        lambda y, x: f(np.array([x, y])), -RADIUS, RADIUS,
        lambda x: 0.0, lambda x: np.sqrt(RADIUS**2 - x**2), epsabs=1e-11, epsrel=1e-11,
    )  # fmt: skip
    assert np.isclose(polar_integral(f, 0.0, np.pi), exact, rtol=1e-7)


def test_categorical_mass_and_moments():
    rng = np.random.default_rng(0)
    c = rng.normal(size=(200, 2))
    q = rng.dirichlet(np.ones(200))
    inside = c[:, 0] > 0
    mass, se = categorical_mass(q, inside)
    assert np.isclose(mass, q[inside].sum())
    var = sum(qi**2 * (b - mass) ** 2 for qi, b in zip(q, inside, strict=True))
    assert np.isclose(se, np.sqrt(var))
    mean, cov = moment_matched_gaussian(q, c)
    assert np.allclose(mean, np.average(c, axis=0, weights=q))
    assert np.allclose(cov, np.cov(c.T, aweights=q, bias=True))

import numpy as np

from vslbook.bounds import dime_bridge_example as BX


def test_controls_and_target():
    a = np.array([-1.0, 0.0, 2.0])
    assert np.allclose(BX.reference_drift(a, 1), [0.5, 0.0, -1.0])
    assert np.allclose(BX.forward_control(a, 0), [-0.2, 0.2, 1.0])
    assert np.allclose(BX.backward_control(a, 2), [1.4, 0.2, -2.2])
    q = BX.gaussian_target_q(0.5, 0.7)
    # exp Q / Z is the N(0.5, 0.49) density
    x = np.linspace(-2, 3, 7)[:, None]
    dens = np.exp(q(x)) / np.sqrt(2 * np.pi * 0.49)
    assert np.allclose(dens, np.exp(-((x[:, 0] - 0.5) ** 2) / 0.98) / np.sqrt(2 * np.pi * 0.49))
    assert np.isclose(q(np.array([[0.5]]))[0], 0.0)

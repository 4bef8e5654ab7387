from types import SimpleNamespace

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from vslbook.bounds.path_plot import plot_path  # noqa: E402


def test_plot_path_draws_objective_and_bound():
    t = np.linspace(-1, 1, 5)
    report = SimpleNamespace(data={"t": t, "path_objective": 1 - t**2, "path_bound": 1 - 2 * t**2})
    fig, ax = plt.subplots()
    plot_path(ax, report, "one expert", objective="Eq. 4.3")
    objective, bound = ax.lines[:2]
    assert np.array_equal(objective.get_ydata(), 1 - t**2)
    assert np.array_equal(bound.get_ydata(), 1 - 2 * t**2)
    assert objective.get_label() == "objective J (Eq. 4.3)"
    assert ax.get_xlabel() == "step along a random perturbation of one expert"
    plt.close(fig)

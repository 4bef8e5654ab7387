"""Fig. 3.1's experiment code: thesis counts at the full budget, runs reused, models reloaded."""

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from vslbook.experiments import svsl_planar as P  # noqa: E402
from vslbook.results import RunDir  # noqa: E402


def test_full_budget_counts_are_the_thesis():
    n = P.planar_counts("full")
    assert (n["n_experts"], n["iterations_per_expert"], n["seeds"]) == (60, 350, 15)
    cfg = P.variant_config("SVSL", "full")
    assert (cfg.alpha, cfg.beta, cfg.beta_w, cfg.fine_tune_every) == (1e-4, 1.0, 1.0, 50)
    assert not P.variant_config("SVSL, no responsibilities", "full").responsibilities
    h = P.variant_config("HiREPS", "full")
    assert (h.eps, h.kappa, h.n_experts) == (0.5, 0.99, 60)  # Table A.2
    with pytest.raises(ValueError, match="unknown variant"):
        P.variant_config("MORE", "full")


@pytest.mark.parametrize("variant", P.VARIANTS)
def test_smoke_run_reloads_and_is_reused(variant, tmp_path):
    path = P.run_planar(variant, 0, tmp_path, "smoke")
    assert RunDir.open(path).done
    mtime = (path / "DONE").stat().st_mtime_ns
    assert P.run_planar(variant, 0, tmp_path, "smoke") == path  # finished: reused
    assert (path / "DONE").stat().st_mtime_ns == mtime
    model = P.load_model(path)
    s = P.planar_scores(model, n_contexts=10, n_draws=5)
    assert s["tip_distance"] > 0 and 0 <= s["collision_rate"] <= 1
    assert 1 <= s["experts_per_context"] <= 5
    fig, ax = plt.subplots(1, 2)
    P.draw_solutions(ax[0], model, n_draws=10)
    P.draw_context_coverage(ax[1], model)
    assert len(ax[0].lines) > len(P.FIG_CONTEXTS)  # at least one arm per context + dots
    plt.close(fig)
    # the reloaded model is the trained one: same samples from the same generator
    again = P.load_model(path)
    c = np.array([[5.5, 0.0]])
    a = P._sample_means(model, c, 4, np.random.default_rng(1))[0]
    b = P._sample_means(again, c, 4, np.random.default_rng(1))[0]
    np.testing.assert_array_equal(a, b)


def test_fig_3_1_from_the_command_line(tmp_path, monkeypatch):
    """`vslbook figure fig3-1`: the notebook's planar run set in ./runs, six panels, and a
    title that says how the counts differ from the thesis's."""
    from vslbook import figures
    from vslbook.cli import main

    monkeypatch.setenv("VSLBOOK_WORKERS", "1")
    monkeypatch.chdir(tmp_path)
    assert main(["figure", "fig3-1", "--budget", "smoke", "--out", str(tmp_path / "out")]) == 0
    assert (tmp_path / "out" / "fig3-1.png").stat().st_size > 10_000
    assert len(list((tmp_path / "runs").glob("*/DONE"))) == 3
    fig = figures.draw_fig_3_1("smoke", tmp_path / "runs", progress=False)
    assert len(fig.axes) == 6
    assert "2 experts, K = 50 of 350, seed 0 of 1" in fig._suptitle.get_text()
    plt.close(fig)

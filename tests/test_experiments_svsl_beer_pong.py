"""Fig. 3.2 (beer pong) and Fig. A.1 experiment code: thesis counts, runs, curves, grids."""

import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from scipy.special import logsumexp  # noqa: E402

from vslbook.envs.robot.task import Rollouts  # noqa: E402
from vslbook.erl import mixture_baseline as mb  # noqa: E402
from vslbook.experiments import svsl_beer_pong as B  # noqa: E402
from vslbook.results import RunDir  # noqa: E402


def mb_rollouts(returns, success):
    n = len(returns)
    return Rollouts(np.asarray(returns, float), np.asarray(success, bool), np.ones(n, bool), {})


def _episodes_by_schedule(cfg) -> int:
    """Episodes of Algorithm 1 counted by walking its schedule iteration by iteration."""
    total, experts = 0, 0
    for t in range(cfg.n_experts * cfg.iterations_per_expert):
        i = t % cfg.iterations_per_expert
        if i == 0:
            experts += 1
            total += cfg.buffer_size
        updated = experts if (i + 1) % cfg.fine_tune_every == 0 else 1
        total += updated * (cfg.new_samples_expert + cfg.new_samples_context)
    if cfg.weight_iterations:
        total += experts * cfg.buffer_size
    return total


def test_full_budget_counts_are_the_thesis():
    n = B.beer_pong_counts("full")
    assert (n["n_experts"], n["iterations_per_expert"], n["fine_tune_every"]) == (70, 750, 50)
    assert n["seeds"] == 20 and n["grid_draws"] == 100 and n["entropy_draws"] == 1000
    s = B.method_config("SVSL", "full")
    assert (s.alpha, s.beta, s.beta_w, s.n_experts, s.iterations_per_expert) == (
        0.001, 0.5, 2.5, 70, 750,
    )  # Table A.1  # fmt: skip
    h = B.method_config("HiREPS", "full")
    assert (h.eps, h.kappa, h.n_experts) == (0.3, 0.9, 70)  # Table A.2
    la = B.method_config("LaDiPS", "full")
    assert (la.eps, la.eps_gating, la.n_experts) == (0.1, 0.05, 70)  # Table A.3
    assert la.alpha == pytest.approx(math.log(30))
    # the baselines evaluate as many episodes as SVSL (to within one iteration)
    episodes = _episodes_by_schedule(s)
    assert B.svsl_episodes(s) == episodes == 3_229_940
    for cfg in (h, la):
        assert (
            0 <= cfg.iterations * cfg.samples_per_iteration - episodes < cfg.samples_per_iteration
        )
    # a budget changes counts only
    r = B.method_config("SVSL", "reduced")
    assert (r.alpha, r.beta, r.beta_w, r.fine_tune_every, r.kl_context) == (
        s.alpha, s.beta, s.beta_w, s.fine_tune_every, s.kl_context,
    )  # fmt: skip
    for k in (3, 1):
        small = B.svsl_config("beer-pong", n_experts=k, iterations_per_expert=120)
        assert B.svsl_episodes(small) == _episodes_by_schedule(small)


def test_bad_input():
    with pytest.raises(ValueError, match="unknown method"):
        B.method_config("MORE", "smoke")
    with pytest.raises(ValueError, match="unknown method"):
        B.run_beer_pong("svsl", 0, "/nonexistent", "smoke")
    with pytest.raises(ValueError, match="unknown method"):
        B.run_all("/nonexistent", "smoke", methods=("SVSL", "PPO"))
    with pytest.raises(ValueError, match="seed"):
        B.run_beer_pong("SVSL", -1, "/nonexistent", "smoke")
    with pytest.raises(ValueError, match="grid shape"):
        B.grid_contexts((0, 3))
    with pytest.raises(ValueError, match="expected an SVSL"):
        B.mixture_of(object())
    with pytest.raises(ValueError, match="runs is empty"):
        B.curve_frame({})


def test_curve_frame_interpolates_each_run_inside_its_range(tmp_path):
    """Runs logged at different episode counts land on one grid, linearly interpolated."""
    runs = {}
    for method, (x_end, slope) in {"SVSL": (100, 2.0), "HiREPS": (60, -1.0)}.items():
        rd = RunDir.create(tmp_path, {"algo": method, "env": "t", "seed": 0})
        for step, x in enumerate(np.linspace(10, x_end, 4), start=1):
            rd.log(step, samples=float(x), test_return=slope * x + 3.0)
            rd.log(step + 10, samples=float(x) + 1)  # a row without a test
        runs[method] = [rd.path]
    frame = B.curve_frame(runs, points=10)  # grid 10, 20, ..., 100
    svsl = frame[frame["method"] == "SVSL"]
    np.testing.assert_allclose(svsl["samples"], np.arange(10, 101, 10))
    np.testing.assert_allclose(svsl["test_return"], 2.0 * svsl["samples"] + 3.0)
    hi = frame[frame["method"] == "HiREPS"]
    np.testing.assert_allclose(hi["samples"], [10, 20, 30, 40, 50, 60])  # no extrapolation
    np.testing.assert_allclose(hi["test_return"], -hi["samples"] + 3.0)
    curves = B.learning_curves(runs, points=10, reps=20)
    assert (curves["n_runs"] == 1).all() and len(curves) == 16


def test_curve_frame_ends_each_run_at_its_final_test(tmp_path):
    """A run ending between two grid counts is drawn up to its own last test, not to the
    grid count before it: its final point is its final recorded value."""
    runs = {}
    for method, x_end in {"SVSL": 100.0, "HiREPS": 65.0}.items():
        rd = RunDir.create(tmp_path, {"algo": method, "env": "t", "seed": 0})
        for step, x in enumerate(np.linspace(10, x_end, 4), start=1):
            rd.log(step, samples=float(x), test_return=float(step % 2))  # zigzag: 1, 0, 1, 0
        runs[method] = [rd.path]
    frame = B.curve_frame(runs, points=10)  # grid 10, 20, ..., 100, plus 65
    hi = frame[frame["method"] == "HiREPS"]
    assert hi["samples"].iloc[-1] == 65.0 and hi["test_return"].iloc[-1] == 0.0
    svsl = frame[frame["method"] == "SVSL"]
    assert 65.0 in set(svsl["samples"])  # the other runs are read at that count too
    assert svsl["samples"].iloc[-1] == 100.0 and svsl["test_return"].iloc[-1] == 0.0


def test_grid_contexts_are_cell_centres():
    g = B.grid_contexts((2, 2))  # box [-0.32, 0.32] x [-2.2, -1.2]
    assert g.shape == (2, 2, 2)
    np.testing.assert_allclose(g[0, 0], [-0.16, -1.95])
    np.testing.assert_allclose(g[1, 1], [0.16, -1.45])


@pytest.fixture(scope="module")
def smoke_runs(tmp_path_factory):
    root = tmp_path_factory.mktemp("bp")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("VSLBOOK_WORKERS", "0")  # in-process: no pool start-up in a test
        runs = B.run_all(root, "smoke", seeds=1)  # every method, seed 0
        assert list(runs) == list(B.METHODS)
        yield runs


@pytest.mark.slow
def test_smoke_runs_give_curve_rows(smoke_runs):
    for method, (path,) in smoke_runs.items():
        rd = RunDir.open(path)
        assert rd.done
        df = rd.metrics_frame()
        assert np.all(np.diff(df["samples"]) >= 0)
        tested = df.dropna(subset=["test_return"])
        assert len(tested) >= 1 and np.isfinite(tested["expected_entropy"]).all()
        assert 0 <= tested["test_success"].min() <= tested["test_success"].max() <= 1
        if method != "SVSL":  # executed episodes add up (rejected θ are not counted)
            assert df["samples"].iloc[-1] == df["samples_iteration"].sum()
            assert df["samples"].iloc[-1] <= df["total_samples"].iloc[-1] + 0
        mtime = (path / "DONE").stat().st_mtime_ns
        assert B.run_beer_pong(method, 0, path.parent, "smoke") == path  # reused
        assert (path / "DONE").stat().st_mtime_ns == mtime
    curves = B.learning_curves(smoke_runs, reps=50)
    assert set(curves["method"]) == set(B.METHODS) and (curves["n_runs"] == 1).all()
    ent = B.learning_curves(smoke_runs, "expected_entropy", reps=50)
    assert np.isfinite(ent["iqm"]).all()
    fig, ax = plt.subplots()
    B.draw_learning_curves(ax, curves)
    assert len(ax.lines) >= 3
    plt.close(fig)


@pytest.mark.slow
def test_baseline_test_return_is_the_protocol(smoke_runs, monkeypatch):
    """The logged test return is θ ~ π(θ | c) of the final model on SVSL's test contexts."""
    monkeypatch.setenv("VSLBOOK_WORKERS", "0")
    path = smoke_runs["HiREPS"][0]
    rd = RunDir.open(path)
    row = rd.metrics_frame().dropna(subset=["test_return"]).iloc[-1]
    model = B.load_model(path)
    task = model.task
    cfg = rd.config
    contexts = task.sample_contexts(cfg["test_contexts"], np.random.default_rng([0, 1]))
    theta, _ = mb.sample_mixture(model.mix, contexts, np.random.default_rng([0, 2, int(row.step)]))
    returns = [task.episode(th, c).ret for th, c in zip(theta, contexts, strict=True)]
    assert row["test_return"] == pytest.approx(np.mean(returns))


def test_mixture_of_baseline_is_its_density(monkeypatch):
    """Fig. A.1 for the baselines: the MixtureModel built from their arrays has their density."""
    from vslbook.erl import hireps

    monkeypatch.setenv("VSLBOOK_WORKERS", "0")
    task = B._task()
    algo = hireps.HiREPS(task, B.method_config("HiREPS", "smoke"), 3)
    rng = np.random.default_rng(0)
    algo.mix.K = rng.normal(size=algo.mix.K.shape)  # not the zero initial gains
    algo.mix.log_prior = algo.mix.log_prior + rng.normal(size=algo.mix.log_prior.shape)
    algo.mix.log_prior -= logsumexp(algo.mix.log_prior)
    c = task.sample_contexts(5, rng)
    th, _ = algo.sample(c, rng)
    want = logsumexp(mb.gating_log_probs(c, algo.mix) + mb.expert_log_density(c, th, algo.mix), 1)
    import torch

    got = B.mixture_of(algo).moe.log_prob(torch.from_numpy(th), torch.from_numpy(c)).numpy()
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-9)


@pytest.mark.slow
def test_success_grid_on_smoke_svsl(smoke_runs, monkeypatch):
    monkeypatch.setenv("VSLBOOK_WORKERS", "0")
    model = B.load_model(smoke_runs["SVSL"][0])
    grid = B.success_grid(model, (2, 3), n_draws=2, seed=5)
    assert grid.shape == (3, 2) and np.all((grid >= 0) & (grid <= 1))
    # what is executed: per cell centre, the means of experts o ~ π(o | c) from rng(seed)
    seen = {}
    task = B._task()

    def fake_evaluate(theta, contexts, workers=None):
        seen["theta"], seen["c"] = theta, contexts
        draw = np.tile(np.arange(4), len(contexts) // 4)
        x, y = contexts[:, 0], contexts[:, 1]
        success = ((x > 0) & (y < -1.9) & (draw < 3)) | (
            (x < 0) & (np.abs(y + 1.7) < 0.1) & (draw < 1)
        )
        n = len(contexts)
        return mb_rollouts(np.zeros(n), success)

    monkeypatch.setattr(task, "evaluate", fake_evaluate)
    got = B.success_grid(model, (2, 3), n_draws=4, seed=7)
    centres = np.array([[x, y] for y in (-2.2 + 1 / 6, -1.7, -1.2 - 1 / 6) for x in (-0.16, 0.16)])
    rep = np.repeat(centres, 4, axis=0)
    np.testing.assert_allclose(seen["c"], rep)
    o = model.model.choose_experts(rep, np.random.default_rng(7))
    np.testing.assert_allclose(seen["theta"], model.model.expert_means(rep, o))
    want = np.zeros((3, 2))
    want[0, 1] = 0.75  # cell x > 0 at the smallest y: three of four draws succeed
    want[1, 0] = 0.25  # cell x < 0 at the middle y: one of four
    np.testing.assert_allclose(got, want)
    monkeypatch.undo()
    monkeypatch.setenv("VSLBOOK_WORKERS", "0")
    trajs = B.ball_trajectories(model, [0.0, -1.7], n_draws=3, seed=0)
    for tr in trajs:
        assert len(tr["t"]) == len(tr["z"]) and 0 <= tr["expert"] < model.model.n_experts
    fig, ax = plt.subplots(1, 3)
    B.draw_success_grid(ax[0], grid, "SVSL")
    B.draw_context_coverage(ax[1], model)
    B.draw_ball_trajectories(ax[2], trajs)
    assert len(ax[1].patches) == model.model.n_experts + 1
    plt.close(fig)


@pytest.mark.slow
def test_every_method_logs_its_final_grid_success(smoke_runs, monkeypatch):
    """Fig. 3.2e/f's number: the final row holds the success over the budget's cup grid of
    the final model (means of experts drawn from π(o | c)), which the claims are checked on."""
    monkeypatch.setenv("VSLBOOK_WORKERS", "0")
    counts = B.beer_pong_counts("smoke")
    for method, (path,) in smoke_runs.items():
        rows = RunDir.open(path).metrics()
        assert [r for r in rows[:-1] if "grid_success" in r] == [], method
        grid = B.success_grid(B.load_model(path), counts["grid"], n_draws=counts["grid_draws"])
        assert rows[-1]["grid_success"] == pytest.approx(grid.mean()), method
        # and every cell, named by column (x) and row (y): smoke's grid is 2 x 3 cells
        assert grid.shape == (3, 2)
        for iy, ix in [(0, 0), (2, 1), (1, 0)]:
            assert rows[-1][f"grid_success_x{ix:02d}_y{iy:02d}"] == grid[iy, ix], method
        assert sum(k.startswith("grid_success_x") for k in rows[-1]) == 6, method


@pytest.mark.slow
def test_a_finished_runs_grid_is_drawn_as_logged_and_a_probes_from_its_checkpoint(
    smoke_runs, monkeypatch, tmp_path
):
    """Fig. 3.2e/f draws a finished run's logged grid without loading its model; a run
    whose last row has no grid (a probe, an older run) is drawn from its checkpoint."""
    monkeypatch.setenv("VSLBOOK_WORKERS", "0")
    (path,) = smoke_runs["HiREPS"]
    counts = B.beer_pong_counts("smoke")
    expected = B.success_grid(B.load_model(path), counts["grid"], n_draws=counts["grid_draws"])

    with monkeypatch.context() as mp:  # the logged grid needs no model
        mp.setattr(B, "load_model", lambda p: pytest.fail("loaded a model"))
        grid, how = B.drawn_grid(path, "smoke")
    np.testing.assert_array_equal(grid, expected)
    assert how == "final model, 2 draws per cell"

    import json
    import shutil

    older = tmp_path / path.name
    shutil.copytree(path, older)
    rows = [json.loads(line) for line in (older / "metrics.jsonl").read_text().splitlines()]
    rows[-1] = {k: v for k, v in rows[-1].items() if k != "grid_success_x01_y02"}
    (older / "metrics.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    (older / "DONE").unlink()
    grid, how = B.drawn_grid(older, "smoke")
    np.testing.assert_array_equal(grid, expected)
    assert how == "2 draws per cell"


def test_grid_metrics_round_trip_and_bad_cells():
    cells = np.array([[0.0, 0.5, 1.0], [0.25, 0.75, 0.5]])  # 2 rows (y) of 3 cells (x)
    metrics = B.grid_metrics(cells)
    assert metrics["grid_success"] == pytest.approx(3.0 / 6)
    assert metrics["grid_success_x02_y00"] == 1.0 and metrics["grid_success_x00_y01"] == 0.25
    assert len(metrics) == 7
    np.testing.assert_array_equal(B.logged_grid(metrics, (3, 2)), cells)
    assert B.logged_grid(metrics, (3, 3)) is None  # a row y = 2 was never logged
    assert B.logged_grid({"grid_success": 0.5}, (3, 2)) is None
    with pytest.raises(ValueError, match=r"\(n_y, n_x\) array, got shape \(3,\)"):
        B.grid_metrics([0.1, 0.2, 0.3])


def test_env_ids_name_the_tasks():
    from vslbook.experiments import svsl_table_tennis as TT
    from vslbook.experiments.ch3_algorithms import env_of

    assert env_of(B.TASK) == B.ENV and env_of(TT.TASK) == TT.ENV


@pytest.mark.slow
def test_fig_3_2_is_a_registered_figure(smoke_runs, monkeypatch, tmp_path):
    """`vslbook figure fig3-2`: beer pong's and table tennis's curves and the two success
    grids, from the figure's runs (here the module's smoke runs, table tennis trained now),
    with where they came from under the figure."""
    import vslbook.figures  # noqa: F401 -- registers the figures
    from vslbook.experiments import figure_draws
    from vslbook.registry import FIGURES

    monkeypatch.setenv("VSLBOOK_WORKERS", "0")
    assert "fig3-2" in FIGURES
    root = smoke_runs["SVSL"][0].parent
    fig = figure_draws.draw_fig_3_2("smoke", root, progress=False)
    titles = [ax.get_title() for ax in fig.axes if ax.get_title()]
    assert any(t.startswith("(a) beer pong") for t in titles)
    assert any(t.startswith("(e) SVSL: mean success") for t in titles)
    assert any("Runs of fig3-2" in t.get_text() for t in fig.texts)
    plt.close(fig)

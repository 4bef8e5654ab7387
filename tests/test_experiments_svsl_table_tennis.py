"""Fig. 3.2 (table tennis) and Fig. A.2 experiment code: thesis counts, runs, coverage, grids."""

import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from vslbook.envs.robot.task import Rollouts  # noqa: E402
from vslbook.erl import hireps, ladips  # noqa: E402
from vslbook.experiments import svsl_table_tennis as T  # noqa: E402
from vslbook.results import RunDir  # noqa: E402


def test_full_budget_counts_are_the_authors():
    n = T.table_tennis_counts("full")
    # K = 1000 as in the authors' configuration; Table A.1's 800 under settings="thesis"
    assert (n["n_experts"], n["iterations_per_expert"], n["fine_tune_every"]) == (50, 1000, 50)
    assert T.table_tennis_counts("full", settings="thesis")["iterations_per_expert"] == 800
    with pytest.raises(ValueError, match="settings must be one of \\('code', 'thesis'\\), got 'x'"):
        T.table_tennis_counts("full", settings="x")
    assert n["seeds"] == 20
    assert (n["entropy_contexts"], n["entropy_draws"]) == (1600, 1000)  # A.3.3.1
    s = T.method_config("SVSL", "full")
    assert (s.alpha, s.beta, s.beta_w, s.n_experts, s.iterations_per_expert) == (
        1e-5, 0.2, 0.2, 50, 1000,
    )  # Table A.1, K from the authors' code  # fmt: skip
    h = T.method_config("HiREPS", "full")
    assert (h.eps, h.kappa, h.n_experts) == (0.3, 0.9, 50)  # Table A.2
    la = T.method_config("LaDiPS", "full")
    assert (la.eps, la.eps_gating, la.n_experts) == (0.01, 0.02, 50)  # Table A.3
    assert la.alpha == pytest.approx(math.log(30))
    # SVSL's episodes by hand: 50 buffer fills of 567, 50·1000 updates of the newest expert
    # (226 + 8 episodes each), every 50th iteration also the k - 1 older experts
    # (20 times per added expert, 0 + 1 + ... + 49 = 1225 older experts in all), the
    # weight phase refills 50 buffers.
    episodes = 50 * 567 + 50 * 1000 * 234 + 20 * 234 * 1225 + 50 * 567
    assert T.svsl_episodes(s) == episodes == 17_489_700
    for cfg in (h, la):
        assert cfg.samples_per_iteration == 500
        assert 0 <= cfg.iterations * 500 - episodes < 500
    # a budget changes counts only
    r = T.method_config("SVSL", "reduced")
    assert (r.alpha, r.beta, r.beta_w, r.fine_tune_every, r.kl_context, r.kl_weights) == (
        s.alpha, s.beta, s.beta_w, s.fine_tune_every, s.kl_context, s.kl_weights,
    )  # fmt: skip
    assert T.method_config("LaDiPS", "reduced").eps_gating == 0.02


def test_chapter3_presets_use_the_chapter3_parameter_layout():
    task = T._task()
    for cfg in (hireps.HIREPS_PRESETS[T.TASK], ladips.LADIPS_PRESETS[T.TASK]):
        mean = np.asarray(cfg.init_mean)
        assert mean.shape == (task.n_params,) == (22,)
        assert 0.1 < mean[0] < 5.0  # a duration inside A.3.3's range, then the weights
        assert np.all(mean[1:] == 0)
    # the Chapter 4 presets are untouched
    tt4 = hireps.HIREPS_PRESETS["table-tennis-4d"]
    assert tt4.init_mean[:2] == (1.03, 0.325) and len(tt4.init_mean) == 23
    assert ladips.LADIPS_PRESETS["table-tennis-4d"].init_cov[:2] == (0.02, 0.01)


def test_bad_input():
    with pytest.raises(ValueError, match="unknown method"):
        T.method_config("MORE", "smoke")
    with pytest.raises(ValueError, match="unknown method"):
        T.run_table_tennis("svsl", 0, "/nonexistent", "smoke")
    with pytest.raises(ValueError, match="unknown method"):
        T.run_all("/nonexistent", "smoke", methods=("SVSL", "PPO"))
    with pytest.raises(ValueError, match="seed"):
        T.run_table_tennis("SVSL", -1, "/nonexistent", "smoke")
    with pytest.raises(ValueError, match="plane"):
        T.draw_context_coverage(None, None, plane="ball")
    with pytest.raises(ValueError, match="fixed="):
        T.mx.box_grid(T.TASK, (2, 2))  # a 4-D context needs the other entries
    with pytest.raises(ValueError, match="dims"):
        T.mx.box_grid(T.TASK, (2, 2), dims=(1, 4), fixed=np.zeros(4))
    with pytest.raises(ValueError, match="incoming"):
        T.goal_success_grid(None, incoming=(0.0, 0.0))  # x_inc > -0.2: the serve is invalid


def test_box_grid_is_cell_centres_with_the_rest_fixed():
    fixed = np.array([-0.7, 0.0, -0.5, 0.25])
    g = T.mx.box_grid(T.TASK, (2, 3), dims=(2, 3), fixed=fixed)  # x_inc ∈ [-1.2, -0.2]
    assert g.shape == (3, 2, 4)
    np.testing.assert_allclose(g[0, 0], [-0.7, 0.0, -0.95, -0.65 + 1.3 / 6])
    np.testing.assert_allclose(g[2, 1], [-0.7, 0.0, -0.45, 0.65 - 1.3 / 6])


@pytest.fixture(scope="module")
def smoke_runs(tmp_path_factory):
    root = tmp_path_factory.mktemp("tt")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("VSLBOOK_WORKERS", "0")  # in-process: no pool start-up in a test
        yield T.run_all(root, "smoke")


@pytest.mark.slow
def test_smoke_runs_give_curve_rows(smoke_runs):
    assert set(smoke_runs) == set(T.METHODS)
    for method, (path,) in smoke_runs.items():
        rd = RunDir.open(path)
        assert rd.done and rd.config["env"] == "vslbook/TableTennisCh3-v0"  # `vslbook run`'s run
        df = rd.metrics_frame()
        assert np.all(np.diff(df["samples"]) >= 0)
        tested = df.dropna(subset=["test_return"])
        assert len(tested) >= 1 and np.isfinite(tested["expected_entropy"]).all()
        assert 0 <= tested["test_success"].min() <= tested["test_success"].max() <= 1
        if method != "SVSL":  # executed episodes add up (rejected θ are not counted)
            assert df["samples"].iloc[-1] == df["samples_iteration"].sum()
            assert rd.config["entropy_contexts"] == 10
    curves = T.learning_curves(smoke_runs, reps=50)
    assert set(curves["method"]) == set(T.METHODS) and (curves["n_runs"] == 1).all()
    ent = T.learning_curves(smoke_runs, "expected_entropy", reps=50)
    assert np.isfinite(ent["iqm"]).all()
    fig, ax = plt.subplots(1, 2)
    T.draw_learning_curves(ax[0], curves)
    T.draw_entropy_curves(ax[1], ent)
    assert len(ax[0].lines) >= 3 and len(ax[1].lines) >= 3
    plt.close(fig)


@pytest.mark.slow
def test_coverage_projects_the_context_gaussians(smoke_runs):
    """Fig. 3.2d: the ellipses are the 2σ contours of the marginals on the chosen plane."""
    model = T.load_model(smoke_runs["SVSL"][0])
    mix = T.mixture_of(model)
    # a context Gaussian whose planes have known axes; the cross terms between the goal
    # and the incoming ball must not enter the marginals
    cov = np.array([
        [0.04, 0.0, 0.01, 0.0],
        [0.0, 0.01, 0.0, 0.005],
        [0.01, 0.0, 0.01, 0.0],
        [0.0, 0.005, 0.0, 0.09],
    ])  # fmt: skip
    mix.ctx_mean = np.array([[-0.7, 0.1, -0.5, -0.2]])
    mix.ctx_cov = cov[None]
    fig, ax = plt.subplots(1, 2)
    T.draw_context_coverage(ax[0], model, "goal")
    T.draw_context_coverage(ax[1], model, "incoming")
    goal = [p for p in ax[0].patches if isinstance(p, matplotlib.patches.Ellipse)]
    inc = [p for p in ax[1].patches if isinstance(p, matplotlib.patches.Ellipse)]
    assert len(goal) == len(inc) == 1
    np.testing.assert_allclose(goal[0].center, [-0.7, 0.1])
    np.testing.assert_allclose([goal[0].width, goal[0].height], [4 * 0.2, 4 * 0.1])
    assert goal[0].angle % 180 == pytest.approx(0.0, abs=1e-9)
    np.testing.assert_allclose(inc[0].center, [-0.5, -0.2])
    np.testing.assert_allclose([inc[0].width, inc[0].height], [4 * 0.3, 4 * 0.1])
    assert inc[0].angle % 180 == pytest.approx(90.0)  # the long axis along y_inc
    # the goal box is the valid one; the incoming plane also shows the smaller valid box
    assert len(ax[0].patches) == 2 and len(ax[1].patches) == 3
    plt.close(fig)


@pytest.mark.slow
def test_goal_success_grid_executes_expert_means(smoke_runs, monkeypatch):
    monkeypatch.setenv("VSLBOOK_WORKERS", "0")
    model = T.load_model(smoke_runs["HiREPS"][0])
    task = T._task()
    seen = {}

    def fake_evaluate(theta, contexts, workers=None):
        seen["theta"], seen["c"] = theta, contexts
        success = (contexts[:, 0] < -0.7) & (contexts[:, 1] > 0) & (np.arange(len(theta)) % 2 == 0)
        n = len(theta)
        return Rollouts(np.zeros(n), success, np.ones(n, bool), {})

    monkeypatch.setattr(task, "evaluate", fake_evaluate)
    got = T.goal_success_grid(model, (2, 3), incoming=(-0.9, 0.3), n_draws=2, seed=4)
    # goal cell centres: x_des ∈ {-0.95, -0.45}, y_des ∈ {-0.4, 0, 0.4}, rows along y
    centres = np.array([[x, y, -0.9, 0.3] for y in (-0.4, 0.0, 0.4) for x in (-0.95, -0.45)])
    rep = np.repeat(centres, 2, axis=0)
    np.testing.assert_allclose(seen["c"], rep, atol=1e-12)
    mix = T.mixture_of(model)
    o = mix.choose_experts(rep, np.random.default_rng(4))
    np.testing.assert_allclose(seen["theta"], mix.expert_means(rep, o))
    want = np.zeros((3, 2))
    want[2, 0] = 0.5  # x_des < -0.7 and y_des > 0: one of the two draws succeeds
    np.testing.assert_allclose(got, want)
    fig, ax = plt.subplots()
    T.draw_goal_success_grid(ax, got, "HiREPS")
    plt.close(fig)


def test_entropy_every_thins_the_entropy_test_points():
    """Full budget: E_c H[π(θ | c)] at every 8th test point and at the end only."""
    assert T.table_tennis_counts("full")["entropy_every"] == 8
    extra = {"entropy_every": 3}
    due = [it for it in range(1, 21) if T.mx.entropy_due(it, 2, 20, extra)]
    assert due == [6, 12, 18, 20]
    assert [it for it in range(1, 7) if T.mx.entropy_due(it, 2, 7, {})] == [2, 4, 6]

"""Fig. 3.1's experiment code: thesis counts at the full budget, runs reused, models reloaded."""

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from vslbook.envs.robot.planar_reacher import OBSTACLES, link_points  # noqa: E402
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


def test_the_figures_runs_are_the_command_lines_presets():
    """Fig. 3.1's runs: each variant is `vslbook run` with the planar preset (the variant
    without responsibilities by `--set responsibilities=false`), its config the variant's."""
    from dataclasses import asdict

    from vslbook.budget import get_budget
    from vslbook.experiments.ch3_runs import figure_runs
    from vslbook.registry import config_from_overrides, get_algorithm

    for budget in ("smoke", "reduced", "full"):
        runs = figure_runs("fig3-1", budget)
        n = P.planar_counts(budget)
        assert [r.method for r in runs] == [v for v in P.VARIANTS for _ in range(n["seeds"])]
        for r in runs:
            spec = get_algorithm(r.algo)
            preset = spec.default_config(r.env, get_budget(budget), r.overrides)
            config = config_from_overrides(spec.config, r.overrides, preset)
            variant = asdict(P.variant_config(r.method, budget))
            assert {k: asdict(config)[k] for k in variant} == variant, (budget, r.method)
            length = config.iterations if r.algo == "hireps" else config.total_iterations
            assert r.length == length
    (no_resp,) = [r for r in figure_runs("fig3-1", "smoke") if r.overrides]
    assert no_resp.command("runs") == (
        "vslbook run svsl --env vslbook/PlanarReacher-v0 --seed 0 --budget smoke "
        "--set responsibilities=false --root runs"
    )


@pytest.mark.parametrize("variant", P.VARIANTS)
def test_smoke_run_reloads_and_is_reused(variant, tmp_path):
    from vslbook.experiments.ch3_runs import run_set

    (path,) = run_set("fig3-1", "smoke", tmp_path, methods=(variant,))[variant]
    assert RunDir.open(path).done
    mtime = (path / "DONE").stat().st_mtime_ns
    assert run_set("fig3-1", "smoke", tmp_path, methods=(variant,))[variant] == [path]  # reused
    assert (path / "DONE").stat().st_mtime_ns == mtime
    config = RunDir.open(path).config
    expected = {"SVSL": True, "SVSL, no responsibilities": False, "HiREPS": None}[variant]
    assert config["algo"] == variant.split(",")[0].lower()
    assert config.get("responsibilities") is expected
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
    from vslbook.cli import main
    from vslbook.experiments import figure_draws

    monkeypatch.setenv("VSLBOOK_WORKERS", "1")
    monkeypatch.chdir(tmp_path)
    assert main(["figure", "fig3-1", "--budget", "smoke", "--out", str(tmp_path / "out")]) == 0
    assert (tmp_path / "out" / "fig3-1.png").stat().st_size > 10_000
    assert len(list((tmp_path / "runs").glob("*/DONE"))) == 3
    fig = figure_draws.draw_fig_3_1("smoke", tmp_path / "runs", progress=False)
    assert len(fig.axes) == 6
    fig.canvas.draw()  # a row per variant: its solutions and its context distributions
    centres = [round((ax.get_position().y0 + ax.get_position().y1) / 2, 2) for ax in fig.axes]
    assert [centres.count(c) for c in centres] == [2] * 6
    assert [ax.get_title() for ax in fig.axes[::2]] == [
        f"{v}: mean solutions at the six targets" for v in P.VARIANTS
    ]
    assert "2 experts, K = 50 of 350, seed 0 of 1" in fig._suptitle.get_text()
    # the settings, read from the runs' task: the authors' joint cost (Fig. 3.1 was theirs)
    assert ("the authors' settings (SVSL_LMOE code): joint cost without the base joint"
            in fig._suptitle.get_text())  # fmt: skip
    plt.close(fig)


def test_score_labels_are_words_with_the_seeds_counted():
    assert P.score_label("solved_rate", 1) == (
        "share of draws that solve their target\n(IQM over 1 seed)"
    )
    assert P.score_label("coverage", 3).endswith("(IQM over 3 seeds)")
    with pytest.raises(ValueError, match="unknown score 'solved'"):
        P.score_label("solved", 3)


def test_distinct_solutions_groups_wrapped_angles_within_the_threshold():
    a = np.zeros(10)
    b = a.copy()
    b[3] = 2 * np.pi + 0.2  # the same arm after wrapping, 0.2 rad away
    c = a.copy()
    c[:2] = 0.9  # sqrt(2) * 0.9 = 1.27 rad away
    assert P.distinct_solutions(np.stack([a, b])) == 1
    assert P.distinct_solutions(np.stack([a, b, c])) == 2
    assert P.distinct_solutions(np.stack([a, c]), threshold=1.5) == 1


def _x_monotone_arms(rng, n):
    """Arms whose links all point rightwards and whose tips lie on y = 0 at x >= 4.5 (5
    headings, then the same 5 negated in another order)."""
    arms = []
    while len(arms) < n:
        first = rng.uniform(-1.35, 1.35, size=5)
        heading = np.concatenate([first, -rng.permutation(first)])  # link directions
        if np.cos(heading).sum() >= 4.5:
            arms.append(np.diff(heading, prepend=0.0))  # relative joint angles θ
    return np.array(arms)


def _sides(theta):
    """Above (True) or below each obstacle's centre where the arm passes its x, read off the
    polyline (only for arms whose x grows along the chain)."""
    pts = link_points(theta)
    cx, cy = OBSTACLES[:, :2].mean(1), OBSTACLES[:, 2:].mean(1)
    return tuple(bool(np.interp(x, pts[:, 0], pts[:, 1]) > y) for x, y in zip(cx, cy, strict=True))


def test_ways_around_obstacles_are_the_sides_the_arms_pass_on():
    """For arms that run left to right the way around the obstacles is the side (above or
    below) of each obstacle centre: the count must be the number of side patterns."""
    rng = np.random.default_rng(0)
    checked = 0
    for _ in range(40):
        arms = _x_monotone_arms(rng, 6)
        tips = np.array([link_points(t)[-1] for t in arms])
        assert np.allclose(tips[:, 1], 0.0) and np.all(tips[:, 0] >= 4.5)
        patterns = {_sides(t) for t in arms}
        assert P.ways_around_obstacles(arms) == len(patterns)
        # groups whose arms pass the middle obstacle on one side but differ elsewhere
        checked += len(patterns) > len({p[0] for p in patterns})
    assert checked >= 5  # (8 of the 40 groups with this seed)
    over = np.diff([0.3] * 5 + [-0.3] * 5, prepend=0.0)  # above the middle obstacle
    under = -over  # its mirror image: below it (and below the lower one)
    bent = over + rng.normal(0.0, 0.01, size=10)
    assert _sides(over) == _sides(bent) != _sides(under)
    assert P.ways_around_obstacles(np.stack([over, bent])) == 1
    assert P.ways_around_obstacles(np.stack([over, bent, under])) == 2


def test_scores_on_given_contexts_count_the_chosen_arms():
    """planar_scores on given targets (the thesis's reading of Fig. 3.1: the six figure
    contexts, 100 draws each): a model whose three experts play fixed arms in turn; two
    arms pass the obstacles on the same sides, the third on other sides, all three reach
    the first target and none the second."""
    from types import SimpleNamespace

    task = P.make_task("planar-reacher")
    target = np.array([6.0, 0.0])
    rng = np.random.default_rng(3)
    found: dict[tuple, list] = {}
    while len(found) < 2 or max(map(len, found.values())) < 2:
        arm = _x_monotone_arms(rng, 1)[0]
        out = task.evaluate(arm[None], target[None])
        if out.info["tip_distance"][0] < 0.25 and out.info["collision"][0] == 0:
            found.setdefault(_sides(arm), []).append(arm)
    pair = next(a for a in found.values() if len(a) >= 2)[:2]
    other = next(a for a in found.values() if not np.array_equal(a[0], pair[0]))[0]
    arms = np.stack([*pair, other])
    assert len({_sides(t) for t in arms}) == 2
    means, covs = np.array([[6.0, 0.0]] * 3), np.eye(2)[None].repeat(3, 0)
    mix = SimpleNamespace(K=np.zeros((3, 10, 2)), k=arms, ctx_mean=means, ctx_cov=covs)
    model = SimpleNamespace(sample=lambda c, rng: (None, np.arange(len(c)) % 3), mix=mix)
    far = np.array([5.0, 5.0])  # out of every arm's reach, 5.1 from the context means
    s = P.planar_scores(model, contexts=np.stack([target, far]), n_draws=6)
    assert s["solved_rate"] == 0.5 and s["collision_rate"] == 0.0
    assert s["ways_per_context"] == 1.0  # (2 + 0) / 2
    assert s["experts_per_context"] == 3.0
    assert s["coverage"] == 0.5  # the target inside the 2σ circles, the far one not
    with pytest.raises(ValueError, match=r"shape \(m, 2\), got \(2,\)"):
        P.planar_scores(model, contexts=target)

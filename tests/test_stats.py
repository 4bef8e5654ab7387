"""IQM, seeded stratified-bootstrap intervals, IQM curves and performance profiles."""

from __future__ import annotations

import time

import numpy as np
import pandas as pd
import pytest

from vslbook import stats


def _scores(seed=0, runs=10, tasks=3):
    return np.random.default_rng(seed).normal(size=(runs, tasks))


def _curves(seeds=10, points=42, offset=0.0):
    """Synthetic learning curves: every run increases with x."""
    rng = np.random.default_rng(1)
    xs = np.arange(points) * 24_000
    rows = []
    for s in range(seeds):
        level = rng.uniform(0.5, 1.5)
        values = offset + level * np.sqrt(xs / xs[-1]) + np.linspace(0, 0.01, points)
        rows += [(s, x, v) for x, v in zip(xs, values, strict=True)]
    return pd.DataFrame(rows, columns=["seed", "env_steps", "mean_return"])


# --------------------------------------------------------------------------- IQM


def test_iqm_against_hand_computation():
    # n = 8: floor(0.25 * 8) = 2 values cut from each end, mean of the middle four.
    runs = np.array([10.0, 1.0, 7.0, 3.0, 100.0, 5.0, -50.0, 6.0])
    assert stats.iqm(runs) == pytest.approx((3.0 + 5.0 + 6.0 + 7.0) / 4)
    matrix = np.stack([runs, 2 * runs], axis=1)
    np.testing.assert_allclose(stats.iqm(matrix), [5.25, 10.5])
    # aggregate over all runs and tasks at once (rliable's definition)
    assert stats.aggregate_iqm(runs.reshape(4, 2))[0] == pytest.approx(5.25)


def test_iqm_rejects_bad_input():
    with pytest.raises(ValueError, match="at least one run"):
        stats.iqm([])
    with pytest.raises(ValueError, match="NaN"):
        stats.iqm([1.0, np.nan])


# --------------------------------------------------------------------------- intervals


def test_interval_estimates_seeded():
    scores = {"a": _scores(0), "b": _scores(1) + 1}
    point, ci = stats.interval_estimates(scores, reps=300, seed=3)
    point2, ci2 = stats.interval_estimates(scores, reps=300, seed=3)
    _, ci_other = stats.interval_estimates(scores, reps=300, seed=4)
    for name in scores:
        np.testing.assert_array_equal(ci[name], ci2[name])
        np.testing.assert_array_equal(point[name], point2[name])
        assert ci[name].shape == (2, 1)
        assert ci[name][0, 0] <= point[name][0] <= ci[name][1, 0]
    assert not np.array_equal(ci["a"], ci_other["a"])


def test_interval_estimates_leaves_global_rng_alone():
    np.random.seed(123)  # noqa: NPY002 - checking that the global RNG is restored
    before = np.random.get_state()[1].copy()  # noqa: NPY002
    stats.interval_estimates({"a": _scores()}, reps=50, seed=0)
    np.testing.assert_array_equal(np.random.get_state()[1], before)  # noqa: NPY002


def test_interval_estimates_validates_shapes():
    with pytest.raises(ValueError, match=r"shape \(runs, tasks\)"):
        stats.interval_estimates({"a": np.ones(5)}, reps=10)
    with pytest.raises(ValueError, match="reps must be a positive integer"):
        stats.interval_estimates({"a": np.ones((5, 1))}, reps=0)


def test_reps_default_from_budget(monkeypatch):
    monkeypatch.setenv("VSLBOOK_BUDGET", "smoke")
    point, ci = stats.interval_estimates({"a": _scores()})
    assert ci["a"].shape == (2, 1)


# --------------------------------------------------------------------------- IQM curves


def test_iqm_curve_shape_columns_and_monotone():
    df = _curves()
    start = time.perf_counter()
    curve = stats.iqm_curve(df, reps=2000, seed=0)
    assert time.perf_counter() - start < 1.5
    assert list(curve.columns) == ["env_steps", "iqm", "lo", "hi", "n_runs"]
    assert len(curve) == 42 and (curve["n_runs"] == 10).all()
    assert curve["env_steps"].is_monotonic_increasing
    assert (curve["lo"] <= curve["iqm"] + 1e-12).all()
    assert (curve["iqm"] <= curve["hi"] + 1e-12).all()
    # every run increases, so the IQM and both bounds increase too
    for column in ("iqm", "lo", "hi"):
        assert (np.diff(curve[column]) >= 0).all(), column
    pd.testing.assert_frame_equal(curve, stats.iqm_curve(df, reps=2000, seed=0))


def test_iqm_curve_point_matches_iqm_and_rliable_interval():
    df = _curves()
    curve = stats.iqm_curve(df, reps=2000, seed=0)
    last = df[df["env_steps"] == df["env_steps"].max()]["mean_return"].to_numpy()
    assert curve["iqm"].iloc[-1] == pytest.approx(stats.iqm(last))
    _, ci = stats.interval_estimates({"x": last.reshape(-1, 1)}, reps=2000, seed=0)
    width = ci["x"][1, 0] - ci["x"][0, 0]
    assert curve["lo"].iloc[-1] == pytest.approx(ci["x"][0, 0], abs=0.15 * width)
    assert curve["hi"].iloc[-1] == pytest.approx(ci["x"][1, 0], abs=0.15 * width)


def test_iqm_curve_groups_and_missing_runs():
    df = pd.concat(
        [_curves(points=5).assign(env="a"), _curves(points=5, offset=10).assign(env="b")]
    )
    df = df[~((df["env"] == "b") & (df["seed"] == 0) & (df["env_steps"] == 0))]
    curve = stats.iqm_curve(df, group="env", reps=200)
    assert list(curve.columns) == ["env", "env_steps", "iqm", "lo", "hi", "n_runs"]
    assert len(curve) == 10
    assert curve.loc[(curve["env"] == "b") & (curve["env_steps"] == 0), "n_runs"].item() == 9
    assert (curve.loc[curve["env"] == "b", "iqm"] > 9).all()
    # a group's band does not depend on which other groups are present
    alone = stats.iqm_curve(df[df["env"] == "a"], group="env", reps=200)
    pd.testing.assert_frame_equal(alone, curve[curve["env"] == "a"].reset_index(drop=True))


def test_iqm_curve_errors():
    df = _curves(points=3)
    with pytest.raises(ValueError, match=r"\['score'\] not in the frame"):
        stats.iqm_curve(df, y="score", reps=10)
    with pytest.raises(ValueError, match="more than one"):
        stats.iqm_curve(pd.concat([df, df.iloc[:1]]), reps=10)


# --------------------------------------------------------------------------- profiles


def test_performance_profile_seeded_and_restores_global_rng():
    scores = {"a": _scores(0), "b": _scores(1) + 0.5}
    taus = np.linspace(-2, 2, 9)
    np.random.seed(7)  # noqa: NPY002 - checking that the global RNG is restored
    expected = np.random.rand(3)  # noqa: NPY002
    np.random.seed(7)  # noqa: NPY002
    profiles, cis = stats.performance_profile(scores, taus, reps=100, seed=1)
    np.testing.assert_array_equal(np.random.rand(3), expected)  # noqa: NPY002
    assert profiles["a"].shape == (9,) and cis["a"].shape == (2, 9)
    assert (np.diff(profiles["a"]) <= 0).all()
    _, cis2 = stats.performance_profile(scores, taus, reps=100, seed=1)
    np.testing.assert_array_equal(cis["b"], cis2["b"])


# --------------------------------------------------------------------------- final scores


def test_final_scores_matrix():
    df = pd.concat(
        [_curves(points=4).assign(env="a"), _curves(points=6, offset=1).assign(env="b")]
    )
    table = stats.final_scores(df)
    assert table.shape == (10, 2) and list(table.columns) == ["a", "b"]
    last_b = df[(df["env"] == "b") & (df["env_steps"] == 5 * 24_000)]
    np.testing.assert_allclose(table["b"].to_numpy(), last_b.sort_values("seed")["mean_return"])
    point, _ = stats.interval_estimates({"m": table}, reps=20)
    assert point["m"].shape == (1,)
    with pytest.raises(ValueError, match="unknown task"):
        stats.final_scores(df, tasks=["c"])
    incomplete = df[~((df["env"] == "a") & (df["seed"] == 2) & (df["env_steps"] == 72_000))]
    with pytest.raises(ValueError, match=r"task 'a': run\(s\) \[2\]"):
        stats.final_scores(incomplete)

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


TINY = dict(
    total_steps=100_000,  # -> 200 env steps (one Pendulum episode) at the smoke budget
    learning_starts=0,
    critic_hidden=16,
    actor_hidden=16,
    n_diffusion_steps=2,
    batch_size=16,
    eval_every=100_000,
    eval_episodes=1,
    v_min=-1600.0,
    v_max=100.0,
    num_threads=1,
)


def test_run_variants_labels_rows_and_reloads_agents(tmp_path):
    import torch

    from vslbook.experiments.dime_runs import load_agent, run_variants

    out = run_variants(
        "Pendulum-v1",
        {"a": ("dime", {}), "b": ("dime-gaussian", {"fixed_alpha": 0.5})},
        seeds=2,
        budget="smoke",
        root=tmp_path / "runs",
        tables=tmp_path / "tables",
        common=TINY,
        progress=False,
    )
    assert sorted(out.runs) == ["a", "b"] and all(len(r) == 2 for r in out.runs.values())
    rows = out.curve_rows()
    assert set(rows.variant) == {"a", "b"}
    assert rows.groupby("variant").run.nunique().to_dict() == {"a": 2, "b": 2}
    # the table on disk is the one returned (read back through the sha256 registry)
    assert (tmp_path / "tables" / "registry.json").exists()
    with pytest.raises(ValueError, match="no metric 'nope'"):
        out.curve_rows("nope")

    agent, env = load_agent(out.runs["b"][1])
    assert agent.alpha.item() == pytest.approx(0.5)
    obs, _ = env.reset(seed=0)
    with torch.no_grad():
        action = agent.policy(torch.as_tensor(obs[None], dtype=torch.float32)).action
    assert action.shape == (1, 1) and torch.all(action.abs() <= 1)


def test_run_variants_rejects_bad_arguments(tmp_path):
    from vslbook.experiments.dime_runs import run_variants

    with pytest.raises(ValueError, match="seeds must be an integer >= 1, got 0"):
        run_variants("Pendulum-v1", {"a": ("dime", {})}, seeds=0, root=tmp_path, tables=tmp_path)
    with pytest.raises(ValueError, match="variants is empty"):
        run_variants("Pendulum-v1", {}, seeds=1, root=tmp_path, tables=tmp_path)


@pytest.mark.parametrize(
    ("budget", "env_steps", "seeds"),
    [("smoke", {"ablations": 5_050, "pointmass": 5_050}, 2),
     ("reduced", {"ablations": 15_000, "pointmass": 10_000}, 3),
     ("full", {"ablations": 100_000, "pointmass": 100_000}, 10)],
)  # fmt: skip
def test_chapter5_run_sets_scale_counts_only(budget, env_steps, seeds):
    from vslbook.budget import get_budget
    from vslbook.experiments.dime_runs import chapter5_run_sets
    from vslbook.registry import config_from_record, get_algorithm
    from vslbook.srl.dime_config import named_config

    b = get_budget(budget)
    sets = chapter5_run_sets(budget)
    assert list(sets) == ["cheetah", "ablations", "pointmass"]
    # each set's length at this budget, as the training loop scales it
    for name, steps in env_steps.items():
        assert b.scale(sets[name].common["total_steps"]) == steps
    assert sets["cheetah"].common["total_steps"] == 1_000_000  # the thesis's count
    assert sets["cheetah"].seeds == sets["ablations"].seeds == b.seeds == seeds
    assert sets["pointmass"].seeds == 1
    # the networks are the named configurations, whatever the budget
    for name, config in (("cheetah", "cpu-256"), ("ablations", "cpu-64"), ("pointmass", "cpu-64")):
        assert named_config(config).items() <= sets[name].common.items()
    # every variant's overrides make a valid config of its algorithm
    for run_set in sets.values():
        for algo, overrides in run_set.variants.values():
            spec = get_algorithm(algo)
            config_from_record(spec.config, {**run_set.common, **overrides})

"""Chapter 5's live run sets are registered figures (:mod:`vslbook.experiments.ch5_runs`):
the runs each declares are the run directories the notebook's run sets train, ``vslbook
plan`` lists them, and a recorded set is drawn back as the runs that were recorded.
Trained once: Fig. 5.7's three smoke runs (one seed per α, 5050 environment steps)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from vslbook.budget import get_budget
from vslbook.cli import main
from vslbook.experiments.ch5_runs import FIGURES, METRIC, chapter5_figure, figure_runs, set_string
from vslbook.experiments.dime_runs import chapter5_run_sets, load_agent
from vslbook.experiments.figure_sources import SMOKE_VERDICT
from vslbook.experiments.record import figure_metric, record
from vslbook.experiments.run_plan import FIGURE_MODULES
from vslbook.results import RunDir
from vslbook.training import run_name

FIGURE, BUDGET = "fig5-7", "smoke"


@pytest.fixture(autouse=True)
def _default_sources(monkeypatch):
    """The notebook's default named configurations, and no source chosen by the caller."""
    for var in ("VSLBOOK_DIME_CONFIG", "VSLBOOK_SOURCE", "VSLBOOK_RETRAIN", "VSLBOOK_BUDGET"):
        monkeypatch.delenv(var, raising=False)


@pytest.mark.parametrize("budget", ["smoke", "reduced"])
@pytest.mark.parametrize("figure", sorted(FIGURES))
def test_declared_runs_are_the_runs_the_run_sets_train(figure, budget):
    # run_variants trains run(algo, env, seed, budget, overrides={**common, **variant's})
    b = get_budget(budget)
    rs = chapter5_run_sets(b)[FIGURES[figure]]
    expected = [(label, run_name(algo, rs.env, seed, b, overrides={**rs.common, **own}))
                for label, (algo, own) in rs.variants.items() for seed in range(rs.seeds)]
    runs = figure_runs(figure, b)
    assert [(r.method, r.name) for r in runs] == expected
    assert FIGURE_MODULES[figure] == "vslbook.experiments.ch5_runs"
    assert figure_metric(figure) == METRIC[figure] == "eval_return"
    assert all(r.unit == "step" and r.budget == b.name for r in runs)
    assert all(r.words == "env steps" for r in runs)  # DIME's step counts env steps
    assert all(isinstance(v, str) for r in runs for v in r.overrides.values())


def test_lengths_are_the_environment_steps_of_the_budget():
    lengths = {f: {r.length for r in figure_runs(f, "smoke")} for f in FIGURES}
    assert lengths == {"fig5-3-cheetah": {2_000}, "fig5-ablations": {5_050}, "fig5-7": {5_050}}
    assert {r.length for r in figure_runs("fig5-7", "reduced")} == {10_000}
    assert len(figure_runs("fig5-ablations", "full")) == 8 * 10  # 8 variants, 10 seeds
    assert (set_string(True), set_string(False), set_string(0.01)) == ("true", "false", "0.01")


def test_a_named_configuration_for_every_set_changes_the_runs(monkeypatch):
    small = figure_runs(FIGURE, BUDGET)
    monkeypatch.setenv("VSLBOOK_DIME_CONFIG", "thesis")
    thesis = figure_runs(FIGURE, BUDGET)
    assert "critic_hidden" not in thesis[0].overrides
    assert {r.name for r in small}.isdisjoint(r.name for r in thesis)


def test_the_command_line_names_the_runs_plan_lists(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("VSLBOOK_DATA", str(tmp_path / "data"))
    runs = figure_runs(FIGURE, BUDGET)
    assert main(["plan", FIGURE, "--budget", BUDGET, "--root", str(tmp_path)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[:-1] == [f"missing  {r.name}" for r in runs]
    assert lines[-1].endswith(f"{len(runs)} runs not yet timed (train one of each method to "
                              "estimate them)")  # fmt: skip
    r = runs[-1]
    argv = ["run", r.algo, "--env", r.env, "--seed", str(r.seed), "--budget", BUDGET,
            "--dry-run", "--root", str(tmp_path)]  # fmt: skip
    argv += [f"--set={k}={v}" for k, v in r.overrides.items()]
    assert main(argv) == 0
    assert capsys.readouterr().out.strip() == r.name
    assert r.command(tmp_path).startswith(f"vslbook run dime --env {r.env} --seed 0 --budget smoke")


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """Fig. 5.7's runs trained by the notebook's call, at the smoke budget."""
    base = tmp_path_factory.mktemp("ch5")
    with pytest.MonkeyPatch.context() as mp:
        for var in ("VSLBOOK_DIME_CONFIG", "VSLBOOK_SOURCE", "VSLBOOK_RETRAIN"):
            mp.delenv(var, raising=False)
        mp.setenv("VSLBOOK_DATA", str(base / "data"))
        fs, pm = chapter5_figure(FIGURE, base / "runs", base / "tables", budget=BUDGET,
                                 mode="budget", progress=False)  # fmt: skip
    return base / "runs", fs, pm


def test_runs_trained_now_are_the_declared_ones(trained):
    root, fs, pm = trained
    runs = figure_runs(FIGURE, BUDGET)
    assert (fs.budget, fs.smoke, fs.recorded) == (BUDGET, True, {})
    assert fs.trained == [r.name for r in runs]
    assert list(pm.runs) == [r.method for r in runs] == ["α = 0.01", "α = 1", "α = 5"]
    assert all(rd.done for rds in pm.runs.values() for rd in rds)
    assert set(pm.evals["variant"]) == set(pm.runs)
    assert pm.curve_rows().groupby("run").step.max().eq(5_050).all()
    assert fs.verdict("as in the thesis") == SMOKE_VERDICT
    assert "1 seed" in pm.captions() and "smoke: code path only" in fs.caption()


def test_recorded_runs_are_drawn_back_as_trained(trained, tmp_path, monkeypatch, capsys):
    root, fs, pm = trained
    monkeypatch.setenv("VSLBOOK_DATA", str(tmp_path / "data"))
    copy = Path(shutil.copytree(root, tmp_path / "runs"))
    assert len(record(FIGURE, BUDGET, copy).recorded) == 3
    empty = tmp_path / "fresh-clone-runs"
    empty.mkdir()
    assert main(["plan", FIGURE, "--budget", BUDGET, "--root", str(empty)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[:-1] == [f"recorded {r.name}" for r in figure_runs(FIGURE, BUDGET)]
    back_fs, back = chapter5_figure(FIGURE, empty, tmp_path / "tables", mode="best",
                                    progress=False)  # fmt: skip
    assert not any(empty.iterdir())  # nothing trained
    assert (back_fs.budget, back_fs.trained) == (BUDGET, [])
    assert sorted(back_fs.recorded) == sorted(fs.trained)
    assert "recorded" in back_fs.caption() and back_fs.verdict("x") == SMOKE_VERDICT

    def returns(vr):
        rows = vr.curve_rows()
        return rows.set_index(["variant", "step"]).value.sort_index().tolist()

    assert returns(back) == returns(pm)
    for label in pm.runs:  # the figure's value maps load the recorded final checkpoint
        a, _ = load_agent(back.runs[label][0])
        b, _ = load_agent(RunDir(root / pm.runs[label][0].name))
        assert all(x.equal(y) for x, y in zip(a.critic.state_dict().values(),
                                              b.critic.state_dict().values(), strict=True))

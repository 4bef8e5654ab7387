"""Each figure's runs are declared once: ``vslbook run --dry-run`` names the runs ``vslbook
plan`` lists, for every registered figure and budget, and ``plan`` reads a root's state."""

from __future__ import annotations

import json
import math
import re

import pytest

from vslbook.cli import main
from vslbook.experiments.run_plan import FIGURE_MODULES, FigureRun, figure_runs, plan, plan_text


@pytest.mark.parametrize("budget", ["smoke", "reduced", "full"])
@pytest.mark.parametrize("figure", sorted(FIGURE_MODULES))
def test_dry_runs_name_the_runs_plan_lists(figure, budget, capsys, tmp_path):
    runs = figure_runs(figure, budget)
    assert runs and len({r.name for r in runs}) == len(runs)  # no run listed twice
    capsys.readouterr()
    assert main(["plan", figure, "--budget", budget, "--root", str(tmp_path)]) == 0
    listed = [line.split()[1] for line in capsys.readouterr().out.splitlines()[:-1]]
    dry = []
    for r in runs:
        argv = ["run", r.algo, "--env", r.env, "--seed", str(r.seed), "--budget", budget,
                "--dry-run", "--root", str(tmp_path)]  # fmt: skip
        argv += [f"--set={k}={v}" for k, v in r.overrides.items()]
        assert main(argv) == 0
        dry.append(capsys.readouterr().out.strip())
    assert dry == listed == [r.name for r in runs]
    assert not any(tmp_path.iterdir())  # neither wrote anything


def test_the_command_line_trains_the_run_the_figure_draws():
    # Fig. 4.3c at reduced: 300 iterations of 10 experts, as the notebook's panel
    from vslbook.budget import get_budget
    from vslbook.registry import get_algorithm

    run = next(r for r in figure_runs("fig4-3c", "reduced") if r.method == "diskill")
    config = get_algorithm("diskill").default_config(run.env, get_budget("reduced"), {})
    assert (run.length, config.iterations, config.n_experts) == (300, 300, 10)
    assert len([r for r in figure_runs("fig4-3c", "full") if r.method == "diskill"]) == 24


def test_plan_reads_the_state_of_each_run(tmp_path, monkeypatch):
    monkeypatch.setenv("VSLBOOK_WORKERS", "1")
    monkeypatch.setenv("VSLBOOK_DATA", str(tmp_path / "data"))  # no recorded times
    runs = figure_runs("fig4-4a", "smoke")
    first = runs[0]
    first.train(tmp_path)
    rows = plan("fig4-4a", "smoke", tmp_path)
    assert [r.state for r in rows] == ["done"] + ["missing"] * (len(runs) - 1)
    assert rows[0].progress == first.length and rows[0].seconds_per_unit > 0
    text = plan_text(rows)
    assert text.splitlines()[0] == f"done     {first.name}"
    assert text.splitlines()[-1].endswith("not yet timed (train one of each method to estimate "
                                          "them)")  # fmt: skip
    with pytest.raises(ValueError, match="figure 'fig9-9' declares no runs; expected one of"):
        figure_runs("fig9-9")
    # made by other code: its state and progress stand, with a note (a replay decides)
    env_path = tmp_path / first.name / "env.json"
    env = json.loads(env_path.read_text())
    env["code_hash"] = "0" * 64
    env_path.write_text(json.dumps(env))
    row = plan("fig4-4a", "smoke", tmp_path)[0]
    assert (row.state, row.progress) == ("done", first.length)
    assert plan_text([row]).splitlines()[0] == (
        f"done     {first.name} (code changed: replayed when resumed or recorded)")


def test_plan_estimates_from_the_recent_mean_cost(tmp_path, monkeypatch):
    """A partial run's hours left: its remaining iterations times the mean of its last
    quarter's logged iteration seconds (rare costly iterations count; costs that grow, as
    SVSL's with each expert added, are taken where they are now); a missing run of the same
    method: the mean over every logged iteration of its method's runs."""
    monkeypatch.setenv("VSLBOOK_DATA", str(tmp_path / "data"))  # no recorded times
    runs = figure_runs("fig4-4a", "reduced")  # three seeds of each method
    first, second = runs[0], next(r for r in runs[1:] if r.algo == runs[0].algo)
    times = [1.0] * 9 + [2.0, 3.0, 7.0]  # the last quarter: mean 4 s (median 3 s)
    _partial_run(tmp_path, first, [{"step": i + 1, "iteration_seconds": t}
                                   for i, t in enumerate(times)])  # fmt: skip
    rows = {r.run.name: r for r in plan("fig4-4a", "reduced", tmp_path)}
    mine = rows[first.name]
    assert (mine.state, mine.progress, mine.seconds_per_unit) == ("partial", 12, 4.0)
    assert mine.hours_left == pytest.approx((first.length - 12) * 4.0 / 3600)
    assert rows[second.name].seconds_per_unit == pytest.approx(sum(times) / len(times))


def test_plan_keeps_only_the_runs_asked_for(capsys, tmp_path, monkeypatch):
    # no recorded results to time the runs with (data/results has Fig. 4.4a at full)
    monkeypatch.setenv("VSLBOOK_DATA", str(tmp_path / "data"))
    runs = figure_runs("fig4-4a", "reduced")
    wanted = [r.name for r in runs if r.seed in (0, 2) and r.method == "bbrl"]
    assert len(wanted) == 2
    capsys.readouterr()
    assert main(["plan", "fig4-4a", "--budget", "reduced", "--root", str(tmp_path),
                 "--seeds", "0", "2", "--methods", "BBRL"]) == 0  # fmt: skip
    lines = capsys.readouterr().out.splitlines()
    assert [line.split()[1] for line in lines[:-1]] == wanted
    assert lines[-1] == "0.0 core-hours left for 0 runs; 2 runs not yet timed (train one of " \
                        "each method to estimate them)"
    assert main(["plan", "fig4-4a", "--budget", "reduced", "--root", str(tmp_path),
                 "--methods", "sac"]) == 2  # fmt: skip
    assert "vslbook: error: fig4-4a at reduced draws no method 'sac'; expected one of" in \
        capsys.readouterr().err


def test_progress_names_the_unit_in_words():
    """A probe's progress reads "900/4500 iterations" (unit ``step``: one metrics row per
    iteration) or "24000/50000 env steps"; an unknown unit is printed as it is."""
    run = FigureRun("fig4-4c", "diskill", "diskill", "vslbook/TableTennisHard-v0", 0, "full",
                    4500)  # fmt: skip
    assert run.progress(900) == "900/4500 iterations"
    dime = FigureRun("fig5-3", "dime", "dime", "dm_control/cheetah-run-v0", 0, "full", 50_000,
                     unit="env_steps")  # fmt: skip
    assert dime.progress(24_000) == "24000/50000 env steps"
    assert FigureRun("f", "m", "a", "e", 0, "smoke", 2, unit="episodes").progress(1) == (
        "1/2 episodes")


def _partial_run(root, run, rows, saved=None):
    """A run directory with a config, ``rows`` of metrics and a checkpoint saved after the
    first ``saved`` of them (default all): ``partial``."""
    from vslbook.results import RunDir

    path = root / run.name
    path.mkdir()
    (path / "config.json").write_text(json.dumps({"algo": run.algo, "env": run.env}))
    line = [json.dumps(r) + "\n" for r in rows]
    saved = len(rows) if saved is None else saved
    (path / "metrics.jsonl").write_text("".join(line[:saved]))
    RunDir(path).save_checkpoint({})
    with open(path / "metrics.jsonl", "a", encoding="utf-8") as fh:
        fh.write("".join(line[saved:]))


def test_plan_counts_progress_to_the_checkpoint(tmp_path, monkeypatch):
    """A partial run resumes from its checkpoint: the rows logged after it are dropped, so
    its progress (and hours left) count the iterations the checkpoint saved; they still
    time the run. Without a checkpoint, it starts again from 0."""
    from vslbook.experiments.train_figure import checkpoint_step

    monkeypatch.setenv("VSLBOOK_DATA", str(tmp_path / "data"))
    first, second = figure_runs("fig4-4a", "reduced")[:2]
    _partial_run(tmp_path, first, [{"step": i + 1, "iteration_seconds": 2.0}
                                   for i in range(10)], saved=6)  # fmt: skip
    row = next(r for r in plan("fig4-4a", "reduced", tmp_path) if r.run.name == first.name)
    assert (row.state, row.progress, row.seconds_per_unit) == ("partial", 6, 2.0)
    assert row.hours_left == pytest.approx((first.length - 6) * 2.0 / 3600)
    assert checkpoint_step(tmp_path / first.name) == 6
    assert f"{first.name} (6/{first.length} iterations" in plan_text([row])
    (tmp_path / second.name).mkdir()
    (tmp_path / second.name / "config.json").write_text("{}")
    (tmp_path / second.name / "metrics.jsonl").write_text('{"step": 1}\n')
    row = next(r for r in plan("fig4-4a", "reduced", tmp_path) if r.run.name == second.name)
    assert (row.state, row.progress) == ("partial", 0)
    assert checkpoint_step(tmp_path / second.name) == 0


def test_plan_times_runs_counted_in_env_steps_by_their_step_rate(tmp_path, monkeypatch):
    """A DIME run's ``step`` counts env steps and its rows log no ``iteration_seconds``:
    its seconds per env step are the inverse of each row's ``env_steps_per_s``, and its
    progress reads in env steps; a PPO run (column ``env_steps``) is timed the same way."""
    monkeypatch.setenv("VSLBOOK_DATA", str(tmp_path / "data"))  # no recorded times
    dime = figure_runs("fig5-ablations", "smoke")[0]
    assert dime.words == "env steps"
    rates = [250.0, 500.0, 1000.0, 125.0]  # the last quarter: one row, 1/125 s per step
    _partial_run(tmp_path, dime, [{"step": 100 * (i + 1), "env_steps_per_s": v}
                                  for i, v in enumerate(rates)])  # fmt: skip
    rows = {r.run.name: r for r in plan("fig5-ablations", "smoke", tmp_path)}
    mine = rows[dime.name]
    assert (mine.state, mine.progress) == ("partial", 400)
    assert mine.seconds_per_unit == pytest.approx(0.008)
    assert mine.hours_left == pytest.approx((dime.length - 400) * 0.008 / 3600)
    same = [r for r in rows.values() if r.run.algo == dime.algo and r.run.name != dime.name
            and r.run.overrides == dime.overrides]  # fmt: skip
    # its other seeds: the mean over every row, (4 + 2 + 1 + 8) / 4 ms
    assert same and all(r.seconds_per_unit == pytest.approx(0.00375) for r in same)
    assert f"{dime.name} (400/{dime.length} env steps" in plan_text([mine])

    ppo = next(r for r in figure_runs("fig4-3c", "reduced") if r.algo == "ppo-ch4")
    assert (ppo.unit, ppo.words) == ("env_steps", "env steps")
    _partial_run(tmp_path, ppo, [{"env_steps": 2048, "env_steps_per_s": 512.0}])
    row = next(r for r in plan("fig4-3c", "reduced", tmp_path) if r.run.name == ppo.name)
    assert (row.progress, row.seconds_per_unit) == (2048, pytest.approx(1 / 512))


def test_plan_does_not_time_iterations_by_a_step_rate(tmp_path, monkeypatch):
    """An iteration-counted run whose rows carry only a step rate is not timed with it."""
    monkeypatch.setenv("VSLBOOK_DATA", str(tmp_path / "data"))
    run = figure_runs("fig4-4a", "reduced")[0]
    assert run.words == "iterations"
    _partial_run(tmp_path, run, [{"step": 1, "env_steps_per_s": 100.0}])
    row = next(r for r in plan("fig4-4a", "reduced", tmp_path) if r.run.name == run.name)
    assert row.state == "partial" and math.isnan(row.seconds_per_unit)


def test_plan_of_probes_trains_each_run_to_the_iteration_asked(tmp_path, monkeypatch):
    """``plan(until=N)`` plans what ``vslbook train --until N`` trains: runs counted in
    iterations to min(N, length), runs counted in env steps not at all."""
    monkeypatch.setenv("VSLBOOK_DATA", str(tmp_path / "data"))
    first = figure_runs("fig4-4a", "reduced")[0]
    _partial_run(tmp_path, first, [{"step": i + 1, "iteration_seconds": 3.0}
                                   for i in range(6)])  # fmt: skip
    mine = {u: next(r for r in plan("fig4-4a", "reduced", tmp_path, until=u)
                    if r.run.name == first.name) for u in (10, 6, 10_000)}  # fmt: skip
    assert (mine[10].end, mine[10].hours_left) == (10, pytest.approx(4 * 3.0 / 3600))
    assert mine[6].hours_left == 0.0 and not mine[6].to_train
    assert mine[10_000].end == first.length
    assert f"{first.name} (6/{first.length} iterations; probe to 10" in plan_text([mine[10]])
    assert "probe to" not in plan_text([mine[6]])  # reached
    assert plan_text([mine[6]]).splitlines()[-1] == "nothing left to train"
    assert plan_text([mine[10]]).splitlines()[-1] == (
        "0.0 core-hours left for 1 runs (probes to iteration 10)")
    ppo = next(r for r in plan("fig4-3c", "reduced", tmp_path, until=10)
               if r.run.algo == "ppo-ch4")  # fmt: skip
    assert (ppo.hours_left, ppo.to_train) == (0.0, False)
    assert ppo.note == "--until counts iterations, not env steps"
    for bad in (0, -3, 2.5, "900"):
        with pytest.raises(ValueError, match=rf"until must be an iteration \(an integer >= 1\), "
                                             rf"got {re.escape(repr(bad))}"):  # fmt: skip
            plan("fig4-4a", "reduced", tmp_path, until=bad)


def test_plan_command_plans_probes(capsys, tmp_path, monkeypatch):
    """``vslbook plan --until N`` prints what ``plan(until=N)`` plans; a bad N is one error
    line naming it."""
    monkeypatch.setenv("VSLBOOK_DATA", str(tmp_path / "data"))
    first = figure_runs("fig4-4a", "reduced")[0]
    _partial_run(tmp_path, first, [{"step": i + 1, "iteration_seconds": 3.0}
                                   for i in range(6)])  # fmt: skip
    capsys.readouterr()
    argv = ["plan", "fig4-4a", "--budget", "reduced", "--root", str(tmp_path),
            "--seeds", str(first.seed), "--methods", first.method]  # fmt: skip
    assert main([*argv, "--until", "10"]) == 0
    out = capsys.readouterr().out
    assert out.strip() == plan_text([r for r in plan("fig4-4a", "reduced", tmp_path, until=10)
                                     if r.run.name == first.name])  # fmt: skip
    assert f"{first.name} (6/{first.length} iterations; probe to 10" in out
    assert out.splitlines()[-1] == "0.0 core-hours left for 1 runs (probes to iteration 10)"
    assert main([*argv, "--until", "0"]) == 2
    assert capsys.readouterr().err.strip() == (
        "vslbook: error: until must be an iteration (an integer >= 1), got 0")

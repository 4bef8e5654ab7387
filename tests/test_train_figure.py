"""``vslbook train FIGURE``: a figure's runs, several processes at once, each exactly the
run ``vslbook run`` trains; finished runs reused, held runs skipped."""

from __future__ import annotations

import pytest

from vslbook.cli import main
from vslbook.experiments.run_plan import figure_runs, plan
from vslbook.experiments.train_figure import select_runs, train_figure
from vslbook.run_lock import RunLock

FIGURE, BUDGET = "fig4-4a", "smoke"


def test_select_runs_filters_and_names_bad_input():
    runs = figure_runs(FIGURE, BUDGET)
    methods = sorted({r.method for r in runs})
    picked = select_runs(FIGURE, BUDGET, methods=[methods[0].upper()])
    assert picked and {r.method for r in picked} == {methods[0]}
    assert select_runs(FIGURE, BUDGET, seeds=[0]) == [r for r in runs if r.seed == 0]
    with pytest.raises(ValueError, match=r"fig4-4a at smoke draws no seed 7; expected one of 0"):
        select_runs(FIGURE, BUDGET, seeds=[7])
    with pytest.raises(ValueError, match=r"draws no method 'nope'; expected one of "):
        select_runs(FIGURE, BUDGET, methods=["nope"])
    with pytest.raises(ValueError, match=r"draws no env 'vslbook/X-v0'"):
        select_runs(FIGURE, BUDGET, envs=["vslbook/X-v0"])


def test_train_two_at_once_skips_a_held_run_then_reuses(tmp_path, capsys):
    runs = figure_runs(FIGURE, BUDGET)
    held = tmp_path / runs[1].name
    held.mkdir(parents=True)
    lines: list[str] = []
    with RunLock(held).acquire():  # another process trains this run
        results = train_figure(runs, tmp_path, jobs=2, report=lines.append)
    states = {r.run.name: r.state for r in results}
    assert states == {r.name: ("skipped" if r is runs[1] else "done") for r in runs}
    assert any(line.startswith(f"skipped  {runs[1].name}  (") for line in lines)
    assert [row.state for row in plan(FIGURE, BUDGET, tmp_path)] == [
        "missing" if r is runs[1] else "done" for r in runs]  # fmt: skip
    # again from the command line: the held run now trains, the others are reused
    capsys.readouterr()
    assert main(["train", FIGURE, "--budget", BUDGET, "--root", str(tmp_path),
                 "--jobs", "2"]) == 0  # fmt: skip
    out = capsys.readouterr().out.splitlines()
    assert sorted(out) == sorted(f"done     {r.name}" for r in runs)
    assert {row.state for row in plan(FIGURE, BUDGET, tmp_path)} == {"done"}


def test_dry_run_and_bad_jobs(tmp_path, capsys):
    capsys.readouterr()
    assert main(["train", FIGURE, "--budget", BUDGET, "--seeds", "0", "--dry-run"]) == 0
    assert capsys.readouterr().out.split() == [r.name for r in select_runs(FIGURE, BUDGET)]
    with pytest.raises(ValueError, match="jobs must be a positive integer, got 0"):
        train_figure([], tmp_path, jobs=0)
    assert main(["train", FIGURE, "--budget", BUDGET, "--jobs", "0",
                 "--root", str(tmp_path)]) == 2  # fmt: skip
    assert "jobs must be a positive integer" in capsys.readouterr().err

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


def _rows(path) -> list[dict]:
    """A run's rows without their wall times (which differ between any two runs)."""
    import json

    rows = [json.loads(line) for line in (path / "metrics.jsonl").read_text().splitlines()]
    return [{k: v for k, v in r.items() if k != "iteration_seconds"} for r in rows]


def test_until_probes_a_run_and_training_again_continues_it_exactly(tmp_path, capsys):
    from vslbook.experiments.train_figure import checkpoint_step
    from vslbook.results import RunDir

    run = next(r for r in figure_runs(FIGURE, BUDGET) if r.method == "diskill")
    assert run.length == 2
    capsys.readouterr()
    assert main(["train", FIGURE, "--budget", BUDGET, "--root", str(tmp_path / "probe"),
                 "--methods", "diskill", "--until", "1"]) == 0  # fmt: skip
    assert capsys.readouterr().out.split() == ["probed", run.name, "(at", "step", "1", "of",
                                               "2)"]  # fmt: skip
    probe = tmp_path / "probe" / run.name
    assert checkpoint_step(probe) == 1 and not RunDir(probe).done
    # probing again does nothing; training without --until finishes the run
    assert train_figure([run], tmp_path / "probe", until=1)[0].state == "probed"
    assert train_figure([run], tmp_path / "probe")[0].state == "done"
    assert train_figure([run], tmp_path / "whole")[0].state == "done"
    assert _rows(probe) == _rows(tmp_path / "whole" / run.name)
    with pytest.raises(ValueError, match="until must be a positive number of iterations, got 0"):
        train_figure([run], tmp_path, until=0)

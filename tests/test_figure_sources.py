"""A figure draws its runs from ``runs/``, from ``data/results/`` or trains them now
(:mod:`vslbook.experiments.figure_sources`), and a recorded run read back as a run
directory (:mod:`vslbook.experiments.recorded_runs`) is the run that was recorded.
Trained once: Fig. 4.4a's three smoke runs."""

from __future__ import annotations

import json
import numbers
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from vslbook.data import register_file
from vslbook.experiments.diskill_runs import load_model
from vslbook.experiments.figure_sources import (
    PROBE_VERDICT,
    SMOKE_VERDICT,
    FigureSet,
    figure_set,
    source_mode,
)
from vslbook.experiments.record import record, recorded_dir
from vslbook.experiments.recorded_runs import materialise, metric_rows
from vslbook.experiments.run_plan import figure_runs
from vslbook.results import RunDir

FIGURE, BUDGET = "fig4-4a", "smoke"


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    root = tmp_path_factory.mktemp("sources") / "runs"
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("VSLBOOK_WORKERS", "1")
        for run in figure_runs(FIGURE, BUDGET):
            run.train(root)
    return root


@pytest.fixture
def recorded(trained, tmp_path, monkeypatch):
    """The runs recorded into an empty ``$VSLBOOK_DATA``; returns the trained root."""
    monkeypatch.setenv("VSLBOOK_DATA", str(tmp_path / "data"))
    for var in ("VSLBOOK_SOURCE", "VSLBOOK_RETRAIN", "VSLBOOK_BUDGET"):
        monkeypatch.delenv(var, raising=False)
    root = Path(shutil.copytree(trained, tmp_path / "runs"))
    report = record(FIGURE, BUDGET, root)
    assert len(report.recorded) == len(figure_runs(FIGURE, BUDGET))
    return root


def _numeric_rows(path: Path) -> list[dict]:
    """The run's own rows with only their numeric fields (what a recorded set keeps)."""
    out = []
    for line in (path / "metrics.jsonl").read_text().splitlines():
        row = json.loads(line)
        kept = {k: v for k, v in row.items() if k != "step"
                and (v is None or (isinstance(v, numbers.Real) and not isinstance(v, bool)))}
        if kept:
            out.append({"step": row["step"], **kept})
    return out


def _same(a, b) -> bool:
    """Nested state dicts hold equal tensors and values."""
    import torch

    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, torch.Tensor):
        return a.equal(b)
    return bool(np.array_equal(a, b)) if isinstance(a, np.ndarray) else a == b


def test_materialised_runs_hold_the_recorded_rows(recorded):
    paths = materialise(FIGURE, BUDGET)
    assert sorted(paths) == sorted(r.name for r in figure_runs(FIGURE, BUDGET))
    for name, path in paths.items():
        rd = RunDir.open(path)
        rd.check_done()  # DONE covers exactly the rows written back
        assert rd.metrics() == _numeric_rows(recorded / name)
        assert rd.config == RunDir(recorded / name).config
        assert rd.config_hash == RunDir(recorded / name).config_hash


def test_materialised_checkpoint_loads_the_trained_policy(recorded):
    paths = materialise(FIGURE, BUDGET)
    name = next(r.name for r in figure_runs(FIGURE, BUDGET) if r.method == "diskill")
    ours, theirs = load_model(paths[name]), load_model(recorded / name)
    assert _same(ours.state_dict(), theirs.state_dict())
    # the checkpoint kept is each method's first seed only
    kept = sorted(p.name for p in (recorded_dir(FIGURE, BUDGET) / "checkpoints").glob("*.gz"))
    assert kept == sorted(f"{r.name}.pt.gz" for r in figure_runs(FIGURE, BUDGET) if r.seed == 0)


def test_materialise_is_rewritten_when_the_set_changes(recorded):
    first = materialise(FIGURE, BUDGET)
    name = sorted(first)[0]
    (first[name] / "metrics.jsonl").write_text("")  # a damaged cache is not trusted...
    directory = recorded_dir(FIGURE, BUDGET)
    prov = json.loads((directory / "provenance.json").read_text())
    prov["runs"][name]["recorded"] = "2000-01-01T00:00:00+00:00"
    (directory / "provenance.json").write_text(json.dumps(prov))
    register_file(directory / "provenance.json", "edited")  # ...and a new set is read afresh
    again = materialise(FIGURE, BUDGET)
    assert RunDir.open(again[name]).metrics() == _numeric_rows(recorded / name)
    assert RunDir(again[name]).env["recorded"]["date"].startswith("2000-01-01")


def test_metric_rows_split_where_step_changes_or_names_restart():
    import pandas as pd

    long = pd.DataFrame({"step": [0, 0, 1, 1, 1], "metric": ["a", "b", "b", "a", "c"],
                         "value": [1.0, float("nan"), 2.0, 3.0, 4.0]})  # fmt: skip
    assert metric_rows(long) == [{"step": 0, "a": 1.0, "b": None}, {"step": 1, "b": 2.0},
                                 {"step": 1, "a": 3.0, "c": 4.0}]  # fmt: skip


def test_best_reads_the_recorded_set_when_runs_is_empty(recorded, tmp_path):
    fs = figure_set(FIGURE, root=tmp_path / "empty", mode="best")
    assert fs.budget == "smoke" and not fs.trained
    assert set(fs.recorded) == {r.name for r in figure_runs(FIGURE, BUDGET)}
    assert all(str(p).startswith(str(tmp_path / "build" / "recorded")) for ps in fs.runs.values()
               for p in ps)  # fmt: skip
    assert not (tmp_path / "empty").exists()  # nothing trained
    caption = fs.caption()
    assert "recorded" in caption and "smoke" in caption and "data/results/fig4-4a/smoke" in caption
    assert fs.verdict("Di-SkilL on par with BBRL, as in the thesis") == SMOKE_VERDICT


def test_finished_runs_in_root_win_over_recorded_ones(recorded):
    fs = figure_set(FIGURE, root=recorded, mode="best")
    assert sorted(fs.trained) == sorted(r.name for r in figure_runs(FIGURE, BUDGET))
    assert not fs.recorded and "trained" in fs.caption()
    assert fs.runs["diskill"] == [recorded / n for n in fs.trained if n.startswith("diskill-")]


def test_stale_recorded_runs_are_drawn_with_a_warning(recorded, tmp_path):
    directory = recorded_dir(FIGURE, BUDGET)
    prov = json.loads((directory / "provenance.json").read_text())
    for entry in prov["runs"].values():
        entry["code_hash"], entry["code_hashes_verified"] = "0" * 64, []
    (directory / "provenance.json").write_text(json.dumps(prov))
    register_file(directory / "provenance.json", "edited")
    with pytest.warns(UserWarning, match="changed since"):
        fs = figure_set(FIGURE, root=tmp_path / "empty", mode="best")
    assert len(fs.stale) == len(figure_runs(FIGURE, BUDGET))
    assert "vslbook results --verify" in fs.caption()


def test_budget_mode_trains_what_is_missing(trained, tmp_path, monkeypatch):
    monkeypatch.setenv("VSLBOOK_DATA", str(tmp_path / "data"))
    monkeypatch.setenv("VSLBOOK_WORKERS", "1")
    fs = figure_set(FIGURE, "smoke", tmp_path / "runs", methods=("bbrl",), mode="budget")
    assert list(fs.runs) == ["bbrl"] and fs.trained and not fs.recorded
    assert RunDir.open(fs.runs["bbrl"][0]).done


def test_source_mode_from_the_environment(monkeypatch):
    for var in ("VSLBOOK_SOURCE", "VSLBOOK_RETRAIN", "VSLBOOK_BUDGET"):
        monkeypatch.delenv(var, raising=False)
    assert source_mode() == "best"
    monkeypatch.setenv("VSLBOOK_BUDGET", "smoke")
    assert source_mode() == "budget"
    monkeypatch.setenv("VSLBOOK_RETRAIN", "1")
    assert source_mode() == "retrain"
    monkeypatch.setenv("VSLBOOK_SOURCE", "newest")
    with pytest.raises(ValueError, match="VSLBOOK_SOURCE='newest'; expected one of best"):
        source_mode()


def test_unknown_method_is_named(recorded, tmp_path):
    with pytest.raises(ValueError, match=r"no method\(s\) \['sac'\]"):
        figure_set(FIGURE, root=tmp_path, methods=("sac",), mode="best")


def test_plan_times_an_untrained_method_from_its_recorded_runs(recorded, tmp_path):
    from vslbook.experiments.run_plan import plan, recorded_times

    times = recorded_times(FIGURE, "reduced")  # nothing at reduced: the smoke recording's
    first = figure_runs(FIGURE, BUDGET)[0]
    rows = [json.loads(line) for line in (recorded / first.name / "metrics.jsonl").open()]
    assert times[(first.algo, first.env)] == [r["iteration_seconds"] for r in rows
                                             if r.get("iteration_seconds") is not None]
    hours = [r.hours_left for r in plan(FIGURE, "reduced", tmp_path / "empty")]
    assert all(h > 0 and np.isfinite(h) for h in hours)


def test_a_probe_is_recorded_up_to_its_checkpoint_and_drawn_as_a_probe(tmp_path, monkeypatch,
                                                                        capsys):  # fmt: skip
    from vslbook.cli import main
    from vslbook.experiments.record_results import result_rows

    monkeypatch.setenv("VSLBOOK_DATA", str(tmp_path / "data"))
    monkeypatch.setenv("VSLBOOK_WORKERS", "1")
    root = tmp_path / "runs"
    run = next(r for r in figure_runs(FIGURE, BUDGET) if r.method == "diskill")
    assert main(["train", FIGURE, "--budget", BUDGET, "--root", str(root), "--methods",
                 "diskill", "--until", "1"]) == 0  # fmt: skip
    with (root / run.name / "metrics.jsonl").open("a") as fh:  # a row after the checkpoint
        fh.write(json.dumps({"step": 2, "test_return": 1e9}) + "\n")
    capsys.readouterr()
    assert main(["record", FIGURE, "--budget", BUDGET, "--root", str(root)]) == 0
    assert "not recorded  partial  " + run.name in capsys.readouterr().out
    assert main(["record", FIGURE, "--budget", BUDGET, "--root", str(root), "--partial"]) == 0
    assert f"recorded      {run.name}  (probe: 1/2 iterations)" in capsys.readouterr().out
    fs = figure_set(FIGURE, root=tmp_path / "empty", mode="best", methods=("diskill",))
    probe = fs.runs["diskill"][0]
    assert [r["step"] for r in RunDir(probe).metrics()] == [0, 1]  # up to the checkpoint
    assert not RunDir(probe).done and fs.probes == {run.name: "1/2 iterations"}
    assert "probes, still training: diskill s0 at 1/2 iterations" in fs.caption()
    assert fs.verdict("x") == SMOKE_VERDICT  # smoke first; at full a probe-only set says so
    assert replace(fs, budget="full").verdict("x") == PROBE_VERDICT
    (row,) = [r for r in result_rows([FIGURE]) if r["method"] == "diskill"]
    assert (row["seeds"], row["probes"], row["iqm"]) == (0, 1, None)  # counted, never scored


def test_annotate_puts_the_caption_under_the_figure_in_red_when_stale(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from vslbook.experiments.figure_sources import annotate

    fresh = FigureSet(FIGURE, "full", {"diskill": [tmp_path / "a"]}, recorded={
        "a": {"date": "2026-11-27", "git_sha": "abc1234", "stale": False}})  # fmt: skip
    stale = replace(fresh, recorded={"a": {"date": "2026-11-27", "git_sha": "abc1234",
                                           "stale": True}})  # fmt: skip
    fig = plt.figure(figsize=(6, 4))
    fig.text(0.01, 0.0, "thesis: one line\nthesis: another", va="top")
    annotate(fig, fresh)
    ours = fig.texts[-1]
    assert ours.get_text().startswith("Runs of fig4-4a: recorded (data/results/fig4-4a/full")
    assert ours.get_position()[1] < 0  # below the two lines already at the foot
    annotate(fig, stale)
    assert fig.texts[-1].get_text().startswith("WARNING: recorded by code that has changed")
    assert fig.texts[-1].get_color() == "#b00020"
    plt.close(fig)


def test_a_panel_of_one_run_can_say_it_is_a_probe(tmp_path):
    fs = FigureSet(FIGURE, "full", {"diskill": [tmp_path / "a", tmp_path / "b"]},
                   probes={"b": "900/4500 iterations"})  # fmt: skip
    assert fs.probe_note(tmp_path / "b") == ", probe at 900/4500 iterations"
    assert fs.probe_note(tmp_path / "a") == ""


def test_probes_are_counted_apart_from_seeds_and_never_compared(tmp_path):
    runs = {"diskill": [tmp_path / "d0"], "bbrl": [tmp_path / "b0"],
            "diskill-v2": [tmp_path / "v0", tmp_path / "v1"]}  # fmt: skip
    for seed, name in enumerate(("v0", "v1")):  # the caption reads a probe's seed
        (tmp_path / name).mkdir()
        (tmp_path / name / RunDir.CONFIG).write_text(json.dumps({"seed": seed}))
    fs = FigureSet("fig4-3b", "full", runs, seeds_full=dict.fromkeys(runs, 24),
                   probes={"v0": "900/4500 iterations", "v1": "450/4500 iterations"})  # fmt: skip
    assert [fs.finished(m) for m in ("diskill", "bbrl", "diskill-v2", "svsl")] == [1, 1, 0, 0]
    assert fs.probe_progress() == {"diskill-v2": "900/4500 iterations, 450/4500 iterations"}
    caption = fs.caption()
    assert "seeds diskill 1 of 24, bbrl 1 of 24, diskill-v2 0 of 24 and 2 probes" in caption
    # Fig. 4.3b's thesis reports "at least 4 seeds", not the full budget's 24
    assert "(of the full budget's; the thesis's had at least 4)" in caption
    assert "(of the thesis's, the full budget's)" in replace(fs, figure="fig4-3c").caption()
    assert ("probes, still training: v0 s0 at 900/4500 iterations, v1 s1 at 450/4500 "
            "iterations") in caption
    # a pair with a probe in it is not compared; a pair of finished runs is
    assert fs.verdict("as in the thesis", ("diskill", "diskill-v2")) == PROBE_VERDICT
    assert fs.verdict("as in the thesis", ("diskill", "bbrl")) == "as in the thesis"
    assert fs.verdict("as in the thesis") == "as in the thesis"  # not every run a probe
    one = replace(fs, probes={"v0": "900/4500 iterations"})
    assert "diskill-v2 1 of 24 and 1 probe" in one.caption()
    # a panel's title: the range of finished seeds over the methods that have one
    assert fs.seeds_phrase() == one.seeds_phrase() == "1 finished seed"
    more = replace(fs, runs={**runs, "bbrl": [tmp_path / "b0", tmp_path / "b1"]})
    assert more.seeds_phrase() == "1–2 finished seeds"
    assert replace(more, probes={}).seeds_phrase() == "1–2 seeds"
    assert replace(fs, runs={"diskill": [tmp_path / "d0"], "bbrl": [tmp_path / "b0"]},
                   probes={}).seeds_phrase() == "1 seed"  # fmt: skip
    assert replace(fs, runs={"diskill-v2": runs["diskill-v2"]}).seeds_phrase() == (
        "0 finished seeds")


def test_a_probe_of_a_method_with_finished_seeds_is_held_back(tmp_path):
    for seed, name in [*enumerate(("d0", "d1", "d2")), (0, "v0")]:
        (tmp_path / name).mkdir()
        (tmp_path / name / RunDir.CONFIG).write_text(json.dumps({"seed": seed}))
    runs = {"diskill": [tmp_path / n for n in ("d0", "d1", "d2")],
            "diskill-v2": [tmp_path / "v0"]}  # fmt: skip
    fs = FigureSet("fig4-3b", "full", runs, seeds_full=dict.fromkeys(runs, 24),
                   probes={"d2": "150/4500 iterations", "v0": "900/4500 iterations"})  # fmt: skip
    fs.hold_back()
    # the finished seeds are drawn alone; a probe-only method keeps its probe
    assert fs.runs == {"diskill": [tmp_path / "d0", tmp_path / "d1"],
                       "diskill-v2": [tmp_path / "v0"]}  # fmt: skip
    assert fs.probes == {"v0": "900/4500 iterations"}
    assert fs.held == {"d2": "s2 at 150/4500 iterations"}
    assert fs.probe_progress() == {"diskill-v2": "900/4500 iterations"}
    caption = fs.caption()
    assert "seeds diskill 2 of 24, diskill-v2 0 of 24 and 1 probe" in caption
    assert "still training, not drawn until they finish: d2 s2 at 150/4500 iterations" in caption
    assert fs.verdict("as in the thesis", ("diskill", "bbrl")) == "as in the thesis"


def test_mark_probes_fades_the_probe_curves_and_names_them_in_the_legend(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fs = FigureSet("fig4-3b", "full", {"diskill": [tmp_path / "d0"],
                                       "diskill-v2": [tmp_path / "v0"]},
                   probes={"v0": "900/4500 iterations"})  # fmt: skip
    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1], label="Di-SkilL", linestyle="-")
    ax.plot([0, 1], [1, 0], label="Di-SkilLV2", linestyle="-")
    ax.legend(fontsize=8)
    fs.mark_probes(ax, {"diskill": "Di-SkilL", "diskill-v2": "Di-SkilLV2"})
    finished, probe = ax.get_lines()
    assert (finished.get_alpha(), finished.get_label()) == (None, "Di-SkilL")
    assert (probe.get_alpha(), probe.get_label()) == (
        0.45, "Di-SkilLV2 (probe, 900/4500 iterations)")
    assert probe.get_linestyle() == "-"  # the method's own style stays
    assert probe.get_zorder() > finished.get_zorder()  # drawn above the finished curves
    texts = [t.get_text() for t in ax.get_legend().get_texts()]
    assert texts == ["Di-SkilL", "Di-SkilLV2 (probe, 900/4500 iterations)"]
    assert ax.get_legend().get_texts()[0].get_fontsize() == 8
    with pytest.raises(ValueError, match=r"no curve label .* method\(s\) \['diskill-v2'\]"):
        fs.mark_probes(ax, {"diskill": "Di-SkilL"})
    plt.close(fig)

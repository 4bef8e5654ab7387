"""``vslbook record`` exports a figure's finished runs into ``data/results/`` as registered
tables with their provenance; ``vslbook results`` summarises the recorded sets and ``vslbook
plan`` marks their runs ``recorded``. Trained once: Fig. 4.4a's three smoke runs."""

from __future__ import annotations

import gzip
import hashlib
import io
import json
import shutil
from datetime import datetime
from pathlib import Path

import pandas as pd
import pytest

from vslbook.cli import main
from vslbook.data import register_file
from vslbook.experiments.record import (
    figure_metric,
    load_recorded,
    recorded_dir,
    recorded_names,
    result_rows,
)
from vslbook.experiments.run_plan import figure_runs
from vslbook.results import RunDir

FIGURE, BUDGET = "fig4-4a", "smoke"
FILES = ("runs.csv", "evals.csv.gz", "provenance.json", "registry.json")
PROVENANCE_KEYS = {
    "method", "algo", "env", "seed", "budget", "config", "config_hash", "code_hash",
    "code_hashes_verified", "code_excluded", "git_sha", "git_dirty", "packages", "hostname",
    "python", "platform", "cpu", "started", "wall_seconds", "wall_from", "metrics", "recorded",
}  # fmt: skip
RESULT_KEYS = {"figure", "method", "task", "budget", "seeds", "probes", "metric", "iqm", "ci_low",
               "ci_high", "stale"}  # fmt: skip


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """Fig. 4.4a's runs at smoke (one seed each of Di-SkilL, BBRL, LinDi-SkilL)."""
    root = tmp_path_factory.mktemp("trained") / "runs"
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("VSLBOOK_WORKERS", "1")
        for run in figure_runs(FIGURE, BUDGET):
            run.train(root)
    return root


@pytest.fixture
def root(trained, tmp_path, monkeypatch):
    """A private copy of the trained runs; ``$VSLBOOK_DATA`` points at an empty folder."""
    monkeypatch.setenv("VSLBOOK_DATA", str(tmp_path / "data"))
    return Path(shutil.copytree(trained, tmp_path / "runs"))


def _record(root: Path, capsys) -> list[str]:
    capsys.readouterr()
    assert main(["record", FIGURE, "--budget", BUDGET, "--root", str(root)]) == 0
    return capsys.readouterr().out.splitlines()


def _bytes(directory: Path) -> dict[str, bytes]:
    return {name: (directory / name).read_bytes() for name in FILES}


def _final(run_dir: Path, metric: str = "test_return") -> float:
    rows = [json.loads(line) for line in (run_dir / "metrics.jsonl").read_text().splitlines()]
    return [r[metric] for r in rows if r.get(metric) is not None][-1]


def _results(capsys) -> list[dict]:
    capsys.readouterr()
    assert main(["results", "--json"]) == 0
    return [json.loads(line) for line in capsys.readouterr().out.splitlines()]


def test_record_writes_registered_tables_and_provenance(root, capsys):
    runs = figure_runs(FIGURE, BUDGET)
    out = _record(root, capsys)
    assert out[:-1] == [f"recorded      {r.name}" for r in runs]
    assert out[-1].startswith(f"3 of 3 runs of {FIGURE} at {BUDGET} recorded in ")
    directory = recorded_dir(FIGURE, BUDGET)
    assert directory.parts[-3:] == ("results", FIGURE, BUDGET)

    table = pd.read_csv(directory / "runs.csv")
    assert list(table.columns) == ["run", "figure", "method", "algo", "env", "seed", "budget",
                                   "config_hash", "status"]  # fmt: skip
    assert list(table["run"]) == sorted(r.name for r in runs)
    for r in runs:
        row = table.set_index("run").loc[r.name]
        rd = RunDir.open(root / r.name)
        assert (row["figure"], row["method"], row["algo"], row["env"], row["seed"],
                row["budget"], row["config_hash"], row["status"]) == (
            FIGURE, r.method, r.algo, r.env, r.seed, BUDGET, rd.config_hash, "done")  # fmt: skip

    evals = pd.read_csv(directory / "evals.csv.gz", float_precision="round_trip")
    assert list(evals.columns) == ["run", "step", "metric", "value"]
    for r in runs:
        rows = RunDir.open(root / r.name).metrics()
        mine = evals[evals["run"] == r.name]
        assert len(mine) == sum(len(row) - 1 for row in rows)  # every metric is numeric here
        last = mine[(mine["metric"] == "test_return")].iloc[-1]
        assert (last["step"], last["value"]) == (rows[-1]["step"], _final(root / r.name))

    registry = json.loads((directory / "registry.json").read_text())
    assert sorted(registry) == ["evals.csv.gz", "provenance.json", "runs.csv"]
    for name, entry in registry.items():
        assert entry["sha256"] == hashlib.sha256((directory / name).read_bytes()).hexdigest()
        assert entry["description"]
    assert registry["runs.csv"]["rows"] == 3
    assert registry["evals.csv.gz"]["rows"] == len(evals)
    assert gzip.decompress((directory / "evals.csv.gz").read_bytes()).endswith(b"\n")

    provenance = json.loads((directory / "provenance.json").read_text())
    assert (provenance["figure"], provenance["budget"]) == (FIGURE, BUDGET)
    assert sorted(provenance["runs"]) == sorted(r.name for r in runs)
    for r in runs:
        entry = provenance["runs"][r.name]
        rd = RunDir.open(root / r.name)
        assert set(entry) == PROVENANCE_KEYS
        assert entry["config"] == rd.config and entry["seed"] == r.seed
        assert entry["code_hash"] == rd.env["code_hash"] and entry["started"] == rd.env["timestamp"]
        assert entry["metrics"] == json.loads((rd.path / "DONE").read_text())["metrics"]
        seconds = [row["iteration_seconds"] for row in rd.metrics() if "iteration_seconds" in row]
        assert entry["wall_seconds"] == pytest.approx(sum(seconds)) and seconds
        assert datetime.fromisoformat(entry["recorded"]).tzinfo is not None

    # the set reads back: per-run frames as the run directories give them
    assert recorded_names(FIGURE, BUDGET) == {r.name for r in runs}
    loaded = load_recorded(FIGURE, BUDGET)
    assert list(loaded) == ["diskill", "bbrl", "lindiskill"]
    for r in runs:
        (frame,) = loaded[r.method]
        assert frame.attrs == {"run": r.name, "seed": r.seed}
        want = RunDir.open(root / r.name).metrics_frame()
        assert list(frame["step"]) == list(want["step"])
        assert list(frame["test_return"]) == list(want["test_return"])


def test_recording_is_deterministic_and_merges(root, capsys, tmp_path):
    runs = figure_runs(FIGURE, BUDGET)
    _record(root, capsys)
    directory = recorded_dir(FIGURE, BUDGET)
    first = _bytes(directory)
    _record(root, capsys)
    assert _bytes(directory) == first  # same runs, same bytes (dates kept)

    # a root with one of the runs: the others stay recorded, the tables do not change
    keep, *gone = runs
    for r in gone:
        shutil.rmtree(root / r.name)
    out = _record(root, capsys)
    for r in gone:
        assert f"not recorded  missing  {r.name}  (recorded earlier: kept)" in out
    assert out[-1].startswith("3 of 3 runs") and "(1 from" in out[-1] and "2 kept)" in out[-1]
    assert _bytes(directory) == first

    # the root's copy of a run wins over the recorded one
    rd = RunDir.open(root / keep.name)
    rows = rd.metrics()
    rows[-1]["test_return"] = 123.25
    rd.metrics_path.write_text("".join(json.dumps(row) + "\n" for row in rows))
    rd.mark_done({})
    _record(root, capsys)
    assert _bytes(directory) != first
    evals = pd.read_csv(directory / "evals.csv.gz")
    mine = evals[(evals["run"] == keep.name) & (evals["metric"] == "test_return")]
    assert mine["value"].iloc[-1] == 123.25
    assert set(pd.read_csv(directory / "runs.csv")["run"]) == {r.name for r in runs}

    # a run made before env.json named the CPU is recorded without one (not "cpu": null)
    env = json.loads((root / keep.name / "env.json").read_text())
    assert env["cpu"] == json.loads(
        (directory / "provenance.json").read_text())["runs"][keep.name]["cpu"]
    del env["cpu"]
    (root / keep.name / "env.json").write_text(json.dumps(env))
    _record(root, capsys)
    assert "cpu" not in json.loads((directory / "provenance.json").read_text())["runs"][keep.name]

    # an empty root writes nothing
    (tmp_path / "empty").mkdir()
    monkey = tmp_path / "other-data"
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("VSLBOOK_DATA", str(monkey))
        out = _record(tmp_path / "empty", capsys)
        assert out[-1] == f"0 of 3 runs of {FIGURE} at {BUDGET} recorded (nothing written)"
        assert not monkey.exists()


def _other_code(run_dir: Path) -> None:
    env = json.loads((run_dir / "env.json").read_text())
    env["code_hash"] = "0" * 64
    (run_dir / "env.json").write_text(json.dumps(env))


def test_unusable_runs_are_listed_and_not_recorded(root, capsys):
    partial, failed, stale = figure_runs(FIGURE, BUDGET)
    (root / partial.name / "DONE").unlink()
    RunDir.open(root / failed.name).mark_failed({"message": "diverged at step 1: non-finite x"})
    # made by other code, and its first row is not what today's code computes
    path = root / stale.name / "metrics.jsonl"
    rows = [json.loads(line) for line in path.read_text().splitlines()]
    rows[0]["test_return"] += 1.0
    path.write_text("".join(json.dumps(r) + "\n" for r in rows))
    (root / stale.name / "DONE").unlink()
    RunDir.open(root / stale.name).mark_done({})
    _other_code(root / stale.name)
    out = _record(root, capsys)
    assert out[:2] == [
        f"not recorded  partial  {partial.name}  (2/2 iterations)",
        f"not recorded  failed   {failed.name}  (diverged at step 1: non-finite x)",
    ]
    assert out[2].startswith(f"not recorded  stale    {stale.name}  (made by other code; "
                             "replay: row 1, test_return: ")  # fmt: skip
    assert out[3] == f"0 of 3 runs of {FIGURE} at {BUDGET} recorded (nothing written)"
    assert not recorded_dir(FIGURE, BUDGET).exists()
    (root / failed.name / "FAILED").unlink()
    with open(root / failed.name / "metrics.jsonl", "a") as fh:
        fh.write('{"step": 3}\n')  # appended after DONE: DONE no longer covers the file
    out = _record(root, capsys)
    assert f"not recorded  damaged  {failed.name}  (its DONE does not match metrics.jsonl)" in out


def test_a_run_made_by_other_code_is_recorded_when_it_replays_equal(root, capsys):
    run = figure_runs(FIGURE, BUDGET)[0]
    _other_code(root / run.name)
    assert not RunDir(root / run.name).code_matches
    assert f"recorded      {run.name}" in _record(root, capsys)
    assert RunDir(root / run.name).code_matches  # today's fingerprint joined its env.json
    assert not [r for r in _results(capsys) if r["method"] == run.method][0]["stale"]


def test_results_lists_each_set_with_its_final_iqm(root, capsys):
    runs = figure_runs(FIGURE, BUDGET)
    capsys.readouterr()
    assert main(["results"]) == 0
    assert capsys.readouterr().out.startswith("no recorded run sets in ")
    _record(root, capsys)
    rows = _results(capsys)
    assert [r["method"] for r in rows] == ["diskill", "bbrl", "lindiskill"]
    for row, r in zip(rows, runs, strict=True):
        assert set(row) == RESULT_KEYS
        final = _final(root / r.name)
        assert row == {"figure": FIGURE, "method": r.method, "task": "hopper-jump",
                       "budget": BUDGET, "seeds": 1, "probes": 0, "metric": "test_return",
                       "iqm": final, "ci_low": final, "ci_high": final, "stale": False}  # fmt: skip
    capsys.readouterr()
    assert main(["results"]) == 0
    text = capsys.readouterr().out.splitlines()
    assert text[0].split() == ["figure", "method", "task", "budget", "seeds", "probes", "metric",
                               "IQM", "[95%", "CI]", "stale"]  # fmt: skip
    assert len(text) == 4 and all(line.startswith(FIGURE) for line in text[1:])

    # a recorded code fingerprint that is not today's: that method's set is stale
    path = recorded_dir(FIGURE, BUDGET) / "provenance.json"
    provenance = json.loads(path.read_text())
    provenance["runs"][runs[1].name]["code_hash"] = "f" * 64
    path.write_text(json.dumps(provenance, indent=2, sort_keys=True) + "\n")
    registry = json.loads((path.parent / "registry.json").read_text())
    register_file(path, registry["provenance.json"]["description"])
    assert [r["stale"] for r in _results(capsys)] == [False, True, False]
    capsys.readouterr()
    assert main(["results"]) == 0
    assert capsys.readouterr().out.splitlines()[2].endswith("stale")

    # an edited table is caught by its registry
    path.write_text(path.read_text() + " ")
    assert main(["results"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("vslbook: error: ") and "sha256 does not match" in err
    assert "\n" not in err


def test_plan_marks_recorded_runs(root, capsys):
    runs = figure_runs(FIGURE, BUDGET)
    _record(root, capsys)
    shutil.rmtree(root / runs[0].name)
    assert main(["plan", FIGURE, "--budget", BUDGET, "--root", str(root)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[:3] == [f"recorded {runs[0].name}"] + [f"done     {r.name}" for r in runs[1:]]
    assert lines[-1] == "nothing left to train"


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["record", "fig9-9"],
         "figure 'fig9-9' declares no runs; expected one of fig3-1, fig3-2, fig3-5, fig4-3b"),
        (["record", FIGURE, "--budget", "huge"], "unknown budget 'huge'; expected one of"),
        (["record", FIGURE, "--root", "{file}"], "is not a folder; expected the folder that"),
        (["record", FIGURE, "--root", "{missing}"], "is not a folder; expected the folder"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(argv, message, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("VSLBOOK_DATA", str(tmp_path / "data"))
    (tmp_path / "file").write_text("not a folder")
    argv = [a.format(file=tmp_path / "file", missing=tmp_path / "nope") for a in argv]
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    err = captured.err
    assert err.startswith("vslbook: error: ") and message in err and err.count("\n") == 1
    assert not (tmp_path / "data").exists()


def test_recorded_tables_read_back_exactly(root, capsys):
    # floats survive the CSV round trip bit for bit (the merge re-reads them)
    _record(root, capsys)
    data = gzip.decompress((recorded_dir(FIGURE, BUDGET) / "evals.csv.gz").read_bytes())
    frame = pd.read_csv(io.BytesIO(data), float_precision="round_trip")
    again = frame.to_csv(index=False, lineterminator="\n").encode()
    assert again == data


def _rewrite(path: Path, data: bytes) -> None:
    """Write a recorded table by hand and register it again (as a damaged set would not)."""
    registry = json.loads((path.parent / "registry.json").read_text())
    path.write_bytes(data)
    register_file(path, registry[path.name]["description"])


def test_verify_replays_changed_runs_and_keeps_equal_ones_current(root, capsys):
    """``results --verify``: a run whose recorded fingerprint differs from today's is
    replayed; equal first rows make it current again (today's fingerprint joins its
    provenance), a recorded number the replay does not give keeps it stale."""
    runs = figure_runs(FIGURE, BUDGET)
    _record(root, capsys)
    directory = recorded_dir(FIGURE, BUDGET)
    provenance = json.loads((directory / "provenance.json").read_text())
    for r in runs[:2]:
        provenance["runs"][r.name]["code_hash"] = "f" * 64
    _rewrite(directory / "provenance.json",
             (json.dumps(provenance, indent=2, sort_keys=True) + "\n").encode())
    # the second run's first recorded test_return is not what its code computes
    evals = pd.read_csv(directory / "evals.csv.gz")
    first = evals[(evals["run"] == runs[1].name) & (evals["metric"] == "test_return")].index[0]
    evals.loc[first, "value"] += 1.0
    _rewrite(directory / "evals.csv.gz",
             gzip.compress(evals.to_csv(index=False, lineterminator="\n").encode(), mtime=0))
    assert [r["stale"] for r in _results(capsys)] == [True, True, False]

    capsys.readouterr()
    assert main(["results", "--verify"]) == 0
    lines = capsys.readouterr().out.splitlines()
    states = {line.split()[3]: line.split()[0] for line in lines[:3]}
    assert states == {runs[0].name: "verified", runs[1].name: "stale", runs[2].name: "current"}
    assert "test_return" in next(line for line in lines if runs[1].name in line)
    assert lines[3] == "1 current, 1 verified, 1 stale"
    assert [r["stale"] for r in _results(capsys)] == [False, True, False]
    kept = json.loads((directory / "provenance.json").read_text())["runs"][runs[0].name]
    assert kept["code_hash"] == "f" * 64 and len(kept["code_hashes_verified"]) == 1


def test_figure_metric_names_one_metric_per_algorithm_where_they_log_it_differently():
    """Fig. 3.5's return is SVSL's ``test_return`` and PPO's ``eval_return`` (the same
    un-normalised return on the same goals); the other figures name one metric."""
    assert figure_metric("fig3-5", "svsl") == "test_return"
    assert figure_metric("fig3-5", "ppo") == "eval_return"
    assert figure_metric("fig3-2") == figure_metric("fig3-2", "ppo") == "test_success"
    assert figure_metric(FIGURE) == "test_return"
    for algo in (None, "hireps"):
        with pytest.raises(ValueError, match="one metric per algorithm"):
            figure_metric("fig3-5", algo)


@pytest.mark.slow
def test_fig_3_5_results_have_a_value_for_svsl_and_ppo(tmp_path, monkeypatch, capsys):
    """One smoke run of each algorithm of Fig. 3.5 (reward Eq. 3.8): each logs the metric
    the figure names for it, and ``vslbook results`` gives both methods their final value."""
    monkeypatch.setenv("VSLBOOK_WORKERS", "1")
    monkeypatch.setenv("VSLBOOK_DATA", str(tmp_path / "data"))
    root = tmp_path / "runs"
    runs = [r for r in figure_runs("fig3-5", BUDGET) if r.method.endswith("Eq. 3.8")]
    assert sorted(r.algo for r in runs) == ["ppo", "svsl"]
    finals = {}
    for r in runs:
        r.train(root)
        finals[r.method] = _final(root / r.name, figure_metric("fig3-5", r.algo))
    capsys.readouterr()
    assert main(["record", "fig3-5", "--budget", BUDGET, "--root", str(root)]) == 0
    rows = {r["method"]: r for r in result_rows(["fig3-5"]) if r["method"] in finals}
    assert set(rows) == set(finals)
    for method, final in finals.items():
        row = rows[method]
        assert row["seeds"] == 1 and row["iqm"] == final, row
        assert row["metric"] == ("eval_return" if method.startswith("PPO") else "test_return")

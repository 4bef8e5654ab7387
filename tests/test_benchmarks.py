"""The benchmark scripts run (their numbers are printed, never asserted: no timed tests)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"


def _load(name: str):
    spec = importlib.util.spec_from_file_location(name, BENCH / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("task", ["beer-pong", "table-tennis-4d"])
def test_robot_benchmark_counts_the_physics_of_python_and_compiled_loops(task, capsys):
    """Beer pong steps from Python, table tennis from its compiled loop: both lines report
    the episodes' physics steps, their bare rate and the overhead."""
    _load("robot_tasks").bench(task, episodes=2, workers=1, scale=0.1, seed=0, repeat=1)
    line = capsys.readouterr().out
    assert "physics" in line and "bare mj_step" in line and "overhead" in line, line


def test_run_set_timing_rejects_an_unknown_set():
    with pytest.raises(SystemExit, match=r"unknown run set\(s\) \['nope'\]"):
        _load("dime_throughput").time_run_sets("smoke", None, ["nope"])


def test_erl_run_sets_train_the_notebook_runs_and_reuse_them(tmp_path, capsys, monkeypatch):
    """Chapter 3's planar set at smoke: the three Fig. 3.1 variants, one seed each; a second
    pass finds them finished (same run directories)."""
    from vslbook.experiments.erl_run_sets import run_sets

    monkeypatch.setenv("VSLBOOK_WORKERS", "1")
    total = _load("erl_run_sets").time_run_sets(3, "smoke", str(tmp_path), ["planar"])
    out = capsys.readouterr().out
    assert "planar" in out and "  3 runs" in out and "beer-pong" not in out and total > 0
    done = {p: p.stat().st_mtime_ns for p in tmp_path.glob("*/DONE")}
    assert len(done) == 3
    again = run_sets(3, "smoke", tmp_path, only=["planar"])["planar"]
    assert sorted(again) == ["HiREPS", "SVSL", "SVSL, no responsibilities"]
    assert {p / "DONE" for ps in again.values() for p in ps} == set(done)
    assert all(p.stat().st_mtime_ns == t for p, t in done.items())  # reused, not retrained
    with pytest.raises(SystemExit, match=r"unknown run set\(s\) \['4.9'\]"):
        _load("erl_run_sets").time_run_sets(4, "smoke", None, ["4.9"])
    with pytest.raises(ValueError, match="chapter must be one of"):
        run_sets(5, "smoke", tmp_path)


def test_chapter4_run_sets_are_the_notebook_figures():
    from vslbook.experiments.diskill_runs import FIGURES
    from vslbook.experiments.erl_run_sets import RUN_SETS

    assert list(RUN_SETS[4]) == list(FIGURES)
    assert list(RUN_SETS[3]) == ["planar", "beer-pong", "table-tennis", "reacher"]


def test_seed_axis_layer_paths_compute_the_same_gradients():
    """The batched-layer critic body of the seed-axis benchmark (baddbmm, per-seed
    BatchRenorm statistics) gives each seed the gradients of its own module, as vmap does;
    a wrong scale inside the batched BatchRenorm is detected."""
    layers = _load("seed_axis_layers")
    assert layers.check_same(16, 3) < 1e-5
    renorm = layers.BatchedBody._renorm
    layers.BatchedBody._renorm = lambda self, x, k: renorm(self, x, k) * 1.01
    try:
        assert layers.check_same(16, 3) > 1e-5
    finally:
        layers.BatchedBody._renorm = renorm


def test_diskill_iteration_benchmark_splits_an_iteration(capsys):
    """Di-SkilL's iteration at smoke sizes: one row per task with the five phases and the
    networks' share, which add up to the iteration."""
    bench = _load("diskill_iteration")
    t = bench.bench("reacher5", iterations=1, warmup=0, workers=1, sizes="smoke")
    out = capsys.readouterr().out
    for phase in (*bench.PHASES, "networks"):
        assert phase in out
    assert "reacher5" in out and "float32" in out
    assert abs(sum(t[p] for p in bench.PHASES) - t["iteration"]) < 1e-9


@pytest.mark.slow
def test_diskill_iteration_benchmark_compares_seeds_side_by_side(capsys):
    """The side-by-side mode runs one seed with two workers, then two seeds with one worker
    each (separate processes), and prints both throughputs and their ratio."""
    _load("diskill_iteration").main(
        ["--tasks", "reacher5", "--sizes", "smoke", "--iterations", "1", "--warmup", "0",
         "--side-by-side"]
    )  # fmt: skip
    line = capsys.readouterr().out
    assert "one seed with 2 workers" in line and "side by side" in line and "ratio" in line

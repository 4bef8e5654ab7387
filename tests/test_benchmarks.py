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

"""Methods compared at equal executed episodes: the last logged test at or before a count."""

import numpy as np
import pytest

from vslbook.experiments import equal_samples as ES
from vslbook.results import RunDir


def _run(tmp_path, method, seed, rows):
    """A run directory whose metrics.jsonl holds ``rows`` of (step, samples, test_success);
    a test_success of None logs a training row without a test."""
    rd = RunDir.create(tmp_path, {"algo": method, "env": "t", "seed": seed})
    for step, samples, success in rows:
        extra = {} if success is None else {"test_success": success}
        rd.log(step, samples=float(samples), **extra)
    return rd.path


@pytest.fixture
def runs(tmp_path):
    long = [(i, 100 * i, None if i % 2 else i / 20) for i in range(1, 11)]  # tests at even i
    return {
        "diskill": [_run(tmp_path, "diskill", 0, long),
                    _run(tmp_path, "diskill", 1, [(s, n, v if v is None else v / 2)
                                                  for s, n, v in long])],
        "svsl": [_run(tmp_path, "svsl", 0, [(1, 150, 0.0), (2, 450, 0.3), (3, 450, None)])],
    }  # fmt: skip


def test_reached_is_each_runs_last_test(runs):
    ends = ES.reached(runs)
    assert ends[["method", "seed", "step", "samples"]].values.tolist() == [
        ["diskill", 0, 10, 1000.0], ["diskill", 1, 10, 1000.0], ["svsl", 0, 2, 450.0],
    ]  # fmt: skip
    np.testing.assert_allclose(ends["test_success"], [0.5, 0.25, 0.3])


def test_at_samples_takes_the_last_test_at_or_before(runs):
    # tests at 200, 400, ..., 1000 executed episodes; 450 falls after the one at 400
    at = ES.at_samples({"diskill": runs["diskill"]}, 450)
    assert at["step"].tolist() == [4, 4] and at["samples"].tolist() == [400.0, 400.0]
    np.testing.assert_allclose(at["test_success"], [0.2, 0.1])
    exact = ES.at_samples({"diskill": runs["diskill"]}, 600)  # "at or before" includes 600
    assert exact["step"].tolist() == [6, 6]
    # before the first test, and past a run's end: no value rather than a wrong one
    early = ES.at_samples(runs, 100)
    assert early["step"].tolist() == [-1, -1, -1] and early["test_success"].isna().all()
    late = ES.at_samples(runs, 800)
    assert late["step"].tolist() == [8, 8, -1]


def test_compare_lines(runs):
    lines = ES.compare_lines(runs, labels={"diskill": "Di-SkilL", "svsl": "SVSL"})
    assert lines == [
        "SVSL seed 0: 30.0% at iteration 2, after 0.000 M executed episodes",
        "    Di-SkilL then: seed 0: 20.0% (iteration 4), seed 1: 10.0% (iteration 4)",
    ]


def test_bad_input(runs, tmp_path):
    with pytest.raises(ValueError, match="samples must be a finite count >= 0, got -1"):
        ES.at_samples(runs, -1)
    with pytest.raises(ValueError, match="runs is empty"):
        ES.at_samples({}, 10)
    with pytest.raises(ValueError, match="reference 'bbrl' has no runs"):
        ES.compare_lines(runs, reference="bbrl")
    bare = _run(tmp_path, "bbrl", 0, [(1, 10, None)])
    with pytest.raises(ValueError, match="metrics.jsonl has no 'test_success'"):
        ES.reached({"bbrl": [bare]})
    untested = _run(tmp_path, "bbrl", 1, [(1, 10, float("nan"))])  # logged as null
    with pytest.raises(ValueError, match="no test row with 'test_success' yet"):
        ES.reached({"bbrl": [untested]})

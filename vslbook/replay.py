"""Stale means other numbers, not other text: replay a run's first rows with today's code.

A run records the fingerprint of the code that made it
(:func:`vslbook.provenance.code_fingerprint`).
An edit anywhere the run's code can reach changes that fingerprint, though most edits (a
docstring, a refactor, a new option) change no number. So a changed fingerprint is a reason
to check, not a verdict: :func:`replay_matches` trains the same run (algorithm, env, seed,
budget, configuration) afresh in a temporary folder until it has logged the first
:data:`REPLAY_ROWS` rows, and compares them with the run's own first rows:

* equal (floats to :data:`RTOL` / :data:`ATOL`, everything else exactly, wall-clock fields
  aside): the run is current, and today's fingerprint is added to its ``env.json``
  (``code_hashes_verified``), so the next check is free;
* different: the run is stale (:func:`vslbook.run_open.open_run` moves it aside).

The replay costs the first few iterations of the run, minutes at most at the thesis's
sizes, against the hours or days a partial run holds.
"""

from __future__ import annotations

import math
import re
import tempfile
from collections.abc import Mapping
from typing import Any

__all__ = ["ATOL", "REPLAY_ROWS", "RTOL", "SEED_AXIS_RTOL", "WALL_CLOCK", "numeric_row",
           "replay_matches", "rows_match"]

#: rows compared (or fewer, when the run has fewer)
REPLAY_ROWS = 2
#: Tolerances of a float. Not 0: the same code on another machine rounds differently. NumPy's
#: BLAS picks its kernels by CPU model, and an iterative solver's answer moves with their
#: rounding: HiREPS's dual ξ on beer pong (``hireps``, seed 0, full), replayed with the code
#: that made the run on a machine with another CPU, differed by 3e-10 relative in row 1 and
#: 1.2e-9 in row 2 (its episodes' returns were identical; the difference grows about 300-fold
#: per iteration, 3e-7 in row 3). A change of a formula, a constant or a precision moves the
#: first rows by far more than 1e-7.
RTOL, ATOL = 1e-7, 1e-12
#: relative tolerance for a run trained on the seed axis (:mod:`vslbook.srl.dime_seeds`):
#: the replay trains one seed alone, whose batched kernels round differently from the
#: stacked seeds' (measured: 1.3e-7 relative on an actor loss after a few updates)
SEED_AXIS_RTOL = 1e-5
#: metrics that measure the machine, not the run
WALL_CLOCK = re.compile(r"seconds|_per_s$|^time|fps")


def _same(a: Any, b: Any, rtol: float = RTOL) -> bool:
    if isinstance(a, float) or isinstance(b, float):
        if a is None or b is None:
            return a is b
        return math.isclose(float(a), float(b), rel_tol=rtol, abs_tol=ATOL)
    return a == b


def rows_match(old: list[Mapping[str, Any]], new: list[Mapping[str, Any]],
               rtol: float = RTOL) -> str | None:  # fmt: skip
    """None when ``new`` equals ``old`` row for row (see the module docstring), else the
    first difference in words."""
    if len(new) < len(old):
        return f"the replay logged {len(new)} rows, the run {len(old)}"
    for i, (a, b) in enumerate(zip(old, new, strict=False), start=1):
        keys = {k for k in set(a) | set(b) if not WALL_CLOCK.search(k)}
        for key in sorted(keys):
            if not _same(a.get(key), b.get(key), rtol):
                return f"row {i}, {key}: {a.get(key)!r} recorded, {b.get(key)!r} now"
    return None


def numeric_row(row: Mapping[str, Any]) -> dict[str, Any]:
    """``row`` reduced to what a recorded table keeps (:func:`vslbook.data.evals_frame`):
    ``step`` and the numeric metrics (ints, floats and ``None``; not booleans)."""
    return {k: v for k, v in row.items() if k == "step" or v is None
            or (isinstance(v, (int, float)) and not isinstance(v, bool))}  # fmt: skip


def replay_matches(spec: Any, record: Mapping[str, Any], rows: list[Mapping[str, Any]],
                   budget: Any, *, numeric_only: bool = False,
                   rtol: float = RTOL) -> str | None:  # fmt: skip
    """Train ``record``'s first :data:`REPLAY_ROWS` rows with today's code and compare them
    with ``rows`` (the run's own); None when they match, else why not.

    Args:
        spec: the :class:`vslbook.registry.Algorithm`.
        record: the run's ``config.json``.
        rows: the run's logged rows.
        budget: the run's :class:`vslbook.budget.Budget`.
        numeric_only: compare only the numeric metrics (:func:`numeric_row`): ``rows``
            come from a recorded table, which keeps no others.
        rtol: relative tolerance of floats (:data:`SEED_AXIS_RTOL` for a run the seed axis
            trained).
    """
    from vslbook.results import DivergenceError, RunDir

    want = rows[:REPLAY_ROWS]
    if not want:
        return None  # nothing logged: nothing to keep or lose
    with tempfile.TemporaryDirectory(prefix="vslbook-replay-") as tmp:
        rd = RunDir.create(tmp, dict(record), code_exclude=spec.independent_of)
        for _ in range(10_000):  # one iteration (or rollout, or episode) per call
            try:
                done = spec.train(rd, dict(record), budget, progress=False, stop_after=1)
            except DivergenceError as err:
                return f"the replay diverged ({err})"
            got = rd.metrics()
            if done is not None or len(got) >= len(want):
                got = got[: len(want)]
                got = [numeric_row(r) for r in got] if numeric_only else got
                return rows_match(want, got, rtol)
    return "the replay did not reach the rows to compare"

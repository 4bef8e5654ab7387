"""The final scores of Chapter 4's learning curves, the thesis's orderings checked on them,
and one line of text per method.

:func:`final_scores` returns, per figure, a table of scores (IQM and 95 % stratified-bootstrap
interval of each method's last evaluation over the seeds) and a table of the thesis's
orderings (:data:`vslbook.experiments.diskill_runs.THESIS_AHEAD`) checked on them with the
book's one rule for "above" (:func:`vslbook.experiments.reproduction.ranked`); the other
functions phrase both. Analysis only: runs never load this module, so editing it leaves
their code identity alone.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd


def final_scores(
    figure: str, runs: dict[str, list[Path]], y: str = "test_return", *, reps: int | None = None
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Each run's last evaluation of ``y``, aggregated per method, and the thesis's pairs.

    Returns (scores, verdicts): scores has one row per method (label, runs, iqm, ci_low,
    ci_high: IQM with a 95 % stratified-bootstrap CI over seeds; s_per_iteration: the
    median wall time of an iteration over its runs, NaN for PPO); verdicts one row per pair
    of ``THESIS_AHEAD`` whose two methods both ran (ahead, behind, as_in_thesis: True where
    the first's IQM lies above the upper end of the second's CI, False where the second's
    lies above the first's, None where neither does, e.g. both at 0 success). Runs of
    different lengths (PPO on 5LR at ``reduced``) are compared at their own last evaluation.

    Raises:
        ValueError: an unknown figure or method.
    """
    from vslbook.experiments.diskill_runs import LABELS, THESIS_AHEAD
    from vslbook.experiments.reproduction import final_scores as finals
    from vslbook.experiments.reproduction import ranked
    from vslbook.results import RunDir

    if figure not in THESIS_AHEAD:
        raise ValueError(f"unknown figure {figure!r}; expected one of {sorted(THESIS_AHEAD)}")
    unknown = sorted(set(runs) - set(LABELS))
    if unknown:
        raise ValueError(f"unknown method(s) {unknown}; expected some of {sorted(LABELS)}")
    scores = finals(runs, y, reps=reps)  # method, runs, iqm, ci_low, ci_high
    seconds = {}
    for method, paths in runs.items():
        times = [r["iteration_seconds"] for path in paths for r in RunDir.open(path).metrics()
                 if "iteration_seconds" in r]  # fmt: skip
        seconds[method] = float(np.median(times)) if times else float("nan")
    scores.insert(1, "label", scores["method"].map(LABELS))
    scores["s_per_iteration"] = scores["method"].map(seconds)
    ran = set(scores["method"])
    verdicts = pd.DataFrame(
        [{"ahead": LABELS[a], "behind": LABELS[b], "as_in_thesis": ranked(scores, a, b),
          "methods": (a, b)}
         for a, b in THESIS_AHEAD[figure] if a in ran and b in ran],
        columns=["ahead", "behind", "as_in_thesis", "methods"],
    )  # fmt: skip
    return scores, verdicts


def verdict(as_in_thesis: bool | None) -> str:
    """The words for one of the thesis's orderings (:func:`final_scores`): None means
    neither IQM lies outside the other's 95 % CI."""
    if as_in_thesis is None:
        return "no ranking (each IQM inside the other's 95 % CI)"
    return "as in the thesis" if as_in_thesis else "NOT as in the thesis"


def score_line(r: Any, with_time: bool = True, probes: dict[str, str] | None = None) -> str:
    """`label IQM [low, high] (s/it.)` for one row of a score table (attributes `label`,
    `iqm`, `ci_low`, `ci_high`, `s_per_iteration`); the time is left out when unknown.
    ``probes`` (method → progress, :meth:`FigureSet.probe_progress
    <vslbook.experiments.figure_sources.FigureSet.probe_progress>`) marks a row whose
    method's runs include a probe: its "final" score is where the probe had got to."""
    time = (
        ""
        if not with_time or math.isnan(r.s_per_iteration)
        else f" ({r.s_per_iteration:.2g} s/it.)"
    )
    method = getattr(r, "method", None)
    probe = f" (probe at {probes[method]})" if probes and method in probes else ""
    return f"{r.label} {r.iqm:.3g} [{r.ci_low:.3g}, {r.ci_high:.3g}]{time}{probe}"

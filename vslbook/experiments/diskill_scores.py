"""One line of text per method for the final scores of Chapter 4's learning curves.

`vslbook.experiments.diskill_runs.final_scores` returns, per figure, a table of scores (IQM
and 95 % stratified-bootstrap interval of each method's last evaluation over the seeds) and
a table of the thesis's orderings checked on them; these functions phrase both.
"""

from __future__ import annotations

import math
from typing import Any


def verdict(as_in_thesis: bool | None) -> str:
    """The words for one of the thesis's orderings: None means the two IQMs are equal."""
    if as_in_thesis is None:
        return "tied (equal IQMs)"
    return "as in the thesis" if as_in_thesis else "NOT as in the thesis"


def score_line(r: Any, with_time: bool = True) -> str:
    """`label IQM [low, high] (s/it.)` for one row of a score table (attributes `label`,
    `iqm`, `ci_low`, `ci_high`, `s_per_iteration`); the time is left out when unknown."""
    time = (
        ""
        if not with_time or math.isnan(r.s_per_iteration)
        else f" ({r.s_per_iteration:.2g} s/it.)"
    )
    return f"{r.label} {r.iqm:.3g} [{r.ci_low:.3g}, {r.ci_high:.3g}]{time}"

"""Draw a bound check's path: the objective and its lower bound along one perturbation.

The bound checks of Chapters 3 and 4 (`check_expert_bound`, `check_context_bound`,
`check_weight_bound`) move one part of the model along a random direction, keep the
auxiliary responsibilities at the old model, and record the objective and the bound at each
step ``t`` in ``report.data`` (``t``, ``path_objective``, ``path_bound``). The bound touches
the objective at ``t = 0`` and lies below it elsewhere.
"""

from __future__ import annotations

from typing import Any

from vslbook.plots import method_color


def plot_path(ax: Any, report: Any, what: str, objective: str = "Eq. 3.3") -> None:
    """Objective (solid) and bound with π̃ = old model (dashed) against the step along a random
    perturbation of ``what``; ``objective`` names the objective's equation in the legend."""
    d = report.data
    ax.plot(d["t"], d["path_objective"], "-", color="k", label=f"objective J ({objective})")
    ax.plot(d["t"], d["path_bound"], "--", color=method_color("ours"), label="bound, π̃ = old model")
    ax.axvline(0.0, color="#999999", lw=0.8)
    ax.set(xlabel=f"step along a random perturbation of {what}", ylabel="value")
    ax.legend(fontsize=8)

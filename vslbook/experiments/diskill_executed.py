"""Chapter 4's test curves taken apart: the return of the executed test episodes and the
share of test θ executed.

A θ rejected before simulation (outside the joint limits, an invalid duration) earns a
fixed penalty, and early in training most are rejected: on mini golf that penalty made up
most of the test return, so a rising return curve measured fewer rejections, not better
strikes. Di-SkilL and its variants log both parts at every test
(:meth:`vslbook.erl.diskill.DiSkill.test`: ``test_executed``, ``test_executed_return``);
:func:`draw_executed` draws them side by side.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

__all__ = ["draw_executed"]


def draw_executed(ax_return: plt.Axes, ax_share: plt.Axes, runs: dict[str, list[Path]], *,
                  reps: int | None = None) -> bool:  # fmt: skip
    """The IQM (95 % CI over seeds) of the executed test episodes' return on ``ax_return``
    and of the share of test θ executed on ``ax_share``, against executed episodes.

    Returns False (and says so on ``ax_return``) where no test θ of any run was executed
    yet, so there is no executed return to draw.
    """
    from vslbook.experiments import diskill_runs as DR
    from vslbook.experiments.svsl_mixtures import draw_learning_curves

    share = DR.curves(runs, "test_executed", reps=reps)
    draw_learning_curves(ax_share, share, ylabel="share of test θ executed (IQM)", thesis=None)
    ax_share.set_ylim(-0.05, 1.05)  # a share: the whole range, so 0 and 1 read as such
    try:
        ret = DR.curves(runs, "test_executed_return", reps=reps)
    except ValueError:  # no run has an executed test episode yet
        ret = None
    if ret is None or not np.isfinite(ret["iqm"]).any():
        ax_return.text(0.5, 0.5, "no test θ executed yet:\nevery one was rejected",
                       ha="center", va="center", transform=ax_return.transAxes)  # fmt: skip
        ax_return.set(xticks=[], yticks=[])
        return False
    draw_learning_curves(ax_return, ret, ylabel="return of executed test episodes (IQM)",
                         thesis=None)  # fmt: skip
    return True

"""Which settings a Chapter 3 figure's runs use, for its title: the authors' code or the thesis.

The project's rule (:mod:`vslbook.experiments.audit`): where the authors' SVSL_LMOE code,
which drew the thesis's Chapter 3 figures, and the thesis's text differ, runs use the code's
choice by default and keep the text's as a named option. Every Chapter 3 figure says which
it used, in a phrase read here from the task objects the runs build
(:func:`vslbook.envs.robot.make_task` with the options the runs pass, the defaults) and
from the counts, never typed into the figure:

* planar reacher (Fig. 3.1, A.3.1): the joint cost without the base joint
  (``exclude_base_joint=True``, the code's) or A.3.1's -‖θ‖²;
* beer pong (Fig. 3.2a, c, e-g, A.3.2): the code's in-cup term and contacts
  (``reward="code"``) or A.3.2's reward;
* table tennis (Fig. 3.2b, d, Fig. 3.3, A.3.3): the code's K = 1000 iterations per expert at
  the ``full`` budget (Table A.1: 800) and its punishments (``settings="code"``) or A.3.3's;
* the 5-link reacher (Fig. 3.5, Section 3.4.3, A.3.3): no public code, so the thesis's.
"""

from __future__ import annotations

from typing import Any

__all__ = ["CODE", "THESIS", "settings_phrase", "task_choices"]

#: How a figure names the authors' settings and the thesis's.
CODE = "the authors' settings (SVSL_LMOE code)"
THESIS = "the thesis's settings"
#: Tasks without public code: why the thesis's settings are used.
_NO_CODE = {"reacher5-ch3": "no public code for the 5-link reacher"}


def task_choices(name: str, task: Any) -> list[tuple[str, str]]:
    """``(what, "code" | "thesis")`` for each setting of task ``name`` (object ``task``)
    where the authors' code and the thesis differ."""
    if name == "planar-reacher":
        if task.exclude_base_joint:
            return [("joint cost without the base joint", "code")]
        return [("A.3.1's joint cost -‖θ‖²", "thesis")]
    if name == "beer-pong":
        if task.reward == "code":
            return [("in-cup term and contacts", "code")]
        return [("A.3.2's reward", "thesis")]
    if name == "table-tennis-ch3":
        from vslbook.experiments.svsl_table_tennis import (
            FULL_ITERATIONS_PER_EXPERT,
            table_tennis_counts,
        )

        k = table_tennis_counts("full")["iterations_per_expert"]
        side = "code" if k == FULL_ITERATIONS_PER_EXPERT["code"] else "thesis"
        punish = "punishments" if task.punishments == "code" else "A.3.3's punishments"
        return [(f"K = {k} at full" if side == "code" else f"Table A.1's K = {k}", side),
                (punish, task.punishments)]  # fmt: skip
    if name in _NO_CODE:
        return []
    known = ", ".join(("planar-reacher", "beer-pong", "table-tennis-ch3", *_NO_CODE))
    raise ValueError(f"no Chapter 3 settings for task {name!r}; expected one of {known}")


def settings_phrase(name: str, task: Any | None = None) -> str:
    """The phrase a figure of task ``name`` shows, e.g. "the authors' settings (SVSL_LMOE
    code): joint cost without the base joint".

    Args:
        name: a Chapter 3 task: ``"planar-reacher"``, ``"beer-pong"``,
            ``"table-tennis-ch3"`` or ``"reacher5-ch3"``.
        task: the task object; None builds the one the runs build (``make_task(name)``).
    """
    if name in _NO_CODE:
        return f"{THESIS} ({_NO_CODE[name]})"
    if task is None:
        from vslbook.envs.robot import make_task

        built = make_task(name)
        try:
            return settings_phrase(name, built)
        finally:
            built.close()
    choices = task_choices(name, task)
    code = [what for what, side in choices if side == "code"]
    thesis = [what for what, side in choices if side == "thesis"]
    if not thesis:
        return f"{CODE}: " + ", ".join(code)
    if not code:
        return f"{THESIS}: " + ", ".join(thesis)
    return f"{CODE}: " + ", ".join(code) + f"; {THESIS}: " + ", ".join(thesis)

"""Budget presets: how much compute a notebook, a test or a sweep spends.

A budget only scales *counts* (iterations, environment steps, seeds, evaluation
episodes); it never changes an algorithm or a hyper-parameter. The active preset comes
from the environment variable ``VSLBOOK_BUDGET`` (default ``reduced``):

``smoke``    every notebook in about a minute on 2 CPU cores: CI, "does it run".
``reduced``  a chapter in minutes to hours on a laptop (Chapter 5, with 3 seeds per curve:
             about three hours on 2 cores); large enough for the qualitative result of a
             figure to show.
``full``     the thesis's own budgets (iterations, steps, 10 seeds): meant for a cluster
             through :mod:`vslbook.sweep`.

An experiment states its full-budget counts (from the thesis) and asks the budget for
its share: ``budget.scale(1_000_000)`` or, where a fraction is not a good fit (e.g. the
length of a stand-in experiment the thesis does not have), a count per budget with
``budget.pick(smoke=..., reduced=..., full=...)`` and :meth:`Budget.full_count`. Network
sizes are not counts: a smaller network is a named configuration
(:data:`vslbook.srl.dime_config.NAMED_CONFIGS`), chosen visibly, never implied by a budget.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import TypeVar

T = TypeVar("T")

ENV_VAR = "VSLBOOK_BUDGET"
DEFAULT = "reduced"


@dataclass(frozen=True)
class Budget:
    """A compute preset.

    Attributes:
        name: ``smoke``, ``reduced`` or ``full``.
        fraction: share of the thesis's iteration / step counts.
        seeds: seeds per configuration (the thesis uses 10 for DIME, >= 4 elsewhere).
        eval_episodes: evaluation episodes per evaluation point.
        bootstrap_reps: bootstrap resamples for confidence intervals.
    """

    name: str
    fraction: float
    seeds: int
    eval_episodes: int
    bootstrap_reps: int

    def scale(self, full: int, minimum: int = 1) -> int:
        """The share of a full-budget count ``full`` under this budget (at least ``minimum``)."""
        if full < 0:
            raise ValueError(f"full-budget count must be >= 0, got {full}")
        return max(int(minimum), int(round(full * self.fraction)))

    def full_count(self, count: int) -> int:
        """The full-budget count that this budget scales to exactly ``count``.

        For experiments that are not the thesis's (so have no thesis count to scale) and
        state their length per budget: ``budget.full_count(budget.pick(smoke=5_200, ...))``.

        Raises:
            ValueError: ``count`` is negative, or no integer full count scales to it.
        """
        if isinstance(count, bool) or not isinstance(count, int) or count < 0:
            raise ValueError(f"count must be an integer >= 0, got {count!r}")
        full = int(round(count / self.fraction))
        if self.scale(full, minimum=0) != count:
            raise ValueError(
                f"no full-budget count scales to {count} at budget {self.name!r} "
                f"(fraction {self.fraction:g}); pick a multiple of {1 / self.fraction:g}"
            )
        return full

    def pick(self, *, smoke: T, reduced: T, full: T) -> T:
        """Choose one of three explicitly given values by budget name."""
        return {"smoke": smoke, "reduced": reduced, "full": full}[self.name]


BUDGETS: dict[str, Budget] = {
    "smoke": Budget("smoke", fraction=0.002, seeds=2, eval_episodes=2, bootstrap_reps=200),
    "reduced": Budget("reduced", fraction=0.05, seeds=3, eval_episodes=5, bootstrap_reps=2000),
    "full": Budget("full", fraction=1.0, seeds=10, eval_episodes=10, bootstrap_reps=50000),
}


def get_budget(name: str | Budget | None = None) -> Budget:
    """Return a preset by name, or the one named by ``$VSLBOOK_BUDGET`` (default ``reduced``).

    Raises:
        ValueError: for an unknown name; the message lists the valid ones.
    """
    if isinstance(name, Budget):
        return name
    if name is None:
        name = os.environ.get(ENV_VAR, DEFAULT)
    key = str(name).strip().lower()
    if key not in BUDGETS:
        source = f" (from ${ENV_VAR})" if name == os.environ.get(ENV_VAR) else ""
        raise ValueError(f"unknown budget {name!r}{source}; expected one of {', '.join(BUDGETS)}")
    return BUDGETS[key]

"""Chapter 3's figures and the runs each draws at a budget (the declaration
:mod:`vslbook.experiments.run_plan` reads).

* ``fig3-2``: beer pong (Fig. 3.2a, e, f; Fig. A.1) and table tennis (Fig. 3.2b-d; Fig. A.2),
  SVSL against HiREPS and LaDiPS, with each task's seeds and counts
  (:func:`vslbook.experiments.svsl_beer_pong.beer_pong_counts`,
  :func:`vslbook.experiments.svsl_table_tennis.table_tennis_counts`). Each run is the one
  ``vslbook run svsl|hireps|ladips --env ENV --seed S --budget B`` trains
  (:mod:`vslbook.experiments.ch3_algorithms`): the configuration is the budget's preset,
  with no overrides.

Figs. 3.1 (planar reacher) and 3.5 (5-link reacher with PPO) train through their own
modules (:mod:`vslbook.experiments.svsl_planar`, :mod:`vslbook.experiments.svsl_reacher`)
and are not declared here yet.
"""

from __future__ import annotations

from vslbook.budget import Budget, get_budget
from vslbook.experiments.ch3_algorithms import env_of, task_counts
from vslbook.experiments.run_plan import FigureRun
from vslbook.experiments.svsl_context import METHODS

__all__ = ["FIGURE_TASKS", "METRIC", "figure_runs"]

#: figure → its tasks (each drawn with every method of METHODS)
FIGURE_TASKS = {"fig3-2": ("beer-pong", "table-tennis-ch3")}
#: figure → the metric its claim is about (Fig. 3.2e/f: success over the context grid; the
#: runs' test success on contexts from p(c) is the recorded summary of it)
METRIC = {"fig3-2": "test_success"}


def figure_runs(figure: str, budget: Budget | str | None = None) -> list[FigureRun]:
    """The runs ``figure`` draws at ``budget``: per task, each method for the task's seeds,
    as long as the preset of ``vslbook run`` (SVSL's N·K + weight iterations; the
    baselines' iterations)."""
    from vslbook.registry import get_algorithm

    if figure not in FIGURE_TASKS:
        raise ValueError(f"unknown figure {figure!r}; expected one of {sorted(FIGURE_TASKS)}")
    b = get_budget(budget)
    runs = []
    for task in FIGURE_TASKS[figure]:
        env = env_of(task)
        for method in METHODS:
            algo = method.lower()
            config = get_algorithm(algo).default_config(env, b, {})
            length = getattr(config, "total_iterations", None) or config.iterations
            runs += [FigureRun(figure, method, algo, env, seed, b.name, length)
                     for seed in range(task_counts(task, b)["seeds"])]  # fmt: skip
    return runs

"""Chapter 3's figures and the runs each draws at a budget (the declaration
:mod:`vslbook.experiments.run_plan` reads).

Every run is the one ``vslbook run ALGO --env ENV --seed S --budget B [--set k=v]`` trains
(:mod:`vslbook.experiments.ch3_algorithms`, :func:`vslbook.training.run`): the
configuration is the budget's preset with the run's declared ``overrides``, so the command
line, the notebook, ``vslbook figure`` and ``vslbook plan`` name the same run directories.

* ``fig3-1``: the planar reacher (Section 3.4.1, Fig. 3.1): SVSL, SVSL without the
  responsibilities (``--set responsibilities=false``: log π̃(o | c, θ) and log π̃(o | c)
  set to zero) and HiREPS, with the seeds and counts of
  :func:`vslbook.experiments.svsl_planar.planar_counts`.
* ``fig3-2``: beer pong (Fig. 3.2a, e, f; Fig. A.1) and table tennis (Fig. 3.2b-d; Fig. A.2),
  SVSL against HiREPS and LaDiPS, with each task's seeds and counts
  (:func:`vslbook.experiments.svsl_beer_pong.beer_pong_counts`,
  :func:`vslbook.experiments.svsl_table_tennis.table_tennis_counts`); no overrides.
* ``fig3-5``: the 5-link reacher (Section 3.4.3, Fig. 3.5), SVSL on the episodic task and
  PPO on the step-based one, each with the reward of one panel (``--set reward=3.8|3.9|3.10``,
  Eqs. 3.8-3.10), with the seeds and counts of
  :func:`vslbook.experiments.svsl_reacher.reacher_counts` (PPO only on the rewards of its
  ``ppo_rewards``). A run's method is ``"SVSL Eq. 3.8"`` and the like: one key per curve.

:func:`run_set` trains (or reuses) a figure's runs and returns their directories by method.
"""

from __future__ import annotations

from pathlib import Path

from vslbook.budget import Budget, get_budget
from vslbook.experiments.ch3_algorithms import PPO_ENVS, env_of, task_counts
from vslbook.experiments.run_plan import FigureRun
from vslbook.experiments.svsl_context import METHODS

__all__ = ["FIGURE_TASKS", "METRIC", "PLANAR_OVERRIDES", "figure_runs", "reacher_method",
           "run_set"]  # fmt: skip

#: figure → its tasks
FIGURE_TASKS = {
    "fig3-1": ("planar-reacher",),
    "fig3-2": ("beer-pong", "table-tennis-ch3"),
    "fig3-5": ("reacher5-ch3",),
}
#: figure → the metric its claim is about, or algorithm → metric where the figure's
#: algorithms log it under different keys (Fig. 3.2e/f: success over the context grid; the
#: runs' test success on contexts from p(c) is the recorded summary of it). Fig. 3.1 draws
#: trained models; its runs' test return is their recorded summary. Fig. 3.5: the thesis's
#: un-normalised return on the same fixed evaluation goals, which SVSL logs as
#: ``test_return`` and PPO as ``eval_return`` (the two columns
#: :func:`vslbook.experiments.svsl_reacher.reacher_curves` draws).
METRIC: dict[str, str | dict[str, str]] = {
    "fig3-1": "test_return",
    "fig3-2": "test_success",
    "fig3-5": {"svsl": "test_return", "ppo": "eval_return"},
}

#: Fig. 3.1's variants (:data:`vslbook.experiments.svsl_planar.VARIANTS`) as
#: (algorithm, overrides of its planar-reacher preset)
PLANAR_OVERRIDES: dict[str, tuple[str, dict[str, str]]] = {
    "SVSL": ("svsl", {}),
    "SVSL, no responsibilities": ("svsl", {"responsibilities": "false"}),
    "HiREPS": ("hireps", {}),
}


def reacher_method(method: str, reward: str) -> str:
    """The method key of a Fig. 3.5 run: ``"SVSL Eq. 3.10"``, ``"PPO Eq. 3.8"``."""
    return f"{method} Eq. {reward}"


def _run(figure: str, method: str, algo: str, env: str, seed: int, b: Budget,
         overrides: dict[str, str]) -> FigureRun:  # fmt: skip
    """A run as long as its preset with ``overrides`` (SVSL's N·K + weight iterations, the
    baselines' iterations, PPO's environment steps)."""
    from vslbook.registry import config_from_overrides, get_algorithm

    spec = get_algorithm(algo)
    config = config_from_overrides(spec.config, overrides, spec.default_config(env, b, overrides))
    if algo == "ppo":
        return FigureRun(figure, method, algo, env, seed, b.name, config.total_steps,
                         unit="env_steps", overrides=dict(overrides))  # fmt: skip
    length = getattr(config, "total_iterations", None) or config.iterations
    return FigureRun(figure, method, algo, env, seed, b.name, length,
                     overrides=dict(overrides))  # fmt: skip


def figure_runs(figure: str, budget: Budget | str | None = None) -> list[FigureRun]:
    """The runs ``figure`` draws at ``budget``, method by method, seeds in order."""
    if figure not in FIGURE_TASKS:
        raise ValueError(f"unknown figure {figure!r}; expected one of {sorted(FIGURE_TASKS)}")
    b = get_budget(budget)
    if figure == "fig3-1":
        from vslbook.experiments.svsl_planar import VARIANTS, planar_counts

        env, seeds = env_of("planar-reacher"), planar_counts(b)["seeds"]
        return [_run(figure, v, PLANAR_OVERRIDES[v][0], env, seed, b, PLANAR_OVERRIDES[v][1])
                for v in VARIANTS for seed in range(seeds)]  # fmt: skip
    if figure == "fig3-5":
        from vslbook.experiments.svsl_reacher import REWARDS, reacher_counts

        n = reacher_counts(b)
        ppo_env = next(iter(PPO_ENVS))
        runs = []
        for reward in REWARDS:
            sets = {"reward": reward}
            runs += [_run(figure, reacher_method("SVSL", reward), "svsl", env_of("reacher5-ch3"),
                          seed, b, sets) for seed in range(n["seeds"])]  # fmt: skip
            if reward in n["ppo_rewards"]:
                runs += [_run(figure, reacher_method("PPO", reward), "ppo", ppo_env, seed, b,
                              sets) for seed in range(n["seeds"])]  # fmt: skip
        return runs
    runs = []
    for task in FIGURE_TASKS[figure]:
        env = env_of(task)
        for method in METHODS:
            runs += [_run(figure, method, method.lower(), env, seed, b, {})
                     for seed in range(task_counts(task, b)["seeds"])]  # fmt: skip
    return runs


def run_set(
    figure: str, budget: Budget | str | None = None, root: str | Path = "runs",
    *, methods: tuple[str, ...] | None = None, progress: bool = False,
) -> dict[str, list[Path]]:  # fmt: skip
    """Train (or reuse, where finished) every run of ``figure`` at ``budget`` in ``root``
    (:func:`figure_runs`, :meth:`FigureRun.train`): method → run directories in seed order;
    ``methods`` picks some of them. :func:`vslbook.experiments.figure_sources.figure_set` in
    mode ``retrain``.

    Raises:
        ValueError: a method the figure does not draw.
        RuntimeError: a run diverged.
    """
    from vslbook.experiments.figure_sources import figure_set

    return figure_set(figure, budget, root, methods=methods, mode="retrain",
                      progress=progress).runs  # fmt: skip

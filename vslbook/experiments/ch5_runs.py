"""Chapter 5's figures and the runs each draws at a budget (the declaration
:mod:`vslbook.experiments.run_plan` reads), and the notebook's way to draw them.

Chapter 5's live run sets (:func:`vslbook.experiments.dime_runs.chapter5_run_sets`) are
registered as figures, so ``vslbook plan``, ``vslbook record`` and
:func:`vslbook.experiments.figure_sources.figure_set` read and write them as Chapters 3
and 4's. A figure's id names the thesis figure its runs reproduce:

* ``fig5-3-cheetah``: DIME on DeepMind Control cheetah-run beside the published DIME curve
  of that task. Fig. 5.3 is the thesis's figure of DeepMind Control training curves; the
  thesis plots dog and humanoid tasks, which a CPU cannot train, so this run stands beside
  the published curves of Figs. 5.2-5.3 (``fig5-2-published``, ``fig5-3-published``) as
  the one DeepMind Control task trained live.
* ``fig5-ablations``: the ablations on Pendulum-v1, one variant per switch the thesis
  studies in Figs. 5.2c-d, 5.4, 5.5-5.6, 5.8 and C.2, and CrossQ; no single thesis figure,
  so the id names the set.
* ``fig5-7``: the four-goal point mass of Fig. 5.7, one run per fixed α.

A run's method is its variant's label (``"fixed α = 0.1"``, ``"α = 5"``), its overrides
are the set's common configuration (the named network configuration and the counts) with
the variant's own, as ``vslbook run dime --set k=v`` strings: the command line trains the
very run directory :func:`vslbook.experiments.dime_runs.run_variants` makes. Its length is
the run's environment steps at the budget (DIME logs one metrics row per evaluation, its
``step`` the environment steps so far).

The named configurations are those the notebook shows: ``cpu-256`` for cheetah-run,
``cpu-64`` for the small tasks, or ``$VSLBOOK_DIME_CONFIG`` for all (:func:`live_configs`).

:func:`chapter5_figure` is what the notebook calls: the figure's runs from
:func:`~vslbook.experiments.figure_sources.figure_set` (recorded, finished, or trained now)
as the :class:`~vslbook.experiments.dime_runs.VariantRuns` its cells draw. Where runs are
trained now, the whole set is trained first by
:meth:`~vslbook.experiments.dime_runs.RunSet.run` (``figure_set``'s ``train_set``), so a
variant's seeds train together on one seed axis as before; ``figure_set`` then reuses them.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from vslbook.budget import Budget, get_budget
from vslbook.experiments.dime_runs import RunSet, VariantRuns, chapter5_run_sets
from vslbook.experiments.run_plan import FigureRun

__all__ = ["DIME_CONFIG_ENV", "FIGURES", "METRIC", "chapter5_figure", "figure_runs",
           "live_configs", "set_string", "variant_runs_from"]  # fmt: skip

#: figure id → the name of its run set in :func:`chapter5_run_sets`
FIGURES = {"fig5-3-cheetah": "cheetah", "fig5-ablations": "ablations", "fig5-7": "pointmass"}
#: figure → the metric it plots (every DIME run logs its evaluation return so)
METRIC: dict[str, str] = dict.fromkeys(FIGURES, "eval_return")
#: the environment variable that names one named configuration for every run set
DIME_CONFIG_ENV = "VSLBOOK_DIME_CONFIG"


def live_configs() -> dict[str, str]:
    """The named configurations of the live runs: ``{"dmc": ..., "small": ...}`` (the
    keywords of :func:`chapter5_run_sets`), ``$VSLBOOK_DIME_CONFIG`` for both where set."""
    named = os.environ.get(DIME_CONFIG_ENV, "").strip()
    return {"dmc": named or "cpu-256", "small": named or "cpu-64"}


def run_set(figure: str, budget: Budget | str | None = None) -> RunSet:
    """The live run set ``figure`` draws at ``budget`` (with :func:`live_configs`)."""
    if figure not in FIGURES:
        raise ValueError(f"unknown figure {figure!r}; expected one of {sorted(FIGURES)}")
    return chapter5_run_sets(budget, **live_configs())[FIGURES[figure]]


def set_string(value: Any) -> str:
    """``value`` as ``vslbook run --set`` takes it (``true``/``false`` for booleans)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


def figure_runs(figure: str, budget: Budget | str | None = None) -> list[FigureRun]:
    """The runs ``figure`` draws at ``budget``, variant by variant, seeds in order."""
    from vslbook.registry import config_from_overrides, get_algorithm
    from vslbook.srl.dime_state import Schedule

    b = get_budget(budget)
    rs = run_set(figure, b)
    runs = []
    for label, (algo, own) in rs.variants.items():
        over = {**rs.common, **own}
        spec = get_algorithm(algo)
        config = config_from_overrides(spec.config, over, spec.default_config(rs.env, b, over))
        length = Schedule.of(config, b).total_steps
        sets = {k: set_string(v) for k, v in over.items()}
        runs += [FigureRun(figure, label, algo, rs.env, seed, b.name, length, overrides=sets,
                           counts="env steps")  # DIME's ``step`` counts env steps
                 for seed in range(rs.seeds)]  # fmt: skip
    return runs


def variant_runs_from(fs: Any, tables: str | Path) -> VariantRuns:
    """A :class:`~vslbook.experiments.figure_sources.FigureSet` of a Chapter 5 figure as
    the :class:`VariantRuns` its notebook cells draw: the runs' metrics collected into
    ``tables`` (:func:`vslbook.data.collect_runs`) and read back with a ``variant`` column,
    the run directories by label, and each label's overrides at the runs' budget (for the
    captions)."""
    from vslbook.data import collect_runs, load_table
    from vslbook.results import RunDir

    rs = run_set(fs.figure, fs.budget)
    by_label = {label: [RunDir(p) for p in fs.runs[label]] for label in rs.variants
                if label in fs.runs}  # fmt: skip
    labels = {rd.name: label for label, rds in by_label.items() for rd in rds}
    collect_runs([rd for rds in by_label.values() for rd in rds], tables)
    evals = load_table("evals.csv.gz", tables)
    evals["variant"] = evals["run"].map(labels)
    used = {label: (algo, {**rs.common, **own}) for label, (algo, own) in rs.variants.items()
            if label in by_label}  # fmt: skip
    return VariantRuns(evals, by_label, used)


def chapter5_figure(
    figure: str, root: str | Path, tables: str | Path, *, budget: Budget | str | None = None,
    mode: str | None = None, progress: bool = True,
) -> tuple[Any, VariantRuns]:  # fmt: skip
    """The runs of ``figure`` from where ``mode`` says (:func:`figure_set`) and the
    :class:`VariantRuns` of them, its tables in ``tables/ch5-<set>-<budget>``.

    Runs trained now (nothing recorded or finished, or mode ``retrain``) are trained as
    the notebook always trained them, by :meth:`RunSet.run` in ``root``: seeds on one
    seed axis where the set has several.
    """
    from vslbook.experiments.figure_sources import figure_set

    if figure not in FIGURES:
        raise ValueError(f"unknown figure {figure!r}; expected one of {sorted(FIGURES)}")
    name = FIGURES[figure]

    def train_set(b: Budget) -> None:
        run_set(figure, b).run(b, root, Path(tables) / f"ch5-{name}-{b.name}", progress=progress)

    fs = figure_set(figure, budget, root, mode=mode, progress=progress, train_set=train_set)
    return fs, variant_runs_from(fs, Path(tables) / f"ch5-{name}-{fs.budget}")

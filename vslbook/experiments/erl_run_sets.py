"""The training behind the Chapter 3 and 4 notebooks, as named run sets.

Each run set trains (or reuses, where finished) exactly the runs one notebook cell
starts, through the same functions (for Figs. 3.1, 3.5 and Chapter 4 the figure's declared
runs, :mod:`vslbook.experiments.run_plan`), so that the cost of a chapter at a budget can be
measured set by set (``benchmarks/erl_run_sets.py``) or the runs trained ahead of a
``make book``, e.g. one set per core. Chapter 5's run sets are
:func:`vslbook.experiments.dime_runs.chapter5_run_sets`.

* Chapter 3 (``03_svsl``): ``planar`` (Fig. 3.1), ``beer-pong`` (Fig. 3.2a, A.1),
  ``table-tennis`` (Figs. 3.2b, 3.3, A.2), ``reacher`` (Fig. 3.5, with PPO);
* Chapter 4 (``04_diskill``): the figures of
  :data:`vslbook.experiments.diskill_runs.FIGURES` (``4.3b`` … ``4.4d``), each with the PPO
  runs the notebook draws in it (5LR at every budget, box pushing above ``smoke``).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from vslbook.budget import Budget, get_budget

__all__ = ["RUN_SETS", "run_sets"]

RunSet = Callable[[Budget, Path, bool], dict[str, list[Path]]]


def _planar(budget: Budget, root: Path, progress: bool) -> dict[str, list[Path]]:
    from vslbook.experiments.ch3_runs import run_set

    return run_set("fig3-1", budget, root, progress=progress)


def _beer_pong(budget: Budget, root: Path, progress: bool) -> dict[str, list[Path]]:
    from vslbook.experiments import svsl_beer_pong as BP

    return BP.run_all(root, budget, progress=progress)


def _table_tennis(budget: Budget, root: Path, progress: bool) -> dict[str, list[Path]]:
    from vslbook.experiments import svsl_table_tennis as TT

    return TT.run_all(root, budget, progress=progress)


def _reacher(budget: Budget, root: Path, progress: bool) -> dict[str, list[Path]]:
    from vslbook.experiments import svsl_reacher as RE

    runs = RE.reacher_runs(root, budget, progress=progress)
    return {f"{method} Eq. {reward}": paths for (method, reward), paths in runs.items()}


def _figure(figure: str) -> RunSet:
    def train(budget: Budget, root: Path, progress: bool) -> dict[str, list[Path]]:
        from vslbook.experiments import diskill_runs as DR

        return DR.run_set(figure, budget, root, progress=progress)

    return train


def _chapter4() -> dict[str, RunSet]:
    from vslbook.experiments.diskill_runs import FIGURES

    return {figure: _figure(figure) for figure in FIGURES}


#: chapter → run-set name → ``train(budget, root, progress) -> {method: [run dirs]}``.
RUN_SETS: dict[int, dict[str, RunSet]] = {
    3: {"planar": _planar, "beer-pong": _beer_pong, "table-tennis": _table_tennis,
        "reacher": _reacher},  # fmt: skip
    4: _chapter4(),
}


def run_sets(
    chapter: int,
    budget: Budget | str | None = None,
    root: str | Path = "runs",
    *,
    only: list[str] | tuple[str, ...] | None = None,
    progress: bool = False,
    report: Callable[[str, int, float], None] | None = None,
) -> dict[str, dict[str, list[Path]]]:
    """Train (or reuse) the run sets of ``chapter`` at ``budget`` in ``root``, in order.

    ``only``: these sets, by name. ``report(name, runs, seconds)`` is called after each set
    with its number of runs and wall time. Returns set name → method → run directories.
    """
    import time

    if chapter not in RUN_SETS:
        raise ValueError(f"chapter must be one of {sorted(RUN_SETS)}, got {chapter!r}")
    sets = RUN_SETS[chapter]
    unknown = sorted(set(only or ()) - set(sets))
    if unknown:
        raise ValueError(f"unknown run set(s) {unknown} of Chapter {chapter}; the sets are "
                         f"{list(sets)}")  # fmt: skip
    b = get_budget(budget)
    out = {}
    for name, train in sets.items():
        if only and name not in only:
            continue
        start = time.perf_counter()
        out[name] = train(b, Path(root), progress)
        if report is not None:
            report(name, sum(len(p) for p in out[name].values()), time.perf_counter() - start)
    return out

"""Fig. 3.2e/f over seeds: the mean success grid of a method's beer-pong runs.

Section 3.4.2 draws each of the two panels as a mean over models: for every cell of a fine
grid of cup positions it draws 100 experts from π(o | c), executes each one's mean, and
"repeated that for all 20 different models and plot[s] the mean success rate". A finished
run logs its final model's grid in its last row
(:func:`vslbook.experiments.svsl_beer_pong.grid_metrics`), so the mean over seeds needs no
model: this module averages the logged grids cell by cell. The mean of the averaged grid is
the mean of the seeds' ``grid_success``, the number the thesis reports as 92 % and 75 %.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from vslbook.budget import Budget
from vslbook.experiments import svsl_beer_pong as BP
from vslbook.results import RunDir

__all__ = ["logged_grids", "seeds_grid"]


def logged_grids(paths: Sequence[str | Path], budget: Budget | str) -> list[tuple[int, np.ndarray]]:
    """(seed, grid) for each run in ``paths`` whose last row holds its final grid at
    ``budget``'s cells (shape (n_y, n_x)); runs without one (probes, runs made before the
    cells were logged) are left out."""
    shape = BP.beer_pong_counts(budget)["grid"]
    out = []
    for path in paths:
        run = RunDir.open(path)
        rows = run.metrics()
        grid = BP.logged_grid(rows[-1], shape) if rows else None
        if grid is not None:
            out.append((int(run.config.get("seed", -1)), grid))
    return out


def seeds_grid(paths: Sequence[str | Path], budget: Budget | str) -> tuple[np.ndarray, str]:
    """Fig. 3.2e/f for one method: the mean success grid over the runs in ``paths``
    (trained at ``budget``) and a note on what was averaged.

    Where at least one run logged its final grid, the grid is the cell-by-cell mean of the
    logged grids, as the thesis draws it over its 20 models. Where none did (only probes),
    it is the first run's grid from its checkpoint
    (:func:`vslbook.experiments.svsl_beer_pong.drawn_grid`).

    Raises:
        ValueError: ``paths`` is empty.
    """
    if len(paths) == 0:
        raise ValueError("paths must name at least one beer-pong run, got none")
    grids = logged_grids(paths, budget)
    if not grids:
        grid, how = BP.drawn_grid(paths[0], budget)
        seed = RunDir.open(paths[0]).config.get("seed", "?")
        return grid, f"seed {seed}, {how}"
    draws = BP.beer_pong_counts(budget)["grid_draws"]
    seeds = ", ".join(str(s) for s, _ in grids)
    if len(grids) == 1:
        what = f"seed {seeds}'s final model"
    else:
        what = f"mean of seeds {seeds}, final models"
    mean = np.mean([g for _, g in grids], axis=0)
    return mean, f"{what}, {draws} draws per cell"

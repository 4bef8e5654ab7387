"""Fig. 3.2e/f over seeds: the mean of the finished runs' logged success grids."""

import numpy as np
import pytest

from vslbook.experiments import beer_pong_grids as G
from vslbook.experiments import svsl_beer_pong as BP
from vslbook.results import RunDir

# smoke's grid: 2 cells along x, 3 along y, 2 draws per cell
GRIDS = {
    0: np.array([[0.0, 0.5], [1.0, 1.0], [0.5, 0.0]]),
    1: np.array([[1.0, 0.5], [0.5, 1.0], [0.0, 0.0]]),
    2: np.array([[0.5, 1.0], [1.0, 0.5], [1.0, 0.5]]),
}


def _run(tmp_path, seed, grid=None):
    rd = RunDir.create(tmp_path, {"algo": "SVSL", "env": "bp", "seed": seed})
    rd.log(10, test_success=0.5)
    last = {"test_success": 0.75}
    if grid is not None:  # a finished run's last row holds its final grid
        last.update(BP.grid_metrics(grid))
    rd.log(20, **last)
    return rd.path


def test_the_mean_over_seeds_of_the_logged_grids(tmp_path):
    paths = [_run(tmp_path, s, g) for s, g in GRIDS.items()]
    grid, how = G.seeds_grid(paths, "smoke")
    # cell by cell, by hand: e.g. the first cell (0 + 1 + 0.5) / 3
    assert grid[0, 0] == pytest.approx(0.5) and grid[2, 1] == pytest.approx(0.5 / 3)
    assert grid[1, 0] == pytest.approx(2.5 / 3)
    np.testing.assert_allclose(grid, sum(GRIDS.values()) / 3)
    # its mean is the mean of the seeds' grid_success (the thesis's 92 % and 75 %)
    rows = [RunDir.open(p).metrics()[-1]["grid_success"] for p in paths]
    assert grid.mean() == pytest.approx(np.mean(rows))
    assert how == "mean of seeds 0, 1, 2, final models, 2 draws per cell"


def test_runs_without_a_logged_grid_are_left_out(tmp_path):
    paths = [_run(tmp_path, 0, GRIDS[0]), _run(tmp_path, 1), _run(tmp_path, 2, GRIDS[2])]
    grid, how = G.seeds_grid(paths, "smoke")
    np.testing.assert_allclose(grid, (GRIDS[0] + GRIDS[2]) / 2)
    assert how.startswith("mean of seeds 0, 2,")
    assert [s for s, _ in G.logged_grids(paths, "smoke")] == [0, 2]
    grid, how = G.seeds_grid(paths[1:2] + paths[2:], "smoke")
    np.testing.assert_array_equal(grid, GRIDS[2])
    assert how == "seed 2's final model, 2 draws per cell"


def test_only_probes_draw_the_first_from_its_checkpoint(tmp_path, monkeypatch):
    paths = [_run(tmp_path, 3), _run(tmp_path, 4)]
    drawn = np.full((3, 2), 0.25)
    seen = []

    def fake_drawn_grid(path, budget):
        seen.append((path, budget))
        return drawn, "2 draws per cell"

    monkeypatch.setattr(BP, "drawn_grid", fake_drawn_grid)
    grid, how = G.seeds_grid(paths, "smoke")
    assert grid is drawn and seen == [(paths[0], "smoke")]
    assert how == "seed 3, 2 draws per cell"


def test_a_grid_of_other_cells_is_not_read(tmp_path):
    """A grid logged on fewer cells than this budget's (a row y = 2 missing) is left out."""
    paths = [_run(tmp_path, 0, np.zeros((2, 2)))]
    assert G.logged_grids(paths, "smoke") == []


def test_no_runs_is_an_error():
    with pytest.raises(ValueError, match="at least one beer-pong run, got none"):
        G.seeds_grid([], "smoke")

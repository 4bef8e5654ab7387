"""Fig. 3.2 (Beer Pong panels a, c, e, f, g) and Fig. A.1: SVSL, HiREPS and LaDiPS on beer pong.

The thesis (Section 3.4.2, Appendix A.3.2) trains SVSL with N = 70 experts added one by one
(K = 750 iterations each, all experts fine-tuned every H = 50 iterations; α = 0.001, β = 0.5,
β_w = 2.5, Table A.1) and HiREPS (ε 0.3, κ 0.9, Table A.2) and LaDiPS (ε 0.1, ε_gating 0.05,
α = log 30, Table A.3) with all 70 experts from the start, over 20 seeds. Its reported
outcome (:data:`THESIS_OUTCOME`): LaDiPS is the most sample-efficient (intra-option
learning), SVSL reaches the highest final reward, HiREPS converges early after about half a
million samples; SVSL's per-expert context distributions cover the whole cup box; executing
the means of experts drawn from π(o | c) on a fine grid of cup positions succeeds 92 % of
the time for SVSL and 75 % for HiREPS on average; for one context, 20 draws from SVSL's
mixture give ball trajectories with different numbers of bounces; and SVSL's mixture has a
much higher expected entropy than LaDiPS's and HiREPS's (Fig. A.1).

What is computed here, and how (the task-independent code is
:mod:`vslbook.experiments.svsl_mixtures`, shared with table tennis):

* :func:`beer_pong_counts` — the counts per budget (a budget scales only counts: experts,
  iterations, seeds, samples per baseline iteration, test contexts, grid cells and draws;
  α, β, β_w, H, the KL bounds and the baselines' ε, κ, α stay the thesis's).
* :func:`run_beer_pong` — one method for one seed in a resumable run directory. The
  baselines run for as many iterations as SVSL evaluates episodes
  (:func:`svsl_episodes`), so the three curves span the same number of episodes.
  :func:`run_all`: every method for the budget's seeds (the notebook's run set).
* :func:`curve_frame` / :func:`learning_curves` — Fig. 3.2a: test return of the mixture
  (θ ~ π(θ | c) on fixed test contexts from p(c)) against *executed* episodes (θ rejected
  before simulation are not counted, A.3.2), IQM and 95 % stratified-bootstrap CI over the
  seeds (the thesis plots the mean ± 2 standard errors). Each run is interpolated onto a
  common grid of episode counts first (runs log at different counts).
* :func:`draw_context_coverage` — Fig. 3.2c: SVSL's per-expert context Gaussians.
* :func:`success_grid` — Fig. 3.2e/f: per cell of a grid over the cup box, experts drawn
  from π(o | c) at the cell's centre and their means executed; the success rate per cell.
* :func:`ball_trajectories` — Fig. 3.2g: the ball's height over time for draws from the
  mixture at one context, with the chosen expert.
* Fig. A.1: the mixture's expected entropy E_c H[π(θ | c)] (Monte Carlo on a grid of
  contexts), logged as ``expected_entropy`` at every test point of every run;
  ``learning_curves(runs, "expected_entropy")`` gives its curves.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from vslbook.budget import Budget, get_budget
from vslbook.erl.svsl import svsl_config  # noqa: F401  (part of this module's namespace)
from vslbook.experiments import svsl_mixtures as mx
from vslbook.experiments.svsl_mixtures import (
    METHODS,
    curve_frame,
    learning_curves,
    load_model,
    mixture_of,
    svsl_episodes,
)
from vslbook.results import RunDir

__all__ = [
    "ENV",
    "METHODS",
    "TASK",
    "THESIS_OUTCOME",
    "ball_trajectories",
    "beer_pong_counts",
    "curve_frame",
    "draw_ball_trajectories",
    "draw_context_coverage",
    "draw_success_grid",
    "draw_learning_curves",
    "drawn_grid",
    "GRID_CELL",
    "grid_contexts",
    "grid_metrics",
    "learning_curves",
    "load_model",
    "logged_grid",
    "method_config",
    "mixture_of",
    "run_all",
    "run_beer_pong",
    "success_grid",
    "svsl_episodes",
]

TASK = "beer-pong"
#: its one-step gymnasium id (``vslbook run ... --env``; the figure's runs of this task)
ENV = "vslbook/BeerPong-v0"

#: What the thesis reports for the beer-pong panels (Section 3.4.2, Fig. 3.2, A.3.2.1).
THESIS_OUTCOME = {
    "curves": (
        "thesis (Fig. 3.2a): LaDiPS most sample-efficient, SVSL highest final reward, "
        "HiREPS converges early after ~0.5 M samples"
    ),
    "coverage": "thesis (Fig. 3.2c): SVSL's context distributions cover the whole cup box",
    "success": "thesis (Fig. 3.2e/f): success 92 % (SVSL) vs 75 % (HiREPS) on average",
    "success_svsl": 0.92,
    "success_hireps": 0.75,
    "trajectories": (
        "thesis (Fig. 3.2g): 20 draws at one context give ball trajectories with different "
        "numbers of bounces, one per expert"
    ),
    "entropy": (
        "thesis (Fig. A.1): SVSL's expected mixture entropy is much higher than LaDiPS's "
        "and HiREPS's"
    ),
}


# --------------------------------------------------------------------------------------
# counts and configurations
# --------------------------------------------------------------------------------------
def beer_pong_counts(budget: Budget | str | None = None) -> dict[str, Any]:
    """Counts of Fig. 3.2 (beer pong) and Fig. A.1 at a budget (full: the thesis's).

    Full: N = 70, K = 750, H = 50 (Table A.1), 20 seeds, the authors' 100 weight iterations;
    the baselines' 70 experts draw 700 episodes per iteration. The rest (test contexts, the
    success grid, the entropy grid) the thesis leaves open ("a fine grid"; 100 draws per
    context for the success rate, 1000 θ per context for the entropy).

    Smoke ("does it run") skips SVSL's weight phase (``weight_iterations = 0``) and runs one
    baseline iteration of 40 episodes; reduced (N = 3, K = 100, 3 seeds) takes about 6 min
    per SVSL run and 18 baseline iterations of 700 episodes on 2 cores. N and K are counts
    a budget may scale; H, α, β, β_w and the KL bounds are not.
    """
    b = get_budget(budget)
    return {
        "seeds": b.pick(smoke=1, reduced=3, full=20),
        "n_experts": b.pick(smoke=1, reduced=3, full=70),  # SVSL's N
        "iterations_per_expert": b.pick(smoke=3, reduced=100, full=750),  # K
        "fine_tune_every": 50,  # H: a hyper-parameter, never scaled
        "weight_iterations": b.pick(smoke=0, reduced=100, full=100),
        "test_every": b.pick(smoke=2, reduced=25, full=50),
        "test_contexts": b.pick(smoke=10, reduced=100, full=200),
        "baseline_experts": 70,  # Tables A.2, A.3 (LaDiPS's α = log 30 needs N >= 30)
        "baseline_samples": b.pick(smoke=40, reduced=700, full=700),
        # None: as many iterations as SVSL evaluates episodes (svsl_episodes)
        "baseline_iterations": b.pick(smoke=1, reduced=None, full=None),
        "grid": b.pick(smoke=(2, 3), reduced=(8, 12), full=(13, 20)),  # cells along (x, y)
        "grid_draws": b.pick(smoke=2, reduced=10, full=100),
        "entropy_grid": b.pick(smoke=(2, 2), reduced=(4, 6), full=(8, 12)),
        "entropy_draws": b.pick(smoke=20, reduced=200, full=1000),
        "trajectory_draws": b.pick(smoke=3, reduced=20, full=20),
    }


def method_config(method: str, budget: Budget | str | None = None) -> Any:
    """The configuration of one method at a budget (SVSLConfig, HiREPSConfig, LaDiPSConfig)."""
    return mx.method_config(TASK, method, beer_pong_counts(budget))


# --------------------------------------------------------------------------------------
# runs
# --------------------------------------------------------------------------------------
def _task() -> Any:
    """The beer-pong task shared by the runs and evaluations of this process."""
    return mx.shared_task(TASK)


def grid_contexts(shape: tuple[int, int]) -> np.ndarray:
    """Centres of an (n_x, n_y) grid of cells over the cup box, shape (n_y, n_x, 2)."""
    return mx.box_grid(TASK, shape)


def run_beer_pong(
    method: str, seed: int, root: str | Path, budget: Budget | str | None = None,
    *, progress: bool = False,
) -> Path:  # fmt: skip
    """Train one method for one seed in a run directory under ``root`` (reused if done).

    Rows of ``metrics.jsonl`` carry ``samples`` (executed episodes so far) and, every
    ``test_every`` iterations and at the end, ``test_return``, ``test_success`` and
    ``expected_entropy`` (:func:`vslbook.experiments.svsl_mixtures.run_method`).
    ``progress``: a bar over the iterations.
    """
    return mx.run_method(TASK, method, seed, root, budget, progress=progress)


def run_all(
    root: str | Path,
    budget: Budget | str | None = None,
    methods: tuple[str, ...] = METHODS,
    seeds: int | None = None,
    *,
    progress: bool = False,
) -> dict[str, list[Path]]:
    """Every method for seeds 0, …, ``seeds`` − 1 (default: the budget's), one after the
    other; returns ``{method: [run directories]}`` for :func:`learning_curves`."""
    n = beer_pong_counts(budget)["seeds"] if seeds is None else seeds
    return mx.run_methods(TASK, root, budget, methods, n, "beer pong runs", progress=progress)


def draw_learning_curves(
    ax: plt.Axes, curves: pd.DataFrame, *, ylabel: str = "test return (IQM)",
    thesis: str | None = THESIS_OUTCOME["curves"],
) -> plt.Axes:  # fmt: skip
    """Fig. 3.2a / A.1: one IQM line with its CI band per method, the thesis's outcome as text."""
    return mx.draw_learning_curves(ax, curves, ylabel=ylabel, thesis=thesis)


# --------------------------------------------------------------------------------------
# Fig. 3.2c, e, f, g
# --------------------------------------------------------------------------------------
def draw_context_coverage(ax: plt.Axes, model: Any) -> plt.Axes:
    """Fig. 3.2c: each expert's context Gaussian (2σ ellipse) over the cup box.

    For SVSL these are the curricula π(c | o); for a baseline its gating's N(c | μ_o, S_o).
    The opacity grows with π(o).
    """
    mx.draw_context_gaussians(ax, model, (0, 1))
    task = _task()
    mx.draw_box(ax, task.context_low, task.context_high)
    ax.set_xlim(-0.6, 0.6)
    ax.set_ylim(-2.5, -0.9)
    ax.set_aspect("equal")
    ax.set_xlabel("cup x [m]")
    ax.set_ylabel("cup y [m]")
    return ax


def success_grid(
    model: Any, shape: tuple[int, int] = (8, 12), *, n_draws: int = 10, seed: int = 0
) -> np.ndarray:
    """Fig. 3.2e/f: success rate per cell of an (n_x, n_y) grid over the cup box.

    At each cell's centre ``n_draws`` experts are drawn from π(o | c) and their means
    K_o c + k_o executed (the thesis: 100 draws per context); returns the fraction in the
    cup, shape (n_y, n_x) (row 0 at the smallest y).
    """
    return mx.success_grid(TASK, model, shape, n_draws=n_draws, seed=seed)


#: a cell of Fig. 3.2e/f's grid in a run's last row (:func:`grid_metrics`): column ix
#: (along x), row iy (along y)
GRID_CELL = "grid_success_x{ix:02d}_y{iy:02d}"


def grid_metrics(cells: np.ndarray) -> dict[str, float]:
    """Fig. 3.2e/f's grid as metrics for a run's last row: ``grid_success``, the mean over
    the cells (the number the thesis reports as 92 % and 75 %), and every cell's success
    rate as its own metric (:data:`GRID_CELL`), so that a recorded run keeps its grid.

    Args:
        cells: the success rates, shape (n_y, n_x), as :func:`success_grid` returns them.
    """
    grid = np.asarray(cells, dtype=np.float64)
    if grid.ndim != 2 or grid.size == 0:
        raise ValueError(f"cells must be a non-empty (n_y, n_x) array, got shape {grid.shape}")
    out = {"grid_success": float(grid.mean())}
    for iy, ix in np.ndindex(*grid.shape):
        out[GRID_CELL.format(ix=ix, iy=iy)] = float(grid[iy, ix])
    return out


def logged_grid(row: dict[str, Any], shape: tuple[int, int]) -> np.ndarray | None:
    """The grid of ``shape`` = (n_x, n_y) cells that a run's last ``row`` holds
    (:func:`grid_metrics`), shape (n_y, n_x); None where the row lacks any of its cells
    (a probe, or a run made before the cells were logged)."""
    n_x, n_y = shape
    names = [[GRID_CELL.format(ix=ix, iy=iy) for ix in range(n_x)] for iy in range(n_y)]
    if any(row.get(name) is None for line in names for name in line):
        return None
    return np.array([[float(row[name]) for name in line] for line in names])


def drawn_grid(path: str | Path, budget: Budget | str) -> tuple[np.ndarray, str]:
    """Fig. 3.2e/f's grid for the run at ``path`` (trained at ``budget``) and a note on how
    it was made.

    A finished run logged its final model's grid at the budget's cells and draws (13 × 20
    cells of 100 draws at ``full``, :func:`vslbook.experiments.ch3_algorithms.final_metrics`),
    so the grid drawn is the logged one. Otherwise (a probe, or a run made before the cells
    were logged) it is computed from the run's checkpoint, for a full run on the reduced
    grid: 100 draws on 13 × 20 cells take minutes per model.
    """
    b = get_budget(budget)
    counts = beer_pong_counts(b)
    rows = RunDir.open(path).metrics()
    grid = logged_grid(rows[-1], counts["grid"]) if rows else None
    if grid is not None:
        return grid, f"final model, {counts['grid_draws']} draws per cell"
    counts = beer_pong_counts("reduced" if b.name == "full" else b)
    grid = success_grid(load_model(path), counts["grid"], n_draws=counts["grid_draws"])
    return grid, f"{counts['grid_draws']} draws per cell"


def draw_success_grid(ax: plt.Axes, grid: np.ndarray, title: str = "") -> plt.Axes:
    """Fig. 3.2e/f: the success rates as an image over the cup box (dark: low)."""
    lo, hi = _task().context_low, _task().context_high
    extent = (lo[0], hi[0], lo[1], hi[1])
    return mx.draw_success_grid(ax, grid, extent, title=title, labels=("cup x [m]", "cup y [m]"))


def ball_trajectories(
    model: Any, context: Any, *, n_draws: int = 20, seed: int = 0
) -> list[dict[str, Any]]:
    """Fig. 3.2g: the ball's path for ``n_draws`` draws θ ~ π(θ | c) at one context.

    Each simulated draw gives ``{"expert", "t" (s), "z" (m), "success"}``; draws rejected
    before simulation (duration or joint limits, A.3.2) or unstable have no path and are
    left out.
    """
    n_draws = mx.check_count("n_draws", n_draws)
    task = _task()
    c = task.check_contexts(np.atleast_2d(np.asarray(context, dtype=np.float64)))
    if len(c) != 1:
        raise ValueError(f"context must be one cup position (x, y), got shape {np.shape(context)}")
    theta, experts = mixture_of(model).sample(
        np.repeat(c, n_draws, axis=0), np.random.default_rng(seed)
    )
    out = []
    for th, o in zip(theta, experts, strict=True):
        ep = task.episode(th, c[0])
        if not ep.executed or "in_cup" not in ep.info:
            continue
        path = task.ball_path
        out.append({
            "expert": int(o), "t": np.arange(len(path)) * 0.005, "z": path[:, 2].copy(),
            "success": bool(ep.success),
        })  # fmt: skip
    return out


def draw_ball_trajectories(ax: plt.Axes, trajectories: list[dict[str, Any]]) -> plt.Axes:
    """Fig. 3.2g: ball height over time, one colour per expert (solid: in the cup)."""
    from vslbook.plots import expert_color

    for tr in trajectories:
        ax.plot(tr["t"], tr["z"], color=expert_color(tr["expert"]), lw=1.0,
                ls="-" if tr["success"] else ":")  # fmt: skip
    ax.set_xlabel("time [s]")
    ax.set_ylabel("ball z [m]")
    return ax

"""SVSL, HiREPS and LaDiPS on any Chapter 3 robot task: runs, curves, coverage, success grids.

The task-independent part of Fig. 3.2 and Figs. A.1 / A.2 (thesis Section 3.4.2, Appendix
A.3.2, A.3.3); :mod:`vslbook.experiments.svsl_beer_pong` and
:mod:`vslbook.experiments.svsl_table_tennis` fill in the counts and drawings of one task.

A task is named as in :mod:`vslbook.envs.robot` (``"beer-pong"``, ``"table-tennis-ch3"``);
its counts are a dict (the ``*_counts(budget)`` functions of the task modules) with the keys

* ``n_experts``, ``iterations_per_expert``, ``fine_tune_every``, ``weight_iterations``,
  ``test_every``, ``test_contexts`` — SVSL's N, K, H, weight iterations and test protocol;
* ``baseline_experts``, ``baseline_samples``, ``baseline_iterations`` — the baselines' N,
  episodes per iteration and iterations (None: as many iterations as SVSL evaluates
  episodes, :func:`svsl_episodes`, so the three curves span the same number of episodes);
* ``entropy_draws`` and either ``entropy_grid`` (cells (n_x, n_y) over a 2-D context box)
  or ``entropy_contexts`` (that many contexts drawn once from p(c) with a fixed stream):
  where the expected mixture entropy E_c H[π(θ | c)] of Figs. A.1 / A.2 is estimated;
  optionally ``entropy_every``: estimate it only at every that-many-th test point (and at
  the end), for entropy sets too costly to evaluate at every test.

What is computed here:

* :func:`run_method` — one method for one seed in a resumable run directory (the run
  ``vslbook run`` trains at the same budget). Rows of
  ``metrics.jsonl`` carry ``samples`` (executed episodes; θ rejected before simulation are
  not counted, A.3.2 / A.3.3) and, at every test point, ``test_return`` and
  ``test_success`` (θ ~ π(θ | c) on fixed test contexts from p(c)) and
  ``expected_entropy``.
* :func:`curve_frame` / :func:`learning_curves` — curves against executed episodes, IQM and
  95 % stratified-bootstrap CI over seeds (the thesis plots the mean ± 2 standard errors).

From :mod:`vslbook.experiments.svsl_context` (the context-space analysis), re-exported
here:

* :func:`mixture_of` — the three methods' policies as one mixture type (Eq. 3.1);
  :func:`expected_entropy` — E_c H[π(θ | c)] by Monte Carlo;
* :func:`box_grid`, :func:`success_grid` — a grid over two chosen context dimensions (the
  others fixed) and the success rate per cell of executing the means of experts drawn from
  π(o | c);
* :func:`draw_context_gaussians` — the per-expert context Gaussians projected on two
  context dimensions (their marginals).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from vslbook.budget import Budget
from vslbook.envs.robot import make_task
from vslbook.erl import hireps, ladips
from vslbook.erl.mixture_baseline import MixtureAlgorithm
from vslbook.erl.svsl import SVSL, SVSLConfig
from vslbook.experiments.svsl_context import (
    METHODS,
    box_grid,
    check_count,
    check_method,
    check_shape,
    draw_box,
    draw_context_gaussians,
    draw_success_grid,
    entropy_contexts,
    entropy_due,
    expected_entropy,
    method_config,
    mixture_of,
    shared_task,
    success_grid,
    svsl_episodes,
)
from vslbook.progress import progress_bar, run_set_progress
from vslbook.results import RunDir
from vslbook.stats import iqm_curve

__all__ = [
    "METHODS",
    "box_grid",
    "check_count",
    "check_method",
    "check_shape",
    "curve_frame",
    "draw_box",
    "draw_context_gaussians",
    "draw_learning_curves",
    "draw_success_grid",
    "entropy_contexts",
    "expected_entropy",
    "learning_curves",
    "load_model",
    "method_config",
    "mixture_of",
    "note_under",
    "run_method",
    "run_methods",
    "shared_task",
    "success_grid",
    "svsl_episodes",
    "train_baseline",
]


# --------------------------------------------------------------------------------------
# runs
# --------------------------------------------------------------------------------------
def run_methods(
    task: str, root: str | Path, budget: Budget | str | None, methods: Sequence[str],
    seeds: int, label: str, *, progress: bool = False,
) -> dict[str, list[Path]]:  # fmt: skip
    """:func:`run_method` for every method and seeds 0, …, ``seeds`` − 1, one after the
    other, as one run set (one line ``label`` on the book's pages); ``{method: [run
    directories]}``."""
    for m in methods:
        check_method(m)
    n = check_count("seeds", seeds)
    with run_set_progress(label):
        return {m: [run_method(task, m, s, root, budget, progress=progress) for s in range(n)]
                for m in methods}  # fmt: skip


def run_method(
    task: str, method: str, seed: int, root: str | Path, budget: Budget | str | None = None,
    *, progress: bool = False,
) -> Path:  # fmt: skip
    """Train one method for one seed on ``task`` at ``budget`` in a run directory under
    ``root``: the run ``vslbook run svsl|hireps|ladips --env ENV --seed S --budget B``
    trains (:mod:`vslbook.experiments.ch3_algorithms`, :func:`vslbook.training.run`).

    A finished run with the same configuration is reused, an unfinished one resumed. Rows
    of ``metrics.jsonl`` carry ``samples`` (executed episodes so far) and, every
    ``test_every`` iterations and at the end, ``test_return``, ``test_success`` and
    ``expected_entropy``. The baselines test as often as SVSL (the same number of test
    points over their run). ``progress``: a bar over the iterations.

    Raises:
        RuntimeError: the run diverged.
    """
    from vslbook.experiments.ch3_algorithms import env_of
    from vslbook.training import run

    check_method(method)
    rd = run(method.lower(), env_of(task), seed, budget, root=root, progress=progress)
    if rd.failed:
        raise RuntimeError(f"{rd.path} diverged: {rd.failure.get('message')}")
    return rd.path


def train_baseline(
    rd: RunDir,
    task: Any,
    method: str,
    config: Any,
    seed: int,
    extra: dict[str, Any],
    *,
    stop_after: int | None = None,
    workers: int | None = 0,
    progress: bool = False,
    final: Callable[[MixtureAlgorithm], dict[str, float]] | None = None,
) -> MixtureAlgorithm:
    """Iterations of HiREPS or LaDiPS in ``rd``, resuming from its checkpoint.

    Every ``extra["test_every"]`` iterations and at the end, θ ~ π(θ | c) is evaluated on
    ``extra["test_contexts"]`` fixed contexts from p(c) (as :meth:`SVSL.test`); with
    ``extra["entropy_draws"]`` the expected mixture entropy is estimated there too;
    ``final(algo)`` adds metrics to the last iteration's row (Fig. 3.2e/f's success over
    the cup grid, :func:`vslbook.experiments.ch3_algorithms.final_metrics`). Stops
    after ``stop_after`` iterations of this call (default: all), checkpointing there; the
    caller marks the run done once ``algo.iterations_done == config.iterations``.
    """
    check_method(method)
    cls = hireps.HiREPS if method == "HiREPS" else ladips.LaDiPS
    algo = cls(task, config, seed, workers=workers)
    saved = rd.load_checkpoint()
    if saved is not None:
        algo.load_state_dict(saved["algo"])
    tests = task.sample_contexts(extra["test_contexts"], np.random.default_rng([seed, 1]))
    contexts = entropy_contexts(task.name, extra) if "entropy_draws" in extra else None
    every = extra["test_every"]
    stop = config.iterations
    if stop_after is not None:
        stop = min(algo.iterations_done + int(stop_after), stop)
    bar = progress_bar(total=config.iterations, initial=algo.iterations_done,
                       disable=not progress, desc=f"{method} {task.name} s{seed}")  # fmt: skip
    for i in range(algo.iterations_done, stop):
        start = time.perf_counter()
        metrics = algo.iteration()
        metrics["samples_iteration"] = metrics.pop("samples")
        metrics["samples"] = algo.total_samples  # executed episodes so far
        it = i + 1
        if it % every == 0 or it == config.iterations:
            # θ ~ π(θ | c) on the fixed test contexts, as SVSL.test
            th, _ = algo.sample(tests, np.random.default_rng([seed, 2, it]))
            out = task.evaluate(th, tests, workers=workers)
            metrics["test_return"] = float(np.mean(out.returns))
            metrics["test_success"] = float(np.mean(out.success))
            if contexts is not None and entropy_due(it, every, config.iterations, extra):
                rng = np.random.default_rng([seed, 3, it])
                metrics["expected_entropy"] = expected_entropy(
                    mixture_of(algo), contexts, extra["entropy_draws"], rng
                )
        if final is not None and it == config.iterations:
            metrics |= final(algo)
        metrics["iteration_seconds"] = time.perf_counter() - start  # tests included
        rd.log(it, **metrics)
        bar.update(1)
        if it % 25 == 0 or it == stop or rd.checkpoint_due():
            rd.save_checkpoint({"algo": algo.state_dict()})
    bar.close()
    return algo


def _config_from(cls: type, cfg: dict[str, Any]) -> Any:
    fields = {k: v for k, v in cfg.items() if k in cls.__dataclass_fields__}
    return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in fields.items()})


def load_model(path: str | Path) -> Any:
    """The trained SVSL, HiREPS or LaDiPS object stored in a run directory's checkpoint
    (any Chapter 3 task; on the 5-link reacher with the run's reward, Eqs. 3.8-3.10)."""
    rd = RunDir.open(path)
    cfg = rd.config
    algo = cfg.get("algo")
    classes = {
        "svsl": (SVSL, SVSLConfig, "svsl"),
        "hireps": (hireps.HiREPS, hireps.HiREPSConfig, "algo"),
        "ladips": (ladips.LaDiPS, ladips.LaDiPSConfig, "algo"),
    }
    if algo not in classes:
        raise ValueError(f"{rd.path}: algo {algo!r} is not one of svsl, hireps, ladips")
    state = rd.load_checkpoint()
    if state is None:
        raise FileNotFoundError(f"{rd.path} has no checkpoint")
    from vslbook.experiments.ch3_algorithms import SVSL_ENVS

    cls, config_cls, key = classes[algo]
    name = SVSL_ENVS.get(cfg["env"], cfg["env"])  # an env id, or a task name (older runs)
    reward = cfg.get("reward")
    task = shared_task(name) if reward is None else make_task(name, reward=reward)
    model = cls(task, _config_from(config_cls, cfg), int(cfg["seed"]))
    model.load_state_dict(state[key])
    return model


# --------------------------------------------------------------------------------------
# curves over executed episodes (Fig. 3.2a/b, Figs. A.1, A.2)
# --------------------------------------------------------------------------------------
def curve_frame(
    runs: dict[str, list[str | Path]],
    y: str = "test_return",
    points: int = 40,
    methods: Sequence[str] = METHODS,
) -> pd.DataFrame:
    """Long frame (method, run, samples, ``y``) with every run on one grid of episode counts.

    Each run's test rows (``y`` against executed episodes ``samples``) are linearly
    interpolated onto ``points`` counts spanning all runs, and onto each run's last count,
    so that every run's curve ends at its final test (a run ending between two grid counts
    would otherwise be drawn up to the count before its end); a run contributes only inside
    its own range (no extrapolation). ``methods``: the names ``runs`` may use.
    """
    if not runs:
        raise ValueError("runs is empty; expected {method: [run directories]}")
    unknown = [m for m in runs if m not in methods]
    if unknown:
        raise ValueError(f"unknown method(s) {unknown}; expected some of {tuple(methods)}")
    tables = []
    for method, paths in runs.items():
        for j, path in enumerate(paths):
            df = RunDir.open(path).metrics_frame()
            if y not in df.columns:
                raise ValueError(f"{path}: no {y!r} column in metrics.jsonl")
            df = df[np.isfinite(pd.to_numeric(df[y], errors="coerce"))]
            tables.append((method, j, df["samples"].to_numpy(float), df[y].to_numpy(float)))
    lo = min(x[0] for *_, x, _ in tables if len(x))
    hi = max(x[-1] for *_, x, _ in tables if len(x))
    ends = [x[-1] for *_, x, _ in tables if len(x)]
    grid = np.unique(np.concatenate([np.linspace(lo, hi, points).round(), ends]))
    rows = []
    for method, j, x, v in tables:
        inside = grid[(grid >= x[0]) & (grid <= x[-1])] if len(x) else grid[:0]
        for g, val in zip(inside, np.interp(inside, x, v), strict=True):
            rows.append({"method": method, "run": j, "samples": g, y: val})
    return pd.DataFrame(rows, columns=["method", "run", "samples", y])


def learning_curves(
    runs: dict[str, list[str | Path]],
    y: str = "test_return",
    *,
    points: int = 40,
    reps: int | None = None,
    seed: int = 0,
    methods: Sequence[str] = METHODS,
) -> pd.DataFrame:
    """IQM and 95 % stratified-bootstrap CI over seeds per method (Fig. 3.2a/b; Figs. A.1,
    A.2 with ``y="expected_entropy"``; Chapter 4's curves with their ``methods``): columns
    method, samples, iqm, lo, hi, n_runs."""
    frame = curve_frame(runs, y, points, methods)
    return iqm_curve(frame, x="samples", y=y, run="run", group="method", reps=reps, seed=seed)


def draw_learning_curves(
    ax: plt.Axes, curves: pd.DataFrame, *, ylabel: str = "test return (IQM)",
    thesis: str | None = None,
) -> plt.Axes:  # fmt: skip
    """One IQM line with its CI band per method over executed episodes, each in its
    method's style (:data:`vslbook.plots.METHOD_STYLES`); the thesis's outcome
    (``thesis``) as a note under the axes."""
    from vslbook.plots import learning_curve

    for method, df in curves.groupby("method", sort=False):
        learning_curve(ax, df.drop(columns="method"), x="samples", label=str(method))
    ax.set_xlabel("executed episodes")
    ax.set_ylabel(ylabel)
    ax.legend(fontsize=8)
    if thesis:
        note_under(ax, thesis)
    return ax


def note_under(ax: plt.Axes, text: str, *, width: int = 70) -> None:
    """``text`` in small italics under the axes' x label, wrapped at ``width`` characters;
    the figure's tight or constrained layout leaves room for it."""
    import textwrap

    ax.annotate(textwrap.fill(text, width), xy=(0, 0), xycoords="axes fraction",
                xytext=(0, -36), textcoords="offset points", ha="left", va="top",
                fontsize=8, style="italic", color="0.3")  # fmt: skip

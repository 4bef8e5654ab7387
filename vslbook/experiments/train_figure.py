"""Train the runs a figure draws, several at once: ``vslbook train FIGURE``.

:func:`train_figure` takes the runs of :func:`vslbook.experiments.run_plan.figure_runs`
(optionally only some seeds, methods or environments) and trains them with ``jobs``
processes, one run per process and one thread per run (``OMP_NUM_THREADS=1``,
``VSLBOOK_WORKERS=1``): on a machine with ``jobs`` cores every core trains one run, which
beats one run with ``jobs`` episode workers because a run's network updates are serial.
Each run is exactly ``vslbook run`` for it (:meth:`FigureRun.train`), so a finished run is
reused, a partial one resumes from its checkpoint, and a run another process holds is
skipped (its lock, :mod:`vslbook.run_lock`), which lets two ``train`` commands, or a
``train`` and a ``sweep``, share one root. Runs are taken in the order the figure lists
them after sorting by seed, so the first seeds of every method finish first.

``until`` (``vslbook train ... --until N``) stops each run once it has trained ``N``
iterations (its checkpoint is then at step ``N``, without ``DONE``): a *probe* of a long
run, e.g. the first 900 of table tennis hard's 4500 iterations, to see where success
starts. Training the same run later without ``until`` continues it from there to its full
length, so a probe costs nothing extra. Probes are recorded with ``vslbook record
--partial``.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass
from multiprocessing import get_context
from pathlib import Path

from vslbook.budget import Budget, get_budget
from vslbook.experiments.run_plan import FigureRun, figure_runs

__all__ = ["TrainResult", "checkpoint_step", "select_runs", "train_figure"]


@dataclass(frozen=True)
class TrainResult:
    """What became of one run: ``done``, ``probed`` (stopped at ``until``), ``skipped``
    (another process holds it) or ``failed`` (diverged, or an error; ``detail`` says
    which)."""

    run: FigureRun
    state: str
    detail: str = ""


def select_runs(figure: str, budget: Budget | str | None = None, *,
                seeds: Iterable[int] | None = None, methods: Iterable[str] | None = None,
                envs: Iterable[str] | None = None) -> list[FigureRun]:  # fmt: skip
    """The figure's runs at ``budget`` restricted to ``seeds``, ``methods`` (legend names,
    e.g. ``SVSL``, case-insensitive) and ``envs``; seed-major order.

    Raises:
        ValueError: a seed, method or env the figure does not draw at this budget.
    """
    runs = figure_runs(figure, budget)
    keep = list(runs)
    for label, wanted, key in (("seed", seeds, lambda r: r.seed),
                               ("method", methods, lambda r: r.method.lower()),
                               ("env", envs, lambda r: r.env)):  # fmt: skip
        if wanted is None:
            continue
        wanted = [w.lower() if label == "method" else w for w in wanted]
        have = {key(r) for r in runs}
        unknown = [w for w in wanted if w not in have]
        if unknown:
            choices = ", ".join(str(h) for h in sorted(have, key=str))
            raise ValueError(f"{figure} at {get_budget(budget).name} draws no {label} "
                             f"{unknown[0]!r}; expected one of {choices}")  # fmt: skip
        keep = [r for r in keep if key(r) in wanted]
    order = {id(r): i for i, r in enumerate(runs)}
    return sorted(keep, key=lambda r: (r.seed, order[id(r)]))


def checkpoint_step(path: str | Path) -> int:
    """The step of the last row a run's checkpoint covers (0 without a checkpoint): where
    the run resumes. Rows logged after the checkpoint are dropped on resume, so they do not
    count (:func:`~vslbook.experiments.run_plan.saved_rows`)."""
    from vslbook.experiments.run_plan import saved_rows

    rows = saved_rows(path)
    return int(rows[-1]["step"]) if rows else 0


def _train_one(run: FigureRun, root: str, until: int | None = None) -> tuple[str, str]:
    """Worker: train ``run`` in ``root`` with one thread (to step ``until``, where given);
    (state, detail)."""
    import torch

    from vslbook.results import RunDir
    from vslbook.run_lock import RunLockedError

    torch.set_num_threads(1)
    kwargs = {}
    if until is not None:
        if run.words != "iterations":
            return "skipped", f"--until counts iterations; {run.name} counts {run.words}"
        if RunDir(Path(root) / run.name).done:
            return "done", ""
        left = until - checkpoint_step(Path(root) / run.name)
        if left <= 0:
            return "probed", f"at step {until} of {run.length}"
        kwargs["stop_after"] = left
    try:
        rd = RunDir(run.train(root, **kwargs))
    except RunLockedError as err:
        return "skipped", str(err)
    except Exception as err:  # noqa: BLE001 -- one failed run must not stop the others
        return "failed", f"{type(err).__name__}: {err}"
    if until is not None and not rd.done:
        return "probed", f"at step {checkpoint_step(rd.path)} of {run.length}"
    return "done", ""


def _one_thread_env() -> None:
    for key in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "VSLBOOK_WORKERS"):
        os.environ[key] = "1"


def train_figure(runs: list[FigureRun], root: str | Path = "runs", jobs: int = 1,
                 report=print, *, until: int | None = None) -> list[TrainResult]:  # fmt: skip
    """Train ``runs`` in ``root`` with ``jobs`` processes (see the module's docstring);
    ``report(line)`` is called as each run ends. Returns one result per run (state
    ``probed`` for a run stopped at ``until``)."""
    if not isinstance(jobs, int) or jobs < 1:
        raise ValueError(f"jobs must be a positive integer, got {jobs!r}")
    if until is not None and (not isinstance(until, int) or until < 1):
        raise ValueError(f"until must be a positive number of iterations, got {until!r}")
    root = Path(root)
    if root.exists() and not root.is_dir():
        raise ValueError(f"root {str(root)!r} is not a folder; expected a folder for the "
                         "run directories")  # fmt: skip
    root.mkdir(parents=True, exist_ok=True)
    results: list[TrainResult] = []
    pending = list(runs)
    ctx = get_context("spawn")
    with ProcessPoolExecutor(max_workers=jobs, mp_context=ctx,
                             initializer=_one_thread_env) as pool:  # fmt: skip
        running: dict[Future, FigureRun] = {}
        while pending or running:
            while pending and len(running) < jobs:
                run = pending.pop(0)
                running[pool.submit(_train_one, run, str(root), until)] = run
            finished, _ = wait(running, return_when=FIRST_COMPLETED)
            for future in finished:
                run = running.pop(future)
                state, detail = future.result()
                results.append(TrainResult(run, state, detail))
                report(f"{state:8s} {run.name}" + (f"  ({detail})" if detail else ""))
    return results

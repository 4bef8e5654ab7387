"""Every figure's runs, declared once per budget, and what a root still needs of them.

A chapter module declares, for each of its figures, the runs the figure draws at a budget
as :class:`FigureRun` values (algorithm, env, seed, the config overrides, how long the run
is): :func:`figure_runs` collects them. Everything that trains or reads a figure's runs
uses this one declaration:

* ``vslbook run ALGO --env ENV --seed S --budget B [--set k=v ...]`` trains the run a
  figure uses at ``B`` (a run's ``overrides`` are its ``--set`` pairs, e.g. Fig. 3.1's
  ``responsibilities=false``), so ``vslbook run ... --dry-run`` prints the names
  :func:`plan` lists;
* the notebooks and ``vslbook figure`` train (or reuse) them with :meth:`FigureRun.train`;
* :func:`plan` (``vslbook plan FIGURE``) says for each run whether it is ``done``,
  ``partial`` (and how far its checkpoint got), ``missing``, ``failed`` or ``recorded`` (in
  ``data/results/``), noting a run made by other code (``code changed``: it is stale only
  if replaying its first rows gives other numbers, which ``vslbook run`` and ``vslbook
  record`` check before they use it, moving a stale run to ``_stale/``), and estimates
  the core-hours left from the per-iteration times the runs in the root measured.

Chapters registered here: 3 (Figs. 3.1, 3.2, 3.5, :mod:`vslbook.experiments.ch3_runs`),
4 (:mod:`vslbook.experiments.diskill_runs`) and 5 (the live DIME run sets: cheetah-run,
the ablations, Fig. 5.7, :mod:`vslbook.experiments.ch5_runs`).
"""

from __future__ import annotations

import importlib
import math
import statistics
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from vslbook.budget import Budget, get_budget

__all__ = ["FIGURE_MODULES", "UNIT_WORDS", "FigureRun", "PlanRow", "figure_runs", "plan",
           "plan_text", "recorded_times", "saved_rows", "unit_seconds"]

#: a run's unit (the metrics column that counts its progress) → how a reader calls it
UNIT_WORDS: dict[str, str] = {"step": "iterations", "env_steps": "env steps"}

#: figure id → the chapter module whose ``figure_runs(figure, budget)`` declares its runs
FIGURE_MODULES: dict[str, str] = {
    **{f"fig3-{n}": "vslbook.experiments.ch3_runs" for n in ("1", "2", "5")},
    **{f"fig4-{n}": "vslbook.experiments.diskill_runs"
       for n in ("3b", "3c", "4a", "4b", "4c", "4d")},
    **dict.fromkeys(("fig5-3-cheetah", "fig5-ablations", "fig5-7"),
                    "vslbook.experiments.ch5_runs"),
}  # fmt: skip


@dataclass(frozen=True)
class FigureRun:
    """One run a figure draws.

    Attributes:
        figure: the figure's id (``vslbook figures``), e.g. ``fig4-3c``.
        method: the method's key in the figure (its legend entry).
        algo, env, seed, budget: what ``vslbook run`` takes.
        length: the run's length in ``unit``.
        unit: the metrics column that counts progress (``step`` or e.g. ``env_steps``).
        counts: what one unit is, in words, where the column's name does not say it (a DIME
            run's ``step`` counts environment steps: ``"env steps"``); empty: from
            :data:`UNIT_WORDS`.
        overrides: config fields set beside the budget's preset, as ``vslbook run --set``
            strings (empty where the preset is the run).
    """

    figure: str
    method: str
    algo: str
    env: str
    seed: int
    budget: str
    length: int
    unit: str = "step"
    overrides: dict[str, Any] = field(default_factory=dict)
    counts: str = ""

    @property
    def words(self) -> str:
        """What the run's length counts, in words (``"iterations"``, ``"env steps"``)."""
        return self.counts or UNIT_WORDS.get(self.unit, self.unit)

    def progress(self, done: int) -> str:
        """How far the run has trained, in words: ``"900/4500 iterations"`` (unit ``step``:
        one row per iteration), ``"24000/50000 env steps"`` (unit ``env_steps``, or a DIME
        run's ``step``)."""
        return f"{done}/{self.length} {self.words}"

    @property
    def name(self) -> str:
        """The run directory's name (:func:`vslbook.training.run_name`)."""
        from vslbook.training import run_name

        return run_name(self.algo, self.env, self.seed, self.budget,
                        overrides=self.overrides or None)  # fmt: skip

    def train(self, root: str | Path = "runs", *, progress: bool = False, **kwargs: Any) -> Path:
        """Train (or reuse, when finished) this run in ``root``; its run directory.

        Raises:
            RuntimeError: the run diverged (its ``FAILED`` record in the message).
        """
        from contextlib import nullcontext

        from vslbook.progress import progress_prefix
        from vslbook.training import run

        # a variant's bar names its legend entry (the algorithm's own label does not)
        with progress_prefix(self.method) if self.overrides else nullcontext():
            rd = run(self.algo, self.env, self.seed, self.budget, root=root,
                     overrides=self.overrides or None, progress=progress, **kwargs)  # fmt: skip
        if rd.failed:
            raise RuntimeError(f"{rd.path} diverged: {rd.failure.get('message')}")
        return rd.path

    def command(self, root: str | Path = "runs") -> str:
        """The ``vslbook run`` command line that trains this run."""
        sets = "".join(f" --set {k}={v}" for k, v in self.overrides.items())
        return (f"vslbook run {self.algo} --env {self.env} --seed {self.seed} "
                f"--budget {self.budget}{sets} --root {root}")  # fmt: skip


def figure_runs(figure: str, budget: Budget | str | None = None) -> list[FigureRun]:
    """The runs ``figure`` draws at ``budget``, as its chapter module declares them.

    Raises:
        ValueError: a figure with no declared runs (the message lists those with).
    """
    if figure not in FIGURE_MODULES:
        raise ValueError(
            f"figure {figure!r} declares no runs; expected one of {', '.join(FIGURE_MODULES)}"
        )
    module = importlib.import_module(FIGURE_MODULES[figure])
    return list(module.figure_runs(figure, get_budget(budget)))


@dataclass(frozen=True)
class PlanRow:
    """One run of a plan: its state, progress and estimated core-hours left."""

    run: FigureRun
    state: str  # done | partial | missing | recorded | failed
    progress: int = 0  # units done (``run.unit``)
    seconds_per_unit: float = math.nan  # measured by this run, or its method's others
    note: str = ""  # e.g. that the code changed since the run was made
    target: int | None = None  # units to train it to (a probe's ``--until``); None: its length

    @property
    def end(self) -> int:
        """Where the plan trains the run to: ``target``, else the run's length."""
        return self.run.length if self.target is None else self.target

    @property
    def to_train(self) -> bool:
        """True when the run still has units to train (partial or missing, short of
        :attr:`end`)."""
        return self.state in ("partial", "missing") and self.progress < self.end

    @property
    def hours_left(self) -> float:
        if not self.to_train:
            return 0.0
        return (self.end - self.progress) * self.seconds_per_unit / 3600.0


def saved_rows(path: str | Path, rows: list[dict[str, Any]] | None = None) -> list[dict[str, Any]]:
    """The metrics rows of the run directory ``path`` that a resume keeps: all rows of a
    finished run; of a partial one, the rows its checkpoint counts (``_metrics_lines``,
    :meth:`vslbook.results.RunDir.save_checkpoint`; rows logged after it are dropped on
    resume); none without a checkpoint. ``rows``: the run's metrics, where already read."""
    import torch

    from vslbook.results import RunDir

    rd = RunDir(path)
    rows = rd.metrics() if rows is None else rows
    if rd.done:
        return rows
    if not rd.checkpoint_path.is_file():
        return []
    # memory-mapped: only the small count is read, not the networks or a replay buffer
    state = torch.load(rd.checkpoint_path, map_location="cpu", weights_only=False, mmap=True)
    lines = int(state.get("_metrics_lines", 0)) if isinstance(state, dict) else 0
    return rows[:lines]


def unit_seconds(rows: list[dict[str, Any]], run: FigureRun) -> list[float]:
    """Seconds per unit of ``run`` that each of its metrics rows measured: an iteration's
    ``iteration_seconds``; for a run counted in env steps (PPO, DIME), the inverse of the
    row's ``env_steps_per_s`` (training's wall clock since the previous row, evaluations
    left out; seeds that DIME trains side by side in one process share that clock, so each
    seed's rate is the group's)."""
    if run.words == "env steps":
        return [1.0 / r["env_steps_per_s"] for r in rows if (r.get("env_steps_per_s") or 0) > 0]
    if run.unit != "step":
        return []
    return [r["iteration_seconds"] for r in rows if r.get("iteration_seconds") is not None]


def _state(path: Path, run: FigureRun) -> tuple[str, int, list[float], str]:
    """(state, progress, per-unit seconds measured, note) of ``run``'s directory ``path``.

    A run made by code other than today's keeps its state with the note ``code changed``:
    whether it is stale is decided by replaying its first rows (:mod:`vslbook.replay`)
    when it is resumed, reused or recorded, not here.
    """
    from vslbook.results import RunDir

    if not (path / RunDir.CONFIG).is_file():
        return "missing", 0, [], ""
    rd = RunDir(path)
    rows = rd.metrics()
    saved = saved_rows(path, rows)  # progress: where a resume starts
    progress = int(saved[-1].get(run.unit, 0) or 0) if saved else 0
    times = unit_seconds(rows, run)
    note = "" if rd.code_matches else "code changed: replayed when resumed or recorded"
    if rd.failed:
        return "failed", progress, times, note
    return ("done" if rd.done else "partial"), progress, times, note


def plan(figure: str, budget: Budget | str | None = None, root: str | Path = "runs",
         recorded: Callable[[FigureRun], bool] | None = None,
         until: int | None = None) -> list[PlanRow]:  # fmt: skip
    """The state of every run ``figure`` needs at ``budget`` in ``root``.

    ``recorded(run)`` says whether a run missing from ``root`` is in ``data/results/``.
    ``until``: plan probes, as ``vslbook train --until``: each run counted in iterations
    is trained to iteration ``until`` (at most its length); runs counted in env steps are
    not trained.
    A run's seconds per unit are the mean of its own most recent measurements (the last
    quarter of its iterations: an SVSL iteration costs more as experts are added), else the
    mean of its method's other runs in the plan, else of its method's recorded runs
    (:func:`recorded_times`), else NaN (not yet measured). Means, not medians: the rare
    costly iterations (SVSL's fine-tuning of every expert every 50th iteration, Di-SkilL's
    tests) are part of a run's cost. A run's logged ``iteration_seconds`` leave out what
    happens between iterations (SVSL's tests, checkpoints), so the hours are a lower bound.

    Raises:
        ValueError: ``until`` is not an iteration (an integer >= 1).
    """
    if until is not None and (isinstance(until, bool) or not isinstance(until, int)
                              or until < 1):  # fmt: skip
        raise ValueError(f"until must be an iteration (an integer >= 1), got {until!r}")
    runs = figure_runs(figure, budget)
    states = [_state(Path(root) / r.name, r) for r in runs]
    by_method: dict[tuple[str, str], list[float]] = {}
    for r, (_, _, times, _) in zip(runs, states, strict=True):
        by_method.setdefault((r.algo, r.env), []).extend(times)
    if not all(by_method.values()):  # a method with no run here: its recorded runs' times
        for key, times in recorded_times(figure, get_budget(budget).name, runs).items():
            if key in by_method and not by_method[key]:
                by_method[key] = times
    rows = []
    for r, (state, progress, times, note) in zip(runs, states, strict=True):
        if state == "missing" and recorded is not None and recorded(r):
            state = "recorded"
        pool = times[-max(1, len(times) // 4):] if times else by_method[(r.algo, r.env)]
        per = statistics.fmean(pool) if pool else math.nan
        target = None
        if until is not None:
            if r.words == "iterations":
                target = min(until, r.length)
            else:
                target, note = progress, "; ".join(
                    filter(None, [note, f"--until counts iterations, not {r.words}"]))
        rows.append(PlanRow(r, state, progress, per, note, target))
    return rows


def recorded_times(
    figure: str, budget: str, runs: list[FigureRun] | None = None
) -> dict[tuple[str, str], list[float]]:
    """(algo, env) → the seconds per unit (:func:`unit_seconds`) of ``figure``'s recorded
    runs, from the set at ``budget`` where it has the method, else from the largest budget
    that has it (an iteration's cost depends on counts such as the number of experts, so
    this is a guess until a run of the budget is timed). ``runs``: the figure's runs at
    ``budget`` (default :func:`figure_runs`), which say what each method's unit counts."""
    from vslbook.experiments.record import read_set, recorded_dir

    declared = {(r.algo, r.env): r for r in (runs or figure_runs(figure, budget))}
    out: dict[tuple[str, str], list[float]] = {}
    for name in dict.fromkeys((budget, "full", "reduced", "smoke")):
        table, evals, _ = read_set(recorded_dir(figure, name))
        timing = evals[evals["metric"].isin(("iteration_seconds", "env_steps_per_s"))]
        timing = timing.dropna(subset=["value"])
        found: dict[tuple[str, str], list[float]] = {}
        for row in table.itertuples():
            if (row.algo, row.env) not in declared:
                continue
            mine = timing[timing["run"] == row.run]
            rows = [{m: v} for m, v in zip(mine["metric"], mine["value"], strict=True)]
            found.setdefault((row.algo, row.env), []).extend(
                unit_seconds(rows, declared[(row.algo, row.env)]))
        out |= {key: values for key, values in found.items() if values and key not in out}
    return out


def plan_text(rows: list[PlanRow]) -> str:
    """``<state> <run directory name>`` per run (with progress where partial), then the
    core-hours left (one core per run) and how many runs have no time measured yet."""
    lines = []
    for row in rows:
        notes = [row.note] if row.note else []
        if row.target is not None and row.to_train:
            notes.insert(0, f"probe to {row.target}")
        if row.state == "partial":
            notes.insert(0, row.run.progress(row.progress))
        extra = f" ({'; '.join(notes)})" if notes else ""
        lines.append(f"{row.state:8s} {row.run.name}{extra}")
    todo = [r for r in rows if r.to_train]
    known = [r.hours_left for r in todo if not math.isnan(r.hours_left)]
    unknown = len(todo) - len(known)
    total = f"{sum(known):.1f} core-hours left for {len(known)} runs"
    if any(r.target is not None for r in rows):
        total += f" (probes to iteration {max(r.target or 0 for r in rows)})"
    if unknown:
        total += f"; {unknown} runs not yet timed (train one of each method to estimate them)"
    lines.append(total if todo else "nothing left to train")
    return "\n".join(lines)

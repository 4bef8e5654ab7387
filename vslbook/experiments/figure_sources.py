"""Where a figure's runs come from: trained in ``runs/``, recorded in ``data/results/``, or
trained now.

The book's long run sets take hours to days of CPU, so by default a figure draws the runs
already made (:func:`figure_set`):

``best`` (the default when ``$VSLBOOK_BUDGET`` is not set)
    the largest budget (full, then reduced, then smoke) at which the figure has recorded
    runs (:mod:`vslbook.experiments.record`) or every run finished in ``runs/``; the
    finished runs of ``runs/`` and the recorded ones together, a run in ``runs/`` winning.
    Where the figure has neither at any budget, its runs are trained now at ``smoke``,
    and the figure says it shows the code path only.
``budget`` (the default when ``$VSLBOOK_BUDGET`` names a budget)
    the same at that budget alone; where nothing is recorded or finished there, its runs
    are trained now at that budget.
``retrain`` (``$VSLBOOK_RETRAIN=1``, ``make book RETRAIN=1``)
    every run of the budget is trained now (finished ones in ``runs/`` made by today's code
    are reused, as :func:`vslbook.training.run` always does); nothing recorded is read.

``$VSLBOOK_SOURCE`` names a mode explicitly. A run of ``runs/`` counts as finished when it
is ``DONE``, its metrics match what ``DONE`` recorded and today's code made it (or replayed
it). A recorded run whose code has changed since is still drawn, with a warning: ``vslbook
results --verify`` replays it. :class:`FigureSet` says where every run came from
(:meth:`FigureSet.caption`), and :meth:`FigureSet.verdict` replaces a comparison with the
thesis by "smoke: code path only" where the runs are smoke runs.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from vslbook.budget import BUDGETS, ENV_VAR, Budget, get_budget
from vslbook.experiments.run_plan import FigureRun, figure_runs
from vslbook.results import RunDir, RunDirError

__all__ = ["MODES", "PROBE_VERDICT", "RETRAIN_ENV", "SMOKE_VERDICT", "SOURCE_ENV", "THESIS_SEEDS",
           "FigureSet", "annotate", "figure_set", "source_mode", "source_text"]  # fmt: skip

SOURCE_ENV = "VSLBOOK_SOURCE"
RETRAIN_ENV = "VSLBOOK_RETRAIN"
MODES = ("best", "budget", "retrain")
#: what a figure says instead of a verdict when its runs are smoke runs
SMOKE_VERDICT = "smoke: code path only (a few iterations or steps; not compared with the thesis)"
#: what a figure says instead of a verdict when every run it draws is a probe
PROBE_VERDICT = "probes: runs still training, not compared with the thesis"
_LARGEST_FIRST = ("full", "reduced", "smoke")
#: how far a probe's curve is lifted above the finished curves (:meth:`FigureSet.mark_probes`)
PROBE_ZORDER_LIFT = 0.5
#: the opacity of a probe's curve (:meth:`FigureSet.mark_probes`)
PROBE_ALPHA = 0.45
#: the figures whose seeds in the thesis differ from the full budget's, with the thesis's
#: words; every other figure's full budget has the thesis's seeds. Fig. 4.3b reports "at
#: least 4 seeds"; the full budget runs the 24 of Section 4.5's other comparisons there too
#: (:func:`vslbook.experiments.diskill_runs.counts`).
THESIS_SEEDS = {"fig4-3b": "at least 4"}


def source_mode() -> str:
    """The mode of :func:`figure_set` from the environment (see the module's docstring).

    Raises:
        ValueError: ``$VSLBOOK_SOURCE`` is not one of :data:`MODES`.
    """
    named = os.environ.get(SOURCE_ENV, "").strip().lower()
    if named:
        if named not in MODES:
            raise ValueError(f"${SOURCE_ENV}={named!r}; expected one of {', '.join(MODES)}")
        return named
    if os.environ.get(RETRAIN_ENV, "").strip().lower() in ("1", "true", "yes"):
        return "retrain"
    return "budget" if os.environ.get(ENV_VAR, "").strip() else "best"


def source_text() -> str:
    """One line for a notebook's first cell: where its figures' runs come from."""
    return {
        "best": "figures draw recorded runs (data/results/, the largest budget) or finished "
                "ones in runs/, else train smoke runs now (set VSLBOOK_BUDGET to train a "
                "budget's)",
        "budget": "figures draw this budget's recorded or finished runs, and train what it "
                  "lacks",
        "retrain": "figures train every run of this budget (finished ones are reused)",
    }[source_mode()]


@dataclass
class FigureSet:
    """A figure's runs and where they came from.

    Attributes:
        figure: the figure's id, e.g. ``fig4-3c``.
        budget: the budget the runs were made at.
        runs: method → run directories in seed order (recorded runs as run directories,
            :func:`vslbook.experiments.recorded_runs.materialise`).
        trained: names of the runs that come from ``runs/`` (trained now or before).
        recorded: name → ``{"date", "git_sha", "stale"}`` of the runs read from
            ``data/results/``.
        seeds_full: method → the seeds the figure has at the ``full`` budget (the thesis's).
        not_drawn: recorded runs that today's declaration of the figure no longer names
            (their configuration changed since they were recorded).
        probes: name → progress (e.g. ``900/4500 iterations``) of the recorded runs that were
            still training when recorded (``vslbook record --partial``): drawn as probes.
        held: name → ``"s2 at 150/4500 iterations"`` of the recorded runs still training
            whose method has finished seeds in the set (:meth:`hold_back`): not drawn, so
            that a run still training is neither mixed into the finished seeds' curve nor
            turns their comparison into a probe's; the caption names them.
    """

    figure: str
    budget: str
    runs: dict[str, list[Path]]
    trained: list[str] = field(default_factory=list)
    recorded: dict[str, dict[str, Any]] = field(default_factory=dict)
    seeds_full: dict[str, int] = field(default_factory=dict)
    not_drawn: list[str] = field(default_factory=list)
    probes: dict[str, str] = field(default_factory=dict)
    held: dict[str, str] = field(default_factory=dict)

    @property
    def smoke(self) -> bool:
        """True where the runs are smoke runs: they test the code path, not the thesis."""
        return self.budget == "smoke"

    @property
    def stale(self) -> list[str]:
        """Recorded runs made by code that has changed since (and not replayed by it)."""
        return sorted(n for n, info in self.recorded.items() if info["stale"])

    def _paths(self) -> dict[str, Path]:
        return {p.name: p for paths in self.runs.values() for p in paths}

    def finished(self, method: str) -> int:
        """How many of ``method``'s runs are finished seeds (its probes not counted)."""
        return sum(p.name not in self.probes for p in self.runs.get(method, []))

    def seeds_phrase(self) -> str:
        """The finished seeds of the set's methods, for a panel's title: ``"3 seeds"`` where
        every method has as many, ``"1–2 seeds"`` where they differ (:meth:`caption` gives
        each method's), ``"finished seeds"`` where the set also draws probes (a method with
        probes only is left out of the range, ``"0 finished seeds"`` where all are)."""
        from vslbook.plots import count_phrase

        counts = [n for m in self.runs if (n := self.finished(m))] or [0]
        noun = "finished seed" if self.probes else "seed"
        low, high = min(counts), max(counts)
        return count_phrase(low, noun) if low == high else f"{low}–{high} {noun}s"

    def probe_progress(self) -> dict[str, str]:
        """method → how far its probes had trained when recorded (``"900/4500 iterations"``,
        several joined by ", "), for the methods that have a probe."""
        out: dict[str, list[str]] = {}
        for method, paths in self.runs.items():
            for p in paths:
                if p.name in self.probes:
                    out.setdefault(method, []).append(self.probes[p.name])
        return {m: ", ".join(dict.fromkeys(v)) for m, v in out.items()}

    def hold_back(self) -> None:
        """Move each probe of a method that also has a finished seed from :attr:`runs` and
        :attr:`probes` to :attr:`held`. A method with probes only keeps them (drawn
        faded, :meth:`mark_probes`): they show where success starts; a further seed of a
        method that has finished ones adds nothing to the figure until it finishes."""
        for method, paths in self.runs.items():
            if self.finished(method) == 0:
                continue
            for p in [p for p in paths if p.name in self.probes]:
                paths.remove(p)
                seed = RunDir(p).config.get("seed")
                self.held[p.name] = f"s{seed} at {self.probes.pop(p.name)}"

    def mark_probes(self, ax: Any, labels: dict[str, str]) -> None:
        """Draw the curves of ``ax`` that come from probes faded (their method's line style
        is kept: every style is some method's) and above the finished curves (a faded probe
        near 0 is otherwise hidden under their markers), with "(probe, 900/4500 iterations)"
        in their legend entry; ``labels`` maps a method to its curve's label.

        Raises:
            ValueError: a method with probes has no label in ``labels``.
        """
        progress = self.probe_progress()
        missing = sorted(set(progress) - set(labels))
        if missing:
            raise ValueError(f"no curve label for the probe method(s) {missing}; expected "
                             f"them among the keys of labels {sorted(labels)}")  # fmt: skip
        named = {labels[m]: p for m, p in progress.items()}
        for line in ax.get_lines():
            if line.get_label() in named:
                line.set_alpha(PROBE_ALPHA)
                line.set_zorder(line.get_zorder() + PROBE_ZORDER_LIFT)
                line.set_label(f"{line.get_label()} (probe, {named[line.get_label()]})")
        old = ax.get_legend()
        if named and old is not None:
            ax.legend(fontsize=old.get_texts()[0].get_fontsize() if old.get_texts() else None)

    def probe_note(self, path: str | Path) -> str:
        """``", probe at 300/4500 iterations"`` for a run still training when recorded (to put in
        the title of a panel drawn from that one run), else ``""``."""
        name = Path(path).name
        return f", probe at {self.probes[name]}" if name in self.probes else ""

    def verdict(self, text: str, methods: tuple[str, ...] = ()) -> str:
        """``text`` (a comparison with the thesis), or :data:`SMOKE_VERDICT` at smoke, or
        :data:`PROBE_VERDICT` where every run is a probe or, when ``methods`` names the
        methods compared, where one of them has a probe (a run still training is not
        compared with a finished one)."""
        if self.smoke:
            return SMOKE_VERDICT
        if self.probes and len(self.probes) == sum(map(len, self.runs.values())):
            return PROBE_VERDICT
        if set(methods) & set(self.probe_progress()):
            return PROBE_VERDICT
        return text

    def caption(self) -> str:
        """One line: budget, origin (recorded: code version and date; trained), seeds per
        method against the full budget's (and the thesis's where they differ,
        :data:`THESIS_SEEDS`), and the warnings (stale, not drawn, smoke)."""
        if self.recorded and self.trained:
            origin = "recorded and trained"
        elif self.recorded:
            origin = "recorded"
        else:
            origin = "trained"
        if self.recorded:
            shas = sorted({str(i["git_sha"] or "?")[:7] for i in self.recorded.values()})
            dates = sorted({str(i["date"] or "?")[:10] for i in self.recorded.values()})
            span = dates[0] if len(dates) == 1 else f"{dates[0]} to {dates[-1]}"
            origin += f" (data/results/{self.figure}/{self.budget}: code {', '.join(shas)}, {span})"
        seeds = ", ".join(
            f"{m} {self.finished(m)} of {self.seeds_full.get(m, '?')}"
            + (f" and {k} probe{'s' * (k > 1)}" if (k := len(p) - self.finished(m)) else "")
            for m, p in self.runs.items())  # fmt: skip
        whose = "of the thesis's, the full budget's"
        if self.figure in THESIS_SEEDS:
            whose = f"of the full budget's; the thesis's had {THESIS_SEEDS[self.figure]}"
        line = (f"Runs of {self.figure}: {origin} at the {self.budget} budget; seeds {seeds} "
                f"({whose})")  # fmt: skip
        notes = []
        if self.stale:
            notes.append(f"{len(self.stale)} recorded by code that changed since "
                         "(vslbook results --verify replays them)")  # fmt: skip
        if self.not_drawn:
            notes.append(f"{len(self.not_drawn)} recorded runs not drawn (configuration changed)")
        if self.probes:
            notes.append("probes, still training: " + ", ".join(
                f"{n.split('-vslbook')[0]} s{RunDir(p).config.get('seed')} at {self.probes[n]}"
                for n, p in self._paths().items() if n in self.probes))  # fmt: skip
        if self.held:
            notes.append("still training, not drawn until they finish: " + ", ".join(
                f"{n.split('-vslbook')[0]} {h}" for n, h in self.held.items()))  # fmt: skip
        if self.smoke:
            notes.append("smoke: code path only")
        return line + ("; " + "; ".join(notes) if notes else "") + "."


def _finished(path: Path) -> bool:
    """A run of ``runs/`` that can be drawn: DONE, metrics as DONE recorded, today's code."""
    rd = RunDir(path)
    if not (path / RunDir.CONFIG).is_file() or not rd.done:
        return False
    try:
        rd.check_done()
    except RunDirError:
        return False
    return rd.code_matches


def _declared(figure: str, budget: Budget, methods: tuple[str, ...] | None,
              envs: tuple[str, ...] | None) -> list[FigureRun]:  # fmt: skip
    runs = figure_runs(figure, budget)
    for what, wanted, have in (("method", methods, [r.method for r in runs]),
                               ("env", envs, [r.env for r in runs])):  # fmt: skip
        unknown = sorted(set(wanted or ()) - set(have))
        if unknown:
            raise ValueError(f"figure {figure} has no {what}(s) {unknown}; expected some of "
                             f"{list(dict.fromkeys(have))}")  # fmt: skip
    return [r for r in runs if (methods is None or r.method in methods)
            and (envs is None or r.env in envs)]  # fmt: skip


def _recorded_info(path: Path) -> dict[str, Any]:
    from vslbook.experiments.record import entry_stale

    env = RunDir(path).env
    return {"date": (env.get("recorded") or {}).get("date"), "git_sha": env.get("git_sha"),
            "stale": entry_stale(env)}  # fmt: skip


def _assemble(figure: str, b: Budget, declared: list[FigureRun], root: Path,
              finished: set[str], recorded: dict[str, Path]) -> FigureSet:  # fmt: skip
    out = FigureSet(figure, b.name, {})
    for r in declared:
        if r.name in finished:
            out.runs.setdefault(r.method, []).append(root / r.name)
            out.trained.append(r.name)
        elif r.name in recorded:
            out.runs.setdefault(r.method, []).append(recorded[r.name])
            out.recorded[r.name] = _recorded_info(recorded[r.name])
            if not RunDir(recorded[r.name]).done:
                rows = RunDir(recorded[r.name]).metrics()
                step = int(rows[-1].get(r.unit, 0) or 0) if rows else 0
                out.probes[r.name] = r.progress(step)
    out.not_drawn = sorted(set(recorded) - {r.name for r in figure_runs(figure, b)})
    out.hold_back()
    return out


def _train(figure: str, b: Budget, declared: list[FigureRun], root: Path, progress: bool,
           train_set: Callable[[Budget], Any] | None = None) -> FigureSet:  # fmt: skip
    from vslbook.progress import run_set_progress

    out = FigureSet(figure, b.name, {})
    if train_set is not None:  # the chapter's own way (e.g. DIME's seed axis); reused below
        train_set(b)
    with run_set_progress(f"{figure} runs"):  # one line per set on the book's pages
        for r in declared:
            out.runs.setdefault(r.method, []).append(r.train(root, progress=progress))
            out.trained.append(r.name)
    return out


def figure_set(
    figure: str,
    budget: Budget | str | None = None,
    root: str | Path = "runs",
    *,
    methods: tuple[str, ...] | None = None,
    envs: tuple[str, ...] | None = None,
    mode: str | None = None,
    progress: bool = False,
    train_set: Callable[[Budget], Any] | None = None,
) -> FigureSet:
    """The runs ``figure`` draws, from where the mode says (see the module's docstring).

    Args:
        budget: the budget of modes ``budget`` and ``retrain`` (default: ``$VSLBOOK_BUDGET``
            or ``reduced``); mode ``best`` ignores it.
        methods, envs: only these of the figure's methods / env ids.
        mode: ``best``, ``budget`` or ``retrain``; default :func:`source_mode`.
        train_set: where runs are trained now, called first with their budget to train
            the figure's whole set its chapter's way (DIME trains a variant's seeds on one
            seed axis, :func:`vslbook.training.run_seeds`); each declared run is then
            reused from ``root`` (or trained, where ``train_set`` left it out).

    Raises:
        ValueError: an unknown figure, method, env or mode.
        RuntimeError: a run trained now diverged.
        vslbook.data.DataIntegrityError: a recorded table fails its registry.
    """
    from vslbook.experiments.recorded_runs import materialise

    mode = source_mode() if mode is None else mode
    if mode not in MODES:
        raise ValueError(f"mode {mode!r}; expected one of {', '.join(MODES)}")
    root = Path(root)
    named = get_budget(budget)
    full = _declared(figure, BUDGETS["full"], methods, envs)
    seeds_full: dict[str, int] = {}
    for r in full:
        seeds_full[r.method] = seeds_full.get(r.method, 0) + 1
    if mode == "retrain":
        out = _train(figure, named, _declared(figure, named, methods, envs), root, progress,
                     train_set)
    else:
        out = None
        for name in ([named.name] if mode == "budget" else _LARGEST_FIRST):
            b = BUDGETS[name]
            declared = _declared(figure, b, methods, envs)
            finished = {r.name for r in declared if _finished(root / r.name)}
            recorded = materialise(figure, b)
            if recorded or len(finished) == len(declared):
                out = _assemble(figure, b, declared, root, finished, recorded)
                if out.runs:
                    break
                out = None
        if out is None:
            b = named if mode == "budget" else BUDGETS["smoke"]
            out = _train(figure, b, _declared(figure, b, methods, envs), root, progress,
                         train_set)
    out.seeds_full = seeds_full
    if out.stale:
        warnings.warn(f"{out.figure}: {len(out.stale)} recorded run(s) were made by code that "
                      f"has changed since ({', '.join(out.stale[:3])}...); `vslbook results "
                      "--verify` replays them with today's code", stacklevel=2)  # fmt: skip
    return out


def annotate(fig, *sets: FigureSet, width: int = 130) -> None:
    """Write under ``fig`` where its runs came from (each set's :meth:`FigureSet.caption`),
    in grey; in red, headed "WARNING", where a recorded run was made by code that has
    changed since (:attr:`FigureSet.stale`), so the warning travels with the figure."""
    import textwrap

    text = " ".join(dict.fromkeys(fs.caption() for fs in sets))
    stale = any(fs.stale for fs in sets)
    if stale:
        text = "WARNING: recorded by code that has changed since; " + text
    below = 0.0  # under any text already at the figure's foot (e.g. the thesis's outcomes)
    for t in fig.texts:
        if t.get_position()[1] <= 0.0 and t.get_va() == "top":
            lines = t.get_text().count("\n") + 1
            below = max(below, lines * t.get_fontsize() * 1.4 / 72 / fig.get_figheight())
    fig.text(0.01, -below, textwrap.fill(text, width), fontsize=7, va="top",
             color="#b00020" if stale else "#555555")  # fmt: skip

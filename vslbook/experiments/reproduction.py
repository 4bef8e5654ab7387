"""The thesis's robot results as checks on a figure's runs: final scores, the thesis's
numbers beside ours, and a verdict per claim.

Each reproduced figure states its claims as :class:`Claim` values (:data:`CLAIMS`, read from
the thesis's text: Section 3.4.2 for beer pong, Sections 4.4.2-4.4.3 for the Chapter 4
figures, Section 5.5 for Chapter 5's live runs); :func:`final_scores` gives each method's
final IQM over seeds with its 95 % stratified-bootstrap CI, and :func:`verdicts` checks
every claim on them:

* ``met`` / ``not met``: the claim holds or fails on the final IQMs (and CIs, where the
  claim is about a CI);
* ``pending``: a method of the claim has no runs yet;
* ``smoke``: the runs are smoke runs, which test the code path only.

Chapter 5's claims are of two kinds. Cheetah-run is held against the authors' published
DIME curve (``data/paper/``) at the step our runs end (``within_or_above_published``): a
check of our implementation against theirs, not a thesis claim. The ablations run on
Pendulum-v1 instead of the thesis's dog and humanoid tasks, so their claims say which thesis
panel each stands for; a ``not met`` there says the thesis's ranking does not carry over to
this small task at this budget, which is a finding too.

Probes (runs still training, :attr:`FigureSet.probes`) are drawn, never scored: a claim is
about a run's end. The thesis's numbers (:data:`THESIS_NUMBERS`) are printed beside ours,
labelled as the thesis's; the thresholds of the ``at_least`` claims are this book's reading
of the thesis's wording (e.g. "high success rates"), and say so.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from vslbook.results import RunDir

__all__ = ["CLAIMS", "KINDS", "THESIS_NUMBERS", "Claim", "claims_overview", "final_scores",
           "claim_runs", "final_step", "published_at", "ranked", "reproduction_text",
           "show_claims", "verdicts"]  # fmt: skip

#: the kinds of claim :func:`verdicts` checks
KINDS = ("at_least", "above", "within_or_above", "within_or_above_published")


@dataclass(frozen=True)
class Claim:
    """One claim of the thesis about a figure's final scores.

    Attributes:
        text: the claim in words, with where the thesis makes it.
        kind: ``at_least`` (``method``'s IQM ≥ ``value``), ``above`` (``method``'s IQM above
            the upper end of ``other``'s CI: clearly above, not within its spread),
            ``within_or_above`` (``method``'s IQM at least ``other``'s CI's lower end) or
            ``within_or_above_published`` (``method``'s IQM at least the lower end of the
            published curve's CI at the step ``method``'s runs end).
        method, other, value: as ``kind`` uses them.
        published: the task id of the published curve (:func:`vslbook.data.paper_curves`)
            of a ``within_or_above_published`` claim.
        env: the task the claim is about where the figure has several (Fig. 3.2).
        metric: the metric the claim is about, where not the figure's (Fig. 3.2e/f: the
            success over the cup grid, ``grid_success``, logged at a run's end).
    """

    text: str
    kind: str
    method: str
    other: str | None = None
    value: float | None = None
    env: str | None = None
    metric: str | None = None
    published: str | None = None

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"claim kind {self.kind!r}; expected one of {KINDS}")
        if (self.kind == "within_or_above_published") != (self.published is not None):
            raise ValueError(f"claim {self.text!r}: a published curve (published=...) goes "
                             "with kind 'within_or_above_published' and only with it")  # fmt: skip


_BP = "vslbook/BeerPong-v0"
#: figure → its claims (the book's reproduction targets)
CLAIMS: dict[str, tuple[Claim, ...]] = {
    "fig3-2": (
        Claim("beer pong: SVSL succeeds on 80 % or more of the cup grid (thesis Fig. 3.2e: "
              "92 %)", "at_least", "SVSL", value=0.80, env=_BP, metric="grid_success"),
        Claim("beer pong: SVSL above HiREPS on the cup grid (thesis Fig. 3.2e/f: 92 % against "
              "75 %)", "above", "SVSL", "HiREPS", env=_BP, metric="grid_success"),
    ),
    "fig4-3b": (
        Claim("table tennis: Di-SkilL at 60 % success or more (thesis: 'high success rates')",
              "at_least", "diskill", value=0.60),
        Claim("table tennis: BBRL at 60 % success or more (thesis: 'high success rates')",
              "at_least", "bbrl", value=0.60),
    ),
    "fig4-3c": (Claim("5-link reacher: Di-SkilL above BBRL (thesis Fig. 4.3c)", "above",
                      "diskill", "bbrl"),),
    "fig4-4a": (Claim("hopper jump: Di-SkilL within BBRL's CI or above it (thesis Fig. 4.4a: "
                      "'on par')", "within_or_above", "diskill", "bbrl"),),
    "fig5-3-cheetah": (
        Claim("cheetah-run: our DIME within the published DIME curve's CI or above it, at the "
              "step our runs end (the authors' 10 seeds; a check of the implementation)",
              "within_or_above_published", "DIME", published="dmc_cheetah_run"),
    ),
    "fig5-ablations": (
        Claim("Pendulum-v1, standing for Figs. 5.2-5.3: DIME within CrossQ's CI or above it "
              "(thesis Fig. 5.2a-b: on par with CrossQ on Ant, above it on Humanoid)",
              "within_or_above", "DIME", "CrossQ"),
        Claim("Pendulum-v1, standing for Fig. 5.2d: DIME (4 diffusion steps) above 2 steps "
              "(thesis: 'two diffusion steps perform badly')", "above", "DIME", "2 steps"),
        Claim("Pendulum-v1, standing for Fig. 5.4c-d: DIME above its Gaussian policy "
              "(thesis: 'the diffusion-based policy reaches a higher return')", "above",
              "DIME", "Gaussian"),
    ),
}  # fmt: skip

#: figure → (metric, method → final value) the thesis's text gives (the thesis's numbers)
THESIS_NUMBERS: dict[str, tuple[str, dict[str, float]]] = {
    "fig3-2": ("grid_success", {"SVSL": 0.92, "HiREPS": 0.75}),  # Section 3.4.2, Fig. 3.2e/f
}


def final_scores(runs: dict[str, list[Path]], metric: str, *, reps: int | None = None,
                 skip: set[str] | frozenset[str] = frozenset()) -> pd.DataFrame:  # fmt: skip
    """Each method's final ``metric`` (every run's last row that has it): IQM over its runs
    with a 95 % stratified-bootstrap CI. ``skip``: run names left out (probes).

    Returns one row per method with runs: method, runs, iqm, ci_low, ci_high.

    Raises:
        ValueError: a run never logged ``metric``.
    """
    from vslbook import stats

    table = {}
    for method, paths in runs.items():
        last = []
        for path in paths:
            if Path(path).name in skip:
                continue
            values = [r[metric] for r in RunDir.open(path).metrics() if r.get(metric) is not None]
            if not values:
                raise ValueError(f"{path}: no {metric!r} in its metrics")
            last.append(float(values[-1]))
        if last:
            table[method] = np.array(last)[:, None]
    if not table:
        return pd.DataFrame(columns=["method", "runs", "iqm", "ci_low", "ci_high"])
    point, ci = stats.interval_estimates(table, reps=reps, seed=0)
    return pd.DataFrame([{"method": m, "runs": len(table[m]), "iqm": float(point[m][0]),
                          "ci_low": float(ci[m][0, 0]), "ci_high": float(ci[m][1, 0])}
                         for m in table])  # fmt: skip


def ranked(scores: pd.DataFrame, a: str, b: str) -> bool | None:
    """Whether method ``a`` ranks above method ``b`` on the final scores of
    :func:`final_scores`: True where ``a``'s IQM lies above the upper end of ``b``'s 95 % CI,
    False where ``b``'s IQM lies above the upper end of ``a``'s, None where neither does (the
    difference is inside the spread over seeds: no ranking). The rule of every "above" in
    this book (:class:`Claim`, the orderings of Chapters 3 and 4).

    Raises:
        ValueError: ``a`` or ``b`` has no row in ``scores``.
    """
    row = scores.set_index("method")
    missing = [m for m in (a, b) if m not in row.index]
    if missing:
        raise ValueError(f"no final scores for {missing}; scores has {sorted(row.index)}")
    if row.loc[a, "iqm"] > row.loc[b, "ci_high"]:
        return True
    if row.loc[b, "iqm"] > row.loc[a, "ci_high"]:
        return False
    return None


def final_step(paths: list[Path], metric: str) -> float:
    """The step of the last row logging ``metric``, the smallest over ``paths`` (where the
    shortest of the runs ends)."""
    ends = []
    for path in paths:
        rows = [r for r in RunDir.open(path).metrics() if r.get(metric) is not None]
        if rows:
            ends.append(float(rows[-1]["step"]))
    if not ends:
        raise ValueError(f"no run of {[Path(p).name for p in paths]} logged {metric!r}")
    return min(ends)


def published_at(task: str, step: float, *, reps: int | None = None) -> dict[str, float]:
    """The published curve of ``task`` (:func:`vslbook.data.paper_curves`) at its evaluation
    step nearest ``step``: ``{"step", "iqm", "ci_low", "ci_high", "seeds"}``, IQM over the
    authors' seeds with a 95 % stratified-bootstrap CI."""
    from vslbook.data import paper_curves
    from vslbook.stats import iqm_curve

    curve = iqm_curve(paper_curves(task), reps=reps)
    row = curve.iloc[int(np.argmin(np.abs(curve["env_steps"].to_numpy() - float(step))))]
    return {"step": float(row.env_steps), "iqm": float(row.iqm), "ci_low": float(row.lo),
            "ci_high": float(row.hi), "seeds": int(row.n_runs)}  # fmt: skip


def _check(claim: Claim, scores: pd.DataFrame, published: dict[str, float] | None = None) -> str:
    row = scores.set_index("method")
    needed = [m for m in (claim.method, claim.other) if m is not None]
    if any(m not in row.index for m in needed):
        return "pending"
    mine = row.loc[claim.method, "iqm"]
    if claim.kind == "at_least":
        ok = mine >= claim.value
    elif claim.kind == "above":
        ok = ranked(scores, claim.method, claim.other) is True
    elif claim.kind == "within_or_above":
        ok = mine >= row.loc[claim.other, "ci_low"]
    else:  # within_or_above_published (Claim checks the kind)
        ok = mine >= published["ci_low"]
    return "met" if ok else "not met"


def claim_runs(claim: Claim, fs) -> dict[str, list[Path]]:
    """The runs of ``fs`` a claim is about: those of its task where it names one, probes
    left out."""
    runs = {m: [p for p in ps if Path(p).name not in fs.probes] for m, ps in fs.runs.items()}
    if claim.env is not None:
        runs = {m: [p for p in ps if RunDir(p).config.get("env") == claim.env]
                for m, ps in runs.items()}  # fmt: skip
    return {m: ps for m, ps in runs.items() if ps}


def verdicts(figure: str, fs, metric: str, *, reps: int | None = None) -> pd.DataFrame:
    """The claims of ``figure`` (:data:`CLAIMS`) checked on the runs of the
    :class:`~vslbook.experiments.figure_sources.FigureSet` ``fs``: one row per claim with
    its text, status (``met``, ``not met``, ``pending``, ``smoke``, or ``not logged`` where a
    run predates the claim's metric) and the seeds behind it.
    """
    rows = []
    for claim in CLAIMS.get(figure, ()):
        runs = claim_runs(claim, fs)
        try:
            scores = final_scores(runs, claim.metric or metric, reps=reps)
        except ValueError:  # a run made before the metric was logged
            scores, status = final_scores({}, metric), "not logged"
        else:
            published = None
            if claim.published is not None and claim.method in runs:
                end = final_step(runs[claim.method], claim.metric or metric)
                published = published_at(claim.published, end, reps=reps)
            status = "smoke" if fs.smoke else _check(claim, scores, published)
        seeds = {m: int(n) for m, n in zip(scores["method"], scores["runs"], strict=True)
                 if m in (claim.method, claim.other)}  # fmt: skip
        rows.append({"claim": claim.text, "status": status, "seeds": seeds})
    return pd.DataFrame(rows, columns=["claim", "status", "seeds"])


def reproduction_text(figure: str, fs, metric: str, *, reps: int | None = None) -> str:
    """Lines for a figure: per method ours (final IQM [95 % CI], seeds) beside the
    thesis's number where it gives one, then each claim's verdict."""
    lines = []
    thesis_metric, thesis = THESIS_NUMBERS.get(figure, (None, {}))
    for name in dict.fromkeys((metric, *([thesis_metric] if thesis_metric else []))):
        try:
            scores = final_scores(fs.runs, name, reps=reps, skip=set(fs.probes))
        except ValueError as err:  # e.g. no grid_success in runs made before it was logged
            lines.append(f"final {name}: not logged by every run ({err})")
            continue
        lines.append(f"final {name} (IQM [95 % CI] over seeds, {fs.budget} budget):")
        for r in scores.itertuples():
            given = (f"; the thesis's: {thesis[r.method]:.3g}"
                     if name == thesis_metric and r.method in thesis else "")  # fmt: skip
            lines.append(f"  {r.method}: {r.iqm:.3g} [{r.ci_low:.3g}, {r.ci_high:.3g}], "
                         f"{r.runs} seed(s){given}")  # fmt: skip
    for v in verdicts(figure, fs, metric, reps=reps).itertuples():
        status = "smoke: code path only" if v.status == "smoke" else v.status
        lines.append(f"  {status:>22}: {v.claim}")
    return "\n".join(lines)


def claims_overview(figures: list[str], budget=None, root: str | Path = "runs", *,
                    reps: int | None = None, sets: dict | None = None) -> pd.DataFrame:  # fmt: skip
    """What a chapter opens with: every claim of ``figures`` checked on the runs each figure
    draws (:func:`vslbook.experiments.figure_sources.figure_set`: recorded, finished, or
    trained now; ``sets``: figure → its FigureSet where the caller has it already): figure,
    claim, status, seeds, and where the runs come from (budget, recorded or trained)."""
    from vslbook.experiments.figure_sources import figure_set
    from vslbook.experiments.record import figure_metric

    rows = []
    for figure in figures:
        fs = (sets or {}).get(figure) or figure_set(figure, budget, root)
        origin = "recorded" if fs.recorded else "trained"
        for v in verdicts(figure, fs, figure_metric(figure), reps=reps).itertuples():
            rows.append({"figure": figure, "claim": v.claim, "status": v.status,
                         "seeds": ", ".join(f"{m} {n}" for m, n in v.seeds.items()) or "-",
                         "runs": f"{origin}, {fs.budget}"})  # fmt: skip
    return pd.DataFrame(rows, columns=["figure", "claim", "status", "seeds", "runs"])


#: a claim's status → its cell colour in :func:`show_claims`
STATUS_COLOURS = {"met": "#d8f0d8", "not met": "#f6d5d5", "pending": "#eeeeee",
                  "smoke": "#eeeeee", "not logged": "#fbeccc"}  # fmt: skip


def show_claims(table: pd.DataFrame):
    """:func:`claims_overview`'s table for a notebook: every claim in full (a DataFrame's
    display cuts long text), left-aligned, without the index, each status coloured."""
    missing = [c for c in ("figure", "claim", "status", "seeds", "runs") if c not in table]
    if missing:
        raise ValueError(f"show_claims: not a claims table (missing columns {missing})")
    return (table.style.hide(axis="index")
            .map(lambda s: f"background-color: {STATUS_COLOURS.get(s, '')}", subset=["status"])
            .set_properties(**{"text-align": "left", "white-space": "normal"}))  # fmt: skip

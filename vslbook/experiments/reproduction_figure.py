"""What a chapter opens with: its claims drawn, ours next to the thesis's.

:func:`results_figure` draws one panel per task a chapter's claims
(:data:`vslbook.experiments.reproduction.CLAIMS`) are about: every method's final IQM over
seeds with its 95 % stratified-bootstrap CI (:func:`~vslbook.experiments.reproduction.final_scores`,
probes left out), and beside them what the thesis says:

* the thesis's numbers (:data:`~vslbook.experiments.reproduction.THESIS_NUMBERS`) as hollow
  diamonds, labelled as the thesis's;
* an ``at_least`` claim's threshold as a dashed line (the book's reading of the thesis's
  words, which the claim's text gives);
* a published curve (Chapter 5's cheetah-run) as its own grey row, at the step our runs end;
* each claim's status in the panel's title (``met``, ``not met``, ``pending``, or ``smoke:
  code path only``); a method without a finished run keeps its row, labelled with how far
  its probes have trained (a claim is about a run's end, so probes are not scored here;
  the chapter's full figures draw them).

The figure's caption (:func:`~vslbook.experiments.figure_sources.annotate`) says where the
runs came from; the chapter prints :func:`~vslbook.experiments.reproduction.claims_overview`
under it with every claim in words.
"""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np

from vslbook.experiments.reproduction import (
    CLAIMS,
    THESIS_NUMBERS,
    Claim,
    claim_runs,
    final_scores,
    final_step,
    published_at,
    verdicts,
)
from vslbook.plots import is_method, method_color, panel_grid

__all__ = ["FIGURE_NAMES", "METRIC_WORDS", "method_label", "results_figure"]

#: figure id → how a panel's title names it
FIGURE_NAMES = {
    "fig3-2": "Fig. 3.2e–f", "fig4-3b": "Fig. 4.3b", "fig4-3c": "Fig. 4.3c",
    "fig4-4a": "Fig. 4.4a", "fig5-3-cheetah": "beside Fig. 5.3",
    "fig5-ablations": "ablations (Figs. 5.2–5.4)",
}  # fmt: skip
#: metric → its name on an axis
METRIC_WORDS = {
    "grid_success": "success over the cup grid", "test_success": "test success rate",
    "test_return": "test return", "eval_return": "evaluation return",
}  # fmt: skip


def method_label(method: str) -> str:
    """A method as figures name it (Chapter 4's run names ``diskill``, ``bbrl`` … as
    :data:`vslbook.experiments.diskill_runs.LABELS`)."""
    from vslbook.experiments.diskill_runs import LABELS

    return LABELS.get(method, method)


def _panels(sets: dict) -> list[tuple[str, str, list[Claim]]]:
    """(figure, metric, claims) per task the claims of ``sets``' figures are about."""
    from vslbook.experiments.record import figure_metric

    panels = []
    for figure in sets:
        groups: dict[tuple, list[Claim]] = {}
        for claim in CLAIMS.get(figure, ()):
            metric = claim.metric or figure_metric(figure)
            groups.setdefault((claim.env, metric), []).append(claim)
        panels += [(figure, metric, claims) for (_, metric), claims in groups.items()]
    return panels


#: the least span of a panel's value axis, as a fraction of the largest value on it
MIN_RELATIVE_SPAN = 0.1


def _at_least_span(ax) -> None:
    """Widen the value axis of ``ax`` about its middle to :data:`MIN_RELATIVE_SPAN` of its
    largest absolute value, so that a difference of a fraction of a percent (two methods on
    par, as on hopper jump) does not fill the panel and read as a large one."""
    lo, hi = ax.get_xlim()
    scale = max(abs(lo), abs(hi))
    if scale > 0 and hi - lo < MIN_RELATIVE_SPAN * scale:
        mid = (lo + hi) / 2
        ax.set_xlim(mid - MIN_RELATIVE_SPAN * scale / 2, mid + MIN_RELATIVE_SPAN * scale / 2)


def _draw_panel(ax, figure: str, fs, metric: str, claims: list[Claim], reps) -> None:
    runs = claim_runs(claims[0], fs)  # the claims of a panel share their task
    rows: list[tuple[str, float, float, float, str, str]] = []  # label, iqm, lo, hi, colour, kind
    try:
        scores = final_scores(runs, metric, reps=reps)
    except ValueError:  # a run made before the metric was logged
        scores = final_scores({}, metric)
    for r in scores.itertuples():
        label = method_label(r.method)
        color = method_color(label) if is_method(label) else "#0072B2"
        rows.append((f"{label} (ours, {r.runs} seed{'s' * (r.runs != 1)})", r.iqm, r.ci_low,
                     r.ci_high, color, "ours"))  # fmt: skip
    named = dict.fromkeys(m for c in claims for m in (c.method, c.other) if m is not None)
    probes = {m: [fs.probes[p.name] for p in ps if p.name in fs.probes]
              for m, ps in fs.runs.items()}  # fmt: skip
    for method in named:
        if method not in set(scores["method"]):
            training = probes.get(method) or []
            state = (f"still training ({', '.join(training)})" if training
                     else "no finished run")  # fmt: skip
            rows.append((f"{method_label(method)} (ours): {state}", np.nan, np.nan, np.nan,
                         "0.5", "pending"))  # fmt: skip
    for claim in claims:
        if claim.published is not None and claim.method in runs:
            pub = published_at(claim.published, final_step(runs[claim.method], metric), reps=reps)
            rows.append((f"published DIME ({pub['seeds']} seeds, at step {pub['step']:,.0f})",
                         pub["iqm"], pub["ci_low"], pub["ci_high"], "#555555", "published"))
    for y, (_label, iqm, lo, hi, color, kind) in enumerate(rows):
        if kind == "pending":  # the row's label says why; no marker
            continue
        ax.errorbar(iqm, y, xerr=[[iqm - lo], [hi - iqm]], fmt="o" if kind == "ours" else "s",
                    color=color, ecolor=color, capsize=4, markersize=7, lw=2)  # fmt: skip
    metric_thesis, numbers = THESIS_NUMBERS.get(figure, (None, {}))
    legend = "the thesis's number"
    for y, (label, *_rest) in enumerate(rows):
        method = next((m for m in numbers if label.startswith(m + " ")), None)
        if metric_thesis == metric and method is not None:
            ax.plot(numbers[method], y, "D", mfc="none", mec="black", markersize=10, mew=1.5,
                    label=legend)  # fmt: skip
            legend = None
    thresholds: dict[float, list[str]] = {}
    for claim in claims:
        if claim.kind == "at_least":
            thresholds.setdefault(claim.value, []).append(method_label(claim.method))
    for value, methods in thresholds.items():
        ax.axvline(value, color="0.35", ls="--", lw=1.2,
                   label=f"claim: {', '.join(methods)} ≥ {value:g}")
    _at_least_span(ax)
    ax.set_yticks(range(len(rows)), [r[0] for r in rows], fontsize=8)
    ax.set_ylim(-0.7, len(rows) - 0.3)
    ax.invert_yaxis()
    ax.set_xlabel(f"final {METRIC_WORDS.get(metric, metric)} (IQM, 95 % CI)")
    if any(line.get_label() and not line.get_label().startswith("_") for line in ax.lines):
        ax.legend(fontsize=7.5, loc="best")
    status = verdicts(figure, fs, metric, reps=reps)
    status = status[status["claim"].isin([c.text for c in claims])]["status"]
    words = ("smoke: code path only" if fs.smoke
             else ", ".join(f"{n} {s}" for s, n in status.value_counts().items()))  # fmt: skip
    task = claims[0].text.split(":")[0].split(",")[0]
    ax.set_title(f"{FIGURE_NAMES.get(figure, figure)}, {task}\nclaims: {words}", fontsize=10)


def results_figure(sets: dict, *, reps: int | None = None) -> plt.Figure:
    """One panel per task the claims of ``sets`` (figure id → its
    :class:`~vslbook.experiments.figure_sources.FigureSet`) are about: ours (final IQM and
    95 % CI per method) next to the thesis's numbers and claims.

    Raises:
        ValueError: no figure of ``sets`` has claims.
    """
    panels = _panels(sets)
    if not panels:
        raise ValueError(f"no claims for figures {sorted(sets)}; figures with claims: "
                         f"{sorted(CLAIMS)}")  # fmt: skip
    fig, axes = panel_grid(len(panels), panel=(5.6, 3.2))
    for ax, (figure, metric, claims) in zip(axes, panels, strict=True):
        _draw_panel(ax, figure, sets[figure], metric, claims, reps)
    fig.tight_layout()
    return fig

"""The registered figures drawn from runs (``vslbook figure fig3-1 ... fig4-4d``).

Each figure takes its runs from :func:`vslbook.experiments.figure_sources.figure_set`, as
the notebooks do: the recorded runs of ``data/results/`` or the finished ones in ``root``
(the largest budget), else runs trained now at smoke; with a ``budget`` (``vslbook figure
ID --budget B``) that budget's, training what it lacks. Every figure's footnote is the set's
caption: budget, where the runs came from (recorded: code version and date), seeds against
the thesis's, and "smoke: code path only" where it applies.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt

from vslbook.budget import Budget, get_budget
from vslbook.plots import panel_grid, use_style

__all__ = ["draw_diskill_curves", "draw_fig_3_1", "draw_fig_3_2", "draw_fig_3_5", "footnote"]


def _set(figure: str, budget: Budget | str | None, root: str | Path, progress: bool, **kw):
    """The figure's runs: the default sources, or ``budget``'s where one is named."""
    from vslbook.experiments.figure_sources import figure_set

    mode = None if budget is None else "budget"
    return figure_set(figure, budget, Path(root), mode=mode, progress=progress, **kw)


def footnote(fig: plt.Figure, *sets, width: int = 150) -> None:
    """Where the figure's runs came from, under it
    (:func:`vslbook.experiments.figure_sources.annotate`: red where a recorded run is stale)."""
    from vslbook.experiments.figure_sources import annotate

    annotate(fig, *sets, width=width)


def draw_diskill_curves(
    figure: str, budget: Budget | str | None = None, root: str | Path = "runs",
    *, progress: bool = True,
) -> plt.Figure:  # fmt: skip
    """One Chapter 4 learning-curve panel (Figs. 4.3b, 4.3c, 4.4a-d): the IQM and 95 %
    stratified-bootstrap band over seeds of the test return or success against executed
    episodes, with the thesis's outcome and the counts that differ from the thesis's."""
    from vslbook.experiments import diskill_runs as DR
    from vslbook.experiments.svsl_mixtures import draw_learning_curves

    if figure not in DR.FIGURES:
        raise ValueError(f"unknown figure {figure!r}; expected one of {sorted(DR.FIGURES)}")
    use_style()
    fs = _set("fig" + figure.replace(".", "-"), budget, root, progress)
    b = get_budget(fs.budget)
    y = DR.METRIC[figure]
    fig, ax = plt.subplots(figsize=(6, 4.2))
    draw_learning_curves(
        ax, DR.curves(fs.runs, y, reps=b.bootstrap_reps),
        ylabel=DR.METRIC_LABELS[y] + " (IQM)", thesis=DR.THESIS_OUTCOME[figure],
    )  # fmt: skip
    task = DR.FIGURES[figure][0]
    c = DR.counts(task, "diskill", b)
    full = DR.counts(task, "diskill", "full")
    cfg = DR.diskill_config(task, "diskill")
    differs = [f"{c['iterations']} of {full['iterations']} iterations",
               f"{len(fs.runs.get('diskill', []))} of {full['seeds']} seeds"]  # fmt: skip
    if "n_experts" in c:
        differs.append(f"{c['n_experts']} of {cfg.n_experts} experts")
    if "samples_per_expert" in c:
        differs.append(f"{c['samples_per_expert']} of {cfg.samples_per_expert} samples per expert")
    source = "the authors' settings" if cfg.settings == "code" else "the thesis's settings"
    ax.set_title(f"Fig. {figure}: {task} (ours, {source}, budget {b.name}: "
                 + ", ".join(differs) + ")", fontsize=8, wrap=True)  # fmt: skip
    fig.tight_layout()
    footnote(fig, fs, width=110)
    return fig


def draw_fig_3_1(budget: Budget | str | None = None, root: str | Path = "runs",
                 *, progress: bool = True) -> plt.Figure:  # fmt: skip
    """Fig. 3.1 (Section 3.4.1): SVSL with and without the responsibilities and HiREPS on the
    planar reacher, seed 0 — the chosen experts' mean solutions at six targets and the
    per-expert context distributions. The title's second line names the settings the runs'
    task uses (:func:`vslbook.experiments.ch3_settings.settings_phrase`)."""
    from vslbook.experiments import svsl_planar as P
    from vslbook.experiments.ch3_settings import settings_phrase

    use_style()
    fs = _set("fig3-1", budget, root, progress)
    n = P.planar_counts(fs.budget)
    k, k_full = n["iterations_per_expert"], P.planar_counts("full")["iterations_per_expert"]
    k_note = "" if k == k_full else f", K = {k} of {k_full}"
    fig = P.draw_fig_3_1(
        {v: P.load_model(fs.runs[v][0]) for v in P.VARIANTS},
        title=f"Fig. 3.1 (ours, budget {fs.budget}: {n['n_experts']} experts{k_note}, seed 0 "
              f"of {len(fs.runs[P.VARIANTS[0]])}; thesis: 60 experts, best of 15 seeds)\n"
              f"{settings_phrase('planar-reacher')}",
    )  # fmt: skip
    footnote(fig, fs, width=120)
    return fig


def draw_fig_3_2(budget: Budget | str | None = None, root: str | Path = "runs",
                 *, progress: bool = True) -> plt.Figure:  # fmt: skip
    """Fig. 3.2 (Section 3.4.2): (a) beer pong's and (b) table tennis's test return against
    executed episodes (IQM and 95 % CI over seeds) for SVSL, HiREPS and LaDiPS, and (e, f)
    SVSL's and HiREPS's success over the cup box (the means of experts drawn from
    π(o | c)): the mean of the finished seeds' final grids as they logged them, as the
    thesis draws the mean over its 20 models; with only probes, the first probe's grid from
    its checkpoint on the reduced grid
    (:func:`vslbook.experiments.beer_pong_grids.seeds_grid`). The grids' mean
    (``grid_success``) and the thesis's claims are printed by
    :func:`vslbook.experiments.reproduction.reproduction_text`.
    """
    from vslbook.experiments import svsl_beer_pong as BP
    from vslbook.experiments import svsl_table_tennis as TT
    from vslbook.experiments.beer_pong_grids import seeds_grid

    use_style()
    bp = _set("fig3-2", budget, root, progress, envs=(BP.ENV,))
    tt = _set("fig3-2", budget, root, progress, envs=(TT.ENV,))
    fig, axes = panel_grid(4, panel=(5.5, 4.2))
    BP.draw_learning_curves(axes[0], BP.learning_curves(bp.runs), thesis=None)
    axes[0].set_title(f"(a) beer pong: test return ({bp.budget})")
    TT.draw_learning_curves(axes[1], TT.learning_curves(tt.runs), thesis=None)
    axes[1].set_title(f"(b) table tennis: test return ({tt.budget})")
    for ax, method, panel in zip(axes[2:], ("SVSL", "HiREPS"), "ef", strict=True):
        cells, how = seeds_grid(bp.runs[method], bp.budget)
        BP.draw_success_grid(ax, cells, title=f"({panel}) {method}:\n{how}")
    fig.suptitle("Fig. 3.2 (ours; thesis: 20 seeds, success 92 % for SVSL and 75 % for HiREPS)",
                 fontsize=10)  # fmt: skip
    fig.tight_layout()
    footnote(fig, bp, tt, width=130)
    return fig


def draw_fig_3_5(budget: Budget | str | None = None, root: str | Path = "runs",
                 *, progress: bool = True) -> plt.Figure:  # fmt: skip
    """Fig. 3.5 (Section 3.4.3): SVSL against PPO on the 5-link reacher with the rewards of
    Eqs. 3.8-3.10."""
    from vslbook.experiments import svsl_reacher as RE

    use_style()
    fs = _set("fig3-5", budget, root, progress)
    fig = RE.draw_fig_3_5(RE.reacher_curves(RE.by_method_and_reward(fs.runs)), fs.budget)
    footnote(fig, fs, width=120)
    return fig

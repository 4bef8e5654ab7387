"""One consistent matplotlib look, learning curves, and thesis-vs-ours overlays.

Usage in a notebook::

    from vslbook import data, plots, stats

    plots.use_style()                       # for the rest of the session, or
    with plots.use_style():                 # only inside the block
        fig, ax = plt.subplots()
        thesis = stats.iqm_curve(data.paper_curves("dmc_cheetah_run"))
        plots.thesis_vs_ours(ax, thesis, ours)
        plots.save_figure(fig, "fig5-3-cheetah_run")

Curves are the frames :func:`vslbook.stats.iqm_curve` returns (columns ``x``, ``iqm``,
``lo``, ``hi``): the line is the IQM over runs, the band its 95 % bootstrap CI.

A method looks the same in every figure: :data:`METHOD_STYLES` fixes its colour, line style
and marker (:func:`method_style`, :func:`method_color`; a curve whose label names a method
takes its style), :data:`FIGURE_METHODS` lists the methods each comparison figure draws
together, and a mixture's experts take :func:`expert_color`. Figures of several panels
come from :func:`panel_grid`: at most two panels per row, in a notebook cell tagged
``full-width``, so that each panel is at least 400 px wide on the site.
"""

from __future__ import annotations

import weakref
from collections.abc import Mapping, Sequence
from types import TracebackType
from typing import Any

import matplotlib as mpl
import numpy as np
import pandas as pd
from cycler import cycler
from matplotlib.axes import Axes
from matplotlib.colors import to_hex
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.transforms import ScaledTranslation

from vslbook.budget import get_budget
from vslbook.figure_files import (
    FIGURES_ENV_VAR,
    LAYOUT_SUFFIX,
    figure_layout,
    figures_dir,
    save_figure,
)

__all__ = [
    "EXPERT_COLORS",
    "FIGURES_ENV_VAR",
    "FIGURE_METHODS",
    "LAYOUT_SUFFIX",
    "METHOD_ALIASES",
    "METHOD_COLORS",
    "METHOD_STYLES",
    "PALETTE",
    "PANELS_PER_ROW",
    "STYLE",
    "StyleContext",
    "count_phrase",
    "expert_color",
    "figure_layout",
    "figures_dir",
    "interval_plot",
    "is_method",
    "learning_curve",
    "method_color",
    "method_style",
    "panel_grid",
    "profile_plot",
    "save_figure",
    "thesis_vs_ours",
    "use_style",
]

#: the file :func:`save_figure` writes beside a figure, with its :func:`figure_layout`

#: colour-blind friendly palette (Okabe & Ito), the default colour cycle
PALETTE = [
    "#0072B2",  # blue
    "#D55E00",  # vermillion
    "#009E73",  # green
    "#CC79A7",  # purple
    "#E69F00",  # orange
    "#56B4E9",  # sky blue
    "#F0E442",  # yellow
    "#000000",  # black
]

#: One line style per method the book draws, so a method looks the same in every figure:
#: its colour, line style and marker (drawn hollow, at a few points of a curve). The colours
#: are Okabe & Ito's and Paul Tol's colour-blind safe sets; where a colour serves two
#: methods, the two never share a figure (:data:`FIGURE_METHODS`) and differ in line style
#: and marker. Within a figure the methods differ in all three, so curves that coincide (a
#: short run's methods often give the same numbers) stay visible.
METHOD_STYLES: dict[str, dict[str, Any]] = {
    # reference curves and our runs (Chapters 2 and 5, published data)
    "thesis": {"color": "#555555", "linestyle": "--", "marker": "s"},
    "ours": {"color": "#0072B2", "linestyle": "-", "marker": "o"},
    # Chapter 3
    "SVSL": {"color": "#D55E00", "linestyle": "-", "marker": "X"},  # not "o": Di-SkilL's
    "SVSL, no responsibilities": {"color": "#E69F00", "linestyle": ":", "marker": "v"},
    "HiREPS": {"color": "#009E73", "linestyle": "--", "marker": "s"},
    "LaDiPS": {"color": "#CC79A7", "linestyle": "-.", "marker": "^"},
    "PPO": {"color": "#000000", "linestyle": ":", "marker": "D"},
    # Chapter 4
    "Di-SkilL": {"color": "#882255", "linestyle": "-", "marker": "o"},
    "BBRL": {"color": "#56B4E9", "linestyle": "--", "marker": "s"},
    "LinDi-SkilL": {"color": "#999933", "linestyle": "-.", "marker": "^"},
    "Di-SkilLV2": {"color": "#CC6677", "linestyle": ":", "marker": "v"},
    "Di-SkilLV3": {"color": "#332288", "linestyle": "-.", "marker": "P"},
    # Chapter 5: DIME and the ablations' variants (vslbook.experiments.dime_runs.ABLATIONS)
    "DIME": {"color": "#117733", "linestyle": "-", "marker": "o"},
    "2 steps": {"color": "#44AA99", "linestyle": "--", "marker": "s"},
    "fixed α = 0.1": {"color": "#AA4499", "linestyle": "--", "marker": "^"},
    "Gaussian": {"color": "#8C564B", "linestyle": "--", "marker": "v"},
    "no distr. Q": {"color": "#E69F00", "linestyle": "--", "marker": "D"},
    "GB": {"color": "#CC6677", "linestyle": "--", "marker": "P"},
    "fixed β": {"color": "#332288", "linestyle": "--", "marker": "X"},
    "CrossQ": {"color": "#D55E00", "linestyle": "--", "marker": "h"},
    # named by the thesis's figures, not drawn from runs of this book
    "SAC": {"color": "#CC79A7", "linestyle": ":", "marker": "<"},
    "BRO": {"color": "#8C564B", "linestyle": ":", "marker": ">"},
    "MORE": {"color": "#56B4E9", "linestyle": ":", "marker": "p"},
    "REPS": {"color": "#009E73", "linestyle": ":", "marker": "h"},
    "TRPL": {"color": "#AA4499", "linestyle": ":", "marker": "*"},
}
#: Other names of a method in :data:`METHOD_STYLES` (the name on the left takes its style).
METHOD_ALIASES: dict[str, str] = {"DIME-GB": "GB"}
#: The colour of each method of :data:`METHOD_STYLES`.
METHOD_COLORS: dict[str, str] = {name: style["color"] for name, style in METHOD_STYLES.items()}

#: The methods each of the book's comparison figures draws together (figure id as saved by
#: the notebooks, less the budget → method labels): no two of them share a colour, nor both
#: line style and marker (``tests/test_plots_palette.py`` checks this, and that these are
#: the labels the experiment modules use).
FIGURE_METHODS: dict[str, tuple[str, ...]] = {
    "ch2-erl-pg": ("ours",),
    "fig-3-1-scores": ("SVSL", "SVSL, no responsibilities", "HiREPS"),
    "fig-3-2-beer-pong": ("SVSL", "HiREPS", "LaDiPS"),
    "fig-3-2-table-tennis": ("SVSL", "HiREPS", "LaDiPS"),
    "fig-3-5-reacher": ("SVSL", "PPO"),
    "fig-4-3b-ablation": ("Di-SkilL", "BBRL", "Di-SkilLV2", "Di-SkilLV3", "SVSL"),
    "fig-4-3c-4-4-curves": ("Di-SkilL", "BBRL", "LinDi-SkilL", "PPO"),
    "fig-4-4-returns": ("Di-SkilL", "BBRL", "LinDi-SkilL", "PPO"),
    "fig-b-3-hopper": ("Di-SkilL", "BBRL", "LinDi-SkilL"),
    "ch5-cheetah-run-ours-vs-published": ("thesis", "ours"),
    "ch5-ablations-pendulum": (
        "DIME", "2 steps", "fixed α = 0.1", "Gaussian", "no distr. Q", "GB", "fixed β", "CrossQ",
    ),  # fmt: skip
}

#: The most panels :func:`panel_grid` puts side by side. The site shows a figure cell
#: tagged ``full-width`` 816-1075 px wide (``book/_static/vslbook.css``), so that two
#: panels per row are each at least 400 px wide as rendered (three would not be).
PANELS_PER_ROW = 2

#: Colours of a mixture's experts, one each (experts beyond 18 repeat them): Matplotlib's
#: qualitative ``tab20``, the ten strong hues first, then their light shades, without its
#: reds (targets, obstacles and goals are drawn in red).
EXPERT_COLORS: list[str] = [
    to_hex(c) for shade in (0, 1) for k, c in enumerate(mpl.colormaps["tab20"].colors)
    if k % 2 == shade and k // 2 != 3
]  # fmt: skip

#: rcParams of the book's look
STYLE: dict[str, Any] = {
    "figure.figsize": (5.0, 3.4),
    "figure.dpi": 110,
    "savefig.dpi": 200,
    "savefig.bbox": "tight",
    "font.size": 10,
    "axes.titlesize": 11,
    "axes.labelsize": 10,
    "xtick.labelsize": 9,
    "ytick.labelsize": 9,
    "legend.fontsize": 9,
    "legend.frameon": False,
    "axes.grid": True,
    "grid.alpha": 0.3,
    "grid.linewidth": 0.6,
    "axes.spines.top": False,
    "axes.spines.right": False,
    "axes.prop_cycle": cycler(color=PALETTE),
    "lines.linewidth": 1.8,
    "axes.formatter.limits": (-3, 4),
    "axes.formatter.use_mathtext": True,
}


class StyleContext:
    """Settings saved by :func:`use_style`; restores them when used as a context manager."""

    def __init__(self, saved: dict[str, Any]) -> None:
        self._saved = saved

    def __enter__(self) -> StyleContext:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.restore()

    def restore(self) -> None:
        """Put back the matplotlib settings that were active before :func:`use_style`."""
        # dict.update skips rcParams validation, as matplotlib's own rc_context does.
        dict.update(mpl.rcParams, self._saved)


def use_style(overrides: Mapping[str, Any] | None = None) -> StyleContext:
    """Apply :data:`STYLE` (plus ``overrides``, extra rcParams) to matplotlib.

    ``use_style()`` alone changes the settings for the rest of the session;
    ``with use_style(): ...`` changes them only inside the block.
    """
    context = StyleContext(dict(mpl.rcParams))
    mpl.rcParams.update(STYLE)
    if overrides:
        mpl.rcParams.update(overrides)
    return context


def _method_key(name: str) -> str | None:
    """The key of ``name`` in :data:`METHOD_STYLES` (case-insensitive, aliases followed)."""
    wanted = str(name).lower()
    for alias, target in METHOD_ALIASES.items():
        if alias.lower() == wanted:
            wanted = target.lower()
    return next((key for key in METHOD_STYLES if key.lower() == wanted), None)


def is_method(name: str) -> bool:
    """Whether ``name`` (case-insensitive) has a style in :data:`METHOD_STYLES`."""
    return _method_key(name) is not None


def method_style(name: str) -> dict[str, Any]:
    """Line keywords of a method (case-insensitive): ``color``, ``linestyle``, ``marker``.

    Raises ``KeyError`` for a name without an entry in :data:`METHOD_STYLES`: a method new to
    the book gets its style there, so that it looks the same in every figure.
    """
    key = _method_key(name)
    if key is None:
        raise KeyError(
            f"no style for method {name!r}; add it to vslbook.plots.METHOD_STYLES (known: "
            f"{list(METHOD_STYLES)})"
        )
    return dict(METHOD_STYLES[key])


def method_color(name: str) -> str:
    """The fixed colour of a method (case-insensitive); ``KeyError`` as :func:`method_style`."""
    return method_style(name)["color"]


def expert_color(index: int) -> str:
    """The colour of a mixture's expert ``index`` (:data:`EXPERT_COLORS`, cycling)."""
    return EXPERT_COLORS[int(index) % len(EXPERT_COLORS)]


def count_phrase(n: int, noun: str, plural: str | None = None) -> str:
    """``n`` and ``noun`` in words: "1 seed", "3 seeds" (``plural``: default noun + "s")."""
    return f"{n} {noun if n == 1 else plural or noun + 's'}"


def panel_grid(
    n: int,
    *,
    cols: int = PANELS_PER_ROW,
    panel: tuple[float, float] = (5.2, 3.6),
    **subplots_kw: Any,
) -> tuple[Figure, np.ndarray]:
    """A figure of ``n`` panels in rows of at most ``cols`` and a flat array of its ``n`` axes.

    ``panel`` is one panel's (width, height) in inches; grid cells after the ``n``-th are
    removed. Extra keywords go to ``plt.subplots`` (e.g. ``sharey=True``). The figure
    should be shown in a notebook cell tagged ``full-width`` (:data:`PANELS_PER_ROW`).
    """
    import matplotlib.pyplot as plt

    if int(n) < 1:
        raise ValueError(f"n must be at least 1 panel, got {n!r}")
    if not 1 <= int(cols) <= PANELS_PER_ROW:
        raise ValueError(
            f"cols must be between 1 and {PANELS_PER_ROW} (panels narrower than 400 px on "
            f"the site otherwise), got {cols!r}"
        )
    cols = min(int(cols), int(n))
    rows = -(-int(n) // cols)
    fig, axes = plt.subplots(
        rows, cols, figsize=(panel[0] * cols, panel[1] * rows), squeeze=False, **subplots_kw
    )
    flat = axes.ravel()
    for ax in flat[n:]:
        ax.remove()
    return fig, flat[:n]


# --------------------------------------------------------------------------- curves


def _check_curve(curve: pd.DataFrame, x: str, what: str) -> pd.DataFrame:
    if not isinstance(curve, pd.DataFrame):
        raise TypeError(f"{what}: expected a DataFrame from stats.iqm_curve, got {type(curve)}")
    missing = [c for c in (x, "iqm", "lo", "hi") if c not in curve.columns]
    if missing:
        raise ValueError(
            f"{what}: column(s) {missing} missing; expected the columns of stats.iqm_curve "
            f"({x}, iqm, lo, hi), got {list(curve.columns)}"
        )
    return curve.sort_values(x)


def _line_style(label: str | None, method: str | None, color: str | None,
                kw: dict[str, Any], points: int) -> dict[str, Any]:  # fmt: skip
    """The keywords of one curve: the method's style (``method``, else a ``label`` that names
    a method), then ``color`` and ``kw`` on top."""
    name = method if method is not None else label
    style: dict[str, Any] = {}
    if method is not None or (name is not None and is_method(name)):
        style = method_style(name)
        # about six hollow markers per curve, shifted per method: curves that coincide (a
        # short run's methods often give the same numbers) each keep their own markers
        step = max(1, -(-points // 6))
        rank = list(METHOD_STYLES).index(_method_key(name))
        style |= {"markevery": (rank % step, step), "markerfacecolor": "none", "markersize": 5}
    if color is not None:
        style["color"] = color
    if "ls" in kw:
        style.pop("linestyle", None)
    return style | kw


#: How many single-point curves :func:`learning_curve` has drawn on an axes.
_SINGLE_POINTS: weakref.WeakKeyDictionary[Axes, int] = weakref.WeakKeyDictionary()


def learning_curve(
    ax: Axes,
    curve_df: pd.DataFrame,
    x: str = "env_steps",
    label: str | None = None,
    color: str | None = None,
    *,
    method: str | None = None,
    band_alpha: float = 0.2,
    **kw: Any,
) -> Line2D:
    """Plot the IQM line of ``curve_df`` with a shaded ``lo``–``hi`` band; return the line.

    The line takes the style of ``method`` (:func:`method_style`; by default the ``label``
    where it names a method of :data:`METHOD_STYLES`, else the axes' next colour); ``color``
    and extra keyword arguments for ``ax.plot`` (e.g. ``linestyle``) override it. A curve of
    a single point (a short run evaluated once) is drawn as a marker with its interval as
    an error bar, so it stays visible; the single points of one axes sit a few points apart
    around their x value (the first on it, then right, left, …), so that methods with
    equal numbers do not hide each other.
    """
    curve = _check_curve(curve_df, x, "learning_curve")
    style = _line_style(label, method, color, dict(kw), len(curve))
    if len(curve) == 1:
        style.pop("markevery", None)
        style.setdefault("marker", "o")
        style.setdefault("markersize", 7)
        k = _SINGLE_POINTS[ax] = _SINGLE_POINTS.get(ax, 0) + 1  # single points on ax so far
        shift = (k // 2) * (1 if k % 2 == 0 else -1) * 4 / 72  # inches: 0, +4, -4, +8, ... pt
        at = ax.transData + ScaledTranslation(shift, 0, ax.figure.dpi_scale_trans)
        (line,) = ax.plot(curve[x], curve["iqm"], label=label, transform=at, **style)
        iqm, lo, hi = (curve[k].to_numpy(float) for k in ("iqm", "lo", "hi"))
        ax.errorbar(curve[x].to_numpy(float), iqm, yerr=[iqm - lo, hi - iqm], transform=at,
                    color=line.get_color(), capsize=3, linestyle="none")  # fmt: skip
        x0 = float(curve[x].iloc[0])  # drawn shifted: the data limits are set here
        ax.update_datalim([(x0, float(lo.min())), (x0, float(hi.max())), (x0, float(iqm[0]))])
        ax.autoscale_view()
        if not ax.get_xlabel():
            ax.set_xlabel(x.replace("_", " "))
        if not ax.get_ylabel():
            ax.set_ylabel("IQM return")
        return line
    (line,) = ax.plot(curve[x], curve["iqm"], label=label, **style)
    ax.fill_between(
        curve[x], curve["lo"], curve["hi"], color=line.get_color(), alpha=band_alpha,
        linewidth=0,
    )
    if not ax.get_xlabel():
        ax.set_xlabel(x.replace("_", " "))
    if not ax.get_ylabel():
        ax.set_ylabel("IQM return")
    return line


def thesis_vs_ours(
    ax: Axes,
    thesis_curve: pd.DataFrame,
    ours_curve: pd.DataFrame | None = None,
    *,
    x: str = "env_steps",
    budget: str | None = None,
    title: str | None = None,
    legend_loc: str = "best",
) -> Axes:
    """Overlay the thesis's published curve (dashed) and ours (solid) on ``ax``.

    Labels: ``"thesis (published data)"`` and ``"ours (<budget> budget)"`` where
    ``budget`` defaults to the active budget's name. With ``ours_curve=None`` only the
    published curve is drawn, with a note saying that no run of ours is shown.
    """
    learning_curve(ax, thesis_curve, x=x, label="thesis (published data)", method="thesis")
    if ours_curve is not None:
        name = get_budget(budget).name
        learning_curve(ax, ours_curve, x=x, label=f"ours ({name} budget)", method="ours")
    else:
        ax.text(
            0.98, 0.04, "ours: no run at this budget (published data only)",
            transform=ax.transAxes, ha="right", va="bottom", fontsize="small",
            color=METHOD_COLORS["thesis"],
        )
    if title is not None:
        ax.set_title(title)
    ax.legend(loc=legend_loc)
    return ax


# --------------------------------------------------------------------------- aggregates


def _color_of(name: str, index: int, colors: Mapping[str, str] | None) -> str:
    given = (colors or {}).get(name)
    if given:
        return given
    return method_color(name) if is_method(name) else PALETTE[index % len(PALETTE)]


def interval_plot(
    ax: Axes,
    point: Mapping[str, Any],
    ci: Mapping[str, Any],
    *,
    index: int = 0,
    colors: Mapping[str, str] | None = None,
    xlabel: str = "IQM",
) -> Axes:
    """Horizontal CI bars (one row per method) with a tick and a dot at the point estimate.

    ``point`` and ``ci`` are the dicts :func:`vslbook.stats.interval_estimates` returns;
    ``index`` picks the aggregate when ``func`` returned several. A bar takes its colour
    from ``colors``, else the method's (:func:`method_color`), else the book's palette by
    row (:data:`PALETTE`) for a name that is not a method.
    """
    missing = [name for name in point if name not in ci]
    if missing:
        raise ValueError(f"interval_plot: no CI for {missing}; CIs given for {list(ci)}")
    names = list(point)
    for row, name in enumerate(names):
        value = float(np.atleast_1d(point[name])[index])
        bounds = np.asarray(ci[name], dtype=float).reshape(2, -1)[:, index]
        color = _color_of(name, row, colors)
        bar = ax.barh(row, bounds[1] - bounds[0], left=bounds[0], height=0.6, color=color,
                      alpha=0.75)  # fmt: skip
        for patch in bar:  # the axes keep a margin around the bars, so a dot at an
            patch.sticky_edges.x.clear()  # interval's end is not cut in half
        ax.vlines(value, row - 0.3, row + 0.3, color="black", linewidth=1.5)
        # the estimate as a dot too: an interval of one run has no width to show a colour
        ax.plot(value, row, "o", color=color, markeredgecolor="black", markersize=6, zorder=3)
    ax.set_yticks(range(len(names)), names)
    ax.set_ylim(-0.6, len(names) - 0.4)
    ax.grid(False, axis="y")
    ax.set_xlabel(xlabel)
    return ax


def profile_plot(
    ax: Axes,
    taus: Sequence[float] | np.ndarray,
    profiles: Mapping[str, Any],
    cis: Mapping[str, Any],
    *,
    colors: Mapping[str, str] | None = None,
    xlabel: str = r"normalised score $\tau$",
    ylabel: str = r"fraction of runs with score $> \tau$",
) -> Axes:
    """Performance profiles with their CI bands (from :func:`stats.performance_profile`).

    Colours as in :func:`interval_plot`: ``colors``, else the method's, else by position.
    """
    tau_arr = np.asarray(taus, dtype=float)
    for i, (name, profile) in enumerate(profiles.items()):
        profile = np.asarray(profile, dtype=float)
        if profile.shape != tau_arr.shape:
            raise ValueError(
                f"profile_plot: profile {name!r} has shape {profile.shape}, "
                f"expected {tau_arr.shape} (one value per tau)"
            )
        color = _color_of(name, i, colors)
        ax.plot(tau_arr, profile, color=color, label=name)
        if name in cis:
            band = np.asarray(cis[name], dtype=float)
            ax.fill_between(tau_arr, band[0], band[1], color=color, alpha=0.2, linewidth=0)
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.legend()
    return ax

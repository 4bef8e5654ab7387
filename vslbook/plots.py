"""Learning curves, thesis-vs-ours overlays, interval plots and the grid of a figure's panels.

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

A method looks the same in every figure (its colour, line style and marker come from
:mod:`vslbook.plot_style`, re-exported here: :data:`METHOD_STYLES`, :func:`method_style`,
:func:`use_style`, ...; a curve whose label names a method takes its style). Figures of
several panels come from :func:`panel_grid`: at most two panels per row, in a notebook cell
tagged ``full-width``, so that each panel is at least 400 px wide on the site.
"""

from __future__ import annotations

import weakref
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
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
from vslbook.plot_style import (
    EXPERT_COLORS,
    FIGURE_METHODS,
    METHOD_ALIASES,
    METHOD_COLORS,
    METHOD_STYLES,
    PALETTE,
    STYLE,
    StyleContext,
    expert_color,
    is_method,
    method_color,
    method_key,
    method_style,
    use_style,
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

#: The most panels :func:`panel_grid` puts side by side. The site shows a figure cell
#: tagged ``full-width`` 816-1075 px wide (``book/_static/vslbook.css``), so that two
#: panels per row are each at least 400 px wide as rendered (three would not be).
PANELS_PER_ROW = 2


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
        rank = list(METHOD_STYLES).index(method_key(name))
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

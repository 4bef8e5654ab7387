"""One style per method across the book, experts' colours, and figures of at most two panels
per row (headless, Agg backend)."""

from __future__ import annotations

import itertools

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
import pytest  # noqa: E402
from matplotlib.colors import to_rgb  # noqa: E402

from vslbook import plots  # noqa: E402
from vslbook.budget import BUDGETS  # noqa: E402


@pytest.fixture(autouse=True)
def _close():
    yield
    plt.close("all")


def _curve(n=12, scale=1.0):
    x = np.linspace(0, 1000, n)
    iqm = scale * np.sqrt(x / max(x[-1], 1.0))
    return pd.DataFrame({"env_steps": x, "iqm": iqm, "lo": iqm - 0.1, "hi": iqm + 0.1})


def _panels_per_row(fig) -> int:
    """The most visible axes side by side (colour bars not counted)."""
    boxes = [ax.get_position() for ax in fig.axes
             if ax.get_visible() and ax.get_label() != "<colorbar>"]  # fmt: skip
    return max(
        sum(min(a.y1, b.y1) - max(a.y0, b.y0) > 0.5 * min(a.height, b.height) for b in boxes)
        for a in boxes
    )


# ------------------------------------------------------------------------- method styles


@pytest.mark.parametrize("figure", sorted(plots.FIGURE_METHODS))
def test_methods_of_one_figure_differ_in_colour_and_line(figure):
    methods = plots.FIGURE_METHODS[figure]
    styles = [plots.method_style(m) for m in methods]
    colors = [to_rgb(s["color"]) for s in styles]
    assert len(set(colors)) == len(methods), f"{figure}: two methods share a colour"
    lines = [(s["linestyle"], s["marker"]) for s in styles]
    assert len(set(lines)) == len(methods), f"{figure}: two methods share line and marker"


def test_a_colour_serves_two_methods_only_apart_and_with_other_lines():
    shared_figure = {
        frozenset(pair) for methods in plots.FIGURE_METHODS.values()
        for pair in itertools.combinations(methods, 2)
    }  # fmt: skip
    for a, b in itertools.combinations(plots.METHOD_STYLES, 2):
        sa, sb = plots.METHOD_STYLES[a], plots.METHOD_STYLES[b]
        if to_rgb(sa["color"]) != to_rgb(sb["color"]):
            continue
        assert frozenset((a, b)) not in shared_figure, f"{a} and {b} share a figure"
        assert sa["linestyle"] != sb["linestyle"], f"{a} and {b} look the same"
        assert sa["marker"] != sb["marker"], f"{a} and {b} look the same"
    assert plots.METHOD_COLORS == {m: s["color"] for m, s in plots.METHOD_STYLES.items()}


def test_figure_methods_are_the_labels_the_experiments_draw():
    from vslbook.experiments import diskill_runs as DR
    from vslbook.experiments import svsl_context, svsl_planar, svsl_reacher
    from vslbook.experiments.dime_runs import ABLATIONS

    groups = plots.FIGURE_METHODS
    assert groups["fig-3-1-scores"] == svsl_planar.VARIANTS
    assert groups["fig-3-2-beer-pong"] == groups["fig-3-2-table-tennis"] == svsl_context.METHODS
    assert groups["fig-3-5-reacher"] == svsl_reacher.METHODS
    for figure, group in (("4.3b", "fig-4-3b-ablation"), ("4.4a", "fig-b-3-hopper")):
        assert groups[group] == tuple(DR.LABELS[m] for m in DR.FIGURES[figure][1])
    for figure in ("4.3c", "4.4a", "4.4b", "4.4c", "4.4d"):  # PPO where the thesis runs it
        drawn = {DR.LABELS[m] for m in DR.FIGURES[figure][1]} | {"PPO"}
        assert drawn <= set(groups["fig-4-3c-4-4-curves"]) == set(groups["fig-4-4-returns"])
    assert set(DR.LABELS.values()) <= set(plots.METHOD_STYLES)
    assert groups["ch5-ablations-pendulum"] == tuple(ABLATIONS)


def test_method_style_is_case_insensitive_follows_aliases_and_rejects_unknown_names():
    assert plots.method_style("di-skill") == plots.METHOD_STYLES["Di-SkilL"]
    assert plots.method_color("dime-gb") == plots.method_color("GB")
    assert plots.is_method("HiREPS") and not plots.is_method("some new method")
    with pytest.raises(KeyError, match="no style for method 'some new method'.*METHOD_STYLES"):
        plots.method_color("some new method")
    style = plots.method_style("SVSL")
    style["color"] = "red"  # a copy: the book's table stays as it is
    assert plots.METHOD_STYLES["SVSL"]["color"] != "red"


def test_learning_curve_takes_the_method_style():
    fig, ax = plt.subplots()
    a = plots.learning_curve(ax, _curve(), label="Di-SkilL")
    b = plots.learning_curve(ax, _curve(), label="BBRL (3 seeds)", method="BBRL")
    for line, name in ((a, "Di-SkilL"), (b, "BBRL")):
        style = plots.METHOD_STYLES[name]
        assert to_rgb(line.get_color()) == to_rgb(style["color"])
        assert line.get_linestyle() == style["linestyle"] and line.get_marker() == style["marker"]
        assert line.get_markerfacecolor() == "none"  # hollow: coinciding markers stay visible
    assert b.get_label() == "BBRL (3 seeds)"
    # two methods with the same numbers: their markers sit at different points
    assert a.get_markevery() != b.get_markevery()
    # colour and keywords given by the caller win
    c = plots.learning_curve(ax, _curve(), label="DIME", color="#123456", ls=":")
    assert c.get_color() == "#123456" and c.get_linestyle() == ":"
    # a single evaluation keeps the method's marker
    d = plots.learning_curve(ax, _curve(n=1), label="PPO")
    assert d.get_marker() == plots.METHOD_STYLES["PPO"]["marker"]
    with pytest.raises(KeyError, match="no style for method"):
        plots.learning_curve(ax, _curve(), label="x", method="unknown method")


def test_single_points_with_equal_numbers_stay_apart():
    fig, ax = plt.subplots()
    lines = [plots.learning_curve(ax, _curve(n=1), label=m) for m in ("DIME", "GB", "CrossQ")]
    fig.canvas.draw()
    shown = [ln.get_transform().transform((0.0, 0.0))[0] for ln in lines]
    assert len(set(np.round(shown, 3))) == 3  # a few points apart on the screen
    assert ax.get_xlim()[0] < 0.0 < ax.get_xlim()[1]  # and the axes still hold their x value
    lo, hi = ax.get_ylim()
    assert lo <= -0.1 and hi >= 0.1  # the error bars too


def test_labels_that_are_no_method_take_the_axes_colours():
    fig, ax = plt.subplots()
    first = plots.learning_curve(ax, _curve(), label="published data")
    second = plots.learning_curve(ax, _curve(), label="another curve")
    assert first.get_color() != second.get_color()
    assert first.get_marker() in ("None", None, "")
    fig, (left, right) = plt.subplots(1, 2)
    point = {"a": np.array([0.5]), "b": np.array([0.6]), "SVSL": np.array([0.7])}
    ci = {k: np.array([[v[0] - 0.1], [v[0] + 0.1]]) for k, v in point.items()}
    plots.interval_plot(left, point, ci)
    bars = [to_rgb(p.get_facecolor()) for p in left.patches]
    assert bars[0] != bars[1]  # names that are no method: the palette by row
    assert bars[2] == to_rgb(plots.method_color("SVSL"))
    lo, hi = left.get_xlim()  # a margin around the intervals: no dot cut in half
    assert lo < 0.4 and hi > 0.8


# ------------------------------------------------------------------------- experts


def test_experts_get_distinct_qualitative_colours_without_red():
    colors = [plots.expert_color(i) for i in range(len(plots.EXPERT_COLORS))]
    assert len(set(colors)) == len(colors) == 18
    assert plots.expert_color(0) != plots.expert_color(1)  # no two shades of one hue first
    assert plots.expert_color(18) == plots.expert_color(0)  # cycling beyond 18
    tab_red = matplotlib.colormaps["tab20"].colors[6:8]
    assert not {to_rgb(c) for c in colors} & {tuple(c) for c in tab_red}


def test_public_names():
    for name in ("METHOD_STYLES", "METHOD_ALIASES", "FIGURE_METHODS", "EXPERT_COLORS",
                 "PANELS_PER_ROW", "method_style", "is_method", "expert_color",
                 "count_phrase", "panel_grid"):  # fmt: skip
        assert name in plots.__all__ and hasattr(plots, name)


def test_count_phrase():
    assert plots.count_phrase(1, "seed") == "1 seed"
    assert plots.count_phrase(3, "seed") == "3 seeds"
    assert plots.count_phrase(2, "reply", "replies") == "2 replies"


# ------------------------------------------------------------------------- layout


def test_panel_grid_puts_at_most_two_panels_per_row():
    fig, axes = plots.panel_grid(5, panel=(5.0, 3.0), sharey=True)
    assert axes.shape == (5,) and len(fig.axes) == 5  # the sixth cell is removed
    assert _panels_per_row(fig) == 2
    assert tuple(fig.get_size_inches()) == (10.0, 9.0)
    fig, axes = plots.panel_grid(1)
    assert len(axes) == 1 and _panels_per_row(fig) == 1
    with pytest.raises(ValueError, match="cols must be between 1 and 2"):
        plots.panel_grid(3, cols=3)
    with pytest.raises(ValueError, match="at least 1 panel"):
        plots.panel_grid(0)


def test_package_figures_have_at_most_two_panels_per_row():
    from vslbook import figures

    smoke = BUDGETS["smoke"]
    for fig in (figures.draw_movement_primitives(),
                figures.draw_fig_5_2_published(budget=smoke),
                figures.draw_fig_5_3_published(budget=smoke)):  # fmt: skip
        assert _panels_per_row(fig) <= plots.PANELS_PER_ROW
        # wide enough for two panels of at least 400 px on the site (inline: figure.dpi)
        width_px = fig.get_size_inches()[0] * fig.dpi
        assert width_px / _panels_per_row(fig) >= 400

"""The book's look: one palette, one style per method, the rcParams every figure uses.

A method looks the same in every figure: :data:`METHOD_STYLES` fixes its colour, line style
and marker (:func:`method_style`, :func:`method_color`; a curve whose label names a method
takes its style), :data:`FIGURE_METHODS` lists the methods each comparison figure draws
together, and a mixture's experts take :func:`expert_color`. :func:`use_style` applies
:data:`STYLE`. :mod:`vslbook.plots` re-exports all of these beside the curves it draws.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import TracebackType
from typing import Any

import matplotlib as mpl
from cycler import cycler
from matplotlib.colors import to_hex

__all__ = [
    "EXPERT_COLORS",
    "FIGURE_METHODS",
    "METHOD_ALIASES",
    "METHOD_COLORS",
    "METHOD_STYLES",
    "PALETTE",
    "STYLE",
    "StyleContext",
    "expert_color",
    "is_method",
    "method_color",
    "method_key",
    "method_style",
    "use_style",
]

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


def method_key(name: str) -> str | None:
    """The key of ``name`` in :data:`METHOD_STYLES` (case-insensitive, aliases followed), or
    None for a name that is not a method."""
    wanted = str(name).lower()
    for alias, target in METHOD_ALIASES.items():
        if alias.lower() == wanted:
            wanted = target.lower()
    return next((key for key in METHOD_STYLES if key.lower() == wanted), None)


def is_method(name: str) -> bool:
    """Whether ``name`` (case-insensitive) has a style in :data:`METHOD_STYLES`."""
    return method_key(name) is not None


def method_style(name: str) -> dict[str, Any]:
    """Line keywords of a method (case-insensitive): ``color``, ``linestyle``, ``marker``.

    Raises ``KeyError`` for a name without an entry in :data:`METHOD_STYLES`: a method new to
    the book gets its style there, so that it looks the same in every figure.
    """
    key = method_key(name)
    if key is None:
        raise KeyError(
            f"no style for method {name!r}; add it to vslbook.plot_style.METHOD_STYLES (known: "
            f"{list(METHOD_STYLES)})"
        )
    return dict(METHOD_STYLES[key])


def method_color(name: str) -> str:
    """The fixed colour of a method (case-insensitive); ``KeyError`` as :func:`method_style`."""
    return method_style(name)["color"]


def expert_color(index: int) -> str:
    """The colour of a mixture's expert ``index`` (:data:`EXPERT_COLORS`, cycling)."""
    return EXPERT_COLORS[int(index) % len(EXPERT_COLORS)]

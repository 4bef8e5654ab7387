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
"""

from __future__ import annotations

import os
import re
import zlib
from collections.abc import Mapping, Sequence
from pathlib import Path
from types import TracebackType
from typing import Any

import matplotlib as mpl
import numpy as np
import pandas as pd
from cycler import cycler
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from vslbook.budget import get_budget

__all__ = [
    "METHOD_COLORS",
    "PALETTE",
    "STYLE",
    "StyleContext",
    "figures_dir",
    "interval_plot",
    "learning_curve",
    "method_color",
    "profile_plot",
    "save_figure",
    "thesis_vs_ours",
    "use_style",
]

FIGURES_ENV_VAR = "VSLBOOK_FIGURES"
_REPO_ROOT = Path(__file__).resolve().parents[1]
_FIGURE_ID = re.compile(r"[A-Za-z0-9_-][A-Za-z0-9._-]*")

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

#: fixed colours so a method looks the same in every figure of the book
METHOD_COLORS: dict[str, str] = {
    "thesis": "#555555",
    "ours": "#0072B2",
    "DIME": "#D55E00",
    "DIME-GB": "#E69F00",
    "Gaussian": "#56B4E9",
    "CrossQ": "#009E73",
    "SAC": "#CC79A7",
    "BRO": "#8C564B",
    "PPO": "#7F7F7F",
    "Di-SkilL": "#D55E00",
    "LinDi-SkilL": "#E69F00",
    "BBRL": "#009E73",
    "SVSL": "#D55E00",
    "HiREPS": "#009E73",
    "LaDiPS": "#CC79A7",
    "MORE": "#56B4E9",
    "REPS": "#009E73",
    "TRPL": "#CC79A7",
}

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


def method_color(name: str) -> str:
    """The fixed colour of a method (case-insensitive), else a stable palette colour."""
    for key, color in METHOD_COLORS.items():
        if key.lower() == str(name).lower():
            return color
    return PALETTE[zlib.crc32(str(name).encode("utf-8")) % len(PALETTE)]


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


def learning_curve(
    ax: Axes,
    curve_df: pd.DataFrame,
    x: str = "env_steps",
    label: str | None = None,
    color: str | None = None,
    *,
    band_alpha: float = 0.2,
    **kw: Any,
) -> Line2D:
    """Plot the IQM line of ``curve_df`` with a shaded ``lo``–``hi`` band; return the line.

    Extra keyword arguments go to ``ax.plot`` (e.g. ``linestyle``). A curve of a single
    point (a short run evaluated once) is drawn as a marker with its interval as an error
    bar, so it stays visible.
    """
    curve = _check_curve(curve_df, x, "learning_curve")
    if color is None and label is not None and label in METHOD_COLORS:
        color = METHOD_COLORS[label]
    if len(curve) == 1:
        kw.setdefault("marker", "o")
        (line,) = ax.plot(curve[x], curve["iqm"], label=label, color=color, **kw)
        iqm, lo, hi = (curve[k].to_numpy(float) for k in ("iqm", "lo", "hi"))
        ax.errorbar(curve[x].to_numpy(float), iqm, yerr=[iqm - lo, hi - iqm],
                    color=line.get_color(), capsize=3, linestyle="none")  # fmt: skip
        if not ax.get_xlabel():
            ax.set_xlabel(x.replace("_", " "))
        if not ax.get_ylabel():
            ax.set_ylabel("IQM return")
        return line
    (line,) = ax.plot(curve[x], curve["iqm"], label=label, color=color, **kw)
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
    learning_curve(
        ax, thesis_curve, x=x, label="thesis (published data)",
        color=METHOD_COLORS["thesis"], linestyle="--",
    )
    if ours_curve is not None:
        name = get_budget(budget).name
        learning_curve(
            ax, ours_curve, x=x, label=f"ours ({name} budget)", color=METHOD_COLORS["ours"],
            linestyle="-",
        )
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


def interval_plot(
    ax: Axes,
    point: Mapping[str, Any],
    ci: Mapping[str, Any],
    *,
    index: int = 0,
    colors: Mapping[str, str] | None = None,
    xlabel: str = "IQM",
) -> Axes:
    """Horizontal CI bars (one row per method) with a tick at the point estimate.

    ``point`` and ``ci`` are the dicts :func:`vslbook.stats.interval_estimates` returns;
    ``index`` picks the aggregate when ``func`` returned several.
    """
    missing = [name for name in point if name not in ci]
    if missing:
        raise ValueError(f"interval_plot: no CI for {missing}; CIs given for {list(ci)}")
    names = list(point)
    for row, name in enumerate(names):
        value = float(np.atleast_1d(point[name])[index])
        bounds = np.asarray(ci[name], dtype=float).reshape(2, -1)[:, index]
        color = (colors or {}).get(name) or method_color(name)
        ax.barh(row, bounds[1] - bounds[0], left=bounds[0], height=0.6, color=color, alpha=0.75)
        ax.vlines(value, row - 0.3, row + 0.3, color="black", linewidth=1.5)
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
    """Performance profiles with their CI bands (from :func:`stats.performance_profile`)."""
    tau_arr = np.asarray(taus, dtype=float)
    for name, profile in profiles.items():
        profile = np.asarray(profile, dtype=float)
        if profile.shape != tau_arr.shape:
            raise ValueError(
                f"profile_plot: profile {name!r} has shape {profile.shape}, "
                f"expected {tau_arr.shape} (one value per tau)"
            )
        color = (colors or {}).get(name) or method_color(name)
        ax.plot(tau_arr, profile, color=color, label=name)
        if name in cis:
            band = np.asarray(cis[name], dtype=float)
            ax.fill_between(tau_arr, band[0], band[1], color=color, alpha=0.2, linewidth=0)
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.legend()
    return ax


# --------------------------------------------------------------------------- saving


def figures_dir() -> Path:
    """Where figures are saved: ``$VSLBOOK_FIGURES`` if set, else ``build/figures``."""
    env = os.environ.get(FIGURES_ENV_VAR)
    if env:
        return Path(env).expanduser()
    return _REPO_ROOT / "build" / "figures"


def save_figure(
    fig: Figure,
    figure_id: str,
    formats: Sequence[str] = ("png", "pdf"),
    out_dir: str | Path | None = None,
) -> list[Path]:
    """Save ``fig`` as ``<out_dir or figures_dir()>/<figure_id>.<fmt>``; return the paths.

    ``figure_id`` may contain letters, digits, ``-``, ``_`` and ``.`` (not leading).
    File metadata carries no creation date, so the same figure gives the same file.
    """
    if not isinstance(figure_id, str) or not _FIGURE_ID.fullmatch(figure_id):
        raise ValueError(
            f"figure_id {figure_id!r} is not valid; expected letters, digits, '-', '_' "
            "or '.' (not leading), e.g. 'fig5-3_dog_run'"
        )
    allowed = {"png", "pdf", "svg"}
    bad = [f for f in formats if f not in allowed]
    if bad or not formats:
        raise ValueError(f"formats {list(formats)}: expected some of {sorted(allowed)}")
    out = Path(out_dir) if out_dir is not None else figures_dir()
    out.mkdir(parents=True, exist_ok=True)
    metadata = {"png": {"Software": None}, "pdf": {"CreationDate": None}, "svg": {"Date": None}}
    paths = []
    for fmt in formats:
        path = out / f"{figure_id}.{fmt}"
        fig.savefig(path, format=fmt, metadata=metadata[fmt])
        paths.append(path)
    return paths

"""The plotting style, curves, overlays and figure saving (headless, Agg backend)."""

from __future__ import annotations

import json
import struct

import matplotlib

matplotlib.use("Agg")

import matplotlib as mpl  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
import pytest  # noqa: E402

from vslbook import plots  # noqa: E402


def _curve(scale=1.0):
    x = np.arange(0, 100_000, 24_000)
    iqm = scale * np.sqrt(x / x[-1])
    return pd.DataFrame({"env_steps": x, "iqm": iqm, "lo": iqm - 0.1, "hi": iqm + 0.1})


@pytest.fixture(autouse=True)
def figures(tmp_path, monkeypatch):
    monkeypatch.setenv("VSLBOOK_FIGURES", str(tmp_path / "figs"))
    yield tmp_path / "figs"
    plt.close("all")


def test_use_style_as_context_restores_settings():
    before = mpl.rcParams["axes.spines.top"]
    with plots.use_style():
        assert mpl.rcParams["axes.spines.top"] is False
        assert mpl.rcParams["axes.grid"] is True
    assert mpl.rcParams["axes.spines.top"] == before
    context = plots.use_style({"font.size": 13})
    assert mpl.rcParams["font.size"] == 13
    context.restore()
    assert mpl.rcParams["axes.spines.top"] == before


def test_method_colors_are_fixed_and_unknown_methods_rejected():
    assert plots.method_color("dime") == plots.METHOD_COLORS["DIME"]
    with pytest.raises(KeyError, match="METHOD_STYLES"):  # tests/test_plots_palette.py
        plots.method_color("some new method")


def test_learning_curve_draws_line_and_band(figures):
    fig, ax = plt.subplots()
    line = plots.learning_curve(ax, _curve(), label="DIME")
    assert line.get_label() == "DIME"
    assert len(ax.collections) == 1
    assert ax.get_xlabel() == "env steps"
    with pytest.raises(ValueError, match=r"\['lo', 'hi'\] missing"):
        plots.learning_curve(ax, _curve()[["env_steps", "iqm"]])


def test_thesis_vs_ours_and_save_figure(figures):
    with plots.use_style():
        fig, (left, right) = plt.subplots(1, 2)
        plots.thesis_vs_ours(left, _curve(), _curve(0.8), budget="smoke", title="cheetah")
        plots.thesis_vs_ours(right, _curve())
    labels = [t.get_text() for t in left.get_legend().get_texts()]
    assert labels == ["thesis (published data)", "ours (smoke budget)"]
    assert left.lines[0].get_linestyle() == "--" and left.lines[1].get_linestyle() == "-"
    assert len(right.lines) == 1 and "published data only" in right.texts[0].get_text()
    paths = plots.save_figure(fig, "fig5-3_cheetah.v1")
    assert [p.name for p in paths] == ["fig5-3_cheetah.v1.png", "fig5-3_cheetah.v1.pdf"]
    assert all(p.parent == figures and p.stat().st_size > 0 for p in paths)
    assert plots.figures_dir() == figures


def test_save_figure_rejects_bad_ids(figures):
    fig, _ = plt.subplots()
    for bad in ("../escape", "a b", "", ".hidden"):
        with pytest.raises(ValueError, match="figure_id"):
            plots.save_figure(fig, bad)


def test_interval_and_profile_plots(figures):
    fig, (left, right) = plt.subplots(1, 2)
    point = {"DIME": np.array([0.8]), "ours": np.array([0.7])}
    ci = {"DIME": np.array([[0.75], [0.85]]), "ours": np.array([[0.6], [0.8]])}
    plots.interval_plot(left, point, ci)
    assert [t.get_text() for t in left.get_yticklabels()] == ["DIME", "ours"]
    taus = np.linspace(0, 1, 5)
    profiles = {"DIME": np.linspace(1, 0, 5)}
    plots.profile_plot(right, taus, profiles, {"DIME": np.stack([profiles["DIME"]] * 2)})
    assert len(right.lines) == 1
    (path,) = plots.save_figure(fig, "aggregates", formats=("png",))
    assert path.exists()


def test_save_figure_writes_the_layout_a_notebook_shows(figures, monkeypatch):
    monkeypatch.setenv("VSLBOOK_BUDGET", "smoke")
    fig, axes = plt.subplots(2, 3, figsize=(9, 5))
    image = axes[0, 0].imshow(np.eye(3))
    fig.colorbar(image, ax=axes[0, 0])          # colorbars, twins and insets are no panels
    axes[0, 1].twinx()
    axes[0, 2].inset_axes([0.5, 0.5, 0.4, 0.4])
    axes[1, 2].set_visible(False)
    plots.save_figure(fig, "grid", formats=("png",))
    layout = json.loads((figures / "grid.layout.json").read_text())
    assert layout["id"] == "grid" and layout["budget"] == "smoke"
    assert layout["panels_per_row"] == 3 and layout["dpi"] == fig.dpi
    # the picture Jupyter's inline backend shows: the tight box at the figure's dpi
    from IPython.core.pylabtools import print_figure

    png = print_figure(fig, "png")
    assert (layout["width_px"], layout["height_px"]) == struct.unpack(">II", png[16:24])
    assert layout["width_in"] == pytest.approx(layout["width_px"] / fig.dpi, abs=1e-3)
    assert not list(figures.glob("*.tmp"))

"""Figs. 5.2 and 5.3 drawn from the published DIME curves (headless, Agg backend)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from vslbook.budget import BUDGETS  # noqa: E402
from vslbook.cli import main  # noqa: E402
from vslbook.data import paper_curves  # noqa: E402
from vslbook.figures import (  # noqa: E402
    draw_fig_5_2_published,
    draw_fig_5_3_published,
)
from vslbook.registry import FIGURES, load_plugins  # noqa: E402
from vslbook.stats import iqm_curve  # noqa: E402

SMOKE = BUDGETS["smoke"]  # 200 bootstrap resamples: fast


@pytest.fixture(scope="module")
def fig52():
    fig = draw_fig_5_2_published(budget=SMOKE)
    yield fig
    plt.close(fig)


@pytest.fixture(scope="module")
def fig53():
    fig = draw_fig_5_3_published(budget=SMOKE)
    yield fig
    plt.close(fig)


def _visible(fig):
    return [ax for ax in fig.axes if ax.get_visible()]


def _footnote(fig):
    return " ".join(t.get_text() for t in fig.texts).replace("\n", " ")


def test_fig_5_2_has_the_two_gym_panels(fig52):
    axes = _visible(fig52)
    assert [ax.get_title() for ax in axes] == ["(a) Ant-v3", "(b) Humanoid-v3"]
    assert {ax.get_ylabel() for ax in axes} == {"return"}
    assert {ax.get_xlabel() for ax in axes} == {"env steps"}
    note = _footnote(fig52)
    assert "10 seeds, thesis data" in note
    assert "(c)-(d)" in note and "ablation" in note
    for name in ("CrossQ", "QSM", "Diffusion-QL", "Consistency-AC", "DIPO", "QVPO", "DACER"):
        assert name in note
    assert "BRO" not in note  # BRO is a baseline of Fig. 5.3 only


def test_fig_5_3_rows_dog_humanoid_myo(fig53):
    axes = _visible(fig53)
    assert len(axes) == 11
    titles = [ax.get_title() for ax in axes]
    assert titles[:4] == ["dog-run", "dog-trot", "dog-walk", "dog-stand"]
    assert titles[4:7] == ["humanoid-run", "humanoid-walk", "humanoid-stand"]
    assert titles[7:] == [
        "object-hold (random)",
        "reach (random)",
        "key-turn (random)",
        "pen-twirl (random)",
    ]
    assert [ax.get_ylabel() for ax in axes] == ["return"] * 7 + ["success rate"] * 4
    # the families one below the other (dog, humanoid, MyoSuite), two panels per row
    tops = [round(ax.get_position().y1, 3) for ax in axes]
    assert min(tops[:4]) > max(tops[4:7]) and min(tops[4:7]) > max(tops[7:])
    assert max(tops.count(top) for top in tops) == 2
    note = _footnote(fig53)
    for name in ("BRO, BRO (Fast)", "CrossQ", "QSM", "DIPO", "QVPO", "DACER", "3M"):
        assert name in note


def _xticks(ax):
    lo, hi = ax.get_xlim()
    ticks = [t for t in ax.get_xticks() if lo <= t <= hi]
    return [ax.xaxis.get_major_formatter()(t) for t in ticks]


def test_axes_without_scientific_notation(fig52, fig53):
    dog_run, dog_trot = _visible(fig53)[:2]
    assert _xticks(dog_run) == ["0", "1M", "2M", "3M"]  # published to 3M steps
    assert _xticks(dog_trot) == ["0", "0.5M", "1M"]
    fig52.canvas.draw()  # Humanoid-v3 returns reach 14k: no "1e4" offset on either axis
    for ax in _visible(fig52):
        assert _xticks(ax) == ["0", "0.5M", "1M"]
        assert ax.xaxis.get_offset_text().get_text() == ""
        assert ax.yaxis.get_offset_text().get_text() == ""
        labels = "".join(t.get_text() for t in ax.get_yticklabels())
        assert "times" not in labels and "^" not in labels and "e+" not in labels


@pytest.mark.parametrize(
    ("which", "index", "task"),
    [
        ("5.2", 1, "gym_humanoid_v3"),
        ("5.3", 0, "dmc_dog_run"),
        ("5.3", 10, "myo_hand_pen_twirl_rndm"),
    ],
)
def test_panel_line_is_the_iqm_of_the_published_seeds(fig52, fig53, which, index, task):
    ax = _visible(fig52 if which == "5.2" else fig53)[index]
    (line,) = [ln for ln in ax.get_lines() if ln.get_gid() == task]
    expected = iqm_curve(paper_curves(task), reps=SMOKE.bootstrap_reps)
    assert expected["n_runs"].max() == 10
    np.testing.assert_allclose(line.get_xdata(), expected["env_steps"])
    np.testing.assert_allclose(line.get_ydata(), expected["iqm"])
    # the band is the CI at the same resample count (the bootstrap is seeded)
    band = ax.collections[0].get_paths()[0].vertices[:, 1]
    np.testing.assert_allclose(
        [band.min(), band.max()], [expected["lo"].min(), expected["hi"].max()]
    )


def test_registered_and_cli_writes_files(tmp_path, capsys):
    load_plugins()
    assert {"fig5-2-published", "fig5-3-published", "dime-published"} <= set(FIGURES)
    assert main(["figure", "fig5-3-published", "--budget", "smoke", "--out", str(tmp_path)]) == 0
    written = sorted(p.name for p in tmp_path.iterdir())
    assert written == ["fig5-3-published.layout.json", "fig5-3-published.pdf",
                       "fig5-3-published.png"]
    assert all((tmp_path / name).stat().st_size > 0 for name in written)
    assert "fig5-3-published.png" in capsys.readouterr().out

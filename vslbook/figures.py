"""Registered figures: ``vslbook figure ID`` and the notebooks draw them with these.

Each ``draw_*`` function returns a matplotlib figure (a notebook shows it inline); the
registered ``make`` wrapper saves it under ``build/figures`` (or ``--out``).
"""

from __future__ import annotations

import math
import textwrap
from pathlib import Path

import matplotlib.pyplot as plt
import torch
from matplotlib.lines import Line2D
from matplotlib.ticker import FuncFormatter, MaxNLocator, MultipleLocator

from vslbook.budget import Budget, get_budget
from vslbook.data import paper_curves, paper_tasks
from vslbook.experiments import figure_draws
from vslbook.movement import DMP, ProDMP, ProMP
from vslbook.plots import (
    PALETTE,
    PANELS_PER_ROW,
    learning_curve,
    method_color,
    panel_grid,
    save_figure,
    use_style,
)
from vslbook.registry import register_figure
from vslbook.stats import iqm_curve


def draw_movement_primitives(seed: int = 0, n_samples: int = 20) -> plt.Figure:
    """ProMP trajectory distribution before/after a via-point, DMP rollouts to a goal,
    ProDMP trajectories from different initial conditions (Section 2.6.1)."""
    use_style()
    gen = torch.Generator().manual_seed(seed)
    fig, axes = panel_grid(3, panel=(5.2, 3.6))

    promp = ProMP(n_basis=8, n_dof=1, duration=1.0, dt=0.01)
    t = promp.times.numpy()
    mean_w, cov_w = torch.zeros(8, dtype=torch.float64), torch.eye(8, dtype=torch.float64)
    via_t, via_y = 0.6, 1.0
    cond_mean, cond_cov = promp.condition(mean_w, cov_w, via_t, torch.tensor([via_y]), 0.02)
    for (m, c), color, label in (
        ((mean_w, cov_w), "#999999", "prior"),
        ((cond_mean, cond_cov), method_color("ours"), "via-point"),
    ):
        mean, _ = promp.distribution(m, c)
        std = promp.marginal_std(c)
        ax = axes[0]
        ax.fill_between(t, (mean - 2 * std)[:, 0], (mean + 2 * std)[:, 0], color=color, alpha=0.2)
        ax.plot(t, mean[:, 0], color=color, label=f"{label} mean ± 2σ")
        chol = torch.linalg.cholesky(c + 1e-10 * torch.eye(8, dtype=torch.float64))
        w = m + torch.randn(n_samples // 4, 8, generator=gen, dtype=torch.float64) @ chol.T
        ax.plot(t, promp.trajectory(w)[..., 0].T.numpy(), color=color, lw=0.6, alpha=0.6)
    axes[0].plot([via_t], [via_y], "k*", ms=10)
    axes[0].set(title="ProMP: τ = Φᵀθ (Eq. 2.46)", xlabel="time [s]", ylabel="position")
    axes[0].legend(loc="lower left", fontsize=8)

    dmp = DMP(n_basis=8, n_dof=1, duration=1.5, dt=0.01)
    w = 150 * torch.randn(n_samples // 2, 8, generator=gen, dtype=torch.float64)
    pos, _ = dmp.rollout(w, torch.zeros(1), torch.zeros(1), torch.ones(1))
    axes[1].plot(dmp.times.numpy(), pos[..., 0].T.numpy(), lw=0.8, color=PALETTE[1])
    axes[1].axhline(1.0, color="k", ls="--", lw=1, label="goal g")
    axes[1].set(title="DMP rollouts (Eq. 2.45)", xlabel="time [s]")
    axes[1].legend(loc="lower right", fontsize=8)

    prodmp = ProDMP(n_basis=8, n_dof=1, duration=1.0, dt=0.01)
    params = torch.cat(
        [
            100 * torch.randn(8, generator=gen, dtype=torch.float64),
            torch.tensor([0.5], dtype=torch.float64),
        ]
    )
    for y0, dy0 in ((-1.0, 0.0), (0.0, 3.0), (1.0, -3.0), (0.5, 0.0)):
        pos, _ = prodmp.trajectory(params, torch.tensor([y0]), torch.tensor([dy0]))
        (line,) = axes[2].plot(prodmp.times.numpy(), pos[:, 0].numpy(), lw=1.2)
        axes[2].plot([0], [y0], "o", color=line.get_color())
    axes[2].set(title="ProDMP: same θ, different (y₀, ẏ₀)", xlabel="time [s]")
    fig.tight_layout()
    return fig


def draw_dime_published(tasks: list[str] | None = None, budget: Budget | None = None) -> plt.Figure:
    """IQM and 95 % stratified-bootstrap CI of the published 10-seed DIME curves."""
    use_style()
    bud = get_budget(budget)
    tasks = tasks or paper_tasks()
    fig, axes = panel_grid(len(tasks), panel=(5.2, 3.0))
    for ax, task in zip(axes, tasks, strict=True):
        curve = iqm_curve(paper_curves(task), reps=bud.bootstrap_reps)
        learning_curve(ax, curve, color=method_color("thesis"))
        ax.set(
            title=task, xlabel="env steps", ylabel="success" if task.startswith("myo") else "return"
        )
    fig.suptitle("DIME, published learning curves (thesis data, 10 seeds): IQM ± 95 % CI")
    fig.tight_layout()
    return fig


# Figs. 5.2 and 5.3 in the thesis's layout, from the published data only. Panel titles
# name the tasks as the thesis does (Section 5.5, Appendix C.3, Table C.1).
#: Fig. 5.2 (a)-(b): (task id in the published data, panel title)
FIG_5_2_PANELS: tuple[tuple[str, str], ...] = (
    ("gym_ant_v3", "(a) Ant-v3"),
    ("gym_humanoid_v3", "(b) Humanoid-v3"),
)
#: Fig. 5.3, one row per task family: (row header, ((task id, panel title), ...)).
#: The text places dog in 5.3a-d, humanoid in e-g, object hold in h and pen twirl in k;
#: the MyoSuite row follows Appendix C's order (object hold, reach, key turn, pen twirl),
#: which agrees with h and k. The order inside the dog and humanoid rows is not stated.
FIG_5_3_ROWS: tuple[tuple[str, tuple[tuple[str, str], ...]], ...] = (
    (
        "DMC dog (Fig. 5.3a-d)",
        (
            ("dmc_dog_run", "dog-run"),
            ("dmc_dog_trot", "dog-trot"),
            ("dmc_dog_walk", "dog-walk"),
            ("dmc_dog_stand", "dog-stand"),
        ),
    ),
    (
        "DMC humanoid (Fig. 5.3e-g)",
        (
            ("dmc_humanoid_run", "humanoid-run"),
            ("dmc_humanoid_walk", "humanoid-walk"),
            ("dmc_humanoid_stand", "humanoid-stand"),
        ),
    ),
    (
        "MyoSuite hand, random targets, the thesis's 'hard' tasks (Fig. 5.3h-k)",
        (
            ("myo_hand_obj_hold_rndm", "object-hold (random)"),
            ("myo_hand_reach_rndm", "reach (random)"),
            ("myo_hand_key_turn_rndm", "key-turn (random)"),
            ("myo_hand_pen_twirl_rndm", "pen-twirl (random)"),
        ),
    ),
)
_DIFFUSION_BASELINES = "QSM, Diffusion-QL, Consistency-AC, DIPO, QVPO, DACER"
_PUBLISHED_LABEL = "DIME (published curves, 10 seeds, thesis data)"


def _steps_label(value: float, _pos: object = None) -> str:
    """Env steps as "0", "0.5M", "1M", "3M" (no scientific notation)."""
    return "0" if value == 0 else f"{value / 1e6:g}M"


def _published_panel(ax: plt.Axes, task: str, title: str, reps: int) -> None:
    """One panel: IQM ± 95 % stratified-bootstrap CI of the 10 published seeds of ``task``."""
    curve = iqm_curve(paper_curves(task), reps=reps)
    line = learning_curve(ax, curve, color=method_color("thesis"), label=_PUBLISHED_LABEL)
    line.set_gid(task)  # tests and readers find the IQM line of a panel by its task id
    last = float(curve["env_steps"].max())
    step = 0.5e6 if last <= 1.5e6 else 1e6
    ax.set_xlim(0, math.ceil(last / step) * step)
    ax.xaxis.set_major_locator(MultipleLocator(step))
    ax.xaxis.set_major_formatter(FuncFormatter(_steps_label))
    if last > 1.5e6:  # published to 3M steps: mark where the 1M panels end
        ax.axvline(1e6, color="0.4", ls=":", lw=1)
    if task.startswith("myo"):
        ax.set_ylim(-0.03, 1.03)
        ax.yaxis.set_major_locator(MultipleLocator(0.5))
        ax.set_ylabel("success rate")
    else:
        ax.yaxis.set_major_locator(MaxNLocator(nbins=4))
        ax.ticklabel_format(axis="y", style="plain", useOffset=False)
        ax.set_ylabel("return")
    ax.set(title=title, xlabel="env steps")


def _footnote(fig: plt.Figure, text: str, width: int) -> None:
    fig.text(0.01, 0.005, textwrap.fill(text, width), ha="left", va="bottom", fontsize=8,
             color="0.25")


def draw_fig_5_2_published(budget: Budget | str | None = None) -> plt.Figure:
    """Fig. 5.2 (a) Ant-v3 and (b) Humanoid-v3 from the published DIME data.

    Each panel is the IQM over the 10 published seeds with its 95 % stratified-bootstrap
    CI (``budget.bootstrap_reps`` resamples), 1M env steps. Not drawn: CrossQ and the
    diffusion baselines of the thesis's figure, whose curves are not in the published
    data, and panels (c)-(d), the diffusion-steps ablation on humanoid-run (runtime and
    learning curves), which is not published data; notebook ``05_dime`` (section 5)
    runs that ablation at the active budget.
    """
    use_style()
    bud = get_budget(budget)
    fig, axes = plt.subplots(1, 2, figsize=(8.6, 3.5))
    for ax, (task, title) in zip(axes, FIG_5_2_PANELS, strict=True):
        _published_panel(ax, task, title, bud.bootstrap_reps)
    axes[0].legend(loc="lower right", fontsize=8)
    fig.suptitle("Fig. 5.2 (a)-(b): DIME on Gym, IQM ± 95 % stratified-bootstrap CI")
    _footnote(
        fig,
        f"Published DIME curves only (10 seeds, thesis data). Not drawn: CrossQ and the "
        f"diffusion baselines ({_DIFFUSION_BASELINES}) of the thesis's figure; their curves "
        f"are not in the published data. Panels (c)-(d), the diffusion-steps ablation on "
        f"humanoid-run, are not published data and are shown elsewhere (notebook 05_dime, "
        f"ablations at the active budget).",
        width=120,
    )
    fig.tight_layout(rect=(0, 0.13, 1, 1))
    return fig


def draw_fig_5_3_published(budget: Budget | str | None = None) -> plt.Figure:
    """Fig. 5.3: DMC dog and humanoid, MyoSuite hand tasks, from the published DIME data.

    The thesis's three task families one below the other (dog: 5.3a-d, humanoid: e-g,
    MyoSuite: h-k; see :data:`FIG_5_3_ROWS`), each in rows of two panels (the legend takes
    humanoid's free place); each panel is the IQM over the 10 published seeds with its
    95 % stratified-bootstrap CI (``budget.bootstrap_reps`` resamples). dog-run and
    humanoid-run are published to 3M env steps and drawn in full (a dotted line marks
    1M, the other panels' horizon; the thesis's 3M humanoid-run comparison is Fig. 5.8c).
    Not drawn: BRO, BRO (Fast), CrossQ and the diffusion baselines of the thesis's
    figure, whose curves are not in the published data.
    """
    use_style()
    bud = get_budget(budget)
    cols = PANELS_PER_ROW
    family_rows = [math.ceil(len(panels) / cols) for _, panels in FIG_5_3_ROWS]
    rows = sum(family_rows)
    fig, axes = plt.subplots(rows, cols, figsize=(5.2 * cols, 3.0 * rows + 1.0),
                             squeeze=False)  # fmt: skip
    spare, first = [], 0
    for (header, panels), n_rows in zip(FIG_5_3_ROWS, family_rows, strict=True):
        block = axes[first : first + n_rows].ravel()
        first += n_rows
        for ax, (task, title) in zip(block, panels, strict=False):
            _published_panel(ax, task, title, bud.bootstrap_reps)
        spare += list(block[len(panels) :])
        label = block[0].annotate(header, xy=(0, 1), xycoords="axes fraction",
                                  xytext=(-42, 22), textcoords="offset points", ha="left",
                                  va="bottom", fontsize=11, fontweight="bold")  # fmt: skip
        label.set_in_layout(False)  # tight_layout leaves room for it through h_pad
    fig.suptitle("Fig. 5.3: DIME on DMC dog / humanoid and MyoSuite, "
                 "IQM ± 95 % stratified-bootstrap CI")
    _footnote(
        fig,
        f"Published DIME curves only (10 seeds, thesis data). Not drawn: BRO, BRO (Fast), "
        f"CrossQ and the diffusion baselines ({_DIFFUSION_BASELINES}) of the thesis's "
        f"figure; their curves are not in the published data. dog-run and humanoid-run are "
        f"published to 3M env steps and drawn in full (dotted line: 1M, the other panels' "
        f"horizon).",
        width=125,
    )
    fig.tight_layout(rect=(0, 0.035, 1, 0.975), h_pad=2.6)
    if spare:  # the legend goes where the humanoid rows have no fourth panel
        box = spare[0].get_position()
        marker = Line2D([], [], color="0.4", ls=":", lw=1, label="1M steps (3M panels)")
        fig.legend(handles=[axes[0, 0].get_lines()[0], marker], loc="center",
                   bbox_to_anchor=(box.x0, box.y0, box.width, box.height), fontsize=9)
    for ax in spare:
        ax.remove()
    return fig


def _saver(fig_id: str, draw):
    def make(budget: Budget | None = None, out_dir: str | Path | None = None) -> list[Path]:
        fig = draw(budget=budget)
        paths = save_figure(fig, fig_id, out_dir=out_dir)
        plt.close(fig)
        return paths

    return make


def _register(fig_id: str, draw, doc: str) -> None:
    register_figure(fig_id, _saver(fig_id, draw), doc=doc)


_register("movement-primitives", lambda budget=None: draw_movement_primitives(),
          "Ch. 2: ProMP with a via-point, DMP rollouts, ProDMP initial conditions")
_register("dime-published", lambda budget=None: draw_dime_published(budget=budget),
          "Ch. 5 data: published 10-seed DIME curves of 21 tasks, IQM with 95 % CIs")
_register("fig5-2-published", lambda budget=None: draw_fig_5_2_published(budget=budget),
          "Fig. 5.2 (a)-(b): Ant-v3, Humanoid-v3 from the published DIME curves (IQM, 95 % CI)")
_register("fig5-3-published", lambda budget=None: draw_fig_5_3_published(budget=budget),
          "Fig. 5.3: dog, humanoid, MyoSuite (11 panels) from the published DIME curves")
_RUNS = "recorded runs, finished ones in ./runs, or trained now (--budget: that budget's)"
_register("fig3-1", lambda budget=None: figure_draws.draw_fig_3_1(budget=budget),
          f"Fig. 3.1: SVSL with / without responsibilities and HiREPS, planar reacher; {_RUNS}")
_register("fig3-2", lambda budget=None: figure_draws.draw_fig_3_2(budget=budget),
          f"Fig. 3.2 (a, b, e, f): beer pong and table tennis, SVSL, HiREPS, LaDiPS; {_RUNS}")
_register("fig3-5", lambda budget=None: figure_draws.draw_fig_3_5(budget=budget),
          f"Fig. 3.5: SVSL against PPO on the 5-link reacher (Eqs. 3.8-3.10); {_RUNS}")
for _fig in ("4.3b", "4.3c", "4.4a", "4.4b", "4.4c", "4.4d"):
    _register("fig" + _fig.replace(".", "-"),
              lambda budget=None, _f=_fig: figure_draws.draw_diskill_curves(_f, budget=budget),
              f"Fig. {_fig}: Chapter 4 learning curves; {_RUNS}")

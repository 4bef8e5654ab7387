"""Registered figures: ``vslbook figure ID`` and the notebooks draw them with these.

Each ``draw_*`` function returns a matplotlib figure (a notebook shows it inline); the
registered ``make`` wrapper saves it under ``build/figures`` (or ``--out``).
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib.pyplot as plt
import torch

from vslbook.budget import Budget, get_budget
from vslbook.movement import DMP, ProDMP, ProMP
from vslbook.plots import learning_curve, method_color, save_figure, use_style
from vslbook.registry import register_figure
from vslbook.results import paper_curves, paper_tasks
from vslbook.stats import iqm_curve


def draw_movement_primitives(seed: int = 0, n_samples: int = 20) -> plt.Figure:
    """ProMP trajectory distribution before/after a via-point, DMP rollouts to a goal,
    ProDMP trajectories from different initial conditions (Section 2.6.1)."""
    use_style()
    gen = torch.Generator().manual_seed(seed)
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6))

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
    axes[1].plot(dmp.times.numpy(), pos[..., 0].T.numpy(), lw=0.8, color=method_color("DIME"))
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
    cols = min(4, len(tasks))
    rows = math.ceil(len(tasks) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.4 * cols, 2.6 * rows), squeeze=False)
    for ax, task in zip(axes.flat, tasks, strict=False):
        curve = iqm_curve(paper_curves(task), reps=bud.bootstrap_reps)
        learning_curve(ax, curve, color=method_color("thesis"))
        ax.set(
            title=task, xlabel="env steps", ylabel="success" if task.startswith("myo") else "return"
        )
    for ax in axes.flat[len(tasks) :]:
        ax.set_visible(False)
    fig.suptitle("DIME, published learning curves (thesis data, 10 seeds): IQM ± 95 % CI")
    fig.tight_layout(rect=(0, 0, 1, 0.97))
    return fig


def _saver(fig_id: str, draw):
    def make(budget: Budget | None = None, out_dir: str | Path | None = None) -> list[Path]:
        fig = draw(budget=budget)
        paths = save_figure(fig, fig_id, out_dir=out_dir)
        plt.close(fig)
        return paths

    return make


register_figure(
    "movement-primitives",
    _saver("movement-primitives", lambda budget=None: draw_movement_primitives()),
    doc="Ch. 2: ProMP with a via-point, DMP rollouts, ProDMP initial conditions",
)
register_figure(
    "dime-published",
    _saver("dime-published", lambda budget=None: draw_dime_published(budget=budget)),
    doc="Ch. 5 data: published 10-seed DIME curves of 21 tasks, IQM with 95 % CIs",
)

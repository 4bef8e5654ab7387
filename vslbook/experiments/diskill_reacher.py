"""Fig. 4.2: what a trained Di-SkilL model does on the 5-link reacher (5LR).

* (a) the high-probability regions of the per-expert context distributions π(c | o):
  each goal of a grid over the disk is coloured by the expert that prefers it most, with an
  intensity proportional to that expert's π(c | o) (:func:`draw_context_regions`);
* (b) how many experts are *active* at each goal (:func:`active_experts`): expert o is
  active at c when π(c | o) > p(c), i.e. it draws c more often than the environment would
  (the thesis does not define "active"; this is our reading of Fig. 4.2b);
* (c) diverse solutions for the same goal: the tip trajectories of the experts' mean θ
  (:func:`reaches`, :func:`draw_reaches`).

π(c | o) is evaluated with the model's own normaliser, a fixed batch of contexts from p(c)
(:meth:`vslbook.erl.diskill.DiSkill.choose_experts`): with N contexts c_j ~ p(c),
π(c | o) / p(c) ≈ exp φ_o(c) / mean_j exp φ_o(c_j).
"""

from __future__ import annotations

from typing import Any

import matplotlib.pyplot as plt
import numpy as np
import torch

__all__ = [
    "active_experts", "disk_grid", "draw_active_experts", "draw_context_regions",
    "draw_reaches", "log_preference", "reaches",
]  # fmt: skip

RADIUS = 0.5  # 5LR's goals: the disk of radius 0.5 around the first joint (B.4.3)


def disk_grid(n: int = 41, radius: float = RADIUS) -> np.ndarray:
    """The points of an n × n grid on [−r, r]² that lie in the disk of radius r: (M, 2)."""
    if not isinstance(n, int) or n < 2:
        raise ValueError(f"n must be an integer >= 2, got {n!r}")
    g = np.linspace(-radius, radius, n)
    xy = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    return xy[np.hypot(xy[:, 0], xy[:, 1]) <= radius]


def log_preference(model: Any, contexts: np.ndarray) -> np.ndarray:
    """log π(c | o) − log p(c) for every expert and context: (K, M).

    Estimated with the model's normaliser batch c_j ~ p(c):
    φ_o(c) − log mean_j exp φ_o(c_j) (Eq. 4.6 with Z from samples of p(c)).
    """
    if model.energies is None:
        raise ValueError("the model has no context distributions (BBRL): nothing to show")
    dtype = model.energies.dtype  # the networks' (config.dtype)
    c = torch.as_tensor(np.asarray(contexts, dtype=np.float64), dtype=dtype)
    norm = torch.as_tensor(model.normaliser_contexts, dtype=dtype)
    with torch.no_grad():
        e_norm = model.energies.energies(norm)
        log_mean_z = torch.logsumexp(e_norm, -1) - np.log(e_norm.shape[-1])
        return (model.energies.energies(c) - log_mean_z[:, None]).double().numpy()


def active_experts(model: Any, contexts: np.ndarray, threshold: float = 0.0) -> np.ndarray:
    """How many experts have log π(c | o) − log p(c) > ``threshold`` at each context: (M,)."""
    return (log_preference(model, contexts) > threshold).sum(0)


def _colors(k: int) -> np.ndarray:
    """RGBA rows of the first ``k`` experts' colours (:func:`vslbook.plots.expert_color`)."""
    from matplotlib.colors import to_rgba

    from vslbook.plots import expert_color

    return np.array([to_rgba(expert_color(i)) for i in range(k)])


def _disk(ax: plt.Axes) -> None:
    ax.add_patch(plt.Circle((0, 0), RADIUS, fill=False, color="tab:red", lw=1.5))
    ax.plot(0, 0, "k+", ms=8)
    ax.set_aspect("equal")
    ax.set_xlim(-0.55, 0.55)
    ax.set_ylim(-0.55, 0.55)
    ax.set_xlabel("goal x [m]")
    ax.set_ylabel("goal y [m]")


def draw_context_regions(ax: plt.Axes, model: Any, grid: np.ndarray | None = None) -> plt.Axes:
    """Fig. 4.2a: each goal in the colour of the expert with the largest π(c | o), the
    intensity proportional to that probability (relative to the expert's own peak)."""
    grid = disk_grid() if grid is None else grid
    pref = log_preference(model, grid)  # (K, M)
    best = pref.argmax(0)
    # intensity: the expert's π(c | o) relative to its own largest value on the grid
    rel = np.exp(pref.max(0) - pref.max(1)[best])
    colors = _colors(pref.shape[0])[best]
    colors[:, 3] = np.clip(rel, 0.1, 1.0)
    ax.scatter(grid[:, 0], grid[:, 1], c=colors, s=18, marker="s", linewidths=0)
    _disk(ax)
    ax.set_title("(a) most probable expert per goal")
    return ax


def draw_active_experts(ax: plt.Axes, model: Any, grid: np.ndarray | None = None) -> plt.Axes:
    """Fig. 4.2b: the number of experts with π(c | o) > p(c) at each goal, one colour per
    count (a discrete scale with a tick at each whole number)."""
    from matplotlib.colors import BoundaryNorm

    grid = disk_grid() if grid is None else grid
    n = active_experts(model, grid)
    top = max(int(n.max()), 1)
    cmap = plt.get_cmap("viridis", top + 1)  # one colour per count 0, 1, …, top
    norm = BoundaryNorm(np.arange(-0.5, top + 1), cmap.N)
    sc = ax.scatter(grid[:, 0], grid[:, 1], c=n, s=18, marker="s", cmap=cmap, norm=norm,
                    linewidths=0)  # fmt: skip
    bar = plt.colorbar(sc, ax=ax, label="active experts", shrink=0.8)
    bar.set_ticks(np.arange(0, top + 1, max(1, (top + 10) // 11)))
    _disk(ax)
    ax.set_title("(b) experts with π(c|o) > p(c)")
    return ax


def reaches(model: Any, goal: np.ndarray) -> list[dict[str, Any]]:
    """Fig. 4.2c: every expert's mean θ at ``goal``: its tip path (T, 3), final distance and
    gating probability π(o | c)."""
    goal = np.asarray(goal, dtype=np.float64).reshape(1, -1)
    k = model.config.n_experts
    theta = model.mean_parameters(np.repeat(goal, k, 0), np.arange(k))
    if model.energies is not None and k > 1:
        from vslbook.erl.diskill_nets import log_gating

        pref = torch.as_tensor(log_preference(model, goal))
        gate = log_gating(pref).exp()[:, 0].numpy()
    else:
        gate = np.ones(k)
    out = []
    for o in range(k):
        tip = model.task.path(theta[o], goal[0])["fingertip"]
        distance = float(np.linalg.norm(tip[-1, :2] - goal[0]))
        out.append({"expert": o, "tip": tip, "distance": distance, "gating": float(gate[o])})
    return out


def draw_reaches(
    ax: plt.Axes, model: Any, goals: np.ndarray, *, min_gating: float = 0.05
) -> plt.Axes:
    """Fig. 4.2c: tip trajectories of the experts that the gating picks with probability at
    least ``min_gating`` at each goal, in the experts' colours."""
    colors = _colors(model.config.n_experts)
    for goal in np.atleast_2d(goals):
        for r in reaches(model, goal):
            if r["gating"] < min_gating:
                continue
            ax.plot(r["tip"][:, 0], r["tip"][:, 1], color=colors[r["expert"]], lw=1.2, alpha=0.9)
            ax.plot(*r["tip"][-1, :2], "o", color=colors[r["expert"]], ms=3)
        ax.plot(*goal, "*", color="tab:red", ms=10, mec="k", mew=0.5)
    _disk(ax)
    ax.set_title(f"(c) tip paths of experts with π(o|c) ≥ {min_gating:g}")
    return ax
